"""How fast could a tick be if everything between Pinocchio and OSQP were one compiled call?

    pip install ".[peers]"
    python benchmarks/single_pass.py [--seconds 15] [--json FILE]

A measurement of a bound, not a controller. Issue 11 asks for a sphere tick 8× faster than
pink + one barrier on OSQP and faster than mink on daqp. qpavoid's tick composes its
numba kernels from Python, one call per stage (perception, distances, laws, QP pieces,
solver data). The other design would run them all in one compiled pass. Before
building it, this script measures what it would reach.

Each tick, qpavoid's sphere tick (persistent OSQP) runs as in ``peers.py``, and its
kernel calls are recorded with copies of their arguments. In the next tick, at its q,
``SinglePass`` replays it (each record once, in order), timing the rest of such a tick:

* what cannot be compiled: the q check, Pinocchio (the calls of ``Robot.kinematics``:
  joint Jacobians, frame placements, the control frames' positions and Jacobians), the
  path reference (Python's quintic: numba's ``t**3`` differs in the last bit), the pose
  error (``pin.log3``), OSQP's update and solve, its warm-start clean-up, the hard-row
  and last-resort checks, the clamp to the bounds and a command object;
* the tick's kernels (``track``, ``tracked_body``, ``sphere_table``, ``avoidance_terms``,
  ``ee_task_cost``, ``damper_rows``, ``osqp_arrays``), called from **one** generated
  ``numba.njit`` function on the recorded arguments (LLVM drops none of them: a review
  found the same time with every result summed).

The variants run in a new order every tick (``peers._interleaved``), among pink on OSQP
and mink on daqp, so the single pass finds the caches as a tick would, not warm from the
tick it replays (a review measured that at about 50 µs).

Left out, so the bound is optimistic: the tick's numpy arithmetic outside kernels (f of
eq. 2, eq. 3's limits, the repulsion rows, eq. 8's damped inverse where it runs, the
assembly's constant parts), its stop rules, the perceiver's bookkeeping (the frozen-frame
check, the trackers by id), the input checks of ``measure`` and its Tick. Kept in, so it
is pessimistic: the one call takes every kernel's arguments (their number is printed,
and the cost of passing them to a function that does nothing, alone), where a real
design would hold most of them.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

import numba
import numpy as np
import pinocchio as pin
from numba.core.registry import CPUDispatcher

sys.path.insert(0, str(Path(__file__).parent))
import peers  # the peers, their loop and the floor: this benchmark builds on them

from qpavoid.control.path import pose_error
from qpavoid.control.qp import QPConfig, QPController
from qpavoid.control.qp.backends import WARM_START_FLOOR
from qpavoid.control.qp.solver_kernels import flush_tiny, hard_excess
from qpavoid.laws._kernels import limit_crossed

#: Kernels a single pass calls after the solve (there, not in the one call).
AFTER_SOLVE = {"flush_tiny", "hard_excess", "limit_crossed"}
STAGES = ("Pinocchio", "reference and pose error", "one compiled call", "OSQP", "after")


class Recorder:
    """Every qpavoid kernel, wrapped where modules look it up, to record its calls (with
    copies of the arguments: several kernels write into them) while ``on``."""

    def __init__(self) -> None:
        self.on, self.calls = False, []
        wrapped: dict[Any, Any] = {}
        for name, module in list(sys.modules.items()):
            if not name.startswith("qpavoid"):
                continue
            for attr, value in list(vars(module).items()):
                if isinstance(value, CPUDispatcher):
                    setattr(module, attr, wrapped.setdefault(value, self._wrap(value)))

    def _wrap(self, kernel: Any) -> Any:
        def call(*args: Any) -> Any:
            if self.on:
                self.calls.append((kernel, tuple(_copy(a) for a in args)))
            return kernel(*args)

        return call


def _copy(a: Any) -> Any:
    return a.copy() if isinstance(a, np.ndarray) else a


class Recorded(QPController):
    """The sphere tick, its kernel calls kept for :class:`SinglePass`: their arguments
    (copied as each call began: the kernels write into the tracker's memory), and the one
    compiled call made for their kernels and argument types (compiled and run once here,
    outside any timing that counts)."""

    def __init__(self, recorder: Recorder, *args: Any, **kw: Any):
        super().__init__(*args, **kw)
        self.recorder, self.compiled = recorder, {}
        self.t, self.solved, self.call, self.record = 0.0, False, None, []

    def step(self, q, joints, state=None, t=0.0, *args: Any, **kw: Any):  # type: ignore[override]
        rec = self.recorder
        rec.calls.clear()
        rec.on = True
        try:
            return super().step(q, joints, state, t, *args, **kw)
        finally:
            rec.on = False
            seq = [(k, a) for k, a in rec.calls if k.__name__ not in AFTER_SOLVE]
            key = tuple((k, tuple(numba.typeof(x) for x in a)) for k, a in seq)
            if key not in self.compiled:
                self.compiled[key] = one_call(seq)
                self.compiled[key](*[_copy(x) for _, a in seq for x in a])
            self.call, self.record = self.compiled[key], [x for _, a in seq for x in a]
            self.t = t
            self.solved = any(k.__name__ == "osqp_arrays" for k, _ in seq)  # not a stop


def one_call(seq: list) -> Any:
    """A ``numba.njit`` function calling the kernels of ``seq`` in order, on its arguments."""
    env: dict[str, Any] = {}
    names, lines = [], []
    for i, (kernel, args) in enumerate(seq):
        env[f"k{i}"] = kernel
        own = [f"a{i}_{j}" for j in range(len(args))]
        names += own
        lines.append(f"    k{i}({', '.join(own)})")
    exec(f"def tick({', '.join(names)}):\n" + "\n".join(lines) + "\n    return 0\n", env)
    return numba.njit(env["tick"])


def no_op(n: int) -> Any:
    """A ``numba.njit`` function of ``n`` arguments that does nothing (the cost of the call)."""
    env: dict[str, Any] = {}
    exec(f"def call({', '.join(f'a{i}' for i in range(n))}):\n    return 0\n", env)
    return numba.njit(env["call"])


class Command(NamedTuple):  # as many fields as qpavoid's Command
    dq: Any
    stopped: bool
    reason: str
    time_scale: float
    f: float
    distance: Any
    table: Any
    v_repelled: Any
    v_end_effector: Any
    limits: Any
    ee_pos: Any
    ee_ref: Any
    info: dict


class SinglePass(peers.Floor):
    """The floor's library calls, the Python a tick cannot do without, and the recorded
    kernels in one compiled call (see the module docstring): each tick, the recorded
    tick's before (as the floor, :meth:`take`: every record replayed once, in order)."""

    def __init__(self, robot, source: Recorded, ticks: int):
        super().__init__(robot, source)
        self.robot, self.recorded = robot, source
        self.clock = np.zeros((ticks, len(STAGES) + 1), dtype=np.int64)  # ns, each tick
        self.k = 0

    def take(self, q: np.ndarray) -> None:
        """The floor's copy, and the record's: its one call, a copy of its arguments, its
        path time, whether it solved, and the problem's hard rows and bounds."""
        super().take(q)
        rec = self.recorded
        prob = rec.assembler._filled
        self.replay = (rec.call, [_copy(x) for x in rec.record], rec.t, rec.solved)
        self.problem = tuple(a.copy() for a in (prob.lb, prob.ub, prob.G, prob.h))

    def step(self, _q=None) -> None:
        assert self.taken is not None
        robot, (call, args, t, solved) = self.robot, self.replay
        q, c, lower, upper, Px, Ax = self.taken
        clock, row = time.perf_counter_ns, self.clock[self.k]
        row[0] = clock()
        q = np.asarray(q, dtype=np.float64)
        if not np.isfinite(q).all():
            raise ValueError("q")
        model, data, LWA = self.model, self.data, pin.LOCAL_WORLD_ALIGNED
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        np.array([m.translation for m in self.placements])
        ee = self.ee_placement.homogeneous
        np.ascontiguousarray(
            np.array([pin.getFrameJacobian(model, data, f, LWA) for f in self.frames])[:, :3]
        )
        pin.getFrameJacobian(model, data, self.ee, LWA)
        row[1] = clock()
        ref_pose, _ = self.recorded.path.reference(t)
        pose_error(ref_pose, ee)
        row[2] = clock()
        call(*args)
        row[3] = clock()
        if not solved:  # a stop: no QP
            row[4] = row[5] = clock()
            self.command = Command(
                np.zeros(robot.nv), True, "stop", 0.0, 0.0, None, None, None, None, None,
                ee[:3, 3].copy(), ref_pose[:3, 3].copy(), {},
            )  # fmt: skip
            self.k += 1
            return
        solver = self.osqp
        solver.update_data_vec(q=c, l=lower, u=upper)
        solver.update_data_mat(P_x=Px, P_i=None, A_x=Ax, A_i=None)
        solver.solve()
        row[4] = clock()
        info, solution = solver.info, solver.solution
        x, y = np.array(solution.x), np.array(solution.y)
        if flush_tiny(x, WARM_START_FLOOR) | flush_tiny(y, WARM_START_FLOOR):
            solver.warm_start(x=x, y=y)
        (lb, ub, G, h), hard, nv = self.problem, self.recorded._hard, robot.nv
        hard_excess(x, nv, lb, ub, G, h, hard.start, hard.stop)
        dq = np.minimum(np.maximum(x[:nv], lb[:nv]), ub[:nv])
        limit_crossed(q, dq, 1.0 / peers.RATE_HZ, robot.q_min, robot.q_max)
        self.command = Command(
            dq, False, "", 1.0, 0.0, None, None, np.zeros(3), np.zeros(3), None,
            ee[:3, 3].copy(), ref_pose[:3, 3].copy(), {"status": info.status, "it": info.iter},
        )  # fmt: skip
        row[5] = clock()
        self.k += 1


def main() -> None:
    args, robot, path, motion, q0 = peers.setup(__doc__.splitlines()[0])
    config = peers.ideal(distance="spheres")
    plain = QPController(robot, config=config, qp=QPConfig())
    recorded = Recorded(Recorder(), robot, config=config, qp=QPConfig())
    single = SinglePass(robot, recorded, int(args.seconds * peers.RATE_HZ))
    variants = {
        "qpavoid QP, spheres, recording its kernels": ("qp", recorded),
        "qpavoid QP, spheres (persistent OSQP)": ("qp", plain),
        "floor: Pinocchio + OSQP calls of that tick": ("floor", peers.Floor(robot, plain)),
        "single pass: the sphere tick, one compiled call": ("floor", single),
        "pink + 1 barrier, osqp": ("pink", peers.Pink(robot, "osqp")),
        "mink + CollisionAvoidanceLimit, daqp": ("mink", peers.Mink("daqp")),
    }
    rows = peers._interleaved(variants, robot, path, motion, q0, args.seconds)
    ns = np.diff(single.clock[10 : single.k], axis=1) / 1e3
    stages = {name: float(np.median(ns[:, i])) for i, name in enumerate(STAGES)}
    stages["sum (median of each tick's)"] = float(np.median(ns.sum(axis=1)))
    calls = recorded.recorder.calls  # the last tick's
    arguments = [x for k, a in calls if k.__name__ not in AFTER_SOLVE for x in a]
    call = no_op(len(arguments))
    call(*arguments)
    alone = []
    for _ in range(3000):
        t0 = time.perf_counter_ns()
        call(*arguments)
        alone.append((time.perf_counter_ns() - t0) / 1e3)
    stages[f"passing {len(arguments)} arguments, alone"] = float(np.median(alone))
    rows["single pass stages"] = stages
    print("\nsingle pass, its stages (median µs):")
    for name, value in stages.items():
        print(f"  {name:36s} {value:6.1f}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
