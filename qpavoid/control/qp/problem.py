"""Assembling the QP: the one place where pieces become a problem.

Each tick every piece (task, limit, barrier: :mod:`.pieces`) gives its full-width cost,
rows and bounds, and the assembler makes the problem

    minimise    ½ xᵀ H x + cᵀ x          H = Σ H_piece,  c = Σ c_piece
    subject to  G x ≤ h                  G, h: the pieces' rows stacked in piece order
                lb ≤ x ≤ ub              lb = max lb_piece,  ub = min ub_piece

over ``x = [q̇; slacks]`` (:class:`~qpavoid.control.qp.variables.Variables`). The rows of each
piece are found by its name (:attr:`QPProblem.rows`), never by position. Pieces whose cost
or bounds are constant are summed once, at construction; each tick the others write into
arrays allocated once (:meth:`Assembler.fill`). The backends that solve it are
in :mod:`.backends`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Generic

import numpy as np

from qpavoid.control.qp.pieces import QPPiece, StateT, free_bounds


@dataclass(frozen=True)
class QPProblem:
    """The dense matrices of one tick's QP (see the module docstring).

    Attributes
    ----------
    H, c
        (n, n) and (n,): the cost ``½ xᵀ H x + cᵀ x``.
    G, h
        (m, n) and (m,): the rows ``G x ≤ h`` (``h = +inf`` for an inactive row).
    lb, ub
        (n,) bounds.
    rows
        The rows of each piece that has any, by the piece's name.
    """

    H: np.ndarray
    c: np.ndarray
    G: np.ndarray
    h: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    rows: Mapping[str, slice] = field(default_factory=dict)


@dataclass(frozen=True)
class QPSolution:
    """What a backend returns.

    Attributes
    ----------
    x
        The solution (n,), or None if not found.
    found
        True only if the solver reported success.
    status
        The solver's status text.
    iterations
        Iterations used (-1 if the solver does not say).
    """

    x: np.ndarray | None
    found: bool
    status: str
    iterations: int = -1


class Assembler(Generic[StateT]):
    """Visits each piece once per tick and sums, stacks and intersects what it gives.

    Parameters
    ----------
    n
        Number of variables.
    pieces
        The tasks, limits and barriers, in order (their rows are stacked in this order).
    """

    def __init__(self, n: int, pieces: Sequence[QPPiece[StateT]]):
        self.n, self.pieces = n, tuple(pieces)
        names = [p.name for p in self.pieces]
        if len(set(names)) < len(names):
            raise ValueError(f"QP pieces need distinct names, got {names}")
        self.H0, self.c0 = np.zeros((n, n)), np.zeros(n)
        self.lb0, self.ub0 = free_bounds(n)
        for p in self.pieces:
            if p.constant_objective:
                obj = p.compute_qp_objective(None, 0.0)
                if obj is not None:
                    self.H0 += obj.H
                    self.c0 += obj.c
            if p.constant_bounds:
                b = p.compute_qp_bounds(None, 0.0)
                if b is not None:
                    np.maximum(self.lb0, b.lb, out=self.lb0)
                    np.minimum(self.ub0, b.ub, out=self.ub0)
        # each tick: only the pieces that have a block of that kind and whose block changes
        self._objectives = [
            p for p in self.pieces if p.gives("objective") and not p.constant_objective
        ]
        self._bounds = [p for p in self.pieces if p.gives("bounds") and not p.constant_bounds]
        self._rows = [p for p in self.pieces if p.rows]
        own = [p for p in self._rows if p.tightens is None]
        offsets = np.cumsum([0] + [p.rows for p in own]).tolist()
        self.rows = {
            p.name: slice(a, b) for p, a, b in zip(own, offsets, offsets[1:], strict=False)
        }
        for k, p in enumerate(self._rows):  # one that tightens another's rows writes after it
            if p.tightens is not None:
                target = self.rows.get(p.tightens)
                before = {q.name for q in self._rows[:k]}
                if (
                    target is None
                    or p.tightens not in before
                    or target.stop - target.start != p.rows
                ):
                    raise ValueError(
                        f"QP piece {p.name!r} tightens the rows of {p.tightens!r}, which "
                        f"comes before it with {p.rows} rows: "
                        f"{ {q.name: q.rows for q in own} }"
                    )
                self.rows[p.name] = target
        self.m = offsets[-1]
        self._slices = [self.rows[p.name] for p in self._rows]
        self._filled = self._arrays()

    def _arrays(self) -> QPProblem:
        n, m = self.n, self.m
        return QPProblem(
            np.zeros((n, n)), np.zeros(n), np.zeros((m, n)), np.zeros(m), np.zeros(n),
            np.zeros(n), self.rows,
        )  # fmt: skip

    def __call__(self, tick: StateT, dt: float) -> QPProblem:
        """The problem of ``tick`` with control period ``dt`` (s), in arrays of its own
        (never touching those of :meth:`fill`)."""
        return self._write(tick, dt, self._arrays())

    def fill(self, tick: StateT, dt: float) -> QPProblem:
        """The problem of ``tick``, written into the assembler's own arrays: no allocation,
        but valid only until the next :meth:`fill` (the controller's loop; else use
        :meth:`__call__`)."""
        return self._write(tick, dt, self._filled)

    def _write(self, tick: StateT, dt: float, out: QPProblem) -> QPProblem:
        H, c, G, h, lb, ub = out.H, out.c, out.G, out.h, out.lb, out.ub
        H[:], c[:], lb[:], ub[:] = self.H0, self.c0, self.lb0, self.ub0
        for p in self._objectives:
            p.add_qp_objective(tick, dt, H, c)
        for p, rows in zip(self._rows, self._slices, strict=True):
            p.write_qp_inequalities(tick, dt, G[rows], h[rows])
        for p in self._bounds:
            p.tighten_qp_bounds(tick, dt, lb, ub)
        return out
