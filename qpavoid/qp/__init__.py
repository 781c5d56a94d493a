"""``qpavoid.qp``: the QP controller's public names, as earlier releases had them here.

The code lives in :mod:`qpavoid.control.qp` (the framework, and its ``tasks/``,
``limits/`` and ``barriers/``); this module only names it, for ``import qpavoid.qp``.
"""

from qpavoid.control.qp import (
    Assembler,
    Bounds,
    Constraint,
    DirectDAQP,
    Objective,
    PersistentOSQP,
    QPConfig,
    QPController,
    QPPiece,
    QPProblem,
    QPSolution,
    QPSolversBackend,
    Variables,
    make_backend,
)

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
