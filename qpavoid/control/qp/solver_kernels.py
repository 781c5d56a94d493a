"""What goes into and comes out of a QP solver, compiled (numba): one pass each.

A problem whose sizes were checked (:func:`~qpavoid.control.qp.checks.kernel_arrays`) is
checked for finiteness and copied into a solver's own arrays in one call
(:func:`osqp_arrays`, :func:`daqp_arrays`); a solution is checked against the hard
rows in one (:func:`hard_excess`); OSQP's warm start is cleaned of subnormal numbers by
:func:`flush_tiny`. As numpy, each was a dozen calls whose overhead outweighed their
arithmetic (docs/performance.md). Compiled code is cached on disk (``cache=True``);
:func:`warm_up` compiles or loads it.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.core.compiling import ctrl_c_deferred

__all__ = [
    "daqp_arrays",
    "flush_tiny",
    "hard_excess",
    "osqp_arrays",
    "problem_defect",
    "stacked_bounds",
    "unreachable_row",
    "warm_up",
]


@njit(cache=True)
def problem_defect(
    H: np.ndarray, c: np.ndarray, G: np.ndarray, h: np.ndarray, lb: np.ndarray, ub: np.ndarray
) -> int:
    """0 if a QP's data are usable, else what is wrong with them: 1 a cost or row
    coefficient that is not finite, 2 a NaN or −inf in h, 3 a NaN or +inf in the lower
    bounds, 4 a NaN or −inf in the upper bounds (h and ub may hold +inf, lb −inf: free
    rows and variables)."""
    for x in H.ravel():
        if not np.isfinite(x):
            return 1
    for x in c:
        if not np.isfinite(x):
            return 1
    for x in G.ravel():
        if not np.isfinite(x):
            return 1
    for code, v, sign in ((2, h, -1.0), (3, lb, 1.0), (4, ub, -1.0)):
        for x in v:
            if np.isnan(x) or x == sign * np.inf:
                return code
    return 0


@njit(cache=True)
def stacked_bounds(
    h: np.ndarray,
    lb: np.ndarray,
    ub: np.ndarray,
    infinity: float,
    lower: np.ndarray,
    upper: np.ndarray,
) -> int:
    """``lower = [lb; −∞]``, ``upper = [ub; h]``, in place, infinities clipped to
    ``±infinity``; the first row with ``lower > upper``, or −1."""
    n, m = lb.shape[0], h.shape[0]
    for j in range(n):
        lower[j] = max(lb[j], -infinity)
        upper[j] = min(ub[j], infinity)
    for r in range(m):
        lower[n + r] = -infinity
        upper[n + r] = min(h[r], infinity)
    for k in range(n + m):
        if lower[k] > upper[k]:
            return k
    return -1


@njit(cache=True)
def osqp_arrays(
    H: np.ndarray,
    c: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    lb: np.ndarray,
    ub: np.ndarray,
    p_index: np.ndarray,
    infinity: float,
    Px: np.ndarray,
    Ax: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
) -> tuple[int, int]:
    """OSQP's data of ``min ½xᵀHx + cᵀx, Gx ≤ h, lb ≤ x ≤ ub`` as ``l ≤ A x ≤ u`` with
    ``A = [I; G]``, in place: ``Px`` the entries ``H.flat[p_index]`` (its upper
    triangle in CSC order), ``Ax`` A's entries column by column (every entry of G is in
    the pattern), ``lower = [lb; −∞]``, ``upper = [ub; h]``, infinities clipped to OSQP's
    ``infinity``.

    Returns ``(defect, crossed)``: :func:`problem_defect`'s code (nothing is written
    unless it is 0) and the first row with ``lower > upper``, or −1
    (:func:`stacked_bounds`). The sizes are the caller's to check
    (:func:`~qpavoid.control.qp.checks.check_shapes`): nothing here is bounds-checked."""
    defect = problem_defect(H, c, G, h, lb, ub)
    if defect:
        return defect, -1
    n, m = G.shape[1], G.shape[0]
    for k in range(p_index.shape[0]):
        Px[k] = H.flat[p_index[k]]
    for j in range(n):
        Ax[j * (m + 1)] = 1.0
        for r in range(m):
            Ax[j * (m + 1) + 1 + r] = G[r, j]
    return 0, stacked_bounds(h, lb, ub, infinity, lower, upper)


@njit(cache=True)
def daqp_arrays(
    H: np.ndarray,
    c: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    lb: np.ndarray,
    ub: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
) -> tuple[int, int]:
    """daqp's bounds ``lower = [lb; −∞] ≤ [x; G x] ≤ upper = [ub; h]``, in place, as
    :func:`osqp_arrays` checks and writes them (daqp takes H, c and G as they are)."""
    defect = problem_defect(H, c, G, h, lb, ub)
    if defect:
        return defect, -1
    return 0, stacked_bounds(h, lb, ub, np.inf, lower, upper)


@njit(cache=True)
def flush_tiny(v: np.ndarray, floor: float) -> bool:
    """Set the entries of ``v`` smaller than ``floor`` in magnitude (but not 0) to 0, in
    place; True if there was any."""
    found = False
    for k in range(v.shape[0]):
        if v[k] != 0.0 and abs(v[k]) < floor:
            v[k] = 0.0
            found = True
    return found


@njit(cache=True)
def hard_excess(
    x: np.ndarray,
    nv: int,
    lb: np.ndarray,
    ub: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    start: int,
    stop: int,
) -> float:
    """How far ``x`` breaks its hard rows: the largest of ``lb − q̇``, ``q̇ − ub`` (joint
    velocities, the first ``nv`` entries) and ``G x − h`` over rows ``start:stop``; NaN if
    any of them is NaN (Python's ``max`` would skip it)."""
    worst = -np.inf
    for j in range(nv):
        for e in (lb[j] - x[j], x[j] - ub[j]):
            if np.isnan(e):
                return np.nan
            worst = max(worst, e)
    for r in range(start, stop):
        e = -h[r]
        for j in range(x.shape[0]):
            e += G[r, j] * x[j]
        if np.isnan(e):
            return np.nan
        worst = max(worst, e)
    return worst


@njit(cache=True)
def unreachable_row(
    G: np.ndarray, h: np.ndarray, lb: np.ndarray, ub: np.ndarray, tol: float
) -> int:
    """The first row ``G_r x ≤ h_r`` that no ``x`` within ``lb ≤ x ≤ ub`` meets by ``tol``,
    or −1: where ``min_{lb≤x≤ub} G_r x = Σ_j (G_rj lb_j if G_rj > 0 else G_rj ub_j)``
    exceeds ``h_r + tol``, the problem is infeasible, whatever a solver would say, and after
    how many iterations. A row with a slack (whose upper bound is +inf) never is; a row or
    bound holding a NaN is not judged (the solver's checks refuse it)."""
    for r in range(G.shape[0]):
        if not h[r] < np.inf:
            continue
        low = 0.0
        for j in range(G.shape[1]):
            g = G[r, j]
            if g > 0.0:
                low += g * lb[j]
            elif g < 0.0:
                low += g * ub[j]
            elif g != g:  # NaN: the row is the solver's checks' to refuse
                low = np.nan
                break
        if low > h[r] + tol:
            return r
    return -1


@functools.cache
def warm_up() -> None:
    """Compile (or load from the disk cache) the kernels, once per process."""
    with ctrl_c_deferred():  # a Ctrl-C while the kernels compile comes right after
        n, nv = 4, 2
        H, c, G, h = np.zeros((n, n)), np.zeros(n), np.zeros((2, n)), np.zeros(2)
        problem_defect(H, c, G, h, c, c)
        hard_excess(c, nv, c, c, G, h, 0, 2)
        unreachable_row(G, h, c, c, 1e-5)
        flush_tiny(c, 1e-20)
        lower, upper = np.zeros(n + 2), np.zeros(n + 2)
        p_index, Px = np.zeros(n * (n + 1) // 2, dtype=np.int64), np.zeros(n * (n + 1) // 2)
        osqp_arrays(H, c, G, h, c, c, p_index, 1e30, Px, np.zeros(3 * n), lower, upper)
        daqp_arrays(H, c, G, h, c, c, lower, upper)
