"""A small regularisation of the joint velocities."""

from __future__ import annotations

import numpy as np

from qpavoid.control.qp.pieces import Objective, QPPiece, readonly
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Tick


class Regularization(QPPiece[Tick]):
    """Cost ``ε ‖q̇‖²``: keeps H positive definite whatever the Jacobian's rank (constant).

    Parameters
    ----------
    variables
        The QP's variables.
    epsilon
        ε, per (rad/s)².
    """

    name = "regularization"
    constant_objective = True

    def __init__(self, variables: Variables, epsilon: float):
        n = variables.n
        self.epsilon = epsilon
        H = np.zeros((n, n))
        idx = np.arange(variables.nv)
        H[idx, idx] = 2.0 * epsilon
        self._objective = Objective(H, np.zeros(n))
        readonly(H, self._objective.c)

    def compute_qp_objective(self, tick: Tick | None, dt: float) -> Objective:
        """``2ε I`` on the joint velocities, 0 elsewhere."""
        return self._objective
