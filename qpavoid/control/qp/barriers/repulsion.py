"""The paper's repulsive velocities (eqs. 4-7) as soft rows with a slack.

In the paper the repulsion is *added* to the motion the task asks for: eq. (8) puts v_EE
into the end effector's target, and eq. (9) adds to the joints the velocity that moves
the repelled set's (L2's) closest point at v_rep,L2 on top of eq. (8)'s motion. As a QP:
the point's speed along the repulsion direction u = v / |v| should be at least its
nominal speed plus the law's speed,

    uᵀ J_p q̇ + s ≥ uᵀ ṗ_nominal + |v|,   s ≥ 0,   cost w s²,

written as the row ``−uᵀ J_p q̇ − s ≤ −(uᵀ ṗ_nominal + |v|)``. For the end effector
(:class:`EERepulsionTask`, eq. 7) ṗ_nominal is the linear part of v_PL + K e (eq. 8
without v_EE); for the repelled set's closest point (:class:`RepelledRepulsionTask`,
eqs. 4-6) it is
J_p q̇₈ with q̇₈ eq. (8)'s joint velocities. Moving away faster costs nothing; falling
short costs w s². Where the task can be met the row costs nothing either, so it only acts
against other constraints. The row is always present (fixed structure); below
:data:`MIN_SPEED_MPS` its bound is +inf.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from qpavoid.control.qp.kernels import MIN_SPEED_MPS, repulsion_row
from qpavoid.control.qp.pieces import Bounds, Objective, QPPiece, free_bounds, readonly
from qpavoid.control.qp.variables import Variables
from qpavoid.control.tick import Tick
from qpavoid.core.compiling import kernel_input

__all__ = [
    "MIN_SPEED_MPS",
    "EERepulsionTask",
    "L2RepulsionTask",
    "RepelledRepulsionTask",
    "RepulsionTask",
]


class RepulsionTask(QPPiece[Tick]):
    """Soft "move away at least this fast" for one robot point: cost, row and bound.

    Its cost ``w s²`` and bound ``s ≥ 0`` on its slack are constant; its one row is not.
    Subclasses say which point, how fast (:meth:`velocity`) and from what nominal motion
    (:meth:`motion`).

    Parameters
    ----------
    variables
        The QP's variables (the slack is found by :attr:`name`).
    weight
        w, per m/s of shortfall.
    """

    rows = 1
    constant_objective = True
    constant_bounds = True

    def __init__(self, variables: Variables, weight: float):
        self.variables, self.weight = variables, weight
        self.slack = variables.slack(self.name)
        n = variables.n
        H = np.zeros((n, n))
        H[self.slack, self.slack] = 2.0 * weight
        self._objective = Objective(H, np.zeros(n))
        lb, ub = free_bounds(n)
        lb[self.slack] = 0.0
        self._bounds = Bounds(lb, ub)
        # no motion needed (writeable, as the kernel was compiled for: never written)
        self._idle = (np.zeros((3, variables.nv)), np.zeros(3))
        readonly(H, self._objective.c, lb, ub)

    def velocity(self, tick: Tick) -> np.ndarray:
        """The law's repulsive velocity v of the point, m/s (3,)."""
        raise NotImplementedError

    def motion(self, tick: Tick) -> tuple[np.ndarray, np.ndarray]:
        """The point's Jacobian J_p (3, nv) and its nominal velocity ṗ_nominal (3,), m/s."""
        raise NotImplementedError

    def compute_qp_objective(self, tick: Tick | None, dt: float) -> Objective:
        """``w s²`` on the slack."""
        return self._objective

    def compute_qp_bounds(self, tick: Tick | None, dt: float) -> Bounds:
        """``s ≥ 0``."""
        return self._bounds

    def row_inputs(self, tick: Tick) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(v, J_p, ṗ_nominal)`` as :func:`~qpavoid.control.qp.kernels.repulsion_row`
        takes them; the point's motion is found only for a speed of at least
        :data:`MIN_SPEED_MPS` (zeros otherwise, which the row does not read)."""
        v = kernel_input(self.velocity(tick), np.float64)
        if math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) < MIN_SPEED_MPS:
            return v, self._idle[0], self._idle[1]
        Jp, nominal = self.motion(tick)
        return v, kernel_input(Jp, np.float64), kernel_input(nominal, np.float64)

    def write_qp_inequalities(self, tick: Tick, dt: float, G: np.ndarray, h: np.ndarray) -> None:
        """One row: ``−uᵀ J_p q̇ − s ≤ −(uᵀ ṗ_nominal + |v|)``."""
        repulsion_row(*self.row_inputs(tick), self.slack, G, h, 0)


class RepelledRepulsionTask(RepulsionTask):
    """Eqs. (4)-(6): the repelled set's point closest to the person moves away at v_rep
    (the paper's L2 and v_rep,L2). The set is the tick's ``roles.repelled``.

    Parameters
    ----------
    variables, weight
        As for :class:`RepulsionTask`.
    task_joint_velocities
        Eq. (8)'s joint velocities q̇₈ of a tick (the controller's), for the point's
        nominal velocity J_p q̇₈.
    """

    name = "repulsion_repelled"

    def __init__(
        self,
        variables: Variables,
        weight: float,
        task_joint_velocities: Callable[[Tick], np.ndarray],
    ):
        super().__init__(variables, weight)
        self.task_joint_velocities = task_joint_velocities

    def velocity(self, tick: Tick) -> np.ndarray:
        return tick.v_repelled

    def motion(self, tick: Tick) -> tuple[np.ndarray, np.ndarray]:
        Jp = tick.table.robot_jacobian(tick.kin, tick.roles.repelled, tick.repelled_part)
        return Jp, Jp @ self.task_joint_velocities(tick)  # J_p q̇₈, eq. (8)


class EERepulsionTask(RepulsionTask):
    """Eq. (7): the end effector moves away at v_EE, on top of v_PL + K e."""

    name = "repulsion_end_effector"

    def velocity(self, tick: Tick) -> np.ndarray:
        return tick.v_end_effector

    def motion(self, tick: Tick) -> tuple[np.ndarray, np.ndarray]:
        assert tick.kin.ee_jacobian is not None
        return tick.kin.ee_jacobian[:3], tick.task_twist[:3]


#: The name earlier releases gave :class:`RepelledRepulsionTask` (the paper's set L2).
L2RepulsionTask = RepelledRepulsionTask
