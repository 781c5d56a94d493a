"""The paper's repulsive velocities (eqs. 4-7) as soft constraints with a slack.

In the paper the repulsion is *added* to the motion the task asks for: eq. (8) puts v_EE
into the end effector's target, and eq. (9) adds to the joints the velocity that moves
the closest L2 point at v_rep,L2 on top of eq. (8)'s motion. As a QP cost: the point's
speed along the repulsion direction u should be at least its nominal speed plus the
law's speed,

    uᵀ J_p q̇ + s ≥ uᵀ v_nominal + |v|,   s ≥ 0,   cost w s²,

i.e. ``−uᵀ J_p q̇ − s ≤ −(uᵀ v_nominal + |v|)``. For the end effector v_nominal is
v_PL + K e (eq. 8 without v_EE); for the L2 point it is J_p q̇₈ with q̇₈ eq. (8)'s joint
velocities. Moving away faster costs nothing; falling short costs w s². Where the task
can be met the row costs nothing either, so it only acts against other constraints.
The row is always present (fixed structure); below ``MIN_SPEED_MPS`` its bound is +inf.
"""

from __future__ import annotations

import numpy as np

from .layout import Layout, QPInput

#: Repulsive speeds below this are treated as none (m/s): 0.1 mm/s.
MIN_SPEED_MPS = 1e-4


class RepulsionTask:
    """Soft "move away at least this fast" for the closest L2 point or the end effector.

    Its cost (on the slack) and bounds (slack ≥ 0) are constant; its one row is not.

    Parameters
    ----------
    layout
        The QP's variables.
    which
        ``"L2"`` (eqs. 4-6, the closest L2 point) or ``"EE"`` (eq. 7, the end effector).
    weight
        w, per m/s of shortfall.
    set_index
        Row of the set in the distance table.
    """

    constant = True    # objective and bounds; the inequality row varies
    rows = 1

    def __init__(self, layout: Layout, which: str, weight: float, set_index: int):
        self.layout, self.which, self.set_index = layout, which, set_index
        self.slack = layout.slack_L2 if which == "L2" else layout.slack_EE
        self.weight = weight
        n = layout.n
        self._H = np.zeros((n, n))
        self._H[self.slack, self.slack] = 2.0 * weight
        self._c = np.zeros(n)
        self._lb = np.full(n, -np.inf)
        self._lb[self.slack] = 0.0
        self._ub = np.full(n, np.inf)
        for a in (self._H, self._c, self._lb, self._ub):
            a.setflags(write=False)

    def compute_qp_objective(self, inp: QPInput) -> tuple[np.ndarray, np.ndarray]:
        """(H, c) over the whole x: ``w s²`` on the slack (constant)."""
        return self._H, self._c

    def compute_qp_bounds(self, inp: QPInput) -> tuple[np.ndarray, np.ndarray]:
        """Bounds over the whole x: the slack is non-negative (constant)."""
        return self._lb, self._ub

    def compute_qp_inequalities(self, inp: QPInput) -> tuple[np.ndarray, np.ndarray]:
        """One row ``(G, h)`` over the whole x: ``−uᵀ J_p q̇ − s ≤ −|v|``."""
        n, nv = self.layout.n, self.layout.nv
        G = np.zeros((1, n))
        G[0, self.slack] = -1.0
        v = inp.v_rep_L2 if self.which == "L2" else inp.v_rep_EE
        speed = float(np.sqrt(v @ v))
        if speed < MIN_SPEED_MPS:
            return G, np.array([np.inf])
        u = v / speed
        if self.which == "L2":
            Jp = inp.tick.table.robot_jacobian(inp.tick.kin, self.set_index, inp.L2_part)
            nominal = u @ (Jp @ inp.dq_nominal)
        else:
            Jp = inp.tick.kin.ee_jacobian[:3]
            nominal = u @ inp.v_nominal[:3]
        G[0, :nv] = -u @ Jp
        return G, np.array([-(nominal + speed)])
