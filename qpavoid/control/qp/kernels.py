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
    "MIN_SPEED_MPS",
    "box_bounds",
    "check_rows",
    "damper_rows",
    "ee_task_cost",
    "pair_inputs",
    "position_bounds",
    "raise_rows",
    "repulsion_row",
    "separation_rows",
    "velocity_bounds",
    "warm_up",
]

#: Repulsive speeds below this are treated as none (m/s): 0.1 mm/s.
MIN_SPEED_MPS = 1e-4


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


@njit(cache=True)
def repulsion_row(
    v: np.ndarray,
    Jp: np.ndarray,
    nominal: np.ndarray,
    slack: int,
    G: np.ndarray,
    h: np.ndarray,
    r: int,
) -> None:
    """Row ``r`` of a repulsion, in place: with ``u = v / |v|``,

        −uᵀ J_p q̇ − s ≤ −(uᵀ ṗ_nominal + |v|)

    (:class:`~qpavoid.control.qp.barriers.repulsion.RepulsionTask`): ``v`` (3,) the law's
    velocity, m/s; ``Jp`` (3, nv) the point's Jacobian and ``nominal`` (3,) its nominal
    velocity, m/s (read only when ``|v| ≥`` :data:`MIN_SPEED_MPS`; else ``h[r] = +inf``);
    ``slack`` the slack's column."""
    nv = Jp.shape[1]
    G[r, :] = 0.0
    G[r, slack] = -1.0
    speed = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if speed < MIN_SPEED_MPS:
        h[r] = np.inf
        return
    u0, u1, u2 = v[0] / speed, v[1] / speed, v[2] / speed
    for k in range(nv):
        G[r, k] = -(u0 * Jp[0, k] + u1 * Jp[1, k] + u2 * Jp[2, k])
    h[r] = -((u0 * nominal[0] + u1 * nominal[1] + u2 * nominal[2]) + speed)


@njit(cache=True, inline="always")
def _larger(a: float, b: float) -> float:
    """``np.maximum(a, b)``: a NaN in either gives NaN (the QP's checks then refuse it)."""
    return a if a >= b or a != a else b


@njit(cache=True, inline="always")
def _smaller(a: float, b: float) -> float:
    """``np.minimum(a, b)``: a NaN in either gives NaN."""
    return a if a <= b or a != a else b


@njit(cache=True)
def raise_rows(h: np.ndarray, floor: np.ndarray) -> None:
    """``h = max(h, floor)`` row by row, in place (``np.maximum``: a NaN stays NaN): power
    and force limiting's permitted contact speeds raising the dampers' bounds."""
    for r in range(h.shape[0]):
        h[r] = _larger(h[r], floor[r])


@njit(cache=True)
def velocity_bounds(limits: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> None:
    """``−q̇_max ≤ q̇ ≤ q̇_max`` intersected into the joint velocities' bounds ``lb``,
    ``ub`` (their first ``nv`` entries), in place (eq. 3's ``limits`` (nv,), rad/s)."""
    for j in range(limits.shape[0]):
        lb[j] = _larger(lb[j], -limits[j])
        ub[j] = _smaller(ub[j], limits[j])


@njit(cache=True)
def position_bounds(
    q: np.ndarray,
    q_min: np.ndarray,
    q_max: np.ndarray,
    gain_per_period: float,
    lb: np.ndarray,
    ub: np.ndarray,
) -> None:
    """``γ/dt (q_min − q) ≤ q̇ ≤ γ/dt (q_max − q)`` intersected into ``lb``, ``ub``, in
    place (``gain_per_period`` = γ/dt, 1/s; angles (nv,), rad)."""
    for j in range(q.shape[0]):
        lb[j] = _larger(lb[j], gain_per_period * (q_min[j] - q[j]))
        ub[j] = _smaller(ub[j], gain_per_period * (q_max[j] - q[j]))


@njit(cache=True)
def box_bounds(lo: np.ndarray, hi: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> None:
    """The bounds so far projected into the command's reachable box ``[lo, hi]`` (nv,),
    rad/s, in place: each end clipped to the box, so a bound the arm cannot reach this
    tick becomes the box's nearest end."""
    for j in range(lo.shape[0]):
        lb[j] = _smaller(_larger(lb[j], lo[j]), hi[j])
        ub[j] = _smaller(_larger(ub[j], lo[j]), hi[j])


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
        repulsion_row(np.zeros(3), np.zeros((3, nv)), np.zeros(3), 3, G, h, 0)
        lb, ub = np.zeros(n), np.zeros(n)
        velocity_bounds(np.ones(nv), lb[:nv], ub[:nv])
        position_bounds(np.zeros(nv), -np.ones(nv), np.ones(nv), 1.0, lb[:nv], ub[:nv])
        box_bounds(np.zeros(nv), np.ones(nv), lb[:nv], ub[:nv])
        raise_rows(h, np.zeros(2))


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
