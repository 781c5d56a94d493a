"""The QP's variables, by name: joint velocities and the slacks of the soft rows."""

from __future__ import annotations

from dataclasses import dataclass

#: The slacks of the two repulsion rows, in order after the joint velocities: the repelled
#: set's (eqs. 4-6) and the end effector's (eq. 7).
REPULSION_SLACKS = ("repulsion_repelled", "repulsion_end_effector")


@dataclass(frozen=True)
class Variables:
    """``x = [q̇ (nv); slacks]``: joint velocities (rad/s), then one slack per soft row (m/s).

    Pieces find their columns by name (:attr:`dq`, :meth:`slack`), never by position.

    Attributes
    ----------
    nv
        Number of joint velocities.
    slacks
        Names of the slack variables, in order.
    """

    nv: int
    slacks: tuple[str, ...] = REPULSION_SLACKS

    @property
    def n(self) -> int:
        """Number of variables."""
        return self.nv + len(self.slacks)

    @property
    def dq(self) -> slice:
        """The joint velocities' columns."""
        return slice(0, self.nv)

    def slack(self, name: str) -> int:
        """The column of the slack called ``name``."""
        return self.nv + self.slacks.index(name)
