"""One person's fusion step as one compiled call (numba), from the sensors' bodies to the
filtered skeleton: steps 3 (mirrors) to 5 of :mod:`qpavoid.fusion.fuser`.

:func:`fuse_person` composes the per-joint kernels of :mod:`qpavoid.fusion._kernels` with
the left/right test (:func:`mirror_costs`), so that fusing a person costs one call from
Python instead of some twenty (docs/performance.md measures it). Arrays as in
:mod:`qpavoid.fusion._kernels`: ``P`` (S, J, 3) float64, NaN where not usable; ``states``
(S, J) int8, 0 wherever ``P`` is NaN; the skeleton format's ``parent``, ``mirror`` and
``sided`` (:class:`~qpavoid.human.skeleton.SkeletonFormat`; the fusion passes copies).
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.core.compiling import ctrl_c_deferred, recompile_if_stale
from qpavoid.fusion import _kernels as fusion_kernels
from qpavoid.fusion._kernels import believed, disagreement, mean_gaps, merge
from qpavoid.fusion._kernels import warm_up as warm_up_pieces
from qpavoid.human import alpha_beta
from qpavoid.human.alpha_beta import alpha_beta_step
from qpavoid.human.skeleton import TRACKED, SkeletonFormat

__all__ = [
    "BONE_GAIN",
    "MIRROR_CHECK_M",
    "PREDICTION_HORIZON_S",
    "fuse_person",
    "mirror_costs",
    "warm_up",
]

#: A body whose sided joints are on average this close to the reference is not checked for
#: a left/right swap (a swap moves them by a shoulder's width), m.
MIRROR_CHECK_M = 0.1
#: Farthest a person's joints are moved along their velocity to serve as the reference, s.
PREDICTION_HORIZON_S = 0.1
#: A track's bones are a running average (:func:`~qpavoid.human.alpha_beta.alpha_beta_step`'s
#: ``grow`` and ``shrink``), measured where both ends are Tracked: an estimate of the
#: person's bone, against which :func:`~qpavoid.fusion._kernels.believed` weighs a sensor's
#: joint. 0.1: a frame's noise moves it little, a settled length in about 20 frames.
BONE_GAIN = 0.1


@njit(cache=True)
def mirror_costs(
    joints: np.ndarray, reference: np.ndarray, sided: np.ndarray, mirror: np.ndarray
) -> tuple[float, float]:
    """Median distance of the ``sided`` joints of ``joints`` (J, 3) to ``reference``, as
    labelled and with left and right swapped by ``mirror``, m.

    Only joints finite in ``joints`` (for the swap: their mirror) and in ``reference``
    count; (inf, inf) when none does.
    """
    as_is, swapped = np.empty(len(sided)), np.empty(len(sided))
    n, m = 0, 0
    for j in sided:
        r = reference[j]
        if np.isnan(r[0] + r[1] + r[2]) or np.isinf(r[0] + r[1] + r[2]):
            continue
        if not np.isnan(joints[j, 0]):
            as_is[n] = np.sqrt(((joints[j] - r) ** 2).sum())
            n += 1
        k = mirror[j]
        if not np.isnan(joints[k, 0]):
            swapped[m] = np.sqrt(((joints[k] - r) ** 2).sum())
            m += 1
    if n == 0 or m == 0:
        return np.inf, np.inf
    return np.median(as_is[:n]), np.median(swapped[:m])


@njit(cache=True)
def fuse_person(
    P: np.ndarray,
    states: np.ndarray,
    age: np.ndarray,
    sensor_weight: np.ndarray,
    recent: bool,
    positions: np.ndarray,
    velocity: np.ndarray,
    last_seen: np.ndarray,
    bone: np.ndarray,
    parent: np.ndarray,
    mirror: np.ndarray,
    sided: np.ndarray,
    t: float,
    state_weight: np.ndarray,
    state_confidence: np.ndarray,
    max_age_s: float,
    max_extrapolation_s: float,
    outlier_threshold_m: float,
    mirror_margin_m: float,
    alpha: float,
    beta: float,
    smooth: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fuse one person's ``S`` bodies at time ``t``; the person's track (``positions``,
    ``velocity``, ``last_seen``, ``bone``: :class:`~qpavoid.fusion.association.PersonTrack`) and
    ``P``, ``states`` are updated in place; ``parent``, ``mirror`` and ``sided`` are the
    skeleton format's.

    1. Reference: the track moved along its velocity to ``t`` (at most
       :data:`PREDICTION_HORIZON_S`) if the person was seen ``recent`` ly, else ``P[0]``.
    2. A body whose sided joints lie on average farther than :data:`MIRROR_CHECK_M` from
       the reference, and whose left/right swap fits it better by ``mirror_margin_m``
       (:func:`mirror_costs`), is relabelled.
    3. Bodies moved along the velocity by their ``age`` (s, at most
       ``max_extrapolation_s``); weights
       :math:`W_{sj} = w_{state}(s, j)\\,(f_s\\,w_s)` and confidences
       :math:`c_{sj} = c_{state}(s, j)\\,f_s` with freshness
       :math:`f_s = \\mathrm{clip}(1 - \\tfrac12\\,\\mathrm{age}_s/\\mathrm{max\\_age},\\,0,\\,1)`.
    4. Joints whose sensors disagree by more than ``outlier_threshold_m``
       (:func:`~qpavoid.fusion._kernels.disagreement`): only the believed sensors keep
       their weight and confidence (:func:`~qpavoid.fusion._kernels.believed`).
    5. Weighted mean (:func:`~qpavoid.fusion._kernels.merge`) and one α-β step of the track
       (:func:`~qpavoid.human.alpha_beta.alpha_beta_step`: a joint unseen for more than
       ``max_age_s`` restarts; bones of Tracked ends averaged, :data:`BONE_GAIN`).

    Returns
    -------
    joints
        (J, 3) the filtered joints if ``smooth``, else the weighted mean; NaN where no
        sensor sees the joint, m.
    state
        (J,) int8 fused tracking states.
    confidence
        (J,) :math:`\\min(\\sum_s c_{sj}, 1)`.
    mirrored
        (S,) bodies relabelled left/right.
    disputed
        Joints on which the sensors disagreed.
    keep
        (S, len(disputed)) who was believed on each.
    """
    S, J = P.shape[0], P.shape[1]
    reference = np.empty((J, 3))
    expected = np.full((J, 3), np.nan)
    for j in range(J):
        dt = max(min(t - last_seen[j], PREDICTION_HORIZON_S), 0.0)
        for k in range(3):
            if recent:
                reference[j, k] = expected[j, k] = positions[j, k] + velocity[j, k] * dt
            else:
                reference[j, k] = P[0, j, k]
    mirrored = np.zeros(S, dtype=np.bool_)
    gaps = mean_gaps(P, reference, sided)
    for s in range(S):
        if gaps[s] > MIRROR_CHECK_M:  # NaN: nothing to compare, no check
            as_is, swapped = mirror_costs(P[s], reference, sided, mirror)
            if swapped + mirror_margin_m < as_is:
                body, body_states = P[s].copy(), states[s].copy()
                for j in range(J):
                    P[s, j] = body[mirror[j]]
                    states[s, j] = body_states[mirror[j]]
                mirrored[s] = True
    W, conf = np.empty((S, J)), np.empty((S, J))
    for s in range(S):
        shift = min(age[s], max_extrapolation_s)
        fresh = min(max(1.0 - 0.5 * age[s] / max_age_s, 0.0), 1.0)
        for j in range(J):
            if shift > 0.0:
                for k in range(3):
                    P[s, j, k] += velocity[j, k] * shift
            W[s, j] = state_weight[states[s, j]] * (fresh * sensor_weight[s])
            conf[s, j] = state_confidence[states[s, j]] * fresh
    gap = disagreement(P)  # -1: fewer than two sensors see the joint
    disputed = np.empty(J, dtype=np.int64)
    n_disputed = 0
    for j in range(J):
        if gap[j] > outlier_threshold_m:
            disputed[n_disputed] = j
            n_disputed += 1
    disputed = disputed[:n_disputed]
    keep = believed(P, states, disputed, expected, bone, parent, outlier_threshold_m)
    is_disputed = np.zeros(J, dtype=np.bool_)
    for n in range(len(disputed)):
        is_disputed[disputed[n]] = True
        for s in range(S):
            if not keep[s, n]:
                W[s, disputed[n]] = 0.0
                conf[s, disputed[n]] = 0.0
    joints, state = merge(P, states, W, is_disputed)
    alpha_beta_step(
        positions,
        velocity,
        last_seen,
        bone,
        parent,
        joints,
        state,
        t,
        alpha,
        beta,
        max_age_s,
        np.int64(TRACKED),  # (not a literal: one specialisation for both callers)
        BONE_GAIN,
        BONE_GAIN,
    )
    confidence = np.empty(J)
    for j in range(J):
        total = 0.0
        for s in range(S):
            total += conf[s, j]
        confidence[j] = min(total, 1.0)
        if smooth:
            for k in range(3):
                joints[j, k] = positions[j, k] if state[j] != 0 else np.nan
    return joints, state, confidence, mirrored, disputed, keep


@functools.cache
def warm_up(skeleton: SkeletonFormat) -> None:
    """Compile (or load from the disk cache) the kernels for frames of ``skeleton``, once
    per process and format, with the argument types :class:`~qpavoid.fusion.fuser.Fuser`
    passes (a person's track, two sensors' bodies, copies of the format's arrays)."""
    warm_up_pieces(skeleton)
    with ctrl_c_deferred():  # a Ctrl-C while the kernels compile comes right after
        n = skeleton.n_joints
        P = np.zeros((2, n, 3))
        states = np.full((2, n), 2, dtype=np.int8)
        parent, mirror, sided = (
            np.array(a) for a in (skeleton.parent, skeleton.mirror, skeleton.sided)
        )
        mirror_costs(P[0], P[1], sided, mirror)
        fuse_person(
            P,
            states,
            np.zeros(2),
            np.ones(2),
            True,
            np.zeros((n, 3)),
            np.zeros((n, 3)),
            np.full(n, -np.inf),
            np.zeros(n),
            parent,
            mirror,
            sided,
            1.0,
            np.array([0.0, 0.2, 1.0]),
            np.array([0.0, 0.15, 0.5]),
            0.1,
            0.0,
            0.2,
            0.05,
            0.3,
            0.05,
            True,
        )
        # fuse_person compiles these modules' code in (numba's cache sees its own file only)
        recompile_if_stale(fuse_person, fusion_kernels, alpha_beta)
