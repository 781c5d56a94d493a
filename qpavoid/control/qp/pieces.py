"""What every piece of the QP gives: its cost, its rows and its bounds over all variables.

As in pink and mink, each task, limit and barrier is one object in one file, and returns
full-width blocks over ``x = [q̇; slacks]`` (:class:`~qpavoid.control.qp.variables.Variables`):

* :class:`Objective` ``(H, c)``: the cost ``½ xᵀ H x + cᵀ x``;
* :class:`Constraint` ``(G, h)``: the rows ``G x ≤ h`` (``h = +inf`` for an inactive row:
  the structure stays fixed, so a persistent solver never changes its pattern);
* :class:`Bounds` ``(lb, ub)``: ``lb ≤ x ≤ ub``.

A piece may give any of the three (:class:`QPPiece` returns None for those it has not).
Every method takes the tick's state and the control period, as mink's take
``(configuration, dt)``. The framework does not know that state's type (``StateT``): the
controller's pieces take its :class:`~qpavoid.control.tick.Tick`, another controller's
pieces whatever it measures.

Each tick the assembler asks for the same blocks in place, into its own arrays (no
allocation): :meth:`QPPiece.add_qp_objective`, :meth:`QPPiece.write_qp_inequalities`,
:meth:`QPPiece.tighten_qp_bounds`. A piece writes either form and the base class derives
the other: the in-place one from ``compute_qp_*`` (add, copy, intersect), or
``compute_qp_*`` from the in-place one applied to fresh zeros (the pieces that change
every tick, whose arithmetic is often a compiled kernel of :mod:`.kernels`). So each
piece's math is written once.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np

from qpavoid.control.qp.variables import Variables

#: The state every piece of one problem reads (the controller's tick).
StateT = TypeVar("StateT")


@dataclass(frozen=True)
class Objective:
    """A cost ``½ xᵀ H x + cᵀ x``: H (n, n), c (n,)."""

    H: np.ndarray
    c: np.ndarray


@dataclass(frozen=True)
class Constraint:
    """Rows ``G x ≤ h``: G (m, n), h (m,)."""

    G: np.ndarray
    h: np.ndarray


@dataclass(frozen=True)
class Bounds:
    """Box ``lb ≤ x ≤ ub``: (n,) each, ±inf where a variable is free."""

    lb: np.ndarray
    ub: np.ndarray


class QPPiece(Generic[StateT]):
    """Base of the tasks, limits and barriers.

    Attributes
    ----------
    name
        The piece's name: its rows are found by it in the assembled problem.
    rows
        Number of rows of :meth:`compute_qp_inequalities` (fixed for the piece's life).
    constant_objective, constant_bounds
        True if the objective (bounds) never change: the assembler computes them once,
        with ``tick=None``.
    tightens
        The name of another piece whose rows bound the same left side ``G x`` as this
        one's, row for row, or None. Then this piece writes into that piece's rows instead
        of adding its own, and :meth:`write_qp_inequalities` only lowers ``h`` (writing a
        row's G where it bounds it): ``G x ≤ min(h₁, h₂)`` is both rows, in one row of
        the solver's (speed and separation's rows tighten the dampers': half the rows
        OSQP factors).
    """

    name = "piece"
    rows = 0
    tightens: str | None = None
    constant_objective = False
    constant_bounds = False
    variables: Variables

    def gives(self, kind: str) -> bool:
        """True if the piece has a ``kind`` (``"objective"``, ``"inequalities"`` or
        ``"bounds"``): it defines one of the two methods that give it."""
        return any(
            getattr(type(self), m) is not getattr(QPPiece, m)
            for m in (f"compute_qp_{kind}", _IN_PLACE[kind])
        )

    def compute_qp_objective(self, tick: StateT | None, dt: float) -> Objective | None:
        """The piece's cost, or None."""
        if not self.gives("objective"):
            return None
        assert tick is not None
        H, c = zero_objective(self.variables.n)
        self.add_qp_objective(tick, dt, H, c)
        return Objective(H, c)

    def compute_qp_inequalities(self, tick: StateT, dt: float) -> Constraint | None:
        """The piece's ``rows`` rows, or None."""
        if not self.gives("inequalities"):
            return None
        G, h = no_rows(self.rows, self.variables.n)
        self.write_qp_inequalities(tick, dt, G, h)
        return Constraint(G, h)

    def compute_qp_bounds(self, tick: StateT | None, dt: float) -> Bounds | None:
        """The piece's bounds, or None."""
        if not self.gives("bounds"):
            return None
        assert tick is not None
        lb, ub = free_bounds(self.variables.n)
        self.tighten_qp_bounds(tick, dt, lb, ub)
        return Bounds(lb, ub)

    def add_qp_objective(self, tick: StateT, dt: float, H: np.ndarray, c: np.ndarray) -> None:
        """Add the piece's cost to ``H`` (n, n) and ``c`` (n,), in place."""
        obj = self.compute_qp_objective(tick, dt)
        if obj is not None:
            H += obj.H
            c += obj.c

    def write_qp_inequalities(self, tick: StateT, dt: float, G: np.ndarray, h: np.ndarray) -> None:
        """Write the piece's rows into ``G`` (rows, n) and ``h`` (rows,), in place."""
        con = self.compute_qp_inequalities(tick, dt)
        assert con is not None, self.name
        G[:], h[:] = con.G, con.h

    def tighten_qp_bounds(self, tick: StateT, dt: float, lb: np.ndarray, ub: np.ndarray) -> None:
        """Intersect ``lb ≤ x ≤ ub`` (n,) with the piece's bounds, in place."""
        b = self.compute_qp_bounds(tick, dt)
        if b is not None:
            np.maximum(lb, b.lb, out=lb)
            np.minimum(ub, b.ub, out=ub)


#: The in-place method of each kind of block.
_IN_PLACE = {
    "objective": "add_qp_objective",
    "inequalities": "write_qp_inequalities",
    "bounds": "tighten_qp_bounds",
}


def zero_objective(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(H, c)`` of no cost over n variables: a start that pieces add to."""
    return np.zeros((n, n)), np.zeros(n)


def no_rows(rows: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(G, h)`` of ``rows`` inactive rows over n variables: a start pieces write into."""
    return np.zeros((rows, n)), np.full(rows, np.inf)


def free_bounds(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(−inf, +inf)`` for n variables: a start that pieces narrow."""
    return np.full(n, -np.inf), np.full(n, np.inf)


def readonly(*arrays: np.ndarray) -> None:
    """Freeze arrays a piece hands out every tick (a caller can never change them)."""
    for a in arrays:
        a.setflags(write=False)
