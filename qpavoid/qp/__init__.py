"""The QP controller (issue 4): the paper's laws as costs and constraints of one QP.

One file per piece, as in pink and mink: :mod:`.ee_task` (eq. 8), :mod:`.repulsion`
(eqs. 4-7), :mod:`.regularization`, :mod:`.elbow_task` (redundancy), :mod:`.velocity_limits`
(eq. 3), :mod:`.position_limits`, :mod:`.velocity_damper`; each returns its own rows.
:mod:`.problem` assembles and solves them; :mod:`.controller` composes them.
"""

from .config import QPConfig
from .controller import QPController
from .problem import PersistentOSQP, QPProblem, QPSolution, QPSolversBackend, assemble

__all__ = ["PersistentOSQP", "QPConfig", "QPController", "QPProblem", "QPSolution",
           "QPSolversBackend", "assemble"]
