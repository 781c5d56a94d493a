"""The QP controller: the paper's laws as costs and constraints of one QP per tick."""

from __future__ import annotations

import numpy as np

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import Robot
from qpavoid.control.controller import Controller, robot_then_keywords
from qpavoid.control.path import PlannedPath
from qpavoid.control.qp.backends import make_backend
from qpavoid.control.qp.barriers.repulsion import EERepulsionTask, RepelledRepulsionTask
from qpavoid.control.qp.barriers.separation import SeparationLimit
from qpavoid.control.qp.config import QPConfig
from qpavoid.control.qp.kernels import warm_up
from qpavoid.control.qp.limits.acceleration import AccelerationLimit
from qpavoid.control.qp.limits.position import PositionLimit
from qpavoid.control.qp.limits.velocity import VelocityLimit
from qpavoid.control.qp.limits.velocity_damper import VelocityDamper
from qpavoid.control.qp.one_pass import OnePass
from qpavoid.control.qp.pieces import QPPiece
from qpavoid.control.qp.problem import Assembler, QPProblem, QPSolution
from qpavoid.control.qp.solver_kernels import hard_excess, unreachable_row
from qpavoid.control.qp.tasks.ee import EndEffectorTask
from qpavoid.control.qp.tasks.elbow import ElbowClearanceTask
from qpavoid.control.qp.tasks.posture import PostureTask
from qpavoid.control.qp.tasks.regularization import Regularization
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Command, ControllerConfig, Tick
from qpavoid.core.errors import InputError
from qpavoid.distance.methods import PointDistance
from qpavoid.human.body import BodyModel
from qpavoid.laws.avoidance import set_stop_distances

#: A solution may break a hard row by at most this much (m/s or rad/s) to be applied.
FEASIBILITY_TOL = 1e-5


class QPController(Controller):
    """Drop-in alternative to :class:`~qpavoid.control.analytic.AnalyticController`.

    Each tick, after the shared prelude (distances, f of eq. 2, the stop rules), it solves
    (L2 is the repelled set, EE the end effector, as the robot description's roles say)

        minimise    ‖W (J q̇ − (v_PL + K e + v_EE))‖²          eq. (8), EndEffectorTask
                  + w (s_L2² + s_EE²)                          eqs. (4)-(7), repulsion
                  + ε ‖q̇‖²                                       Regularization
                  [+ w_el (nᵀ J_p q̇ − v_el)²]                    ElbowClearanceTask (7 joints)
                  [+ w_po ‖N (q̇ − k (q_rest − q))‖²]             PostureTask (7 joints)
        subject to  u_L2ᵀ J_L2 q̇ + s_L2 ≥ u_L2ᵀ J_L2 q̇₈ + |v_rep,L2|     RepelledRepulsionTask
                    u_EEᵀ J_EE q̇ + s_EE ≥ u_EEᵀ (v_PL + K e) + |v_EE|  EERepulsionTask
                    s_L2, s_EE ≥ 0
                    −nᵀ J_p q̇ ≤ ξ (d − d_s) / (d_i − d_s) [− v_h,n] VelocityDamper, every pair
                   [−nᵀ J_p q̇ ≤ v_max(d)                         SeparationLimit, ssm only:
                                                                   one row per pair with
                                                                   the damper's, the smaller
                                                                   bound]
                    |q̇| ≤ q̇_max, scaled joints × (1 − f)          VelocityLimit, eq. (3)
                    γ (q_min − q)/dt ≤ q̇ ≤ γ (q_max − q)/dt      PositionLimit
                    lo ≤ q̇ ≤ hi, within reach of the last command AccelerationLimit

    (q̇₈: eq. (8)'s joint velocities; :mod:`qpavoid.control.qp.barriers.repulsion` explains the
    repulsion
    rows),
    and commands q̇ only if the solver reports success and the solution meets the hard
    rows; otherwise the robot stops with the solver's status as the reason.

    Parameters
    ----------
    robot, path, config, human
        As for :class:`~qpavoid.control.controller.Controller`.
    qp
        The QP's weights, gains and solver settings.
    rest_posture
        (nq,) the posture task's rest posture, rad (used with ``qp.posture_weight > 0``);
        None (the default): the start configuration, the inverse kinematics of the path's
        start pose, as :func:`~qpavoid.loop.simulation.simulate` starts a run. The start,
        rather than the middle of the joint ranges: it is the posture the description's
        IK seed chose for the task (the branch, the elbow up), where the arm starts
        collision-free beside the person's table, so the task only undoes the drift of
        the null space (minimum-norm steps are not cyclic) and returns the elbow after the
        elbow task has pushed it away; the middle of the ranges would swing the elbow away
        from the chosen posture at the first tick, and the position limits are already
        the QP's bounds.

    Raises
    ------
    InputError
        If ``qp.elbow_weight > 0`` and the description names no elbow, or
        ``rest_posture`` is not a finite (nq,) array.
    IKNotConvergedError
        If the posture task needs the start configuration and the path's start pose is
        out of reach.
    """

    name = "qp"

    @robot_then_keywords
    def __init__(
        self,
        robot: Robot,
        *,
        path: PlannedPath | None = None,
        config: ControllerConfig | None = None,
        human: BodyModel | None = None,
        qp: QPConfig | None = None,
        rest_posture: np.ndarray | None = None,
    ):
        super().__init__(robot, path=path, config=config, human=human)
        self.qp = qp or QPConfig()
        w, cfg = self.qp, self.config
        self.variables = x = Variables(robot.nv)
        ssm = cfg.monitors_separation
        d_stop = set_stop_distances(cfg.avoidance, self.roles, len(robot.sets))
        self.ee_task = EndEffectorTask(x, w.weight_position, w.weight_orientation)
        pieces: list[QPPiece[Tick]] = [
            self.ee_task,
            RepelledRepulsionTask(x, w.weight_repulsion, self.task_joint_velocities),
            EERepulsionTask(x, w.weight_repulsion),
            Regularization(x, w.regularization),
        ]
        if w.elbow_weight > 0:
            elbow = self.roles.elbow  # the description's: for the iiwa A4, where L1 meets L2
            if elbow is None:
                raise InputError(
                    f"elbow_weight: the robot description {robot.name!r} names no elbow "
                    "point (add elbow to its [roles], docs/robot.md)",
                    name="elbow_weight",
                    value=w.elbow_weight,
                )
            radius = float(robot.sphere_radii[elbow])
            pieces.append(
                ElbowClearanceTask(
                    x,
                    elbow,
                    PointDistance(elbow, len(robot.point_frames), radius, self.human),
                    w.elbow_weight,
                    w.elbow_influence_m,
                    w.elbow_speed_mps,
                )
            )
        if w.posture_weight > 0:
            rest = (
                inverse_kinematics(robot, self.path.reference(0.0)[0])
                if rest_posture is None
                else robot.check_q(rest_posture)
            )
            pieces.append(PostureTask(x, rest, w.posture_weight, w.posture_gain_per_s))
        pieces += [
            VelocityDamper(
                x, d_stop, w.damper_influence_m, w.damper_gain_mps, len(self.human.parts)
            ),
            # with the paper's rules every separation row is inactive: not in the problem
            *(
                [
                    SeparationLimit(
                        x, len(robot.sets) * len(self.human.parts), robot.arm.max_point_speed_mps
                    )
                ]
                if ssm
                else []
            ),
            VelocityLimit(x),
            PositionLimit(x, robot.q_min, robot.q_max, w.position_limit_gain),
            AccelerationLimit(x),  # last: the others' bounds projected into its box
        ]
        warm_up()  # the QP's compiled pieces, before the first tick (the backend warms its own)
        self.assembler = Assembler(x.n, pieces)
        # the standard pieces' problem in one compiled call (None: another set of pieces,
        # which the assembler writes piece by piece)
        self.one_pass = OnePass.of(self.assembler)
        self.backend = make_backend(w, x.n, self.assembler.m)
        # the hard rows: the pairs' (the dampers', which the separation's bounds tighten)
        self._hard = self.assembler.rows[VelocityDamper.name]

    def problem(self, tick: Tick) -> QPProblem:
        """The QP of a tick (for inspection and cross-checks)."""
        return self.assembler(tick, self.config.control_period_s)

    def _unreachable(self, prob: QPProblem, row: int) -> QPSolution:
        """The solution of a problem whose row ``row`` no x within the bounds meets."""
        pieces = ", ".join(n for n, rows in prob.rows.items() if rows.start <= row < rows.stop)
        return QPSolution(
            None, False, f"primal infeasible: row {row} ({pieces}) beyond the bounds", 0
        )

    def act(self, tick: Tick) -> Command:
        # the pass only for the assembler it was made for (one swapped in later writes its
        # own pieces, as problem() shows them)
        one_pass = self.one_pass
        writer: Assembler[Tick] | OnePass = (
            one_pass
            if one_pass is not None and one_pass.assembler is self.assembler
            else self.assembler
        )
        prob = writer.fill(tick, self.config.control_period_s)
        # a row beyond the bounds: infeasible, said at once (a solver takes hundreds of
        # iterations to say so, thousands at worst: a hold's every tick late)
        row = unreachable_row(prob.G, prob.h, prob.lb, prob.ub, FEASIBILITY_TOL)
        sol = self.backend.solve(prob) if row < 0 else self._unreachable(prob, row)
        info = {"solver": self.backend.name, "status": sol.status, "iterations": sol.iterations}
        if not sol.found or sol.x is None:
            reason = f"QP not solved ({self.backend.name}: {sol.status})"
            if (tick.approach_limit < 0.0).any():  # a part inside its protective distance
                # infeasible: no command keeps the separation, the hold itself; any other
                # failure (iterations, an inaccurate solve) is said as the solver's too
                hold = "infeasible" in str(sol.status)
                reason = tick.separation_reason() + ("" if hold else f" ({reason})")
            return self.command(tick, None, reason=reason, info=info)
        x, dq = sol.x, self.variables.dq
        # Hard rows, checked against the problem we meant to solve: a solution that breaks
        # a bound or a damper by more than the solver's tolerance is never applied; within
        # it, the bounds (joint limits) are then met exactly.
        lb, ub, dq_x = prob.lb[dq], prob.ub[dq], x[dq]
        excess = hard_excess(  # NaN if any is NaN
            x,
            self.variables.nv,
            prob.lb,
            prob.ub,
            prob.G,
            prob.h,
            self._hard.start,
            self._hard.stop,
        )
        if not excess <= FEASIBILITY_TOL:  # NaN too
            return self.command(
                tick,
                None,
                reason=f"QP solution breaks a hard constraint by "
                f"{excess:.2e} ({self.backend.name}: {sol.status})",
                info=info,
            )
        return self.command(
            tick,
            np.minimum(np.maximum(dq_x, lb), ub),  # as np.clip, without its slower checks
            1.0,
            tick.v_repelled,
            tick.v_end_effector,
            info=info,
        )
