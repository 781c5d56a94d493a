"""The QP controller: the paper's laws as costs and constraints of one QP per tick.

One file per piece, as in pink and mink, each returning full-width blocks
(:mod:`.pieces`: ``Objective(H, c)``, ``Constraint(G, h)``, ``Bounds(lb, ub)``) over the
named variables of :mod:`.variables`: :mod:`.ee_task` (eq. 8), :mod:`.repulsion`
(eqs. 4-7), :mod:`.regularization`, :mod:`.elbow_task` (redundancy), :mod:`.velocity_limits`
(eq. 3), :mod:`.position_limits`, :mod:`.velocity_damper`. :mod:`.problem` assembles them,
:mod:`.backends` solves, :mod:`.controller` composes.
"""

from qpavoid.control.qp.backends import DirectDAQP, PersistentOSQP, QPSolversBackend, make_backend
from qpavoid.control.qp.config import QPConfig
from qpavoid.control.qp.controller import QPController
from qpavoid.control.qp.pieces import Bounds, Constraint, Objective, QPPiece
from qpavoid.control.qp.problem import Assembler, QPProblem, QPSolution
from qpavoid.control.qp.variables import Variables

__all__ = [
    "Assembler",
    "Bounds",
    "Constraint",
    "DirectDAQP",
    "Objective",
    "PersistentOSQP",
    "QPConfig",
    "QPController",
    "QPPiece",
    "QPProblem",
    "QPSolution",
    "QPSolversBackend",
    "Variables",
    "make_backend",
]
