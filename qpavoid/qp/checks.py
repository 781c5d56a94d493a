"""What a backend checks before it hands a problem to a solver.

Solvers take bad data silently: daqp ignores a NaN row and reports success; one NaN left
in OSQP's warm start spoils every later solve; OSQP keeps its *previous* data when an
update has ``l > u`` and then reports "solved" for that old problem. Each check returns a
failed :class:`~qpavoid.qp.problem.QPSolution` saying what is wrong, or None.
"""

from __future__ import annotations

import numpy as np

from ..compiling import kernel_input
from .problem import QPProblem, QPSolution
from .solver_kernels import problem_defect

__all__ = ["DEFECTS", "KernelArrays", "check_shapes", "crossed_bounds", "not_finite"]


#: What :func:`~qpavoid.qp.solver_kernels.problem_defect`'s codes mean.
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


def not_finite(prob: QPProblem) -> QPSolution | None:
    """A failed solution if the problem holds a NaN (or an infinite cost or row
    coefficient), else None. Solvers take such data silently: daqp ignores a NaN row and
    reports success; one NaN left in OSQP's warm start spoils every later solve."""
    defect = problem_defect(
        *(kernel_input(a, np.float64) for a in (prob.H, prob.c, prob.G, prob.h, prob.lb, prob.ub))
    )
    return QPSolution(None, False, DEFECTS[defect]) if defect else None


def crossed_bounds(lower: np.ndarray, upper: np.ndarray, k: int) -> QPSolution:
    """The failed solution of bounds crossed in row ``k`` (``lower[k] > upper[k]``)."""
    return QPSolution(
        None, False, f"infeasible bounds: l > u in row {k} ({lower[k]:.4g} > {upper[k]:.4g})"
    )


class KernelArrays:
    """A problem's six arrays as the compiled checks take them (``kernel_input``), looked
    at in full once per problem object: the assembler fills the same one every tick.

    Its shapes are checked then (:func:`check_shapes`: a ``ValueError``); after that only
    what can change in place without a copy is looked at again, each call: the number of
    dimensions and the write flag (a change of either is looked at in full again), and
    the sizes, which the kernels check themselves
    (:data:`~qpavoid.qp.solver_kernels.WRONG_SHAPES`).

    Parameters
    ----------
    n, m
        The backend's numbers of variables and of G rows.
    """

    NDIM = (2, 1, 2, 1, 1, 1)  # H, c, G, h, lb, ub

    def __init__(self, n: int, m: int) -> None:
        self.n, self.m = n, m
        self.ready: QPProblem | None = None  # the last problem whose arrays were taken as is

    def __call__(self, prob: QPProblem) -> tuple[np.ndarray, ...]:
        arrays = (prob.H, prob.c, prob.G, prob.h, prob.lb, prob.ub)
        if prob is self.ready and all(
            a.ndim == d and a.flags.writeable for a, d in zip(arrays, self.NDIM, strict=True)
        ):
            return arrays
        check_shapes(prob, self.n, self.m)
        taken = tuple(kernel_input(a, np.float64) for a in arrays)
        self.ready = prob if all(a is b for a, b in zip(taken, arrays, strict=True)) else None
        return taken
