"""Speed and separation monitoring (ISO/TS 15066 §5.5.4, ISO 10218-2): each term one function.

The protective separation distance at time t₀ (ISO/TS 15066, eq. 1):

    S_p(t₀) = S_h + S_r + S_s + C + Z_d + Z_r

* S_h: how far the person moves from the moment the frame was captured until the robot
  is stationary, v_h · (T_f + T_r + T_s), where T_f is the frame's age (sensor latency
  and sample-and-hold: the person moved while the frame travelled);
* S_r: how far the robot moves during its reaction time, v_r · T_r;
* S_s: the robot's stopping distance. A stop is a path-keeping ramp that takes
  ``T_s = max_j |q̇_j| / a_j`` (:mod:`qpavoid.arm.braking`); the controllers keep every joint
  within ``a_j T_s`` for a budget T_s (:func:`joint_speed_limits`), so a point moving at
  v_r travels at most v_r · T_s / 2 while braking;
* C: the intrusion distance, how far a body part reaches past what the model covers;
* Z_d: the sensing uncertainty of the person's position (a tracked joint's; lost and
  inferred joints add their own radius, :mod:`qpavoid.perception.tracker`);
* Z_r: the uncertainty of the robot's position.

T_r, T_s and so S_r and S_s come from the robot description (:meth:`SSMConfig.resolve`),
and from its maker's data where it gives them (``[arm]``, :mod:`qpavoid.arm.dynamics`):

* a_j is the **slower** of the joint's acceleration limit and the maker's stopping data:
  a stop the maker measured from v₀ lasting T₀ over D₀ brakes at ``min(v₀/T₀, v₀²/(2D₀))``
  (:meth:`~qpavoid.arm.dynamics.ArmDynamics.braking_deceleration_radps2`), so T_s and S_s
  are never shorter than the maker's stop at its speed, nor than the ramp the acceleration
  limit allows (without stopping data a_j is the acceleration limit, as before);
* T_r is the arm's reaction plus, for an arm with jerk limits, the lag
  ``2 max_j a_j / j_j`` (:func:`~qpavoid.arm.braking.jerk_lag_s`) after which a
  constant-deceleration ramp bounds the jerk-limited stop in time and distance.

``S_p ≤ d`` is then linear in the robot point's approach speed v_r and
:func:`max_approach_speed` is its bound: the fastest the robot may approach a person at
separation d and still be stationary before contact. Where even a robot at rest is too
close, the bound is negative: the robot must move away at least that fast, or stop. The
human speed is ISO 13855's: 2.0 m/s within 0.5 m, 1.6 m/s beyond (:func:`human_speed`).

Every function is pure and works element-wise on arrays (every set × part pair at once).
Units: m, s, m/s, rad/s².
"""

from __future__ import annotations

import copy
import functools
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from qpavoid.arm.braking import jerk_lag_s, per_joint, stop_time
from qpavoid.arm.dynamics import ArmDynamics
from qpavoid.core.checks import check_range
from qpavoid.core.errors import InputError
from qpavoid.distance.table import DistanceTable
from qpavoid.human.body import KINECT_V2_BODY_PARTS
from qpavoid.human.kinect_v2 import KINECT_V2


@dataclass(frozen=True)
class SSMConfig:
    """Constants of speed and separation monitoring (sources: docs/safety.md).

    Attributes
    ----------
    human_speed_near_mps, human_speed_far_mps, human_speed_zone_m
        ISO 13855 approach speed of a hand or arm: 2.0 m/s when the separation is at most
        0.5 m, 1.6 m/s beyond.
    body_parts, body_speed_mps
        Parts that move with the body, not the arm (the head and trunk of a seated person:
        by default the body model file's ``moves_with_body`` parts), and their speed:
        ISO 13855's approach speed of the body, 1.6 m/s.
    reaction_time_s
        T_r: from the controller's tick to the arm starting to brake: one control period
        and the arm's reaction, s. None (the default): the robot description's
        (``[arm] reaction_time_s``, plus the jerk lag of an arm with jerk limits;
        :meth:`resolve`).
    stop_time_s
        T_s,max: the longest stop the controllers allow, s; each tick's budget is shorter
        while the robot moves slowly (:class:`StopTimeBudget`), and every joint is kept
        within ``a_j T_s``.
    max_acceleration_radps2
        a_j: the joint decelerations a stop counts on, ``(joint name, rad/s²)`` pairs (as
        in :class:`~qpavoid.arm.braking.BrakingConfig`). None (the default): the robot
        description's, the slower of ``[arm] max_acceleration_radps2`` and the maker's
        ``[[arm.stopping]]`` data (:meth:`resolve`).
    intrusion_m
        C: how far a hand reaches past its modelled capsule (the fingers beyond HandTip).
    sensing_uncertainty_m
        Z_d: the position error of a tracked joint, m (by default the Kinect v2 format
        file's ``sensor.tracked_uncertainty_m``).
    robot_uncertainty_m
        Z_r: the robot's position error (repeatability and the capsules' fit), m.
    body_acceleration_mps2, speed_error_mps
        The reachable occupancy of a part moving with the body (SaRA shield's acceleration
        model, :func:`accelerated_reach`): from its tracked speed plus ``speed_error_mps``,
        it cannot pass the body's speed sooner than ``body_acceleration_mps2`` allows
        (SaRA's human model: 20 m/s² for the torso, 25 for the neck and head). None (the
        default): off, the body's speed for the whole time, because the model is sound
        only if the tracked speed is within ``speed_error_mps`` of the truth, which no
        body-tracking camera publishes and a position error Z_d does not give (a lunge of
        25 m/s² hides within 2 Z_d = 8 cm for 80 ms, long enough to reach 2 m/s): an
        option for a sensor that measures velocity, weighed in docs/safety.md §7b.
    """

    human_speed_near_mps: float = 2.0
    human_speed_far_mps: float = 1.6
    human_speed_zone_m: float = 0.5
    body_parts: tuple[str, ...] = KINECT_V2_BODY_PARTS
    body_speed_mps: float = 1.6
    reaction_time_s: float | None = None
    stop_time_s: float = 0.06
    max_acceleration_radps2: tuple[tuple[str, float], ...] | None = None
    intrusion_m: float = 0.02
    sensing_uncertainty_m: float = KINECT_V2.sensor.tracked_uncertainty_m
    robot_uncertainty_m: float = 0.005
    body_acceleration_mps2: float | None = None
    speed_error_mps: float = 0.5

    def __post_init__(self) -> None:
        if self.body_acceleration_mps2 is not None:
            # a body's acceleration: above 0, and a human body's far below 1000 m/s²
            check_range("body_acceleration_mps2", self.body_acceleration_mps2, 1e-3, 1e3, "m/s²")
        check_range("speed_error_mps", self.speed_error_mps, 0.0, 10.0, "m/s")

    def resolve(self, arm: ArmDynamics) -> SSMConfig:
        """This config with the arm's values left at None taken from the robot
        description's ``arm``; a value given here is used as it is.

        * ``max_acceleration_radps2``: per joint the slower of the acceleration limit and
          the maker's stopping data, ``a_j = min(a_j, v₀/T₀, v₀²/(2 D₀))``
          (:meth:`~qpavoid.arm.dynamics.ArmDynamics.braking_deceleration_radps2`): where the
          maker's stop is slower than the ramp the limit allows, T_s and S_s are the maker's
          (scaled to the speed as a constant deceleration); otherwise they are as computed
          from the limit. Without stopping data: the limits themselves.
        * ``reaction_time_s``: the arm's reaction, plus the jerk lag ``2 max_j a_j / j_j``
          of an arm with jerk limits (:func:`~qpavoid.arm.braking.jerk_lag_s`; none for
          the iiwa).
        """
        # (getattr: a description read before the maker's data existed has neither)
        if self.reaction_time_s is None:
            lag = jerk_lag_s(arm.max_acceleration_radps2, getattr(arm, "max_jerk_radps3", ()))
            reaction = arm.reaction_time_s + lag if lag > 0.0 else arm.reaction_time_s
        else:
            reaction = self.reaction_time_s
        braking = getattr(arm, "braking_deceleration_radps2", None)
        return replace(
            self,
            reaction_time_s=reaction,
            max_acceleration_radps2=(
                (braking() if braking is not None else arm.max_acceleration_radps2)
                if self.max_acceleration_radps2 is None
                else self.max_acceleration_radps2
            ),
        )


def _t_r(cfg: SSMConfig) -> float:
    """T_r of ``cfg``, s.

    Raises
    ------
    InputError
        If ``cfg`` leaves it to the robot description (not resolved: :meth:`SSMConfig.resolve`).
    """
    if cfg.reaction_time_s is None:
        raise InputError(
            "no reaction time: take it from the robot description first "
            "(SSMConfig.resolve(robot.arm))",
            name="reaction_time_s",
            value=None,
        )
    return cfg.reaction_time_s


def human_speed(separation_m: ArrayLike, cfg: SSMConfig, body: ArrayLike = False) -> np.ndarray:
    """v_h (ISO 13855): a hand or arm 2.0 m/s within 0.5 m, 1.6 m/s beyond; ``body`` parts
    (head, trunk; broadcast against ``separation_m``) 1.6 m/s."""
    d = np.asarray(separation_m, dtype=float)
    arm = np.where(d <= cfg.human_speed_zone_m, cfg.human_speed_near_mps, cfg.human_speed_far_mps)
    return np.where(body, cfg.body_speed_mps, arm)


def human_distance(
    human_speed_mps: ArrayLike, frame_age_s: ArrayLike, cfg: SSMConfig
) -> np.ndarray:
    """S_h = v_h (T_f + T_r + T_s): the person's travel from capture until the robot stands."""
    return np.asarray(human_speed_mps, dtype=float) * (
        np.asarray(frame_age_s, dtype=float) + _t_r(cfg) + cfg.stop_time_s
    )


def accelerated_reach(
    horizon_s: ArrayLike, speed_mps: ArrayLike, max_speed_mps: float, acceleration_mps2: float
) -> np.ndarray:
    """How far a point moving at ``speed_mps`` now can travel in ``horizon_s``, m, if it
    accelerates at most ``acceleration_mps2`` up to ``max_speed_mps`` (SaRA shield's
    acceleration model under ISO 13855's speed, Schepp et al., ICRA 2022):

        D(T) = ∫₀ᵀ min(v_max, v₀ + a t) dt
             = v₀ T + a T² / 2                          for T ≤ t₁ = (v_max − v₀) / a
             = v₀ t₁ + a t₁² / 2 + v_max (T − t₁)        beyond,

    with v₀ = min(speed, v_max): never more than ``v_max T``, ISO's bound, and equal to it
    for a point already at v_max."""
    t = np.asarray(horizon_s, dtype=float)
    v0 = np.minimum(np.asarray(speed_mps, dtype=float), max_speed_mps)
    t1 = (max_speed_mps - v0) / acceleration_mps2
    ramp = v0 * t + 0.5 * acceleration_mps2 * t * t
    capped = v0 * t1 + 0.5 * acceleration_mps2 * t1 * t1 + max_speed_mps * (t - t1)
    return np.where(t <= t1, ramp, capped)


def reaction_distance(robot_speed_mps: ArrayLike, cfg: SSMConfig) -> np.ndarray:
    """S_r = v_r T_r: the robot's travel during its reaction time."""
    return np.asarray(robot_speed_mps, dtype=float) * _t_r(cfg)


def stopping_distance(robot_speed_mps: ArrayLike, cfg: SSMConfig) -> np.ndarray:
    """S_s = v_r T_s / 2: the robot's travel during a linear ramp to rest lasting T_s."""
    return np.asarray(robot_speed_mps, dtype=float) * cfg.stop_time_s / 2.0


def fixed_terms(cfg: SSMConfig) -> float:
    """C + Z_d + Z_r, m."""
    return cfg.intrusion_m + cfg.sensing_uncertainty_m + cfg.robot_uncertainty_m


def protective_distance(
    robot_speed_mps: ArrayLike,
    separation_m: ArrayLike,
    frame_age_s: ArrayLike,
    cfg: SSMConfig,
    body: ArrayLike = False,
) -> np.ndarray:
    """S_p = S_h + S_r + S_s + C + Z_d + Z_r (ISO/TS 15066 eq. 1), m.

    Parameters
    ----------
    robot_speed_mps
        v_r: the robot point's speed towards the person (negative: moving away).
    separation_m
        The current separation d (it selects the human speed's zone).
    frame_age_s
        T_f: the age of the frame d was measured on.
    cfg
        The constants.
    body
        True for a part that moves with the body (:func:`human_speed`).
    """
    return (
        human_distance(human_speed(separation_m, cfg, body), frame_age_s, cfg)
        + reaction_distance(robot_speed_mps, cfg)
        + stopping_distance(robot_speed_mps, cfg)
        + fixed_terms(cfg)
    )


def max_approach_speed(
    separation_m: ArrayLike,
    frame_age_s: ArrayLike,
    cfg: SSMConfig,
    body: ArrayLike = False,
    part_speed_mps: ArrayLike | None = None,
) -> np.ndarray:
    """The largest v_r with ``S_p(v_r) ≤ d``: ``(d − S_h − C − Z_d − Z_r) / (T_r + T_s/2)``.

    Negative where even a robot at rest is too close (it must move away at least that fast,
    or stop); −inf stays −inf and +inf (a part not seen) gives +inf. A frame of infinite
    or unknown age allows no approach at all (−inf; the controller stops on it anyway).
    With ``cfg.body_acceleration_mps2`` set and the parts' tracked speeds
    ``part_speed_mps`` given, a ``body`` part's S_h is the smaller of ISO's and
    :func:`accelerated_reach` from its speed plus ``cfg.speed_error_mps``.
    """
    d = np.asarray(separation_m, dtype=float)
    if not np.all(np.isfinite(frame_age_s)):
        return np.full(d.shape, -np.inf)
    s_h = human_distance(human_speed(d, cfg, body), frame_age_s, cfg)
    if cfg.body_acceleration_mps2 is not None and part_speed_mps is not None:
        horizon = np.asarray(frame_age_s, dtype=float) + _t_r(cfg) + cfg.stop_time_s
        reach = accelerated_reach(
            horizon,
            np.asarray(part_speed_mps, dtype=float) + cfg.speed_error_mps,
            cfg.body_speed_mps,
            cfg.body_acceleration_mps2,
        )
        s_h = np.where(body, np.minimum(s_h, reach), s_h)
    room = d - s_h - fixed_terms(cfg)
    return room / (_t_r(cfg) + cfg.stop_time_s / 2.0)


def hold_distance(separation_m: float, frame_age_s: float, cfg: SSMConfig, body: bool) -> float:
    """The separation a robot at rest needs from a part, m: S_p at v_r = 0, S_h + C + Z_d +
    Z_r (ISO/TS 15066 eq. 1; ``separation_m`` selects the human speed's zone). Closer,
    :func:`max_approach_speed` is negative and the robot holds (or retreats). ISO 13855's
    speeds: with ``cfg.body_acceleration_mps2`` set (off by default), the bound used for a
    body part may be smaller than this."""
    speed = human_speed(separation_m, cfg, body)
    return float(human_distance(speed, frame_age_s, cfg)) + fixed_terms(cfg)


def with_stop_time(cfg: SSMConfig, stop_time_s: float) -> SSMConfig:
    """``cfg`` with this tick's T_s: a shallow copy, ten times cheaper than
    ``dataclasses.replace`` (which runs the checks again), for a value that changes
    every tick."""
    out = copy.copy(cfg)
    object.__setattr__(out, "stop_time_s", float(stop_time_s))
    return out


def joint_speed_limits(cfg: SSMConfig, joint_names: Sequence[str]) -> np.ndarray:
    """|q̇_j| ≤ a_j T_s: the joint speeds from which a stop takes at most T_s, rad/s."""
    return per_joint(cfg.max_acceleration_radps2, joint_names) * cfg.stop_time_s


def speed_scale(approach_mps: np.ndarray, limit_mps: np.ndarray) -> float | None:
    """The largest s in [0, 1] with ``s · v_r ≤ limit`` for every pair, or None if none.

    Speed scaling: the whole command is multiplied by s, so each pair's approach speed
    v_r scales with it. A pair with a negative limit needs a retreat at least that fast,
    which scaling can only keep (v_r < 0) and never create: None (the robot stops).
    """
    v, b = np.asarray(approach_mps, dtype=float), np.asarray(limit_mps, dtype=float)
    if np.any(b[v == 0.0] < 0.0):
        return None
    up, down = v > 0.0, v < 0.0
    high = float(np.min(b[up] / v[up], initial=1.0))
    low = float(np.max(b[down] / v[down], initial=0.0))
    return min(high, 1.0) if min(high, 1.0) >= max(low, 0.0) else None


def separation_bounds(
    table: DistanceTable, part_velocity: np.ndarray, frame_age_s: float, cfg: SSMConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Every set × part pair's bound and the part's own speed towards the set, (S, K) m/s.

    The bound is :func:`max_approach_speed` of the pair's distance; the part's speed is its
    velocity (``part_velocity`` (K, 3), m/s) along the direction from the part to the set,
    where positive (approaching). With several people, ``part_velocity`` may be (S, K, 3):
    the velocity of the part of the person closest to each set.
    """
    body = _body_mask(tuple(table.part_names), tuple(cfg.body_parts))
    v = np.broadcast_to(part_velocity, table.vector.shape)  # (K, 3) or per pair (S, K, 3)
    speed = None if cfg.body_acceleration_mps2 is None else np.linalg.norm(v, axis=-1)
    limit = max_approach_speed(table.distance, frame_age_s, cfg, body, speed)
    towards = np.einsum("skx,skx->sk", table.vector, v)  # vector: human -> robot
    return limit, np.maximum(towards, 0.0)


def separation_constants(cfg: SSMConfig) -> tuple[float, ...]:
    """The scalars :func:`approach_bounds` takes, in its order: T_r, T_s, the human
    speeds' zone (m) and speeds (near, far, body; m/s), C + Z_d + Z_r (m), the body's
    acceleration (m/s², NaN: off) and the speed error (m/s)."""
    accel = cfg.body_acceleration_mps2
    return (
        _t_r(cfg),
        cfg.stop_time_s,
        cfg.human_speed_zone_m,
        cfg.human_speed_near_mps,
        cfg.human_speed_far_mps,
        cfg.body_speed_mps,
        fixed_terms(cfg),
        math.nan if accel is None else float(accel),
        cfg.speed_error_mps,
    )


def body_mask(part_names: Sequence[str], cfg: SSMConfig) -> np.ndarray:
    """(K,) True for the parts moving at the body's speed (a writeable copy, as the
    compiled :func:`approach_bounds` was warmed up for)."""
    return np.array(_body_mask(tuple(part_names), tuple(cfg.body_parts))[0])


@njit(cache=True)
def approach_bounds(
    distance: np.ndarray,
    vector: np.ndarray,
    who: np.ndarray,
    part_velocity: np.ndarray,
    body: np.ndarray,
    frame_age_s: float,
    t_r: float,
    t_s: float,
    zone_m: float,
    near_mps: float,
    far_mps: float,
    body_mps: float,
    fixed_m: float,
    body_acceleration_mps2: float,
    speed_error_mps: float,
) -> tuple[np.ndarray, np.ndarray]:
    r""":func:`separation_bounds` in one compiled pass (the stage's; the numpy functions
    above are its reference in the tests), each pair's part taken from its closest person.

    For pair (i, j) with distance d, unit direction n (human → robot) and the velocity v
    of part j of person ``who[i, j]`` (``part_velocity`` (P, K, 3), m/s):

    .. math::

        \bar v_r = \frac{d − v_h (T_f + T_r + T_s) − (C + Z_d + Z_r)}{T_r + T_s / 2},
        \qquad v_{h,n} = \max(n · v, 0),

    with v_h ISO 13855's (:func:`human_speed`; ``body`` (K,) the parts at the body's
    speed), and for a body part with ``body_acceleration_mps2`` finite the smaller S_h of
    :func:`accelerated_reach` from ``‖v‖ + speed_error_mps`` (:func:`max_approach_speed`).
    An infinite or NaN ``frame_age_s`` allows no approach (−inf); NaN propagates as in
    numpy. The scalars are :func:`separation_constants`'.

    Returns
    -------
    limit, towards
        (S, K) m/s.
    """
    n_sets, n_parts = distance.shape
    limit = np.empty((n_sets, n_parts))
    towards = np.empty((n_sets, n_parts))
    known = np.isfinite(frame_age_s)
    horizon = frame_age_s + t_r + t_s
    per_speed = t_r + t_s / 2.0
    accelerating = body_acceleration_mps2 == body_acceleration_mps2  # not NaN
    for i in range(n_sets):
        for j in range(n_parts):
            p = who[i, j]
            vx, vy, vz = part_velocity[p, j, 0], part_velocity[p, j, 1], part_velocity[p, j, 2]
            along = vector[i, j, 0] * vx + vector[i, j, 1] * vy + vector[i, j, 2] * vz
            towards[i, j] = along if along > 0.0 else 0.0
            if not known:
                limit[i, j] = -np.inf
                continue
            d = distance[i, j]
            speed = body_mps if body[j] else (near_mps if d <= zone_m else far_mps)
            s_h = speed * horizon
            if accelerating and body[j]:
                v0 = np.sqrt(vx * vx + vy * vy + vz * vz) + speed_error_mps
                v0 = v0 if not v0 > body_mps else body_mps  # NaN stays NaN (np.minimum)
                t1 = (body_mps - v0) / body_acceleration_mps2
                if horizon <= t1:
                    reach = v0 * horizon + 0.5 * body_acceleration_mps2 * horizon * horizon
                else:
                    reach = (
                        v0 * t1 + 0.5 * body_acceleration_mps2 * t1 * t1 + body_mps * (horizon - t1)
                    )
                s_h = s_h if s_h < reach else reach  # NaN reach gives NaN (np.minimum)
            limit[i, j] = (d - s_h - fixed_m) / per_speed
    return limit, towards


@functools.lru_cache(maxsize=8)
def _body_mask(part_names: tuple[str, ...], body_parts: tuple[str, ...]) -> np.ndarray:
    """(1, K) True for the parts moving at the body's speed (``np.isin`` on strings is
    slow: done once per model, not per tick)."""
    mask = np.isin(part_names, body_parts)[None, :]
    mask.setflags(write=False)
    return mask


def reaction_time(cfg: SSMConfig, control_period_s: float, compute_s: float = 0.0) -> float:
    """T_r of a controller ticking every ``control_period_s``: a decision waits up to one
    period to be revised, up to ``compute_s`` more to be computed and sent (a real-time
    loop's deadline; 0 offline), then the arm's reaction, in whole periods (as the
    simulation's arm, :class:`~qpavoid.arm.braking.ArmResponse`), s."""
    periods = math.ceil(_t_r(cfg) / control_period_s - 1e-9)
    return control_period_s * (1 + periods) + compute_s


class StopTimeBudget:
    """T_s of each tick: as short as the arm's recent commands allow (build once per controller).

    The arm may still be following any command of the last few ticks (its reaction, then a
    ramp of at most 2 T_s,max), so its stop takes at most the longest stop time of those
    commands; a new command may lengthen it by one control period (the arm cannot speed up
    faster anyway). The tick's budget is therefore

        T_s = min(T_s,max, max_recent T_s(q̇) + Δt)

    and the controllers keep every joint within ``a_j T_s`` (:func:`joint_speed_limits`), so
    the budget holds for the command they send. A robot at rest needs no braking time:
    the protective distance shrinks to ``v_h (T_f + T_r + Δt) + C + Z_d + Z_r``.

    Parameters
    ----------
    cfg
        The constants (``stop_time_s`` is T_s,max; ``reaction_time_s`` the full T_r).
    joint_names
        The arm's active joints.
    control_period_s
        Δt, s.
    """

    def __init__(self, cfg: SSMConfig, joint_names: Sequence[str], control_period_s: float):
        self.a = per_joint(cfg.max_acceleration_radps2, joint_names)
        self.cap, self.dt = cfg.stop_time_s, control_period_s
        ticks = math.ceil((_t_r(cfg) + 2.0 * cfg.stop_time_s) / control_period_s) + 2
        self.history: deque[float] = deque([0.0], maxlen=ticks)

    def budget(self) -> float:
        """This tick's T_s, s."""
        return min(self.cap, max(self.history) + self.dt)

    def record(self, dq: np.ndarray) -> None:
        """Remember the command sent (rad/s)."""
        self.history.append(stop_time(dq, self.a))
