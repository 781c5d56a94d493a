"""The reach of the next command: the arm's acceleration and jerk limits around the last one."""

from __future__ import annotations

import numpy as np

from qpavoid.control.qp.kernels import box_bounds
from qpavoid.control.qp.pieces import QPPiece
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Tick
from qpavoid.core.compiling import kernel_input


class AccelerationLimit(QPPiece[Tick]):
    """Bounds ``lo ≤ q̇ ≤ hi``, the reachable box of :mod:`qpavoid.control.smoothing`:

        max(u₁ − a dt, u₁ + (u₁ − u₂) − j dt²) ≤ q̇ ≤ min(u₁ + a dt, u₁ + (u₁ − u₂) + j dt²)

    (u₁, u₂ the last two commands, a and j each joint's acceleration and jerk limits), with
    room to brake before each joint limit. It comes after every other bound: the bounds so
    far are projected into the box, so that a velocity or position bound the arm cannot
    reach this tick becomes the box's nearest end (slow down as fast as the arm may),
    never an infeasible problem.
    """

    name = "acceleration_limits"

    def __init__(self, variables: Variables):
        self.variables = variables

    def tighten_qp_bounds(self, tick: Tick, dt: float, lb: np.ndarray, ub: np.ndarray) -> None:
        if tick.command_box is None:  # the paper's steps (ControllerConfig.smooth=False)
            return
        lo, hi = (kernel_input(a, np.float64) for a in tick.command_box)
        dq = self.variables.dq
        box_bounds(lo, hi, lb[dq], ub[dq])
