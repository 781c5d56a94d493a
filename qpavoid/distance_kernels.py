"""The sphere distance table's arithmetic, compiled (numba): one pass over the pairs.

:class:`~qpavoid.distances.SphereDistance` says *what* is compared (which robot point
with which human point for each robot set and human part); :func:`sphere_table` computes
eq. (1) for all of them in one call, instead of a dozen numpy calls on (P, M, 3) arrays
whose call overhead outweighed their arithmetic (docs/performance.md measures it). The
compiled code is cached on disk (``cache=True``); :func:`warm_up` compiles or loads it.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from .compiling import ctrl_c_deferred

__all__ = ["TINY_DISTANCE_M", "sphere_table", "warm_up"]

#: Two points closer than this have no direction between them; the table's fallback is
#: used instead, m.
TINY_DISTANCE_M = 1e-12


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
        if best_value < TINY_DISTANCE_M:
            direction[r] = fallback
        else:
            for k in range(3):
                direction[r, k] = (robot_points[p, k] - human_points[m, k]) / best_value
    return distance, direction, robot_point, human_point


@functools.cache
def warm_up() -> None:
    """Compile (or load from the disk cache) the kernel, once per process."""
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
