"""The paper's controller as written (Sect. 5): eqs. (2)-(9) and its stop rules."""

from __future__ import annotations

from dataclasses import InitVar, dataclass

import numpy as np

from qpavoid.arm.model import Robot, joint_columns
from qpavoid.control.controller import Controller, robot_then_keywords
from qpavoid.control.path import PlannedPath
from qpavoid.control.tick import Command, ControllerConfig, Tick
from qpavoid.core.errors import InputError
from qpavoid.human.body import BodyModel
from qpavoid.laws.avoidance import repelled_joint_velocity
from qpavoid.laws.ssm import speed_scale

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
    repelled_joints
        Joints of the 3×3 Jacobian of eq. (6) and of ``q̇(1:3)`` in eq. (9); None (the
        default): the robot description's (``Roles.repelled_joints``: the paper's A1, A2
        and A4 for the iiwa, A3 locked).
    l2_joints
        The name earlier releases gave ``repelled_joints`` (the paper's set L2), still
        taken as a keyword; given both, they must agree.
    """

    limit_mode: str = "scale"
    repelled_joints: tuple[str, ...] | None = None
    l2_joints: InitVar[tuple[str, ...] | None] = None

    def __post_init__(self, l2_joints: tuple[str, ...] | None) -> None:
        if l2_joints is not None:
            if self.repelled_joints is not None and tuple(self.repelled_joints) != tuple(l2_joints):
                raise InputError(
                    f"l2_joints {l2_joints!r} and repelled_joints {self.repelled_joints!r} "
                    "name one setting: give one",
                    name="l2_joints",
                    value=l2_joints,
                )
            object.__setattr__(self, "repelled_joints", tuple(l2_joints))
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

    The sets and joints are the robot description's by role (the paper's, for the iiwa,
    in brackets). Each tick (after the shared prelude, which computes f by eq. (2) from
    the scaled set (L1) and applies the stop rules f > 0.8, d ≤ 0.05 m for the repelled
    (L2) and end-effector (EE) sets):

    1. eqs. (4)-(6): repulsive velocity of the repelled set's point closest to the
       operator, mapped to the repelled joints (A1, A2, A4) through its position Jacobian
       (damped inverse);
    2. eq. (7): the sum of the end effector's repulsive velocities from all the parts;
    3. eq. (8): ``q̇ = J⁻¹ (v_PL + K e + v_EE)`` (damped inverse near singularities);
    4. eq. (9): ``q̇(repelled joints) += q̇_L2``;
    5. eq. (3): the limits of the scaled joints (A1, A2) scaled by (1 − f), enforced as
       configured (:func:`enforce_limits`);
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

    @robot_then_keywords
    def __init__(
        self,
        robot: Robot,
        *,
        path: PlannedPath | None = None,
        config: ControllerConfig | None = None,
        human: BodyModel | None = None,
        analytic: AnalyticConfig | None = None,
    ):
        super().__init__(robot, path=path, config=config, human=human)
        self.analytic = analytic or AnalyticConfig()
        self.repelled_cols = joint_columns(robot, self.analytic.repelled_joints, "repelled_joints")
        #: A speed and separation bound above this cannot bind (no point of the arm moves
        #: so fast: the description's ``max_point_speed_mps``), m/s.
        self.inactive_above_mps = robot.arm.max_point_speed_mps

    def act(self, tick: Tick) -> Command:
        cfg = self.config
        cols = self.repelled_cols
        dq_rep = np.zeros(len(cols))
        if tick.v_repelled.any():
            Jp = tick.table.robot_jacobian(tick.kin, tick.roles.repelled, tick.repelled_part)
            dq_rep = repelled_joint_velocity(  # eq. (6)
                Jp[:, cols], tick.v_repelled, cfg.sigma_min, cfg.lambda_max
            )
        dq = self.task_joint_velocities(tick)  # eq. (8)
        dq[cols] += dq_rep  # eq. (9)
        dq, scale = enforce_limits(dq, tick.limits, self.analytic.limit_mode)  # eq. (3)
        active = np.flatnonzero(tick.approach_limit.ravel() < self.inactive_above_mps)
        if len(active):  # speed and separation monitoring (safety="ssm")
            table = tick.table
            sets, parts = np.divmod(active, table.distance.shape[1])
            Jp = table.robot_jacobians(tick.kin, sets, parts)
            approach = -np.einsum("ak,akv,v->a", table.vector.reshape(-1, 3)[active], Jp, dq)
            s = speed_scale(approach, tick.approach_limit.ravel()[active])
            if s is None:
                return self.command(tick, None, reason=tick.separation_reason())
            dq, scale = dq * s, scale * s
        return self.command(tick, dq, scale, tick.v_repelled, tick.v_end_effector)
