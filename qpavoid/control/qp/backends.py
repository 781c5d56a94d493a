"""Solving the QP: a persistent OSQP problem, daqp directly, or any solver through qpsolvers.

The backends give the same answer to the documented tolerance (docs/qp.md):

* :class:`PersistentOSQP` (the default) sets one ``osqp.OSQP`` problem up once with a
  fixed sparsity pattern (dense blocks: every G row exists every tick, inactive rows have
  h = +inf) and only ``update()``s its numbers each tick, warm started;
* :class:`DirectDAQP` calls daqp directly each tick (cold, no qpsolvers layer);
* :class:`QPSolversBackend` builds a new problem each tick through qpsolvers, with any
  installed solver, for portability and cross-checking.

A solution is returned with ``found = False`` (and a reason) unless the solver reports
success; the controller then stops the robot.
"""

from __future__ import annotations

import importlib
from typing import Any

import numpy as np
import osqp
import scipy.sparse as sp

from qpavoid.control.qp.checks import DEFECTS, crossed_bounds, kernel_arrays, not_finite
from qpavoid.control.qp.config import QPConfig
from qpavoid.control.qp.problem import QPProblem, QPSolution
from qpavoid.control.qp.solver_kernels import daqp_arrays, flush_tiny, osqp_arrays, warm_up
from qpavoid.core.errors import InputError, SolverError

#: QP solvers that come with an extra of ours, and its name (``pip install "qpavoid[solvers]"``).
SOLVER_EXTRAS = {"daqp": "solvers", "proxqp": "solvers"}


def qpsolvers() -> Any:
    """The qpsolvers module, imported on first use: with the solvers it finds (and SciPy's
    optimizers) it takes about 0.3 s, which a run on OSQP or daqp never needs."""
    return importlib.import_module("qpsolvers")


def check_solver(name: str) -> str:
    """``name`` if qpsolvers has that solver installed; else say which extra brings it."""
    available = qpsolvers().available_solvers
    if name in available:
        return name
    hint = (
        f'; install it with pip install "qpavoid[{SOLVER_EXTRAS[name]}]"'
        if name in SOLVER_EXTRAS
        else ""
    )
    raise InputError(
        f"QP solver {name!r} is not installed (installed: {', '.join(sorted(available))}){hint}",
        name="solver",
        value=name,
    )


#: ProxQP's absolute tolerance: at OSQP's 1e-7 its answers differ from daqp's by up to
#: 4e-5 rad/s on recorded ticks; at 1e-9 by less than 1e-6 (docs/qp.md).
PROXQP_EPS_ABS = 1e-9


#: Warm-start values below this (in magnitude) are set to zero between solves: far below
#: any tolerance, and they would otherwise decay into subnormal numbers, which make
#: OSQP's iterations twice as slow (:meth:`PersistentOSQP._clean_warm_start`).
WARM_START_FLOOR = 1e-20


def _osqp_settings(cfg: QPConfig) -> dict:
    return dict(
        eps_abs=cfg.eps_abs,
        eps_rel=cfg.eps_rel,
        max_iter=cfg.max_iter,
        polishing=cfg.polish,
        verbose=False,
    )


class PersistentOSQP:
    """One OSQP problem for the controller's lifetime, updated and warm started each tick.

    OSQP's form is ``min ½xᵀPx + qᵀx, l ≤ Ax ≤ u``: here ``A = [I; G]``,
    ``l = [lb; −inf]``, ``u = [ub; h]``. P (upper triangle) and A have a fixed dense
    pattern, so each tick is ``update(q, l, u, Px, Ax)`` and ``solve()``.

    Parameters
    ----------
    n
        Number of variables.
    m
        Number of G rows.
    cfg
        Tolerances and iteration cap.
    """

    name = "osqp-persistent"

    def __init__(self, n: int, m: int, cfg: QPConfig):
        self.n, self.m = n, m
        # CSC patterns: P upper triangle column by column; A = [I; G] with every G entry.
        rows_p = [r for j in range(n) for r in range(j + 1)]
        cols_p = [j for j in range(n) for _ in range(j + 1)]
        self._p_idx = np.array(rows_p) * n + np.array(cols_p)
        rows_a = [r for j in range(n) for r in (j, *range(n, n + m))]  # solver_kernels.osqp_arrays
        cols_a = [j for j in range(n) for _ in range(m + 1)]
        P = sp.csc_matrix((np.ones(len(rows_p)), (rows_p, cols_p)), shape=(n, n))
        A = sp.csc_matrix((np.ones(len(rows_a)), (rows_a, cols_a)), shape=(n + m, n))
        self._l = np.full(n + m, -np.inf)
        self._u = np.full(n + m, np.inf)
        self._Px, self._Ax = np.zeros(len(rows_p)), np.zeros(len(rows_a))
        warm_up()  # solver_kernels, before the first solve
        self._solver = osqp.OSQP()
        # The numbers here are placeholders (P must be positive semidefinite for setup);
        # only the pattern matters: every tick replaces all of them.
        P.data[:] = np.eye(n)[rows_p, cols_p]
        self._solver.setup(P, np.zeros(n), A, self._l, self._u, **_osqp_settings(cfg))
        self._solved = osqp.SolverStatus.OSQP_SOLVED
        self._infinity = float(self._solver.constant("OSQP_INFTY"))
        # osqp's Python layer costs 5-8 times its C solve on a problem this small (it
        # rebuilds an info namespace per solve and caches data for derivatives per update):
        # where the compiled solver object offers the calls that layer makes, use them.
        native = getattr(self._solver, "_solver", None)
        self._native = (
            native
            if all(
                hasattr(native, a)
                for a in ("update_data_vec", "update_data_mat", "solve", "info", "solution")
            )
            else None
        )

    def solve(self, prob: QPProblem) -> QPSolution:
        Px, Ax, lower, upper = self._Px, self._Ax, self._l, self._u
        H, c, G, h, lb, ub = kernel_arrays(prob, self.n, self.m)  # sizes checked
        # finiteness (checks.not_finite) checked and the data copied in one pass
        defect, crossed = osqp_arrays(
            H, c, G, h, lb, ub, self._p_idx, self._infinity, Px, Ax, lower, upper
        )
        if defect:
            return QPSolution(None, False, DEFECTS[defect])
        # OSQP rejects l > u (or a non-convex P) in an update by keeping the *previous*
        # data, after which solve() reports "solved" for that old problem: never let it.
        if crossed >= 0:
            return crossed_bounds(lower, upper, crossed)
        if self._native is not None:
            s = self._native
            flag = s.update_data_vec(q=prob.c, l=lower, u=upper) or s.update_data_mat(
                P_x=Px, P_i=None, A_x=Ax, A_i=None
            )
            if flag:
                return QPSolution(None, False, f"OSQP rejected the update (exit flag {flag})")
            s.solve()
            info = s.info
            status_val, status, iters = info.status_val, info.status, info.iter
            x = self._clean_warm_start(s, s.solution)
        else:
            # The public update() discards OSQP's exit flag: check convexity here instead.
            if not _convex(prob.H):
                return QPSolution(None, False, "the cost is not convex (or not finite)")
            self._solver.update(q=prob.c, l=lower, u=upper, Px=Px, Ax=Ax)
            res = self._solver.solve(raise_error=False)
            status_val, status, iters = res.info.status_val, res.info.status, res.info.iter
            x = self._clean_warm_start(self._solver, res)
        found = status_val == self._solved
        return QPSolution(x if found else None, found, str(status), int(iters))  # x: a copy

    @staticmethod
    def _clean_warm_start(solver: Any, solution: Any) -> np.ndarray:
        """The solution's x, after zeroing its tiniest entries (and y's) in the warm start.

        The rows that are inactive (h = +inf) end each solve with duals of about 1e-17
        (rounding), which shrink with every warm-started solve until they are subnormal:
        then every iteration is about twice as slow, the iterations unchanged
        (docs/performance.md §1). Entries below :data:`WARM_START_FLOOR` are set to
        0 in OSQP's warm start (the answer moves by 1e-11, docs/performance.md).
        """
        x = np.array(solution.x, dtype=np.float64)
        y = np.array(solution.y, dtype=np.float64)
        if flush_tiny(x, WARM_START_FLOOR) | flush_tiny(y, WARM_START_FLOOR):
            solver.warm_start(x=x, y=y)
        return x

    def update_settings(self, **settings: Any) -> None:
        """Change OSQP settings (e.g. ``max_iter``) of the live problem."""
        self._solver.update_settings(**settings)


class DirectDAQP:
    """daqp called directly each tick, on buffers kept for the controller's lifetime.

    daqp's form is ``min ½xᵀHx + fᵀx, blower ≤ [x; A x] ≤ bupper`` (its first ``n``
    bounds are simple bounds): here ``A = G``, ``bupper = [ub; h]``,
    ``blower = [lb; −inf]``. Each tick is one cold ``daqp.solve`` (a few µs on these
    problems, docs/performance.md), without qpsolvers' conversions. Not warm started: daqp 0.11's
    ``Model.update`` + ``solve`` was found (adversarial testing) to return a wrong answer
    reported as optimal on about 1 % of recorded ticks, and a NaN one with exit flag 1
    (tests/data/daqp_warm_start_pairs.npz); a cold solve of the same problems is right.
    ``pip install "qpavoid[solvers]"``.

    Parameters
    ----------
    n, m
        Number of variables and of G rows.
    """

    name = "daqp-direct"
    #: daqp's exit flags that mean an optimal solution (1; 2 is soft-optimal: we have no
    #: soft constraints, so it is not accepted).
    SOLVED = (1,)

    def __init__(self, n: int, m: int):
        try:
            import daqp  # the solvers extra; optional
        except ImportError:
            raise SolverError(
                'the daqp backend needs daqp: pip install "qpavoid[solvers]"',
                solver="daqp",
                status="not installed",
            ) from None
        self._daqp = daqp
        warm_up()  # solver_kernels, before the first solve
        self.n, self.m = n, m
        self._upper = np.full(n + m, np.inf)
        self._lower = np.full(n + m, -np.inf)

    def solve(self, prob: QPProblem) -> QPSolution:
        H, c, G, h, lb, ub = kernel_arrays(prob, self.n, self.m)  # sizes checked
        # finiteness (checks.not_finite) checked and the bounds stacked in one pass
        defect, crossed = daqp_arrays(H, c, G, h, lb, ub, self._lower, self._upper)
        if defect:
            return QPSolution(None, False, DEFECTS[defect])
        if crossed >= 0:
            return crossed_bounds(self._lower, self._upper, crossed)
        x, _, flag, info = self._daqp.solve(H, c, G, self._upper, self._lower)
        iterations = int(info.get("iterations", -1)) if isinstance(info, dict) else -1
        if flag not in self.SOLVED:
            return QPSolution(None, False, f"daqp exit flag {flag}", iterations)
        if not np.isfinite(x).all():
            return QPSolution(None, False, f"daqp returned a non-finite x (exit flag {flag})")
        return QPSolution(np.array(x), True, "solved", iterations)


class QPSolversBackend:
    """A new problem each tick through qpsolvers (any installed solver).

    Rows with h = +inf are dropped (not every solver accepts infinite bounds).
    """

    def __init__(self, solver: str, cfg: QPConfig):
        available = qpsolvers().available_solvers
        if solver not in available:
            raise SolverError(
                f"QP solver {solver!r} is not installed; available: {sorted(available)}",
                solver=solver,
                status="not installed",
            )
        self.name, self._qpsolvers = solver, qpsolvers()
        warm_up()  # solver_kernels (checks.not_finite; the controller's hard_excess)
        self._settings = _osqp_settings(cfg) if solver == "osqp" else {}
        if solver == "proxqp":
            self._settings = dict(eps_abs=PROXQP_EPS_ABS, eps_rel=0.0)

    def solve(self, prob: QPProblem) -> QPSolution:
        failed = not_finite(prob)  # solvers take a NaN silently (checks.not_finite)
        if failed is not None:
            return failed
        keep = np.isfinite(prob.h)
        H, G = prob.H, prob.G[keep]
        if self.name == "osqp":  # it wants sparse matrices (and warns otherwise)
            H, G = sp.csc_matrix(H), sp.csc_matrix(G)
        problem = self._qpsolvers.Problem(H, prob.c, G, prob.h[keep], lb=prob.lb, ub=prob.ub)
        try:
            sol = self._qpsolvers.solve_problem(problem, solver=self.name, **self._settings)
        except Exception as exc:  # a solver's own failure must stop the robot, not crash
            return QPSolution(None, False, f"{type(exc).__name__}: {exc}")
        found = bool(sol.found) and sol.x is not None and bool(np.all(np.isfinite(sol.x)))
        return QPSolution(sol.x if found else None, found, "solved" if found else "not solved")


def make_backend(cfg: QPConfig, n: int, m: int) -> PersistentOSQP | DirectDAQP | QPSolversBackend:
    """The backend named by ``cfg.backend``."""
    if cfg.backend == "persistent":
        if cfg.solver != "osqp":
            raise SolverError(
                f"the persistent backend is OSQP's, not {cfg.solver!r}: use backend='daqp' "
                "or backend='qpsolvers'",
                solver=cfg.solver,
                status="unknown backend",
            )
        return PersistentOSQP(n, m, cfg)
    if cfg.backend == "daqp":
        return DirectDAQP(n, m)
    if cfg.backend == "qpsolvers":
        return QPSolversBackend(cfg.solver, cfg)
    raise SolverError(
        f"unknown QP backend {cfg.backend!r}; choose 'persistent', 'daqp' or 'qpsolvers'",
        solver=cfg.backend,
        status="unknown backend",
    )


def _convex(H: np.ndarray) -> bool:
    """True if ``H`` is finite and positive semidefinite (to -1e-9); never raises."""
    if not np.isfinite(H).all():  # eigvalsh returns garbage (or raises) on NaN
        return False
    try:
        return bool(np.linalg.eigvalsh(H).min() >= -1e-9)
    except np.linalg.LinAlgError:  # did not converge
        return False
