"""The paper's controller as written (Sect. 5): eqs. (2)-(9) and its stop rules."""

from __future__ import annotations

import numpy as np

from .controller import Command, Controller, Tick
from .laws import ee_repulsive_velocity, l2_joint_velocity, modified_ik, repulsive_velocity


def enforce_limits(dq: np.ndarray, limits: np.ndarray, mode: str) -> tuple[np.ndarray, float]:
    """Keep ``|dq| <= limits`` (rad/s); return the command and the path clock's rate.

    ``"scale"`` multiplies the whole vector by ``s = min(1, min_i limits_i / |dq_i|)``
    (direction kept, the path clock runs at rate ``s``); ``"clip"`` saturates each joint
    (direction changes, clock at rate 1).
    """
    if mode == "clip":
        return np.clip(dq, -limits, limits), 1.0
    over = np.abs(dq) > limits
    if not over.any():
        return dq, 1.0
    s = float(np.min(limits[over] / np.abs(dq[over])))
    return dq * s, s


class AnalyticController(Controller):
    """The paper's controller: modified inverse kinematics with repulsive velocities.

    Each tick (after the shared prelude, which computes f by eq. (2) and applies the stop
    rules f > 0.8, d_L2 <= 0.05 m, d_EE <= 0.05 m):

    1. eqs. (4)-(6): repulsive velocity of the L2 point closest to the operator, mapped
       to (A1, A2, A4) through its 3×3 position Jacobian (damped inverse);
    2. eq. (7): the sum of the EE repulsive velocities from all eight parts;
    3. eq. (8): ``q̇ = J⁻¹ (v_PL + K e + v_EE)`` (damped inverse near singularities);
    4. eq. (9): ``q̇(A1, A2, A4) += q̇_L2``;
    5. eq. (3): the limits of A1 and A2 scaled by (1 − f), enforced as configured
       (:func:`enforce_limits`).
    """

    name = "analytic"

    def act(self, tick: Tick) -> Command:
        cfg, avo = self.config, self.config.avoidance
        table, kin = tick.table, tick.kin
        j = table.closest_part(self.i_L2)
        v_rep_L2 = repulsive_velocity(table.distance[self.i_L2, j], table.vector[self.i_L2, j], avo)
        dq_L2 = np.zeros(3)
        if v_rep_L2.any():
            J_L2 = table.robot_jacobian(kin, self.i_L2, j)[:, self.l2_cols]
            dq_L2 = l2_joint_velocity(J_L2, v_rep_L2, cfg.sigma_min, cfg.lambda_max)     # eq. (6)
        v_rep_EE = ee_repulsive_velocity(table.distance[self.i_EE], table.vector[self.i_EE], avo)
        dq = modified_ik(kin.ee_jacobian, tick.ref_twist, self.K, tick.error, v_rep_EE,
                         cfg.sigma_min, cfg.lambda_max)                                    # eq. (8)
        dq[self.l2_cols] += dq_L2                                                          # eq. (9)
        dq, scale = enforce_limits(dq, tick.limits, cfg.limit_mode)                         # eq. (3)
        return self.command(tick, dq, scale, v_rep_L2, v_rep_EE)
