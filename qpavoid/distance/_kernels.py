"""The sphere distance table's arithmetic, compiled (numba): one pass over the pairs.

:class:`~qpavoid.distance.methods.SphereDistance` says *what* is compared (which robot point
with which human point for each robot set and human part); :func:`sphere_table` computes
eq. (1) for all of them in one call, instead of a dozen numpy calls on (P, M, 3) arrays
whose call overhead outweighed their arithmetic (docs/performance.md measures it). The
compiled code is cached on disk (``cache=True``); :func:`warm_up` compiles or loads it.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.core import geometry
from qpavoid.core.compiling import ctrl_c_deferred, recompile_if_stale
from qpavoid.core.geometry import TINY

__all__ = ["capsule_axes", "capsule_directions", "sphere_table", "warm_up"]


@njit(cache=True)
def sphere_table(
    robot_points: np.ndarray,
    human_points: np.ndarray,
    human_valid: np.ndarray,
    pairs: np.ndarray,
    radii: np.ndarray,
    part_margin: np.ndarray,
    fallback: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. (1) for every (robot set, human part) row of ``pairs``.

    Row ``r`` lists flat pair indices ``p M + m`` (robot point ``p``, human point ``m``,
    ``M`` human points), padded with ``P M`` (no pair). Its distance is

    .. math:: d_r = \\min_{(p, m)} \\lVert x_p - h_m \\rVert - \\rho_r - \\mu_r

    over the pairs whose human point is usable (``human_valid``), with the summed sphere
    radii :math:`\\rho_r` (``radii``) and the part's margin :math:`\\mu_r`
    (``part_margin[r % n_parts]``); the first minimum wins.

    Returns
    -------
    distance
        (R,) m; ``inf`` where no pair is usable.
    direction
        (R, 3) unit vector from the human point to the robot point (0 where the distance
        is infinite, ``fallback`` where the points coincide).
    robot_point, human_point
        (R,) indices of the closest pair (-1 where the distance is infinite).
    """
    n_rows, width = pairs.shape
    M = human_points.shape[0]
    pad = robot_points.shape[0] * M
    n_parts = part_margin.shape[0]
    distance = np.empty(n_rows)
    direction = np.zeros((n_rows, 3))
    robot_point = np.full(n_rows, -1, dtype=np.int64)
    human_point = np.full(n_rows, -1, dtype=np.int64)
    for r in range(n_rows):
        best, best_value = pad, np.inf
        for k in range(width):
            flat = pairs[r, k]
            if flat == pad or not human_valid[flat % M]:
                continue
            p, m = flat // M, flat % M
            dx = robot_points[p, 0] - human_points[m, 0]
            dy = robot_points[p, 1] - human_points[m, 1]
            dz = robot_points[p, 2] - human_points[m, 2]
            value = np.sqrt(dx * dx + dy * dy + dz * dz)
            if value < best_value:
                best, best_value = flat, value
        distance[r] = best_value - radii[r] - part_margin[r % n_parts]
        if best == pad:
            continue
        p, m = best // M, best % M
        robot_point[r], human_point[r] = p, m
        if best_value < TINY:  # no direction between the points: the fallback
            direction[r] = fallback
        else:
            for k in range(3):
                direction[r, k] = (robot_points[p, k] - human_points[m, k]) / best_value
    return distance, direction, robot_point, human_point


@njit(cache=True)
def capsule_axes(segments: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Axis ``b − a`` (N, 3), half length (N,) and centre (N, 3) of the segments
    ``(a, b)`` (N, 2, 3), m (NaN in, NaN out)."""
    n = segments.shape[0]
    axis, half, centre = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
    for i in range(n):
        length2 = 0.0
        for k in range(3):
            axis[i, k] = segments[i, 1, k] - segments[i, 0, k]
            centre[i, k] = 0.5 * (segments[i, 0, k] + segments[i, 1, k])
            length2 += axis[i, k] * axis[i, k]
        half[i] = 0.5 * np.sqrt(length2)
    return axis, half, centre


@njit(cache=True)
def capsule_directions(
    segments: np.ndarray,
    distance: np.ndarray,
    robot_point: np.ndarray,
    human_point: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The capsule table's directions and axis parameters from coal's witness points.

    Row ``r`` is the pair of robot set ``r // K`` (``K = R / S``) with a body part. Its
    direction is ``(robot_point − human_point) / d`` (the unit vector from the human to
    the robot; unscaled where ``d ≤ 1e-9``, for the caller to replace, and 0 for a part
    not seen, ``d = inf``); its parameter is that of the robot witness point's projection
    on the set's axis ``a → b``, clipped to [0, 1] (0 for a part not seen).

    Returns
    -------
    vector
        (R, 3).
    s
        (R,).
    """
    n_rows, n_sets = distance.shape[0], segments.shape[0]
    n_parts = n_rows // n_sets
    vector = np.zeros((n_rows, 3))
    s = np.zeros(n_rows)
    for r in range(n_rows):
        d = distance[r]
        if not np.isfinite(d):
            continue
        i = r // n_parts
        scale = d if d > 1e-9 else 1.0
        along, length2 = 0.0, 0.0
        for k in range(3):
            vector[r, k] = (robot_point[r, k] - human_point[r, k]) / scale
            ab = segments[i, 1, k] - segments[i, 0, k]
            along += (robot_point[r, k] - segments[i, 0, k]) * ab
            length2 += ab * ab
        s[r] = min(max(along / max(length2, 1e-18), 0.0), 1.0)
    return vector, s


@functools.cache
def warm_up() -> None:
    """Compile (or load from the disk cache) the kernels, once per process; the sphere
    table again if :mod:`qpavoid.core.geometry` changed after its cache was written (it
    compiles :data:`~qpavoid.core.geometry.TINY` in:
    :func:`~qpavoid.core.compiling.recompile_if_stale`)."""
    with ctrl_c_deferred():  # a Ctrl-C while the kernel compiles comes right after
        sphere_table(
            np.zeros((2, 3)),
            np.ones((3, 3)),
            np.ones(3, dtype=np.bool_),
            np.zeros((2, 2), dtype=np.int64),
            np.zeros(2),
            np.zeros(2),
            np.zeros(3),
        )
        capsule_directions(np.zeros((1, 2, 3)), np.ones(2), np.zeros((2, 3)), np.ones((2, 3)))
        capsule_axes(np.zeros((1, 2, 3)))
        recompile_if_stale(sphere_table, geometry)  # it compiles geometry.TINY in
