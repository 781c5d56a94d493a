"""Velocity dampers: every robot set × human part pair may approach only so fast.

For a pair at distance d (m) inside the influence distance d_i, with the unit direction n
from the human to the robot and the Jacobian J_p of the robot's closest point:

    approach speed  −nᵀ J_p q̇  ≤  ξ (d − d_s) / (d_i − d_s)

so the allowed approach speed falls linearly from ξ at d_i to 0 at the set's stop
distance d_s (Faverjon and Tournassoud's damper). d_s is the stop distance of the
paper's rules: 0.05 m for the repelled and end-effector sets (L2, EE), for the scaled set
(L1) the distance at which f reaches 0.8
(eq. 2 inverted, 0.0423 m). A row exists for every pair (fixed structure); pairs beyond
d_i, or not seen, get the bound +inf.

With speed and separation monitoring (``safety="ssm"``) the bound is reduced by the part's
own speed towards the set (``Tick.human_approach``): the robot slows, or retreats, before
a fast hand closes the gap. With power and force limiting (``safety="pfl"``) a pair whose
part permits contact may approach at its permitted contact speed where that is larger
(``Tick.contact_limit``, :mod:`qpavoid.control.contact`): the damper's hard bound becomes
``max(ξ (d − d_s)/(d_i − d_s) − v_h,n, v_max)``, and the avoidance of those parts is left
to the soft repulsion tasks.
"""

from __future__ import annotations

import numpy as np

from qpavoid.control.qp.kernels import check_rows, damper_rows, pair_inputs, raise_rows
from qpavoid.control.qp.pieces import QPPiece
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Tick
from qpavoid.core.compiling import kernel_input
from qpavoid.core.errors import InputError


class VelocityDamper(QPPiece[Tick]):
    """All set × part damper rows (hard: a solution must meet them to be applied).

    Parameters
    ----------
    variables
        The QP's variables.
    d_stop
        (S,) stop distance of each robot set, m.
    influence_m
        d_i, m.
    gain_mps
        ξ, m/s.
    n_parts
        Number of human parts (table columns).
    """

    name = "velocity_damper"

    def __init__(
        self,
        variables: Variables,
        d_stop: np.ndarray,
        influence_m: float,
        gain_mps: float,
        n_parts: int,
    ):
        self.variables = variables
        self.d_stop = np.repeat(np.asarray(d_stop, dtype=float), n_parts)
        if not influence_m > self.d_stop.max():  # else the bound divides by d_i − d_s <= 0
            raise InputError(
                f"damper_influence_m = {influence_m} m must exceed every stop distance "
                f"({self.d_stop.max():.4f} m)",
                name="damper_influence_m",
                value=influence_m,
            )
        self.influence_m, self.gain = float(influence_m), float(gain_mps)  # as compiled
        self.rows = len(self.d_stop)

    def write_qp_inequalities(self, tick: Tick, dt: float, G: np.ndarray, h: np.ndarray) -> None:
        """(rows, n) G and (rows,) h, one row per set × part pair."""
        check_rows(self.name, self.rows, tick.table.distance.size, G, h)
        damper_rows(  # the joint velocities are the first columns
            kernel_input(tick.table.distance.reshape(-1), np.float64),
            *pair_inputs(tick.table, tick.kin),
            self.d_stop,
            self.influence_m,
            self.gain,
            kernel_input(tick.human_approach.reshape(-1), np.float64),
            G,
            h,
        )
        if tick.contact_limit is not None:  # pfl: a transient contact's speed is permitted
            raise_rows(h, kernel_input(tick.contact_limit.reshape(-1), np.float64))
