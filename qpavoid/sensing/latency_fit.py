"""A camera's latency fitted: the lag that best aligns its landmark with the arm's flange.

The model (:func:`estimate_latency`)::

    h_k = p(t_k − τ) + b + e_k

``h_k`` the hand landmark of the frame stamped ``t_k`` (base frame, m), ``p`` the flange's
position from the encoders (linear interpolation between the arm's samples), ``b`` the
hand's constant offset from the flange, ``e_k`` the camera's noise. τ and ``b`` are fitted
by least squares: for each lag on a grid over a bounded range the offset is the mean
residual (exact for a given lag), the best lag of the grid is refined by Brent's bounded
method (:func:`scipy.optimize.minimize_scalar`) between its neighbours. The camera's
samples are used at their own time stamps (irregular, with gaps), never resampled, and
the arm's are dense (100 Hz to 1 kHz), so the lag is continuous, not a multiple of a frame
period. Frames whose hand is more than :attr:`LatencyConfig.outlier_factor` times the
median distance from the fit (a left/right swap, a tracker's glitch) are left out and the
fit is made again. What τ is, the camera's latency or the error of its stamps, depends on
the stamps the recording holds (:mod:`qpavoid.sensing.latency`).

**Its uncertainty** is the delete-one-block jackknife's standard error over
:attr:`LatencyConfig.blocks` contiguous blocks of the frames (Künsch, "The jackknife and
the bootstrap for general stationary observations", Ann. Statist. 17(3), 1989): it holds
for noise that is correlated in time (a hand that wobbles on the flange), where the fit's
own standard error would be too small.

**Refused** (:class:`~qpavoid.core.errors.InputError` naming the measure at fault and its
value), never a number: too few frames of the landmark within the arm log's time (two
clocks), a flange that hardly moved, a hand that did not follow it (the fit's residual
and the share of the hand's motion it explains), too many outliers, a best lag at an end
of the range searched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from qpavoid.core.checks import as_array, check_range, finite_number
from qpavoid.core.errors import InputError
from qpavoid.sensing.arm_log import increasing_times
from qpavoid.sensing.hand_track import landmark_index

__all__ = ["NEAR_S", "LatencyConfig", "LatencyEstimate", "estimate_latency"]


@dataclass(frozen=True)
class LatencyConfig:
    """How a latency is fitted, and when a recording is refused (units: s, m).

    Attributes
    ----------
    landmark
        The landmark on the flange (:data:`~qpavoid.sensing.hand_track.LANDMARKS`; default
        the right hand: most people hold with it; the wrist for a camera that derives the
        hand, docs/sensors.md §10).
    min_lag_s, max_lag_s
        The lags searched, s. Default −0.1 to 0.5: the largest latency users report for
        these cameras is 0.25 s (docs/sensors.md §10), twice that is searched; a negative
        lag (stamps earlier than the poses) is only possible with capture stamps on a
        clock that is off, and 0.1 s of it is searched so that it shows as a number.
    grid_step_s
        The step of the grid the best lag is first looked for on, s (then refined between
        its neighbours). 2 ms: a sixteenth of a 30 Hz frame period, far below the
        excitation's quarter period (0.35 s at 0.71 Hz), so no minimum is stepped over.
    min_frames
        The fewest frames of the landmark that may be fitted: 150, 5 s at 30 Hz (and 15
        frames per jackknife block).
    min_motion_m
        The least RMS excursion of the flange about its mean over the frames fitted, m:
        20 mm, the noisiest camera's noise per axis at 2 m (15 mm) and some.
    max_residual_m
        The largest RMS distance between the hand and the fitted flange (3D), m: 50 mm,
        twice the noisiest camera's 3D noise at 2 m (26 mm). A hand that did not hold the
        flange is off by the flange's whole excursion.
    min_explained
        The least share of the hand's motion (its variance about its mean) that the
        flange's explains: 0.5. A hand on the flange explains 0.8-1.0 of it (the camera's
        noise the rest); one off the flange, at rest or moving on its own, nearly none.
    outlier_factor, outlier_floor_m
        A frame whose hand is farther from the fit than ``outlier_factor`` times the
        median distance, and than ``outlier_floor_m``, is an outlier. 4: for Gaussian noise
        in 3D the median distance is 1.54 σ and 99.9 % of them are within 4.03 σ, so
        4 × 1.54 σ = 6.2 σ leaves out no honest frame; 10 mm: within every camera's noise.
    max_outlier_fraction
        The largest share of outliers: 0.2. More, and the hand was off the flange (or
        the tracker lost it) too often for the rest to be trusted.
    blocks
        The jackknife's blocks: 10 contiguous stretches of the frames fitted (each at
        least 3 excitation periods long in a 30 s recording).
    """

    landmark: str = "right_hand"
    min_lag_s: float = -0.1
    max_lag_s: float = 0.5
    grid_step_s: float = 0.002
    min_frames: int = 150
    min_motion_m: float = 0.02
    max_residual_m: float = 0.05
    min_explained: float = 0.5
    outlier_factor: float = 4.0
    outlier_floor_m: float = 0.01
    max_outlier_fraction: float = 0.2
    blocks: int = 10

    def __post_init__(self) -> None:
        landmark_index(self.landmark)
        for name, low, high, unit in (
            ("min_lag_s", -1.0, 1.0, "s"),
            ("max_lag_s", -1.0, 1.0, "s"),
            ("grid_step_s", 1e-4, 0.05, "s"),
            ("min_motion_m", 0.0, 1.0, "m"),
            ("max_residual_m", 0.0, 1.0, "m"),
            ("min_explained", 0.0, 1.0, "(a fraction)"),
            ("outlier_factor", 1.0, 100.0, "(times the median)"),
            ("outlier_floor_m", 0.0, 1.0, "m"),
            ("max_outlier_fraction", 0.0, 1.0, "(a fraction)"),
        ):
            check_range(name, finite_number(getattr(self, name), name), low, high, unit)
        if self.max_lag_s - self.min_lag_s < 4 * self.grid_step_s:
            raise InputError(
                f"the lags searched, {self.min_lag_s:g} to {self.max_lag_s:g} s (--max-lag), "
                f"must span at least 4 grid steps ({4 * self.grid_step_s:g} s)",
                name="max_lag_s",
                value=self.max_lag_s,
            )
        for name, low in (("min_frames", 10), ("blocks", 2)):
            value = getattr(self, name)
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= low):
                raise InputError(
                    f"{name} must be a whole number from {low}, got {value!r}",
                    name=name,
                    value=value,
                )


@dataclass(frozen=True)
class LatencyEstimate:
    """A camera's latency fitted to the arm's encoders (:func:`estimate_latency`).

    Attributes
    ----------
    latency_s
        The lag of the recording's time stamps behind the arm, s (with arrival stamps, the
        camera's latency: :mod:`qpavoid.sensing.latency`).
    uncertainty_s
        Its standard error, s (the blocks' jackknife).
    residual_m
        RMS distance (3D) between the landmark and the flange shifted by the lag and the
        offset, over the frames fitted, m: how well the hand followed the flange.
    explained
        The share of the landmark's motion (variance about its mean) the flange's explains,
        0-1 (0 also for a hand whose motion is not the flange's at all: R² below 0).
    frames
        The camera frames fitted (outliers left out).
    outliers
        The frames left out as outliers.
    motion_m
        The flange's RMS excursion about its mean over the frames fitted, m.
    offset_m
        The landmark's mean offset from the flange, base frame, m.
    landmark
        The landmark fitted (:data:`~qpavoid.sensing.hand_track.LANDMARKS`).
    """

    latency_s: float
    uncertainty_s: float
    residual_m: float
    explained: float
    frames: int
    outliers: int
    motion_m: float
    offset_m: tuple[float, float, float]
    landmark: str

    @property
    def suggested_latency_s(self) -> float:
        """What to give ``--latency``, s: the estimate plus two standard errors (an
        under-estimated latency is unsafe, speed and separation's distance grows with it),
        rounded up to the millisecond, at least 0."""
        upper = self.latency_s + 2.0 * self.uncertainty_s
        return max(0.0, math.ceil(round(upper * 1000.0, 6)) / 1000.0)


def estimate_latency(
    camera_t: object,
    camera_m: object,
    arm_t: object,
    flange_m: object,
    config: LatencyConfig | None = None,
) -> LatencyEstimate:
    """The lag that best aligns a camera's landmark with the flange (module docstring).

    Parameters
    ----------
    camera_t
        (N,) the frames' time stamps, s, strictly increasing, on the arm's clock.
    camera_m
        (N, 3) the landmark in the base frame, m; NaN where not seen.
    arm_t
        (M,) the arm's sample times, s, strictly increasing.
    flange_m
        (M, 3) the flange in the base frame at those times, m
        (:func:`~qpavoid.sensing.arm_log.flange_positions`).
    config
        The lags searched and the refusals.

    Returns
    -------
    LatencyEstimate

    Raises
    ------
    InputError
        On arrays of the wrong shape, or a recording that cannot give a latency (module
        docstring); ``name`` is the measure at fault (``"frames"``, ``"motion_m"``,
        ``"outliers"``, ``"residual_m"``, ``"latency_s"``) and ``value`` its value.
    """
    cfg = config or LatencyConfig()
    t = increasing_times(camera_t, "camera_t (frame times, s)", least=0)
    h = as_array(camera_m, (t.size, 3), "camera_m (landmark, m)", finite=False)
    ta = increasing_times(arm_t, "arm_t (arm log times, s)")
    p = as_array(flange_m, (ta.size, 3), "flange_m (flange, m)")
    inside = (t - cfg.max_lag_s >= ta[0]) & (t - cfg.min_lag_s <= ta[-1])
    keep = inside & np.isfinite(h).all(axis=1)
    if keep.sum() < cfg.min_frames:
        seen = f"{t[0]:.3f} to {t[-1]:.3f} s" if t.size else "nothing"
        hand = cfg.landmark.replace("_", " ")
        raise InputError(
            f"only {int(keep.sum())} frames with the {hand} seen lie within the arm log's "
            f"time at every lag searched ({cfg.min_lag_s:g} to {cfg.max_lag_s:g} s): at "
            f"least {cfg.min_frames} are needed; the recording spans {seen}, the arm log "
            f"{ta[0]:.3f} to {ta[-1]:.3f} s: are they on one clock?",
            name="frames",
            value=int(keep.sum()),
        )
    t, h = t[keep], h[keep]
    fit = _Fit(t, h, ta, p, cfg)
    inliers = np.ones(t.size, dtype=bool)
    lag = fit.best_lag(inliers)
    for _ in range(3):  # leave the outliers out and fit again, until they stay the same
        distance = np.linalg.norm(fit.residuals(lag, inliers, robust=True), axis=1)
        limit = max(cfg.outlier_factor * float(np.median(distance[inliers])), cfg.outlier_floor_m)
        again = distance <= limit
        if np.array_equal(again, inliers):
            break
        inliers = again
        if inliers.sum() < cfg.min_frames:  # refused below: too many outliers
            break
        lag = fit.best_lag(inliers)
    r = fit.residuals(lag, inliers)[inliers]
    hand = h[inliers] - h[inliers].mean(axis=0)
    flange = fit.flange(lag)[inliers]
    motion = float(np.sqrt(np.mean(np.sum((flange - flange.mean(axis=0)) ** 2, axis=1))))
    residual = float(np.sqrt(np.mean(np.sum(r**2, axis=1))))
    explained = max(0.0, float(1.0 - np.sum(r**2) / max(np.sum(hand**2), 1e-300)))
    n, outliers = int(inliers.sum()), int((~inliers).sum())
    _check_fit(cfg, lag, n, outliers, motion, residual, explained)
    blocks = np.array_split(np.flatnonzero(inliers), cfg.blocks)
    leave_one_out = []
    for block in blocks:
        rest = inliers.copy()
        rest[block] = False
        leave_one_out.append(fit.best_lag(rest, near=lag))
    spread = np.asarray(leave_one_out) - np.mean(leave_one_out)
    uncertainty = math.sqrt((cfg.blocks - 1) / cfg.blocks * float(np.sum(spread**2)))
    offset = (h[inliers] - flange).mean(axis=0)
    return LatencyEstimate(
        latency_s=float(lag),
        uncertainty_s=uncertainty,
        residual_m=residual,
        explained=explained,
        frames=n,
        outliers=outliers,
        motion_m=motion,
        offset_m=(float(offset[0]), float(offset[1]), float(offset[2])),
        landmark=cfg.landmark,
    )


#: How far from the whole recording's lag the jackknife looks for each block's first, s.
NEAR_S = 0.04


class _Fit:
    """The least-squares cost of a lag over a subset of the frames (module docstring)."""

    def __init__(
        self, t: np.ndarray, h: np.ndarray, arm_t: np.ndarray, p: np.ndarray, cfg: LatencyConfig
    ):
        self.t, self.h, self.arm_t, self.p, self.cfg = t, h, arm_t, p, cfg
        n = round((cfg.max_lag_s - cfg.min_lag_s) / cfg.grid_step_s) + 1
        self.lags = np.linspace(cfg.min_lag_s, cfg.max_lag_s, n)

    def flange(self, lag: float) -> np.ndarray:
        """(N, 3) the flange at each frame's time less ``lag``."""
        at = self.t - lag
        return np.stack([np.interp(at, self.arm_t, self.p[:, a]) for a in range(3)], axis=1)

    def residuals(self, lag: float, subset: np.ndarray, robust: bool = False) -> np.ndarray:
        """(N, 3) landmark less flange at ``lag``, less their mean over ``subset`` (``robust``:
        their median, which outliers do not drag)."""
        r = self.h - self.flange(lag)
        return r - (np.median(r[subset], axis=0) if robust else r[subset].mean(axis=0))

    def cost(self, lag: float, subset: np.ndarray) -> float:
        """The sum of squared residuals over ``subset`` at ``lag``, m²."""
        return float(self.costs(np.array([lag]), subset)[0])

    def costs(self, lags: np.ndarray, subset: np.ndarray) -> np.ndarray:
        """:meth:`cost` at each of ``lags`` (a few dozen lags at a time in one array)."""
        t, h = self.t[subset], self.h[subset]
        out = []
        for chunk in np.array_split(lags, math.ceil(lags.size / 32)):
            at = (t[None, :] - chunk[:, None]).ravel()
            p = np.stack([np.interp(at, self.arm_t, self.p[:, a]) for a in range(3)], axis=1)
            r = h[None] - p.reshape(chunk.size, t.size, 3)
            r -= r.mean(axis=1, keepdims=True)
            out.append(np.einsum("gnx,gnx->g", r, r))
        return np.concatenate(out)

    def best_lag(self, subset: np.ndarray, near: float | None = None) -> float:
        """The lag of least cost: the grid's best, refined between its neighbours. ``near``:
        the grid within :data:`NEAR_S` of it first (a jackknife's estimate is near the
        whole one's), the whole grid if the best is at that window's edge."""
        lags = self.lags
        if near is not None:
            lags = lags[np.abs(lags - near) <= NEAR_S]
        costs = self.costs(lags, subset)
        i = int(np.argmin(costs))
        if near is not None and i in (0, lags.size - 1) and lags.size < self.lags.size:
            return self.best_lag(subset)
        lo, hi = lags[max(i - 1, 0)], lags[min(i + 1, lags.size - 1)]
        found = minimize_scalar(
            self.cost, bounds=(lo, hi), args=(subset,), method="bounded", options={"xatol": 1e-7}
        )
        return float(found.x) if found.fun <= costs[i] else float(lags[i])


def _check_fit(
    cfg: LatencyConfig,
    lag: float,
    frames: int,
    outliers: int,
    motion: float,
    residual: float,
    explained: float,
) -> None:
    """Refuse a fit that gives no latency (module docstring): too many outliers (the rest
    is too few to judge), no motion, a hand off the flange, a lag at an end of the range."""
    name = cfg.landmark.replace("_", " ")
    share = outliers / (frames + outliers)
    if share > cfg.max_outlier_fraction or frames < cfg.min_frames:
        raise InputError(
            f"the {name} was off the flange in {outliers} of {frames + outliers} frames "
            f"({share:.0%}, at most {cfg.max_outlier_fraction:.0%}): hold the flange for the "
            "whole recording, facing the camera",
            name="outliers",
            value=outliers,
        )
    if motion < cfg.min_motion_m:
        raise InputError(
            f"the flange moved {motion * 1e3:.1f} mm RMS over the frames fitted: at least "
            f"{cfg.min_motion_m * 1e3:g} mm are needed to see a lag (record while the arm "
            "moves its excitation)",
            name="motion_m",
            value=motion,
        )
    if residual > cfg.max_residual_m or explained < cfg.min_explained:
        raise InputError(
            f"the {name} did not follow the flange: {residual * 1e3:.1f} mm RMS from it at the "
            f"best lag (at most {cfg.max_residual_m * 1e3:g} mm), {explained:.0%} of its motion "
            f"explained by the flange's (at least {cfg.min_explained:.0%}); was the hand on "
            "the flange, the calibration right, the landmark the hand that held it?",
            name="residual_m",
            value=residual,
        )
    step = cfg.grid_step_s
    if lag <= cfg.min_lag_s + step or lag >= cfg.max_lag_s - step:
        raise InputError(
            f"the best lag, {lag:.3f} s, is at an end of the lags searched "
            f"({cfg.min_lag_s:g} to {cfg.max_lag_s:g} s): a latency beyond them (--max-lag), "
            "or the two files' clocks apart",
            name="latency_s",
            value=lag,
        )
