"""The QP controller: the paper's laws as costs and constraints of one QP per tick."""

from __future__ import annotations

import numpy as np

from ..controller import Command, Controller, ControllerConfig, Tick
from ..human import KinectHuman
from ..laws import ee_repulsive_velocity, modified_ik, repulsive_velocity
from ..robot import Robot
from ..task import ArcPath
from .config import QPConfig
from .ee_task import EndEffectorTask
from .elbow_task import ElbowClearanceTask
from .layout import Layout, QPInput
from .position_limits import PositionLimit
from .problem import Assembler, make_backend
from .regularization import Regularization
from .repulsion import MIN_SPEED_MPS, RepulsionTask
from .velocity_damper import VelocityDamper
from .velocity_limits import VelocityLimit

#: A solution may break a hard row by at most this much (m/s or rad/s) to be applied.
FEASIBILITY_TOL = 1e-5


class QPController(Controller):
    """Drop-in alternative to :class:`~qpavoid.analytic.AnalyticController`.

    Each tick, after the shared prelude (distances, f of eq. 2, the stop rules), it solves

        minimise    ‖W (J q̇ − (v_PL + K e + v_EE))‖²            eq. (8), EndEffectorTask
                  + w (s_L2² + s_EE²)                              eqs. (4)-(7), RepulsionTask
                  + ε ‖q̇‖²                                         Regularization
                  [+ w_el (nᵀ J_p q̇ − v_el)²]                      ElbowClearanceTask (7 joints)
        subject to  u_L2ᵀ J_L2 q̇ + s_L2 ≥ |v_rep,L2|,  s_L2 ≥ 0    closest L2 point moves away
                    u_EEᵀ J_EE q̇ + s_EE ≥ |v_EE|,      s_EE ≥ 0    end effector moves away
                    −nᵀ J_p q̇ ≤ ξ (d − d_s) / (d_i − d_s)          VelocityDamper, every pair
                    |q̇| ≤ q̇_max, A1 and A2 scaled by (1 − f)       VelocityLimit, eq. (3)
                    γ (q_min − q)/dt ≤ q̇ ≤ γ (q_max − q)/dt        PositionLimit

    and commands q̇ only if the solver reports success and the solution meets the hard
    rows; otherwise the robot stops with the solver's status as the reason.

    Parameters
    ----------
    robot, path, config, human
        As for :class:`~qpavoid.controller.Controller`.
    qp
        The QP's weights, gains and solver settings.
    """

    name = "qp"

    def __init__(self, robot: Robot, path: ArcPath | None = None,
                 config: ControllerConfig | None = None, human: KinectHuman | None = None,
                 qp: QPConfig | None = None):
        super().__init__(robot, path, config, human)
        self.qp = qp or QPConfig()
        q, avo = self.qp, self.config.avoidance
        self.layout = layout = Layout(robot.nv)
        d_stop = np.zeros(len(robot.sets))
        d_stop[self.i_L1] = avo.d_stop_L1_m()
        d_stop[self.i_L2] = avo.d_stop_L2_m
        d_stop[self.i_EE] = avo.d_stop_EE_m
        self.ee_task = EndEffectorTask(layout, self.K, q.weight_position, q.weight_orientation)
        rep_L2 = RepulsionTask(layout, "L2", q.weight_repulsion, self.i_L2)
        rep_EE = RepulsionTask(layout, "EE", q.weight_repulsion, self.i_EE)
        self.damper = VelocityDamper(layout, d_stop, q.damper_influence_m, q.damper_gain_mps,
                                     len(self.human.parts))
        self.objectives = [self.ee_task, rep_L2, rep_EE, Regularization(layout, q.regularization)]
        if q.elbow_weight > 0:
            elbow = robot.sets[self.i_L1].points[-1]          # A4, where L1 meets L2
            radii = np.where(self.human.point_part, self.human.sphere_radii, 0.0).max(axis=1)
            self.elbow_task = ElbowClearanceTask(layout, elbow, robot.sphere_radii[elbow], radii,
                                                 q.elbow_weight, q.elbow_influence_m,
                                                 q.elbow_speed_mps)
            self.objectives.append(self.elbow_task)
        self.inequalities = [rep_L2, rep_EE, self.damper]
        self._hard_rows = slice(2, 2 + self.damper.rows)       # the damper rows of G (after 2 soft)
        self.bounds = [VelocityLimit(), PositionLimit(robot.q_min, robot.q_max, q.position_limit_gain),
                       rep_L2, rep_EE]
        self.assembler = Assembler(self.objectives, self.inequalities, self.bounds, layout.n)
        self.backend = make_backend(q, layout.n, self.assembler.m)

    def problem(self, tick):
        """The QP input and problem of a tick (for inspection and cross-checks)."""
        avo = self.config.avoidance
        table = tick.table
        j = table.closest_part(self.i_L2)
        v_rep_L2 = repulsive_velocity(table.distance[self.i_L2, j], table.vector[self.i_L2, j], avo)
        v_rep_EE = ee_repulsive_velocity(table.distance[self.i_EE], table.vector[self.i_EE], avo)
        v_nominal = tick.ref_twist + self.K * tick.error
        dq_nominal = np.zeros(self.layout.nv)
        if np.dot(v_rep_L2, v_rep_L2) >= MIN_SPEED_MPS ** 2:     # only the L2 row needs it
            cfg = self.config
            dq_nominal = modified_ik(tick.kin.ee_jacobian, tick.ref_twist, self.K, tick.error,
                                     v_rep_EE, cfg.sigma_min, cfg.lambda_max)       # eq. (8)
        inp = QPInput(tick, v_rep_L2, v_rep_EE, j, self.config.control_period_s, v_nominal,
                      dq_nominal)
        return inp, self.assembler(inp)

    def act(self, tick: Tick) -> Command:
        inp, prob = self.problem(tick)
        sol = self.backend.solve(prob)
        info = {"solver": self.backend.name, "status": sol.status, "iterations": sol.iterations}
        if not sol.found:
            return self.command(tick, None, reason=f"QP not solved ({self.backend.name}: "
                                f"{sol.status})", info=info)
        x = sol.x
        nv = self.layout.nv
        # Hard rows, checked against the problem we meant to solve: a solution that breaks
        # a bound or a damper by more than the solver's tolerance is never applied; within
        # it, the bounds (joint limits) are then met exactly.
        lb, ub = prob.lb[:nv], prob.ub[:nv]
        excess = max(float(np.max(lb - x[:nv])), float(np.max(x[:nv] - ub)),
                     float(np.max(prob.G[self._hard_rows] @ x - prob.h[self._hard_rows],
                                   initial=-np.inf)))
        if excess > FEASIBILITY_TOL:
            return self.command(tick, None, reason=f"QP solution breaks a hard constraint by "
                                f"{excess:.2e} ({self.backend.name}: {sol.status})", info=info)
        return self.command(tick, np.clip(x[:nv], lb, ub), 1.0, inp.v_rep_L2, inp.v_rep_EE,
                            info=info)
