"""Redundancy mode: use the seventh joint to keep the elbow away from the person."""

from __future__ import annotations

import numpy as np

from qpavoid.control.qp.pieces import Objective, QPPiece
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Tick
from qpavoid.distance.methods import PointDistance
from qpavoid.laws.avoidance import logistic


class ElbowClearanceTask(QPPiece[Tick]):
    """Cost ``w (nᵀ J_e q̇ − v)²`` on the elbow point (the description's ``[roles] elbow``).

    ``d`` and ``n`` are the sphere distance of eq. (1) and the unit direction from the
    closest human part to the elbow (the distance stage's
    :class:`~qpavoid.distance.methods.PointDistance`: each part's own radius, no
    uncertainty margin), ``J_e`` the elbow's Jacobian and
    ``v = v_el / (1 + exp((2d/ρ − 1) α))`` eq. (4)'s shape with a wider ρ: the elbow
    drifts away well before the paper's laws act. With a redundant arm (the iiwa with A3
    free), the end effector's 6 rows leave one joint motion that does not move it (the
    elbow turning about the shoulder-wrist line), so a small weight lets this cost act in
    that null space without disturbing the path.

    Parameters
    ----------
    variables
        The QP's variables.
    point
        Index of the elbow among the robot's control points.
    distance
        The elbow's distance to each human part (built for ``point``).
    weight, influence_m, speed_mps, alpha
        w, ρ (m), v_el (m/s) and α.
    """

    name = "elbow_task"

    def __init__(
        self,
        variables: Variables,
        point: int,
        distance: PointDistance,
        weight: float,
        influence_m: float,
        speed_mps: float,
        alpha: float = 9.0,
    ):
        self.variables, self.point, self.weight = variables, point, weight
        self.distance = distance
        self.rho, self.speed, self.alpha = influence_m, speed_mps, alpha

    def clearance(self, tick: Tick) -> tuple[float, np.ndarray]:
        """Distance (m) and unit direction human → elbow (zero if nobody is seen)."""
        d, vector = self.distance(tick.kin.points, tick.human)
        k = int(np.argmin(d))
        if not np.isfinite(d[k]):
            return float("inf"), np.zeros(3)
        return float(d[k]), vector[k]

    def compute_qp_objective(self, tick: Tick | None, dt: float) -> Objective:
        assert tick is not None
        n_var, dq = self.variables.n, self.variables.dq
        H, c = np.zeros((n_var, n_var)), np.zeros(n_var)
        d, n = self.clearance(tick)
        if not np.isfinite(d):
            return Objective(H, c)
        v = self.speed * float(logistic(d, self.rho, self.alpha))
        assert tick.kin.point_jacobians is not None  # a tick's kinematics carry the Jacobians
        a = n @ tick.kin.point_jacobians[self.point]  # (nv,)
        H[dq, dq] = 2.0 * self.weight * np.outer(a, a)
        c[dq] = -2.0 * self.weight * v * a
        return Objective(H, c)
