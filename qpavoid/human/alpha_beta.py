"""The α-β filter of a skeleton's joints and its bone lengths: one step, compiled (numba).

Both memories of a person use it: the controller's tracker
(:mod:`qpavoid.perception.tracker`, one sensor's frames) and the fusion's tracks
(:mod:`qpavoid.fusion.person`, several sensors' merged frames). Their compiled kernels call
:func:`alpha_beta_step` inside their own one call per frame, with their own parameters:

=====================  =========================  ==================================
parameter              perception (tracker)       fusion (tracks)
=====================  =========================  ==================================
``max_gap_s``          ∞: any gap is stepped      ``max_age_s``: a longer gap restarts
``bone_state``         1: both ends seen          2: both ends Tracked
``grow, shrink``       1, 0: the longest seen     0.1, 0.1: a running average
=====================  =========================  ==================================

The bones differ on purpose: the tracker needs an *upper bound* of each bone (a lost
joint lies within the summed bones of its nearest tracked ancestor, and a forearm the
sensor folds onto the elbow just before losing the hand must not shrink it), the fusion
an *estimate* (a sensor whose joint is at the wrong distance from the predicted parent is
not believed). One rule with two parameters gives both.

Arrays: ``position``, ``velocity`` (J, 3) float64, m and m/s; ``last_seen``, ``bone``
(J,) float64, s and m; ``parent`` (J,) int64, -1 at a root; ``z`` (J, 3) float64, m, NaN
where not measured; ``state`` (J,) int8 (0 not tracked, 1 inferred, 2 tracked).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["alpha_beta_step"]


@njit(cache=True, inline="always")  # compiled into each caller's one call per frame
def alpha_beta_step(
    position: np.ndarray,
    velocity: np.ndarray,
    last_seen: np.ndarray,
    bone: np.ndarray,
    parent: np.ndarray,
    z: np.ndarray,
    state: np.ndarray,
    t: float,
    alpha: float,
    beta: float,
    max_gap_s: float,
    bone_state: int,
    grow: float,
    shrink: float,
) -> np.ndarray:
    """One frame ``z``, ``state`` measured at ``t`` (s) into a person's memory, in place.

    A joint *seen* now (finite in ``z``, state not 0) and last seen ``Δt = t − last_seen``
    ago, ``0 < Δt ≤ max_gap_s``, takes an α-β step:

    .. math:: \\hat p = p + v\\,\\Delta t,\\quad r = z - \\hat p,\\quad
              p \\leftarrow \\hat p + \\alpha r,\\quad v \\leftarrow v + \\beta r / \\Delta t

    Seen for the first time, or after a longer gap (its velocity then is no guide: the
    person may have stopped, turned, or be another), it restarts at ``z`` at rest; seen
    again at the same ``t`` it is left as it is. A joint not seen keeps its position and
    velocity. ``last_seen`` becomes ``t`` where seen.

    A bone (joint to parent) whose two ends are seen with states at least ``bone_state``
    measures ``L``; the first measure (``bone ≤ 0``) is taken as is, then
    ``bone ← (1 − g) bone + g L`` with ``g = grow`` if ``L > bone``, else ``shrink``.

    Returns
    -------
    numpy.ndarray
        (J,) bool, the joints seen now.
    """
    n = z.shape[0]
    seen = np.empty(n, dtype=np.bool_)
    for j in range(n):
        seen[j] = state[j] != 0 and not np.isnan(z[j, 0] + z[j, 1] + z[j, 2])
        if not seen[j]:
            continue
        dt = t - last_seen[j]
        if not (np.isfinite(dt) and dt <= max_gap_s):  # never seen, or not for too long
            for k in range(3):
                position[j, k], velocity[j, k] = z[j, k], 0.0
        elif dt > 0.0:
            for k in range(3):
                pred = position[j, k] + velocity[j, k] * dt
                r = z[j, k] - pred
                position[j, k] = pred + alpha * r
                velocity[j, k] = velocity[j, k] + beta * r / dt
        last_seen[j] = t
    for j in range(n):
        a = parent[j]
        if a < 0 or not (seen[j] and seen[a]) or state[j] < bone_state or state[a] < bone_state:
            continue
        dx, dy, dz = z[j, 0] - z[a, 0], z[j, 1] - z[a, 1], z[j, 2] - z[a, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if bone[j] <= 0.0:
            bone[j] = length
        else:
            g = grow if length > bone[j] else shrink
            bone[j] = (1.0 - g) * bone[j] + g * length
    return seen
