"""What every piece of the QP gives: its cost, its rows and its bounds over all variables.

As in pink and mink, each task, limit and barrier is one object in one file, and returns
full-width blocks over ``x = [q̇; slacks]`` (:class:`~qpavoid.qp.variables.Variables`):

* :class:`Objective` ``(H, c)``: the cost ``½ xᵀ H x + cᵀ x``;
* :class:`Constraint` ``(G, h)``: the rows ``G x ≤ h`` (``h = +inf`` for an inactive row:
  the structure stays fixed, so a persistent solver never changes its pattern);
* :class:`Bounds` ``(lb, ub)``: ``lb ≤ x ≤ ub``.

A piece may give any of the three (:class:`QPPiece` returns None for those it has not);
the assembler visits each piece once per tick. Every method takes the tick's measurements
and the control period, as mink's take ``(configuration, dt)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..controller import Tick


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


class QPPiece:
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
    """

    name = "piece"
    rows = 0
    constant_objective = False
    constant_bounds = False

    def compute_qp_objective(self, tick: Tick | None, dt: float) -> Objective | None:
        """The piece's cost, or None."""
        return None

    def compute_qp_inequalities(self, tick: Tick, dt: float) -> Constraint | None:
        """The piece's ``rows`` rows, or None."""
        return None

    def compute_qp_bounds(self, tick: Tick | None, dt: float) -> Bounds | None:
        """The piece's bounds, or None."""
        return None


def free_bounds(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(−inf, +inf)`` for n variables: a start that pieces narrow."""
    return np.full(n, -np.inf), np.full(n, np.inf)


def readonly(*arrays: np.ndarray) -> None:
    """Freeze arrays a piece hands out every tick (a caller can never change them)."""
    for a in arrays:
        a.setflags(write=False)
