"""The paper's controller as written (Sect. 5): eqs. (2)-(9) and its stop rules."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from qpavoid.arm.model import Robot, joint_columns
from qpavoid.control.controller import Controller
from qpavoid.control.task import ArcPath
from qpavoid.control.tick import Command, ControllerConfig, Tick
from qpavoid.core.errors import InputError
from qpavoid.human.body import KinectHuman
from qpavoid.laws.avoidance import l2_joint_velocity
from qpavoid.laws.ssm import BOUND_INACTIVE_MPS, speed_scale

#: How eq. (3)'s scaled limits can be enforced (:func:`enforce_limits`).
LIMIT_MODES = ("scale", "clip")


@dataclass(frozen=True)
class AnalyticConfig:
    """Settings of the paper's controller only (shared ones: :class:`ControllerConfig`).

    Attributes
    ----------
    limit_mode
        How the velocity limits of eq. (3) are enforced: ``"scale"`` shrinks the whole
        joint velocity vector (the direction, hence the path, is kept and the path clock
        slows by the same factor; the default, because it keeps the path), ``"clip"``
        saturates each joint on its own (the clock runs on; the direction changes).
    l2_joints
        Joints of the 3×3 Jacobian of eq. (6) and of ``q̇(1:3)`` in eq. (9): the
        paper's A1, A2 and A4 (A3 is locked).
    """

    limit_mode: str = "scale"
    l2_joints: tuple[str, ...] = ("A1", "A2", "A4")

    def __post_init__(self) -> None:
        if self.limit_mode not in LIMIT_MODES:
            raise InputError(
                f"limit_mode must be 'scale' or 'clip', got {self.limit_mode!r}",
                name="limit_mode",
                value=self.limit_mode,
            )


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
       (:func:`enforce_limits`);
    6. with ``safety="ssm"``, speed scaling: the command is scaled down until every robot
       point approaches every body part no faster than the speed and separation bound
       (:func:`~qpavoid.laws.ssm.speed_scale`); where no scaling can meet it, the robot stops.

    Parameters
    ----------
    robot, path, config, human
        As for :class:`~qpavoid.control.controller.Controller`.
    analytic
        This controller's own settings (:class:`AnalyticConfig`).
    """

    name = "analytic"

    def __init__(
        self,
        robot: Robot,
        path: ArcPath | None = None,
        config: ControllerConfig | None = None,
        human: KinectHuman | None = None,
        analytic: AnalyticConfig | None = None,
    ):
        super().__init__(robot, path, config, human)
        self.analytic = analytic or AnalyticConfig()
        self.l2_cols = joint_columns(robot, self.analytic.l2_joints, "l2_joints")

    def act(self, tick: Tick) -> Command:
        cfg = self.config
        dq_L2 = np.zeros(3)
        if tick.v_rep_L2.any():
            J_L2 = tick.table.robot_jacobian(tick.kin, self.i_L2, tick.L2_part)[:, self.l2_cols]
            dq_L2 = l2_joint_velocity(J_L2, tick.v_rep_L2, cfg.sigma_min, cfg.lambda_max)  # (6)
        dq = self.task_joint_velocities(tick)  # eq. (8)
        dq[self.l2_cols] += dq_L2  # eq. (9)
        dq, scale = enforce_limits(dq, tick.limits, self.analytic.limit_mode)  # eq. (3)
        active = np.flatnonzero(tick.approach_limit.ravel() < BOUND_INACTIVE_MPS)
        if len(active):  # speed and separation monitoring (safety="ssm")
            table = tick.table
            sets, parts = np.divmod(active, table.distance.shape[1])
            Jp = table.robot_jacobians(tick.kin, sets, parts)
            approach = -np.einsum("ak,akv,v->a", table.vector.reshape(-1, 3)[active], Jp, dq)
            s = speed_scale(approach, tick.approach_limit.ravel()[active])
            if s is None:
                return self.command(tick, None, reason=tick.separation_reason())
            dq, scale = dq * s, scale * s
        return self.command(tick, dq, scale, tick.v_rep_L2, tick.v_rep_EE)
