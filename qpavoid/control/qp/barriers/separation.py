"""Speed and separation monitoring: every robot set × body part pair keeps S_p of room.

For a pair at distance d, with the unit direction n from the human to the robot and the
Jacobian J_p of the robot's closest point, the robot point's approach speed is bounded so
that it can still be stationary before the person arrives (ISO/TS 15066 eq. 1, the terms
of :mod:`qpavoid.laws.ssm`):

    −nᵀ J_p q̇  ≤  v_max(d) = (d − v_h (T_f + T_r + T_s) − C − Z_d − Z_r) / (T_r + T_s/2)

A negative bound asks for a retreat at least that fast; if no command meets every row the
QP is infeasible and the robot stops. Pairs whose bound is beyond any speed the robot can
reach (``inactive_above_mps``), or that are not seen, get the bound +inf (fixed structure).

The left side is the velocity dampers' (:mod:`qpavoid.control.qp.limits.velocity_damper`)
pair for pair, so these bounds tighten the dampers' rows rather than adding as many again
(:attr:`~qpavoid.control.qp.pieces.QPPiece.tightens`): each pair's row is bounded by the
smaller of the two, and OSQP factors half the rows (docs/performance.md §2f).
"""

from __future__ import annotations

import numpy as np

from qpavoid.control.qp.kernels import check_rows, pair_inputs, separation_rows
from qpavoid.control.qp.pieces import QPPiece
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Tick
from qpavoid.core.compiling import kernel_input


class SeparationLimit(QPPiece[Tick]):
    """All set × part speed and separation rows (hard).

    Parameters
    ----------
    variables
        The QP's variables.
    rows
        Number of set × part pairs.
    inactive_above_mps
        A bound above this speed cannot bind (no robot point moves that fast: the robot
        description's ``[arm] max_point_speed_mps``), m/s.
    """

    name = "separation"
    tightens = "velocity_damper"

    def __init__(self, variables: Variables, rows: int, inactive_above_mps: float):
        self.variables, self.rows = variables, rows
        self.inactive_above_mps = float(inactive_above_mps)  # as compiled

    def write_qp_inequalities(self, tick: Tick, dt: float, G: np.ndarray, h: np.ndarray) -> None:
        """Lower ``h`` (rows,) of the pairs' rows ``G`` (rows, n) to speed and separation's
        bounds, one row per set × part pair (rows of ``0 ≤ +inf`` given: its own rows)."""
        check_rows(self.name, self.rows, tick.approach_limit.size, G, h)
        separation_rows(  # the joint velocities are the first columns
            kernel_input(tick.approach_limit.reshape(-1), np.float64),
            *pair_inputs(tick.table, tick.kin),
            self.inactive_above_mps,
            G,
            h,
        )
