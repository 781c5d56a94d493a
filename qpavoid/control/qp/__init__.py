"""The QP controller: the paper's laws as costs and constraints of one QP per tick.

One file per piece, as in pink and mink, each returning full-width blocks
(:mod:`.pieces`: ``Objective(H, c)``, ``Constraint(G, h)``, ``Bounds(lb, ub)``) over the
named variables of :mod:`.variables`: the tasks :mod:`.tasks.ee` (eq. 8),
:mod:`.tasks.regularization`, :mod:`.tasks.elbow` and :mod:`.tasks.posture`
(redundancy); the limits
:mod:`.limits.velocity` (eq. 3), :mod:`.limits.position`, :mod:`.limits.velocity_damper`;
the barriers :mod:`.barriers.repulsion` (eqs. 4-7) and :mod:`.barriers.separation` (ISO/TS
15066). :mod:`.problem` assembles them, :mod:`.backends` solves, :mod:`.controller`
composes.
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
