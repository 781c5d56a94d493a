"""What a backend checks before it hands a problem to a solver.

Solvers take bad data silently: daqp ignores a NaN row and reports success; one NaN left
in OSQP's warm start spoils every later solve; OSQP keeps its *previous* data when an
update has ``l > u`` and then reports "solved" for that old problem. Each check returns a
failed :class:`~qpavoid.control.qp.problem.QPSolution` saying what is wrong, or None.
"""

from __future__ import annotations

import numpy as np

from qpavoid.control.qp.problem import QPProblem, QPSolution
from qpavoid.control.qp.solver_kernels import problem_defect
from qpavoid.core.compiling import kernel_input

__all__ = ["DEFECTS", "check_shapes", "crossed_bounds", "kernel_arrays", "not_finite"]


#: What :func:`~qpavoid.control.qp.solver_kernels.problem_defect`'s codes mean.
DEFECTS = {
    1: "the QP's cost or rows are not finite",
    2: "the QP's h hold a NaN or −inf",
    3: "the QP's lower bounds hold a NaN or +inf",
    4: "the QP's upper bounds hold a NaN or −inf",
}


def check_shapes(prob: QPProblem, n: int, m: int) -> None:
    """Raise ``ValueError`` unless ``prob`` has ``n`` variables and ``m`` rows, as the
    backend was built for (its compiled copy into the solver's arrays writes unchecked)."""
    shapes = [a.shape for a in (prob.H, prob.c, prob.G, prob.h, prob.lb, prob.ub)]
    if shapes != [(n, n), (n,), (m, n), (m,), (n,), (n,)]:
        raise ValueError(f"a QP of shapes {shapes} for a backend of n = {n}, m = {m}")


def kernel_arrays(prob: QPProblem, n: int, m: int) -> tuple[np.ndarray, ...]:
    """``prob``'s H, c, G, h, lb, ub as the compiled checks take them (``kernel_input``),
    after :func:`check_shapes` (every call: an array can be reshaped in place)."""
    check_shapes(prob, n, m)
    return _as_kernel_input(prob)


def _as_kernel_input(prob: QPProblem) -> tuple[np.ndarray, ...]:
    """``prob``'s H, c, G, h, lb, ub, each through ``kernel_input`` (float64, C order)."""
    return tuple(
        kernel_input(a, np.float64) for a in (prob.H, prob.c, prob.G, prob.h, prob.lb, prob.ub)
    )


def not_finite(prob: QPProblem) -> QPSolution | None:
    """A failed solution if the problem holds a NaN (or an infinite cost or row
    coefficient), else None. Solvers take such data silently: daqp ignores a NaN row and
    reports success; one NaN left in OSQP's warm start spoils every later solve."""
    defect = problem_defect(*_as_kernel_input(prob))  # any sizes: no shape to check
    return QPSolution(None, False, DEFECTS[defect]) if defect else None


def crossed_bounds(lower: np.ndarray, upper: np.ndarray, k: int) -> QPSolution:
    """The failed solution of bounds crossed in row ``k`` (``lower[k] > upper[k]``)."""
    return QPSolution(
        None, False, f"infeasible bounds: l > u in row {k} ({lower[k]:.4g} > {upper[k]:.4g})"
    )
