"""Joint position limits turned into velocity bounds for the next control period."""

from __future__ import annotations

import numpy as np

from qpavoid.control.qp.kernels import position_bounds
from qpavoid.control.qp.pieces import QPPiece
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Tick
from qpavoid.core.compiling import kernel_input


class PositionLimit(QPPiece[Tick]):
    """Bounds ``γ (q_min − q) / dt ≤ q̇ ≤ γ (q_max − q) / dt``.

    After one period of length dt, ``q_max − q`` shrinks at most by the factor (1 − γ), so
    a joint inside its limits never crosses them (it approaches geometrically).

    Parameters
    ----------
    variables
        The QP's variables.
    q_min, q_max
        Position limits, rad.
    gain
        γ in (0, 1].
    """

    name = "position_limits"

    def __init__(self, variables: Variables, q_min: np.ndarray, q_max: np.ndarray, gain: float):
        self.variables = variables
        self.q_min = kernel_input(q_min, np.float64)  # as compiled
        self.q_max = kernel_input(q_max, np.float64)
        self.gain = float(gain)

    def tighten_qp_bounds(self, tick: Tick, dt: float, lb: np.ndarray, ub: np.ndarray) -> None:
        dq, q = self.variables.dq, kernel_input(tick.q, np.float64)
        position_bounds(q, self.q_min, self.q_max, self.gain / dt, lb[dq], ub[dq])
