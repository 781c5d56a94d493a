"""Joint velocity limits: nominal, with the scaled joints' scaled by (1 − f) (eq. 3)."""

from __future__ import annotations

import numpy as np

from qpavoid.control.qp.kernels import velocity_bounds
from qpavoid.control.qp.pieces import QPPiece
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Tick
from qpavoid.core.compiling import kernel_input


class VelocityLimit(QPPiece[Tick]):
    """Bounds ``−q̇_max,r ≤ q̇ ≤ q̇_max,r`` with ``q̇_max,r`` of eq. (3) (rad/s).

    The shared prelude computed the limits (:func:`~qpavoid.laws.avoidance.scaled_velocity_limits`):
    the joints that move the scaled set (the iiwa's A1, A2) scaled by (1 − f).
    """

    name = "velocity_limits"

    def __init__(self, variables: Variables):
        self.variables = variables

    def tighten_qp_bounds(self, tick: Tick, dt: float, lb: np.ndarray, ub: np.ndarray) -> None:
        dq = self.variables.dq
        velocity_bounds(kernel_input(tick.limits, np.float64), lb[dq], ub[dq])
