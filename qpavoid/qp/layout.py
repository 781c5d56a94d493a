"""The QP's variables and what every piece of it sees each tick."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..controller import Tick


@dataclass(frozen=True)
class Layout:
    """Variables ``x = [q̇ (nv), s_L2, s_EE]``: joint velocities (rad/s) and the slacks of
    the two repulsion costs (m/s)."""

    nv: int

    @property
    def n(self) -> int:
        """Number of variables."""
        return self.nv + 2

    @property
    def slack_L2(self) -> int:
        """Index of the L2 repulsion slack."""
        return self.nv

    @property
    def slack_EE(self) -> int:
        """Index of the EE repulsion slack."""
        return self.nv + 1


@dataclass(frozen=True)
class QPInput:
    """One tick's measurements plus what the laws derived from them.

    Attributes
    ----------
    tick
        The shared measurements (kinematics, distance table, f, reference, error).
    v_rep_L2, v_rep_EE
        (3,) repulsive velocities of eqs. (5) and (7), m/s.
    L2_part
        Column of the human part closest to L2.
    dt
        Control period, s.
    v_nominal
        (6,) the end effector's nominal twist v_PL + K e (eq. 8 without v_EE).
    dq_nominal
        (nv,) eq. (8)'s joint velocities, J⁻¹ (v_PL + K e + v_EE) (damped inverse).
    """

    tick: Tick
    v_rep_L2: np.ndarray
    v_rep_EE: np.ndarray
    L2_part: int
    dt: float
    v_nominal: np.ndarray
    dq_nominal: np.ndarray
