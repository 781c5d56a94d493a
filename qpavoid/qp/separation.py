"""Speed and separation monitoring: every robot set × body part pair keeps S_p of room.

For a pair at distance d, with the unit direction n from the human to the robot and the
Jacobian J_p of the robot's closest point, the robot point's approach speed is bounded so
that it can still be stationary before the person arrives (ISO/TS 15066 eq. 1, the terms
of :mod:`qpavoid.ssm`):

    −nᵀ J_p q̇  ≤  v_max(d) = (d − v_h (T_f + T_r + T_s) − C − Z_d − Z_r) / (T_r + T_s/2)

A negative bound asks for a retreat at least that fast; if no command meets every row the
QP is infeasible and the robot stops. Pairs whose bound is beyond any speed the robot can
reach (``inactive_above_mps``), or that are not seen, get the bound +inf (fixed structure).
"""

from __future__ import annotations

import numpy as np

from ..ssm import BOUND_INACTIVE_MPS
from ..tick import Tick
from .pieces import Constraint, QPPiece
from .variables import Variables


class SeparationLimit(QPPiece):
    """All set × part speed and separation rows (hard).

    Parameters
    ----------
    variables
        The QP's variables.
    rows
        Number of set × part pairs.
    inactive_above_mps
        A bound above this speed cannot bind (no robot point moves that fast), m/s.
    """

    name = "separation"

    def __init__(
        self, variables: Variables, rows: int, inactive_above_mps: float = BOUND_INACTIVE_MPS
    ):
        self.variables, self.rows = variables, rows
        self.inactive_above_mps = inactive_above_mps

    def compute_qp_inequalities(self, tick: Tick, dt: float) -> Constraint:
        """(rows, n) G and (rows,) h, one row per set × part pair."""
        table = tick.table
        bound = tick.approach_limit.ravel()
        G = np.zeros((self.rows, self.variables.n))
        h = np.full(self.rows, np.inf)
        active = np.flatnonzero(bound < self.inactive_above_mps)
        if len(active):
            sets, parts = np.divmod(active, table.distance.shape[1])
            Jp = table.robot_jacobians(tick.kin, sets, parts)  # (A, 3, nv)
            normal = table.vector.reshape(-1, 3)[active]
            G[active, self.variables.dq] = -np.einsum("ak,akv->av", normal, Jp)
            h[active] = bound[active]
        return Constraint(G, h)
