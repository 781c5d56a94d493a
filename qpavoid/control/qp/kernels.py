"""The QP's per-tick arithmetic, compiled (numba): the rows and costs that change each tick.

Each piece of :mod:`qpavoid.control.qp` says *what* it adds to the problem; the pieces that change
every tick write it with one of these kernels, in place, into the assembler's arrays. As
numpy, each was a dozen calls on (8, 9) arrays whose call overhead outweighed their
arithmetic (docs/performance.md measures it). The checks and copies around the solve
are in :mod:`.solver_kernels`. Compiled code is cached on disk (``cache=True``);
:func:`warm_up` compiles or loads it.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.arm.model import Kinematics
from qpavoid.core.compiling import ctrl_c_deferred, kernel_input
from qpavoid.distance.table import DistanceTable

__all__ = [
    "check_rows",
    "damper_rows",
    "ee_task_cost",
    "pair_inputs",
    "separation_rows",
    "warm_up",
]


@njit(cache=True)
def ee_task_cost(
    J: np.ndarray,
    w2: np.ndarray,
    twist: np.ndarray,
    v_rep: np.ndarray,
    H: np.ndarray,
    c: np.ndarray,
) -> None:
    """Add eq. (8)'s task ``‖W (J q̇ − v*)‖²`` to ``½ xᵀHx + cᵀx``, in place.

    With ``v* = twist + [v_rep; 0]``: ``H[:nv, :nv] += 2 JᵀW²J`` and
    ``c[:nv] −= 2 JᵀW²v*`` (``J`` (6, nv), ``w2`` the (6,) diagonal of W²).
    """
    nv = J.shape[1]
    target = twist.copy()
    target[:3] += v_rep
    for a in range(nv):
        ca = 0.0
        for k in range(6):
            ca += J[k, a] * w2[k] * target[k]
        c[a] -= 2.0 * ca
        for b in range(nv):
            hab = 0.0
            for k in range(6):
                hab += J[k, a] * w2[k] * J[k, b]
            H[a, b] += 2.0 * hab


@njit(cache=True, inline="always")
def _approach_row(
    r: int,
    n_parts: int,
    vector: np.ndarray,
    robot_index: np.ndarray,
    robot_s: np.ndarray,
    point_jacobians: np.ndarray,
    segment_jacobians: np.ndarray,
    G: np.ndarray,
) -> None:
    """``G[r, :nv] = −nᵀ J_p`` for pair ``r`` (set ``r // n_parts``): J_p the Jacobian of
    its robot point (control point ``robot_index[r]``, or for capsules, ``robot_index[r]
    < 0``, the point at ``robot_s[r]`` along its set's axis: ``(1 − s) J_a + s J_b``)."""
    nv = point_jacobians.shape[2]
    p = robot_index[r]
    s = robot_s[r]
    i = r // n_parts
    for v in range(nv):
        g = 0.0
        for k in range(3):
            if p >= 0:
                jac = point_jacobians[p, k, v]
            else:
                jac = (1.0 - s) * segment_jacobians[i, 0, k, v] + s * segment_jacobians[i, 1, k, v]
            g -= vector[r, k] * jac
        G[r, v] = g


@njit(cache=True)
def damper_rows(
    distance: np.ndarray,
    vector: np.ndarray,
    robot_index: np.ndarray,
    robot_s: np.ndarray,
    point_jacobians: np.ndarray,
    segment_jacobians: np.ndarray,
    d_stop: np.ndarray,
    influence_m: float,
    gain_mps: float,
    human_approach: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
) -> None:
    """The velocity dampers' rows, in place: for each pair ``r`` closer than d_i,

        −nᵀ J_p q̇ ≤ ξ (d − d_s) / (d_i − d_s) − v_h,n

    (:class:`~qpavoid.control.qp.limits.velocity_damper.VelocityDamper`); other rows ``0 ≤ +inf``.
    ``distance``, ``d_stop``, ``human_approach``, ``robot_index``, ``robot_s``: (R,) per
    pair; ``vector`` (R, 3); ``G`` (R, n) and ``h`` (R,) written.
    """
    n_parts = distance.shape[0] // segment_jacobians.shape[0]
    G[:] = 0.0
    for r in range(distance.shape[0]):
        d = distance[r]
        if not d < influence_m:
            h[r] = np.inf
            continue
        _approach_row(
            r, n_parts, vector, robot_index, robot_s, point_jacobians, segment_jacobians, G
        )
        h[r] = gain_mps * (d - d_stop[r]) / (influence_m - d_stop[r]) - human_approach[r]


@njit(cache=True)
def separation_rows(
    bound: np.ndarray,
    vector: np.ndarray,
    robot_index: np.ndarray,
    robot_s: np.ndarray,
    point_jacobians: np.ndarray,
    segment_jacobians: np.ndarray,
    inactive_above_mps: float,
    G: np.ndarray,
    h: np.ndarray,
) -> None:
    """Speed and separation's bounds on the pairs' rows, in place: for each pair whose
    bound ``v_max`` is below ``inactive_above_mps``, the row ``−nᵀ J_p q̇`` and
    ``h = min(h, v_max)``; other rows untouched
    (:class:`~qpavoid.control.qp.barriers.separation.SeparationLimit`, which tightens the
    dampers' rows: rows of ``0 ≤ +inf`` given, its own rows). Shapes as
    :func:`damper_rows`."""
    n_parts = bound.shape[0] // segment_jacobians.shape[0]
    for r in range(bound.shape[0]):
        if not bound[r] < inactive_above_mps:
            continue
        _approach_row(
            r, n_parts, vector, robot_index, robot_s, point_jacobians, segment_jacobians, G
        )
        h[r] = min(h[r], bound[r])


@functools.cache
def warm_up() -> None:
    """Compile (or load from the disk cache) the kernels, once per process."""
    with ctrl_c_deferred():  # a Ctrl-C while the kernels compile comes right after
        n, nv = 4, 2
        H, c, G, h = np.zeros((n, n)), np.zeros(n), np.zeros((2, n)), np.zeros(2)
        ee_task_cost(np.zeros((6, nv)), np.ones(6), np.zeros(6), np.zeros(3), H, c)
        pair = (np.zeros((2, 3)), np.zeros(2, dtype=np.int64), np.zeros(2),
                np.zeros((1, 3, nv)), np.zeros((1, 2, 3, nv)))  # fmt: skip
        damper_rows(np.ones(2), *pair, np.zeros(2), 0.15, 0.25, np.zeros(2), G, h)
        separation_rows(np.ones(2), *pair, 1.0, G, h)


def check_rows(name: str, rows: int, pairs: int, G: np.ndarray, h: np.ndarray) -> None:
    """Raise ``ValueError`` unless ``G`` and ``h`` hold one row per pair, as many as the
    piece ``name``'s ``rows`` (the kernels do not check their bounds: a mismatch would
    write past the arrays' ends, where numpy raised)."""
    if not (pairs == rows == G.shape[0] == h.shape[0]):
        raise ValueError(f"{name}: {pairs} set × part pairs for {rows} rows (G {G.shape})")


def pair_inputs(
    table: DistanceTable, kin: Kinematics
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What :func:`damper_rows` and :func:`separation_rows` need to find each pair's
    robot point Jacobian: ``vector`` (R, 3), ``robot_index`` (R,), ``robot_s`` (R,) and the
    kinematics' point and capsule-end Jacobians, as the kernels were compiled for them."""
    assert kin.point_jacobians is not None and kin.segment_jacobians is not None
    return (
        kernel_input(table.vector.reshape(-1, 3), np.float64),
        kernel_input(table.robot_index.reshape(-1), np.int64),
        kernel_input(table.robot_s.reshape(-1), np.float64),
        kernel_input(kin.point_jacobians, np.float64),
        kernel_input(kin.segment_jacobians, np.float64),
    )
