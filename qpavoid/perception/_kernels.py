"""The tracker's per-joint arithmetic, compiled (numba): one pass over a skeleton's joints.

:mod:`qpavoid.perception.tracker` says *what* is computed (and holds the state); this
kernel computes it, instead of some thirty numpy calls on (J, 3) arrays whose call
overhead outweighed their arithmetic (docs/performance.md measures it). The compiled code
is cached on disk (``cache=True``) and :func:`warm_up` compiles or loads it before the
first frame, for the skeleton format the tracker will see.

Arrays: ``joints`` (J, 3) float64, m; ``state`` (J,) int8 (0 NotTracked, 1 Inferred,
2 Tracked); ``parent`` (J,) int64, -1 at the root.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.core.compiling import ctrl_c_deferred, recompile_if_stale
from qpavoid.human import alpha_beta
from qpavoid.human.alpha_beta import alpha_beta_step
from qpavoid.human.skeleton import INFERRED, SkeletonFormat

__all__ = ["BONE_GROW", "BONE_SHRINK", "track", "warm_up"]

#: The tracker's bones are the longest seen (an upper bound: :func:`alpha_beta_step`'s
#: ``grow``, ``shrink``): a Kinect folds a forearm onto the elbow just before losing the
#: hand, and that frame must not shrink the reach of a lost hand.
BONE_GROW, BONE_SHRINK = 1.0, 0.0


@njit(cache=True)
def track(
    position: np.ndarray,
    velocity: np.ndarray,
    last_seen: np.ndarray,
    last_tracked: np.ndarray,
    bone: np.ndarray,
    parent: np.ndarray,
    z: np.ndarray,
    state: np.ndarray,
    t: float,
    alpha: float,
    beta: float,
    inferred_uncertainty: float,
    max_speed: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One frame ``z``, ``state`` captured at ``t`` into a tracker's memory, in place.

    The memory (``position``, ``velocity`` (J, 3); ``last_seen``, ``last_tracked``,
    ``bone`` (J,)) follows :meth:`qpavoid.perception.tracker.Tracker.update`:

    * a joint seen (finite, not NotTracked) takes a step of the α-β filter
      (:func:`~qpavoid.human.alpha_beta.alpha_beta_step`: with no gap limit, so a joint
      seen again after a loss steps from its last position); not seen, its velocity is 0
      (it comes back from rest);
    * a bone seen at both ends keeps its longest length (:data:`BONE_GROW`,
      :data:`BONE_SHRINK`);
    * the uncertainty of a joint: 0 tracked; ``inferred_uncertainty + max_speed ×``
      (time since last tracked) inferred; ``max_speed ×`` (time since last seen) lost;
      infinite if never seen;
    * a joint not tracked lies within the summed bones of its nearest tracked ancestor:
      placed there when that bound is tighter; with no tracked ancestor (a camera whose
      spine landmarks derive from a lost shoulder), within the summed bones of the
      nearest tracked joint along the tree (a descendant, or one reached through a common
      ancestor): a joint never seen is bounded too, not left missing.

    Returns
    -------
    joints, state, radius, velocity
        The frame to trust (lost joints filled in, flagged Inferred; NaN where nothing
        is known, radius 0 there), each joint's uncertainty (m) and velocity (m/s, 0
        where not seen now).
    """
    seen = alpha_beta_step(
        position,
        velocity,
        last_seen,
        bone,
        parent,
        z,
        state,
        t,
        alpha,
        beta,
        np.inf,
        np.int64(INFERRED),  # (not a literal: one specialisation for both callers)
        BONE_GROW,
        BONE_SHRINK,
    )
    n = z.shape[0]
    tracked = np.empty(n, dtype=np.bool_)
    for j in range(n):
        tracked[j] = seen[j] and state[j] == 2
        if tracked[j]:
            last_tracked[j] = t
        if not seen[j]:
            for k in range(3):
                velocity[j, k] = 0.0
    joints = np.empty((n, 3))
    radius = np.zeros(n)
    for j in range(n):
        if seen[j]:
            joints[j] = z[j]
            if not tracked[j]:
                radius[j] = inferred_uncertainty + max_speed * max(t - last_tracked[j], 0.0)
        else:
            joints[j] = position[j]
            lost = t - last_seen[j]
            radius[j] = max_speed * lost if np.isfinite(last_seen[j]) else np.inf
    along = np.empty(n)  # a joint's ancestors' distance from it, bone by bone (-1: none)
    for j in range(n):
        if tracked[j]:
            continue
        reach, a = bone[j], parent[j]
        while a >= 0 and not tracked[a]:
            reach, a = reach + bone[a], parent[a]
        if a >= 0:
            if reach < radius[j]:
                joints[j], radius[j] = z[a], reach
            continue
        # no tracked ancestor (a camera that lost the spine): the nearest tracked joint
        # along the tree, a descendant or through a common ancestor
        along[:] = -1.0
        x, reach = j, 0.0
        while x >= 0:
            along[x], reach, x = reach, reach + bone[x], parent[x]
        best, at = np.inf, -1
        for k in range(n):
            if not tracked[k]:
                continue
            y, up = k, 0.0
            while y >= 0 and along[y] < 0.0:
                up, y = up + bone[y], parent[y]
            if y >= 0 and up + along[y] < best:
                best, at = up + along[y], k
        if at >= 0 and best < radius[j]:
            joints[j], radius[j] = z[at], best
    out_state = state.copy()
    out_velocity = np.zeros((n, 3))
    for j in range(n):
        known = not np.isnan(joints[j, 0] + joints[j, 1] + joints[j, 2])
        if not known:
            radius[j] = 0.0
        elif not seen[j]:
            out_state[j] = 1
        if seen[j]:
            out_velocity[j] = velocity[j]
    return joints, out_state, radius, out_velocity


@functools.cache
def warm_up(skeleton: SkeletonFormat) -> None:
    """Compile (or load from the disk cache) every kernel for frames of ``skeleton``, once
    per process and format: the argument types :class:`~qpavoid.perception.tracker.Tracker`
    passes (its memory, its copy of the format's ``parent``, a frame)."""
    with ctrl_c_deferred():  # a Ctrl-C while the kernels compile comes right after
        n = skeleton.n_joints
        z = np.zeros((n, 3))
        state = np.full(n, 2, dtype=np.int8)
        track(
            z.copy(),
            z.copy(),
            np.full(n, -np.inf),
            np.full(n, -np.inf),
            np.array(skeleton.max_bone_m),
            np.array(skeleton.parent),  # writable, as the tracker's copy
            z,
            state,
            1.0,
            0.3,
            0.05,
            0.05,
            1.6,
        )
        recompile_if_stale(track, alpha_beta)  # it compiles alpha_beta_step in
