"""Redundancy mode: use the seventh joint to keep the elbow away from the person."""

from __future__ import annotations

import numpy as np

from qpavoid.control.qp.pieces import Objective, QPPiece
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Tick
from qpavoid.laws.avoidance import logistic


class ElbowClearanceTask(QPPiece[Tick]):
    """Cost ``w (nᵀ J_e q̇ − v)²`` on the elbow point (A4 for the iiwa).

    ``d`` and ``n`` are the sphere distance and unit direction from the closest usable
    human point to the elbow (radii as in eq. 1, each human point with the largest radius
    of its parts), ``J_e`` the elbow's Jacobian and ``v = v_el / (1 + exp((2d/ρ − 1) α))``
    eq. (4)'s shape with a wider ρ: the elbow drifts away well before the paper's laws
    act. With A3 free, the end effector's 6 rows leave one joint motion that does not move
    it (the elbow turning about the shoulder-wrist line), so a small weight lets this cost
    act in that null space without disturbing the path.

    Parameters
    ----------
    variables
        The QP's variables.
    point
        Index of the elbow among the robot's control points.
    robot_radius_m
        Sphere radius of the elbow point, m.
    human_radii_m
        (M,) radius of each human model point, m.
    weight, influence_m, speed_mps, alpha
        w, ρ, v_el and α.
    """

    name = "elbow_task"

    def __init__(
        self,
        variables: Variables,
        point: int,
        robot_radius_m: float,
        human_radii_m: np.ndarray,
        weight: float,
        influence_m: float,
        speed_mps: float,
        alpha: float = 9.0,
    ):
        self.variables, self.point, self.weight = variables, point, weight
        self.radii = robot_radius_m + np.asarray(human_radii_m, dtype=float)
        self.rho, self.speed, self.alpha = influence_m, speed_mps, alpha

    def clearance(self, tick: Tick) -> tuple[float, np.ndarray]:
        """Distance (m) and unit direction human → elbow (zero if nobody is seen)."""
        geo = tick.human
        diff = tick.kin.points[self.point] - geo.filled_points
        d = np.sqrt(np.einsum("mk,mk->m", diff, diff)) - self.radii + geo.point_penalty
        k = int(np.argmin(d))
        if not np.isfinite(d[k]):
            return float("inf"), np.zeros(3)
        return float(d[k]), diff[k] / max(np.linalg.norm(diff[k]), 1e-12)

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
