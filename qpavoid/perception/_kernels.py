"""The tracker's per-joint arithmetic, compiled (numba): one pass over a skeleton's joints.

:mod:`qpavoid.perception.tracker` says *what* is computed (and holds the state); this
kernel computes it, instead of some thirty numpy calls on (J, 3) arrays whose call
overhead outweighed their arithmetic (docs/performance.md measures it). The compiled code
is cached on disk (``cache=True``) and :func:`warm_up` compiles or loads it before the
first frame.

Arrays: ``joints`` (J, 3) float64, m; ``state`` (J,) int8 (0 NotTracked, 1 Inferred,
2 Tracked); ``parent`` (J,) int64, -1 at the root.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.core.compiling import ctrl_c_deferred

__all__ = ["track", "warm_up"]


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

    The memory (``position``, ``velocity`` (25, 3); ``last_seen``, ``last_tracked``,
    ``bone`` (25,)) follows :meth:`qpavoid.perception.tracker.Tracker.update`:

    * a joint seen (finite, not NotTracked) now and before takes an α-β step,
      ``p̂ = p + v Δt``, ``r = z − p̂``, ``p = p̂ + α r``, ``v = v + β r / Δt``; seen
      for the first time, it starts at rest at ``z``; not seen, its velocity is 0;
    * a bone seen at both ends keeps its longest length;
    * the uncertainty of a joint: 0 tracked; ``inferred_uncertainty + max_speed ×``
      (time since last tracked) inferred; ``max_speed ×`` (time since last seen) lost;
      infinite if never seen;
    * a joint not tracked lies within the summed bones of its nearest tracked ancestor:
      placed there when that bound is tighter.

    Returns
    -------
    joints, state, radius, velocity
        The frame to trust (lost joints filled in, flagged Inferred; NaN where nothing
        is known, radius 0 there), each joint's uncertainty (m) and velocity (m/s, 0
        where not seen now).
    """
    n = z.shape[0]
    seen = np.empty(n, dtype=np.bool_)
    tracked = np.empty(n, dtype=np.bool_)
    for j in range(n):
        seen[j] = state[j] != 0 and not np.isnan(z[j, 0] + z[j, 1] + z[j, 2])
        tracked[j] = seen[j] and state[j] == 2
        if seen[j]:
            dt = t - last_seen[j]
            if np.isfinite(dt):
                for k in range(3):
                    pred = position[j, k] + velocity[j, k] * dt
                    r = z[j, k] - pred
                    position[j, k] = pred + alpha * r
                    velocity[j, k] = velocity[j, k] + beta * r / dt
            else:
                for k in range(3):
                    position[j, k], velocity[j, k] = z[j, k], 0.0
            last_seen[j] = t
            if tracked[j]:
                last_tracked[j] = t
        else:
            for k in range(3):
                velocity[j, k] = 0.0
    for j in range(n):
        a = parent[j]
        if a >= 0 and seen[j] and seen[a]:
            dx, dy, dz = z[j, 0] - z[a, 0], z[j, 1] - z[a, 1], z[j, 2] - z[a, 2]
            bone[j] = max(bone[j], np.sqrt(dx * dx + dy * dy + dz * dz))
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
    for j in range(n):
        if tracked[j] or parent[j] < 0:
            continue
        reach, a = bone[j], parent[j]
        while a >= 0 and not tracked[a]:
            reach, a = reach + bone[a], parent[a]
        if a >= 0 and reach < radius[j]:
            joints[j], radius[j] = z[a], reach
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
def warm_up() -> None:
    """Compile (or load from the disk cache) every kernel, once per process."""
    with ctrl_c_deferred():  # a Ctrl-C while the kernels compile comes right after
        z = np.zeros((25, 3))
        state = np.full(25, 2, dtype=np.int8)
        parent = np.full(25, -1, dtype=np.int64)
        track(
            z.copy(),
            z.copy(),
            np.zeros(25),
            np.zeros(25),
            np.zeros(25),
            parent,
            z,
            state,
            1.0,
            0.3,
            0.05,
            0.05,
            1.6,
        )
