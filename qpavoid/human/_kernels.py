"""The body model's arithmetic, compiled (numba): a frame's points and capsules, and each
part's margin and velocity, in one pass over the skeleton's joints.

:mod:`qpavoid.human.body` says *what* is computed; these kernels compute it. Arrays:
``joints`` (J, 3) float64, m; ``state`` (J,) int8 (0 NotTracked, 1 Inferred, 2 Tracked).
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.core import geometry
from qpavoid.core.compiling import ctrl_c_deferred, recompile_if_stale
from qpavoid.core.geometry import TINY
from qpavoid.human.skeleton import SkeletonFormat

__all__ = [
    "append_centres",
    "capsules",
    "fastest_joint",
    "largest_per_part",
    "point_segment_distance",
    "tracked_body",
    "warm_up",
]


@njit(cache=True, inline="always")  # compiled into the capsules' loop
def point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Distance from the point ``p`` (3,) to the segment ``[a, b]``, m.

    The closest point is ``a + s (b − a)`` with ``s = clip((p − a)·(b − a) / ‖b − a‖², 0, 1)``;
    a segment shorter than :data:`~qpavoid.core.geometry.TINY` is its end point ``a``. NaN
    if any coordinate is.
    """
    ab, ap = b - a, p - a
    s = (ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / max(
        ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2], TINY
    )
    s = min(max(s, 0.0), 1.0)
    d = ap - s * ab
    return np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])


@njit(cache=True)
def capsules(
    joints: np.ndarray,
    state: np.ndarray,
    joint_ids: np.ndarray,
    mid_ids: np.ndarray,
    chains: np.ndarray,
    reach_pairs: np.ndarray,
    capsule_radii: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The body model's points and capsules at one frame (:meth:`KinectHuman.geometry`).

    Parameters
    ----------
    joints, state
        The frame (module docstring); a joint NaN or NotTracked is not usable.
    joint_ids, mid_ids
        Joints that are model points, and the (M, 2) joint pairs whose mid-points are.
    chains
        (K, L) each part's joints from one end to the other (padded with its last).
    reach_pairs
        (R, 2) (part, joint): joints the part's capsule must reach (fingers).
    capsule_radii
        (K,) each part's capsule radius, m.

    Returns
    -------
    points, point_valid, segments, segment_valid, reach
        (P, 3) points (NaN not usable), (K, 2, 3) each capsule's axis between the first
        and last usable joints of its chain, whether it has one, and (K,) how far each
        ``reach_pairs`` joint sticks out of its capsule, m (0 if nowhere or not known).
    """
    n = joints.shape[0]
    clean = np.full((n, 3), np.nan)
    usable = np.zeros(n, dtype=np.bool_)
    for j in range(n):
        if state[j] != 0 and not np.isnan(joints[j, 0] + joints[j, 1] + joints[j, 2]):
            usable[j] = True
            clean[j] = joints[j]
    n_points = len(joint_ids) + len(mid_ids)
    points = np.empty((n_points, 3))
    for i in range(len(joint_ids)):
        points[i] = clean[joint_ids[i]]
    for i in range(len(mid_ids)):
        points[len(joint_ids) + i] = 0.5 * (clean[mid_ids[i, 0]] + clean[mid_ids[i, 1]])
    point_valid = np.empty(n_points, dtype=np.bool_)
    for i in range(n_points):
        point_valid[i] = not np.isnan(points[i, 0])
    K, L = chains.shape
    segments = np.full((K, 2, 3), np.nan)
    segment_valid = np.zeros(K, dtype=np.bool_)
    for k in range(K):
        first, last = -1, -1
        for i in range(L):
            if usable[chains[k, i]]:
                if first < 0:
                    first = i
                last = i
        if first < 0:
            first = last = 0
        else:
            segment_valid[k] = True
        segments[k, 0] = clean[chains[k, first]]
        segments[k, 1] = clean[chains[k, last]]
    reach = np.zeros(K)
    for r in range(reach_pairs.shape[0]):
        k, j = reach_pairs[r, 0], reach_pairs[r, 1]
        out = point_segment_distance(clean[j], segments[k, 0], segments[k, 1]) - capsule_radii[k]
        if out > reach[k]:  # NaN compares False: sticks out by 0
            reach[k] = out
    return points, point_valid, segments, segment_valid, reach


@njit(cache=True)
def largest_per_part(members: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(K,) the largest of each part's ``values`` (J,) ≥ 0 over its joints ``members``
    (K, J) bool; 0 for a part with none."""
    out = np.zeros(members.shape[0])
    for k in range(members.shape[0]):
        for j in range(members.shape[1]):
            if members[k, j] and values[j] > out[k]:
                out[k] = values[j]
    return out


@njit(cache=True)
def fastest_joint(members: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """(K, 3) each part's velocity: that of its fastest joint (the first of equals; joint 0
    for a part with none), from the joints' ``velocity`` (J, 3), m/s."""
    out = np.empty((members.shape[0], 3))
    for k in range(members.shape[0]):
        best, pick = -1.0, 0
        for j in range(members.shape[1]):
            if members[k, j]:
                v = velocity[j]
                speed = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
                if speed > best:
                    best, pick = speed, j
        out[k] = velocity[pick]
    return out


@njit(cache=True)
def tracked_body(
    joints: np.ndarray,
    state: np.ndarray,
    joint_radius: np.ndarray,
    joint_velocity: np.ndarray,
    joint_ids: np.ndarray,
    mid_ids: np.ndarray,
    chains: np.ndarray,
    reach_pairs: np.ndarray,
    capsule_radii: np.ndarray,
    members: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A tracked frame's body in one call: :func:`capsules`, then each part's margin
    (:func:`largest_per_part` of the joints' uncertainty ``joint_radius``, m) and
    velocity (:func:`fastest_joint` of ``joint_velocity``, m/s), (K,) and (K, 3)."""
    points, point_valid, segments, segment_valid, reach = capsules(
        joints, state, joint_ids, mid_ids, chains, reach_pairs, capsule_radii
    )
    margin = largest_per_part(members, joint_radius)
    velocity = fastest_joint(members, joint_velocity)
    return points, point_valid, segments, segment_valid, reach, margin, velocity


@njit(cache=True)
def append_centres(
    joints: np.ndarray,
    state: np.ndarray,
    joint_radius: np.ndarray,
    joint_velocity: np.ndarray,
    centres: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The frame's rows, then one row per centre (:class:`~qpavoid.human.body.BodyModel`'s
    ``centres``): each the mean of its joints (``centres`` (C, M) joint ids, padded with
    −1), usable only if they all are (else NaN, state 0), its state the lowest of theirs,
    its uncertainty radius the largest of theirs, m, its velocity the mean of theirs, m/s."""
    n, c_count = joints.shape[0], centres.shape[0]
    out_j = np.empty((n + c_count, 3))
    out_s = np.empty(n + c_count, dtype=np.int8)
    out_r = np.empty(n + c_count)
    out_v = np.empty((n + c_count, 3))
    out_j[:n], out_s[:n], out_r[:n], out_v[:n] = joints, state, joint_radius, joint_velocity
    for c in range(c_count):
        row, count, whole, low, radius = n + c, 0, True, 127, 0.0
        mean, velocity = np.zeros(3), np.zeros(3)
        for m in range(centres.shape[1]):
            j = centres[c, m]
            if j < 0:
                break
            count += 1
            p = joints[j]
            if state[j] == 0 or not np.isfinite(p[0] + p[1] + p[2]):
                whole = False
            low = min(low, state[j])
            radius = max(radius, joint_radius[j])
            mean += p
            velocity += joint_velocity[j]
        if whole:
            out_j[row], out_s[row] = mean / count, low
        else:
            out_j[row], out_s[row] = np.nan, 0
        out_r[row] = radius
        out_v[row] = velocity / count
    return out_j, out_s, out_r, out_v


@functools.cache
def warm_up(skeleton: SkeletonFormat) -> None:
    """Compile (or load from the disk cache) every kernel for frames of ``skeleton``, once
    per process and format: the argument types :class:`~qpavoid.human.body.BodyModel`
    passes (a frame, the joints' uncertainty and velocity, the model's index arrays)."""
    with ctrl_c_deferred():  # a Ctrl-C while the kernels compile comes right after
        n = skeleton.n_joints
        z = np.zeros((n, 3))
        state = np.full(n, 2, dtype=np.int8)
        ids = np.arange(min(n, 3), dtype=np.int64)
        pairs = np.zeros((1, 2), dtype=np.int64)
        members = np.ones((2, n), dtype=np.bool_)
        capsules(z, state, ids, pairs, pairs, pairs, np.ones(1))
        largest_per_part(members, np.zeros(n))
        fastest_joint(members, z)
        tracked_body(z, state, np.zeros(n), z, ids, pairs, pairs, pairs, np.ones(1), members)
        append_centres(z, state, np.zeros(n), z, pairs)
        for kernel in (point_segment_distance, capsules, tracked_body):
            recompile_if_stale(kernel, geometry)  # they compile geometry.TINY in
