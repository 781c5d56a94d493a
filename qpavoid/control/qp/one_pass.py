"""The QP of a tick in one compiled call, for the controller's standard pieces.

:class:`~qpavoid.control.qp.problem.Assembler` visits each piece and each piece calls its
kernel: about twenty Python calls a tick around arithmetic of a few microseconds
(docs/performance.md §2g). When the pieces are the standard ones of
:class:`~qpavoid.control.qp.controller.QPController`,

    ee_task, repulsion_repelled, repulsion_end_effector, regularization,
    velocity_damper, [separation], velocity_limits, position_limits, acceleration_limits

(no elbow, no posture task), :class:`OnePass` writes the same problem with one call of
:func:`standard_problem`, which runs the very kernels the pieces call
(:mod:`qpavoid.control.qp.kernels`), in the assembler's order: the constant cost and
bounds, the task's cost, the rows in piece order (the separation's tightening the
dampers'), then the bounds in piece order. The pieces keep their settings, names and
kernels; the assembler stays the reference and the path for any other set of pieces
(tests/test_one_pass.py holds the two equal, bit for bit).
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.control.qp.barriers.repulsion import (
    EERepulsionTask,
    RepelledRepulsionTask,
    RepulsionTask,
)
from qpavoid.control.qp.barriers.separation import SeparationLimit
from qpavoid.control.qp.kernels import (
    box_bounds,
    damper_rows,
    ee_task_cost,
    pair_inputs,
    position_bounds,
    raise_rows,
    repulsion_row,
    separation_rows,
    velocity_bounds,
)
from qpavoid.control.qp.limits.acceleration import AccelerationLimit
from qpavoid.control.qp.limits.position import PositionLimit
from qpavoid.control.qp.limits.velocity import VelocityLimit
from qpavoid.control.qp.limits.velocity_damper import VelocityDamper
from qpavoid.control.qp.pieces import QPPiece
from qpavoid.control.qp.problem import Assembler, QPProblem
from qpavoid.control.qp.tasks.ee import EndEffectorTask
from qpavoid.control.qp.tasks.regularization import Regularization
from qpavoid.control.tick import Tick
from qpavoid.core.compiling import ctrl_c_deferred, kernel_input

__all__ = ["STANDARD_PIECES", "OnePass", "standard_problem", "warm_up"]

#: The pieces :class:`OnePass` writes, in order, by name and exact class (``separation``
#: optional): a subclass may write otherwise, so it leaves the set to the assembler.
STANDARD_PIECES: dict[str, type[QPPiece[Tick]]] = {
    "ee_task": EndEffectorTask,
    "repulsion_repelled": RepelledRepulsionTask,
    "repulsion_end_effector": EERepulsionTask,
    "regularization": Regularization,
    "velocity_damper": VelocityDamper,
    "separation": SeparationLimit,
    "velocity_limits": VelocityLimit,
    "position_limits": PositionLimit,
    "acceleration_limits": AccelerationLimit,
}


@njit(cache=True)
def standard_problem(
    H0: np.ndarray,
    c0: np.ndarray,
    lb0: np.ndarray,
    ub0: np.ndarray,
    ee_jacobian: np.ndarray,
    w2: np.ndarray,
    task_twist: np.ndarray,
    v_end_effector: np.ndarray,
    repelled_v: np.ndarray,
    repelled_jacobian: np.ndarray,
    repelled_nominal: np.ndarray,
    end_effector_v: np.ndarray,
    end_effector_jacobian: np.ndarray,
    end_effector_nominal: np.ndarray,
    slacks: np.ndarray,
    repulsion_rows: np.ndarray,
    distance: np.ndarray,
    vector: np.ndarray,
    robot_index: np.ndarray,
    robot_s: np.ndarray,
    point_jacobians: np.ndarray,
    segment_jacobians: np.ndarray,
    d_stop: np.ndarray,
    influence_m: float,
    gain_mps: float,
    human_approach: np.ndarray,
    contact_limit: np.ndarray,
    approach_limit: np.ndarray,
    inactive_above_mps: float,
    damper_start: int,
    limits: np.ndarray,
    q: np.ndarray,
    q_min: np.ndarray,
    q_max: np.ndarray,
    position_gain_per_period: float,
    box_lo: np.ndarray,
    box_hi: np.ndarray,
    H: np.ndarray,
    c: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    lb: np.ndarray,
    ub: np.ndarray,
) -> None:
    """The standard pieces' problem ``½ xᵀHx + cᵀx``, ``G x ≤ h``, ``lb ≤ x ≤ ub``, in place.

    As the assembler writes it (:mod:`.problem`): ``H = H0 + 2 JᵀW²J`` and ``c = c0 −
    2 JᵀW²v*`` (eq. 8's task, :func:`ee_task_cost`); the two repulsions' rows
    (:func:`repulsion_row`; their slacks' columns and their rows in ``slacks`` and
    ``repulsion_rows``, the repelled set's first); the dampers' rows from
    ``damper_start`` (:func:`damper_rows`), raised to ``contact_limit`` where it is given
    (power and force limiting: an empty array otherwise), lowered to speed and separation's
    ``approach_limit`` (:func:`separation_rows`; an empty array without it); the bounds
    ``lb0``, ``ub0`` intersected with eq. (3)'s ``limits``, the position limits' and,
    where ``box_lo`` is given (an empty array without the ramp), projected into the
    command's reachable box. Shapes and units as the pieces' kernels take them.
    """
    nv = q.shape[0]
    H[:] = H0
    c[:] = c0
    lb[:] = lb0
    ub[:] = ub0
    ee_task_cost(ee_jacobian, w2, task_twist, v_end_effector, H, c)
    repulsion_row(
        repelled_v, repelled_jacobian, repelled_nominal, slacks[0], G, h, repulsion_rows[0]
    )
    repulsion_row(
        end_effector_v,
        end_effector_jacobian,
        end_effector_nominal,
        slacks[1],
        G,
        h,
        repulsion_rows[1],
    )
    rows = distance.shape[0]
    G_pairs, h_pairs = G[damper_start : damper_start + rows], h[damper_start : damper_start + rows]
    damper_rows(
        distance,
        vector,
        robot_index,
        robot_s,
        point_jacobians,
        segment_jacobians,
        d_stop,
        influence_m,
        gain_mps,
        human_approach,
        G_pairs,
        h_pairs,
    )
    if contact_limit.shape[0] == rows:
        raise_rows(h_pairs, contact_limit)
    if approach_limit.shape[0] == rows:
        separation_rows(
            approach_limit,
            vector,
            robot_index,
            robot_s,
            point_jacobians,
            segment_jacobians,
            inactive_above_mps,
            G_pairs,
            h_pairs,
        )
    velocity_bounds(limits, lb[:nv], ub[:nv])
    position_bounds(q, q_min, q_max, position_gain_per_period, lb[:nv], ub[:nv])
    if box_lo.shape[0] == nv:
        box_bounds(box_lo, box_hi, lb[:nv], ub[:nv])


class OnePass:
    """:meth:`Assembler.fill <qpavoid.control.qp.problem.Assembler.fill>` for the standard
    pieces in one compiled call (module docstring), into the assembler's own arrays.

    Build it with :meth:`of`, which gives None for any other set of pieces.
    """

    def __init__(self, assembler: Assembler[Tick], pieces: dict[str, QPPiece[Tick]]):
        self.assembler = assembler
        ee, damper = pieces["ee_task"], pieces["velocity_damper"]
        repelled, end = pieces["repulsion_repelled"], pieces["repulsion_end_effector"]
        position, separation = pieces["position_limits"], pieces.get("separation")
        assert separation is None or isinstance(separation, SeparationLimit)
        assert isinstance(ee, EndEffectorTask) and isinstance(damper, VelocityDamper)
        assert isinstance(repelled, RepulsionTask) and isinstance(end, RepulsionTask)
        assert isinstance(position, PositionLimit)
        self._repulsions = (repelled, end)
        rows = assembler.rows
        self._slack = np.array([repelled.slack, end.slack], dtype=np.int64)
        self._row = np.array([rows[repelled.name].start, rows[end.name].start], dtype=np.int64)
        self._damper, self._ee, self._position = damper, ee, position
        self._separation = separation
        self._damper_start = rows[damper.name].start
        self._nv = len(position.q_min)
        self._none = np.zeros(0)
        self._constant = (assembler.H0, assembler.c0, assembler.lb0, assembler.ub0)

    @classmethod
    def of(cls, assembler: Assembler[Tick]) -> OnePass | None:
        """The pass for ``assembler``'s pieces, or None if they are not the standard ones
        (:data:`STANDARD_PIECES`: those names in that order, each of exactly that class,
        ``separation`` optional)."""
        pieces = {p.name: p for p in assembler.pieces}
        names = [p.name for p in assembler.pieces]
        if names != [n for n in STANDARD_PIECES if n in pieces]:
            return None
        if not set(STANDARD_PIECES) - {"separation"} <= set(names):
            return None
        if any(type(p) is not STANDARD_PIECES[p.name] for p in assembler.pieces):
            return None
        warm_up()
        return cls(assembler, pieces)

    def fill(self, tick: Tick, dt: float) -> QPProblem:
        """The problem of ``tick`` (control period ``dt``, s), in the assembler's arrays,
        as :meth:`Assembler.fill <qpavoid.control.qp.problem.Assembler.fill>` writes it."""
        out, (repelled, end) = self.assembler._filled, self._repulsions
        table, damper, separation = tick.table, self._damper, self._separation
        contact, box, rows = tick.contact_limit, tick.command_box, damper.rows
        # the kernels do not check their bounds: one row per pair, or no write at all
        if (
            table.distance.size != rows
            or tick.human_approach.size != rows
            or (contact is not None and contact.size != rows)
            or (separation is not None and tick.approach_limit.size != rows)
        ):
            raise ValueError(
                f"{damper.name}: {table.distance.size} set × part pairs for {rows} rows"
            )
        pairs = pair_inputs(table, tick.kin)
        assert tick.kin.ee_jacobian is not None  # a tick's kinematics carry the Jacobians
        nv = self._nv  # and one column per joint everywhere
        joints = [tick.q.shape[0], tick.limits.shape[0], tick.kin.ee_jacobian.shape[-1]]
        joints += [pairs[3].shape[-1], pairs[4].shape[-1]]
        joints += [] if box is None else [box[0].shape[0], box[1].shape[0]]
        if any(size != nv for size in joints):
            raise ValueError(f"a tick of {joints} joints for a problem of {nv}")
        standard_problem(
            *self._constant,
            kernel_input(tick.kin.ee_jacobian, np.float64),
            self._ee.w2,
            kernel_input(tick.task_twist, np.float64),
            kernel_input(tick.v_end_effector, np.float64),
            *repelled.row_inputs(tick),
            *end.row_inputs(tick),
            self._slack,
            self._row,
            kernel_input(table.distance.reshape(-1), np.float64),
            *pairs,
            damper.d_stop,
            damper.influence_m,
            damper.gain,
            kernel_input(tick.human_approach.reshape(-1), np.float64),
            self._none if contact is None else kernel_input(contact.reshape(-1), np.float64),
            (
                self._none
                if separation is None
                else kernel_input(tick.approach_limit.reshape(-1), np.float64)
            ),
            np.inf if separation is None else separation.inactive_above_mps,
            self._damper_start,
            kernel_input(tick.limits, np.float64),
            kernel_input(tick.q, np.float64),
            self._position.q_min,
            self._position.q_max,
            self._position.gain / dt,
            self._none if box is None else kernel_input(box[0], np.float64),
            self._none if box is None else kernel_input(box[1], np.float64),
            out.H,
            out.c,
            out.G,
            out.h,
            out.lb,
            out.ub,
        )
        return out


@functools.cache
def warm_up() -> None:
    """Compile (or load from the disk cache) :func:`standard_problem`, once per process."""
    with ctrl_c_deferred():
        n, nv, rows = 4, 2, 2
        z = np.zeros
        for extra in (z(0), z(rows)):  # without and with contact and separation bounds
            for box in (z(0), z(nv)):
                standard_problem(
                    z((n, n)), z(n), z(n), z(n), z((6, nv)), np.ones(6), z(6), z(3),
                    z(3), z((3, nv)), z(3), z(3), z((3, nv)), z(3), np.array([2, 3]),
                    np.array([0, 1]),
                    np.ones(rows), z((rows, 3)), z(rows, dtype=np.int64), z(rows),
                    z((1, 3, nv)), z((1, 2, 3, nv)), z(rows), 0.15, 0.25, z(rows), extra,
                    extra, 1.0, 2, z(nv), z(nv), -np.ones(nv), np.ones(nv), 1.0, box, box,
                    z((n, n)), z(n), z((4, n)), z(4), z(n), z(n),
                )  # fmt: skip
