"""The fusion's per-joint arithmetic, compiled (numba): one person, ``S`` sensors, J joints.

:mod:`qpavoid.fusion.fuser` decides *what* to merge (which frames, which person, whom to believe);
these kernels do the arithmetic on every joint in one pass each, instead of some thirty
numpy calls on (S, J, 3) arrays that cost more in call overhead than in arithmetic
(docs/performance.md measures it). Their compiled code is cached on disk
(``cache=True``) and :func:`warm_up` compiles or loads it before the first frame, for the
skeleton format the fusion will see. The person's α-β filter is
:func:`qpavoid.human.alpha_beta.alpha_beta_step` (the tracker's too).

Arrays: ``P`` (S, J, 3) float64 joints in the base frame, NaN where not usable;
``states`` (S, J) int8 (0 NotTracked, 1 Inferred, 2 Tracked; 0 wherever ``P`` is NaN);
``parent`` (J,) int64, -1 at a root (a copy of the format's).
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.core.compiling import ctrl_c_deferred
from qpavoid.human.skeleton import SkeletonFormat

__all__ = [
    "believed",
    "disagreement",
    "ingest",
    "mean_gaps",
    "merge",
    "subset_mean",
    "warm_up",
]


@njit(cache=True)
def mean_gaps(P: np.ndarray, reference: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(S,) mean distance of ``joints`` of each body to ``reference`` (J, 3), m.

    Joints missing on either side do not count; NaN for a body with nothing to compare.
    """
    out = np.empty(P.shape[0])
    for s in range(P.shape[0]):
        total, n = 0.0, 0
        for j in joints:
            dx = P[s, j, 0] - reference[j, 0]
            dy = P[s, j, 1] - reference[j, 1]
            dz = P[s, j, 2] - reference[j, 2]
            d = np.sqrt(dx * dx + dy * dy + dz * dz)
            if not np.isnan(d):
                total += d
                n += 1
        out[s] = total / n if n else np.nan
    return out


@njit(cache=True)
def ingest(
    joints: np.ndarray, state: np.ndarray, rotation: np.ndarray, translation: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A sensor's joints (J, 3) and states (J,) in the base frame, m: ``R p + t``, NaN and
    NotTracked (0) wherever a joint is not finite or NotTracked, in a new (J, 3) array and
    a new (J,) int8 array."""
    out = np.empty(joints.shape)
    usable = np.empty(state.shape, dtype=np.int8)
    for j in range(joints.shape[0]):
        for k in range(3):
            out[j, k] = (
                rotation[k, 0] * joints[j, 0]
                + rotation[k, 1] * joints[j, 1]
                + rotation[k, 2] * joints[j, 2]
                + translation[k]
            )
        usable[j] = state[j]
        if state[j] == 0 or not (
            np.isfinite(out[j, 0]) and np.isfinite(out[j, 1]) and np.isfinite(out[j, 2])
        ):
            out[j, 0] = out[j, 1] = out[j, 2] = np.nan
            usable[j] = 0
    return out, usable


@njit(cache=True)
def subset_mean(joints: np.ndarray, subset: np.ndarray) -> np.ndarray:
    """Mean (3,) of the finite ``joints`` (J, 3) among ``subset``; of all finite joints if
    none is; NaN if no joint is finite, m."""
    out = np.zeros(3)
    n = 0
    for j in subset:
        if not np.isnan(joints[j, 0] + joints[j, 1] + joints[j, 2]):
            out += joints[j]
            n += 1
    if n:
        return out / n
    for j in range(joints.shape[0]):  # none of the subset: every joint (out is still 0)
        if not np.isnan(joints[j, 0] + joints[j, 1] + joints[j, 2]):
            out += joints[j]
            n += 1
    if n:
        return out / n
    return np.full(3, np.nan)


@njit(cache=True)
def disagreement(P: np.ndarray) -> np.ndarray:
    """(J,) largest distance between two sensors' positions of each joint, m (-1 where
    fewer than two sensors see it)."""
    S, J = P.shape[0], P.shape[1]
    out = np.full(J, -1.0)
    for j in range(J):
        for a in range(S):
            for b in range(a + 1, S):
                dx = P[a, j, 0] - P[b, j, 0]
                dy = P[a, j, 1] - P[b, j, 1]
                dz = P[a, j, 2] - P[b, j, 2]
                d = np.sqrt(dx * dx + dy * dy + dz * dz)
                if d > out[j]:  # NaN compares False
                    out[j] = d
    return out


@njit(cache=True)
def believed(
    P: np.ndarray,
    states: np.ndarray,
    joints: np.ndarray,
    prediction: np.ndarray,
    bone: np.ndarray,
    parent: np.ndarray,
    threshold_m: float,
) -> np.ndarray:
    """Whom to believe on each joint where the sensors disagree: (S, len(joints)) bool.

    For joint ``j`` the best sensor is one that tracks it rather than infers it, then the
    one closest to the person's predicted joint (``prediction`` (J, 3); all NaN for a new
    person) plus the error of the bone to the predicted parent against its known length
    (``bone`` (J,), m; 0 unknown); every sensor within ``threshold_m`` of the best is
    kept. A sensor that does not see the joint is never kept.
    """
    S = P.shape[0]
    keep = np.zeros((S, len(joints)), dtype=np.bool_)
    for n in range(len(joints)):
        j = joints[n]
        a = parent[j]
        best, best_score = -1, np.inf
        for s in range(S):
            if states[s, j] == 0:
                continue
            err = 0.0
            if not np.isnan(prediction[j, 0] + prediction[j, 1] + prediction[j, 2]):
                err += np.sqrt(((P[s, j] - prediction[j]) ** 2).sum())
            if a >= 0 and bone[j] > 0.0:
                anchor = prediction[a]
                if not np.isnan(anchor[0] + anchor[1] + anchor[2]):
                    err += abs(np.sqrt(((P[s, j] - anchor) ** 2).sum()) - bone[j])
            if np.isnan(err):
                err = 100.0
            score = (0.0 if states[s, j] == 2 else 1e3) + err
            if score < best_score:
                best, best_score = s, score
        if best < 0:
            continue
        for s in range(S):
            if states[s, j] != 0:
                keep[s, n] = np.sqrt(((P[s, j] - P[best, j]) ** 2).sum()) <= threshold_m
    return keep


@njit(cache=True)
def merge(
    P: np.ndarray,
    states: np.ndarray,
    W: np.ndarray,
    disputed: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The weighted mean of the sensors' joints and its tracking state.

    .. math:: p_j = \\sum_s W_{sj} P_{sj} / \\sum_s W_{sj}

    Parameters
    ----------
    P, states
        The sensors' joints and states (module docstring).
    W
        (S, J) weights, 0 for a sensor not used on a joint.
    disputed
        (J,) joints on which sensors disagreed: Inferred whoever was believed.

    Returns
    -------
    joints, state
        (J, 3) fused joints (NaN where no weight) and (J,) int8 states: Tracked where a
        weighted sensor tracks the joint, Inferred where only inferring ones do or it was
        disputed, NotTracked where no sensor has weight.
    """
    S, J = W.shape
    joints = np.full((J, 3), np.nan)
    state = np.zeros(J, dtype=np.int8)
    for j in range(J):
        total, x, y, z, tracked = 0.0, 0.0, 0.0, 0.0, False
        for s in range(S):
            w = W[s, j]
            if w > 0.0:
                total += w
                x += w * P[s, j, 0]
                y += w * P[s, j, 1]
                z += w * P[s, j, 2]
                tracked = tracked or states[s, j] == 2
        if total > 0.0:
            joints[j, 0], joints[j, 1], joints[j, 2] = x / total, y / total, z / total
            state[j] = 1 if disputed[j] or not tracked else 2
    return joints, state


@functools.cache
def warm_up(skeleton: SkeletonFormat) -> None:
    """Compile (or load from the disk cache) every kernel for frames of ``skeleton``, once
    per process and format, with the argument types the fusion passes (writable copies of
    the format's index arrays; :func:`~qpavoid.fusion.association.torso_centre` passes the
    format's read-only ``torso_ids``)."""
    with ctrl_c_deferred():  # a Ctrl-C while the kernels compile comes right after
        n = skeleton.n_joints
        P = np.zeros((2, n, 3))
        states = np.full((2, n), 2, dtype=np.int8)
        mean_gaps(P, P[0], np.array(skeleton.sided))
        subset_mean(P[0], skeleton.torso_ids)
        ingest(P[0], states[0], np.eye(3), np.zeros(3))
        disagreement(P)
        disputed = np.arange(min(n, 3), dtype=np.int64)
        believed(P, states, disputed, P[0], np.zeros(n), np.array(skeleton.parent), 0.2)
        merge(P, states, np.ones((2, n)), np.zeros(n, dtype=np.bool_))
