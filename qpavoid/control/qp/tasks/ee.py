"""The end-effector task of eq. (8) as a least-squares cost."""

from __future__ import annotations

import numpy as np

from qpavoid.control.qp.kernels import ee_task_cost
from qpavoid.control.qp.pieces import QPPiece
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Tick
from qpavoid.core.compiling import kernel_input


class EndEffectorTask(QPPiece[Tick]):
    """Cost ``‖W (J q̇ − v*)‖²`` with ``v* = v_PL + K e + [v_EE; 0]`` (eq. 8).

    ``J`` is the (6, nv) end-effector Jacobian (twist ``[v; ω]`` in the base frame),
    ``W = diag(w_p, w_p, w_p, w_o, w_o, w_o)``. Expanded, up to a constant:
    ``q̇ᵀ (JᵀW²J) q̇ − 2 (JᵀW²v*)ᵀ q̇``, so with the ``½ xᵀHx + cᵀx`` convention
    ``H = 2 JᵀW²J`` and ``c = −2 JᵀW²v*`` on the joint velocities (0 on the slacks).

    Parameters
    ----------
    variables
        The QP's variables.
    weight_position, weight_orientation
        w_p (per m/s) and w_o (per rad/s).
    """

    name = "ee_task"

    def __init__(self, variables: Variables, weight_position: float, weight_orientation: float):
        self.variables = variables
        self.w2 = np.array([weight_position**2] * 3 + [weight_orientation**2] * 3, dtype=float)

    @staticmethod
    def target(tick: Tick) -> np.ndarray:
        """v* of eq. (8): planned twist + K e + the EE repulsion (linear part), (6,)."""
        v = tick.task_twist.copy()
        v[:3] += tick.v_end_effector
        return v

    def add_qp_objective(self, tick: Tick, dt: float, H: np.ndarray, c: np.ndarray) -> None:
        """``H[q̇, q̇] += 2 JᵀW²J``, ``c[q̇] −= 2 JᵀW²v*`` (the joint velocities come first)."""
        J = tick.kin.ee_jacobian
        assert J is not None  # a tick's kinematics carry the Jacobians
        ee_task_cost(
            kernel_input(J, np.float64),  # Pinocchio's are column-major
            self.w2,
            kernel_input(tick.task_twist, np.float64),
            kernel_input(tick.v_end_effector, np.float64),
            H,
            c,
        )
