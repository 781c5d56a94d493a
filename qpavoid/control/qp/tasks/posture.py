"""Redundancy mode: a posture task in the end effector's null space."""

from __future__ import annotations

import numpy as np
from scipy.linalg import null_space

from qpavoid.control.qp.pieces import QPPiece
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Tick


class PostureTask(QPPiece[Tick]):
    """Cost ``w ‖N (q̇ − k (q_rest − q))‖²``: pull q towards a rest posture, only where the
    end effector does not move.

    ``N = Z Zᵀ`` is the orthogonal projector onto the null space of the (6, nv)
    end-effector Jacobian J (``Z`` (nv, r) an orthonormal basis of it, from the SVD:
    ``scipy.linalg.null_space``), so ``J N = 0``: the joint motion this cost asks for never
    moves the end effector, whatever its weight. ``q̇* = k (q_rest − q)`` is a proportional
    pull towards ``q_rest`` (time constant 1/k). N is symmetric and idempotent
    (``NᵀN = N``), so, up to a constant,

        w ‖N (q̇ − q̇*)‖² = w q̇ᵀ N q̇ − 2 w (N q̇*)ᵀ q̇,

    and with the ``½ xᵀHx + cᵀx`` convention ``H = 2 w N`` and ``c = −2 w N q̇*`` on the
    joint velocities (0 on the slacks).

    The end-effector task ``‖W (J q̇ − v*)‖²`` is flat along the null space (``J Z = 0``)
    and this cost is flat across it (``N`` vanishes on the range of Jᵀ): where no
    constraint binds, the two split q̇ between them, the task's answer is unchanged
    and the null-space component becomes ``w/(w + ε) Zᵀq̇*`` (ε the regularisation).
    A 6-joint arm has no null space away from singularities (``Z`` empty, the cost is
    0); a redundant one (7 joints) has one direction, the elbow's swivel about the
    shoulder-wrist line. At a singular configuration the null space grows by the
    direction the end effector cannot move in to first order, and the cost acts there
    too.

    Parameters
    ----------
    variables
        The QP's variables.
    rest
        (nv,) the rest posture q_rest, rad.
    weight
        w, per (rad/s)².
    gain_per_s
        k, 1/s.
    """

    name = "posture_task"

    def __init__(self, variables: Variables, rest: np.ndarray, weight: float, gain_per_s: float):
        self.variables = variables
        self.rest = np.array(rest, dtype=float)
        self.rest.setflags(write=False)
        self.weight, self.gain = float(weight), float(gain_per_s)

    def target(self, tick: Tick) -> np.ndarray:
        """q̇* = k (q_rest − q), rad/s (nv,)."""
        return self.gain * (self.rest - tick.q)

    def projector(self, tick: Tick) -> np.ndarray:
        """N (nv, nv): the orthogonal projector onto the null space of the end-effector
        Jacobian at the tick."""
        assert tick.kin.ee_jacobian is not None  # a tick's kinematics carry the Jacobians
        Z = null_space(tick.kin.ee_jacobian)
        return Z @ Z.T

    def add_qp_objective(self, tick: Tick, dt: float, H: np.ndarray, c: np.ndarray) -> None:
        """``H[q̇, q̇] += 2 w N``, ``c[q̇] −= 2 w N q̇*``."""
        N = self.projector(tick)
        dq = self.variables.dq
        H[dq, dq] += 2.0 * self.weight * N
        c[dq] -= 2.0 * self.weight * (N @ self.target(tick))
