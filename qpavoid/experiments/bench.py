"""Where a tick's time goes: per-stage timings, whole ticks, scaling (``qpavoid bench``).

The states of one closed-loop run (the paper's Test 1, QP controller, 100 Hz, real bench:
the hand near L2 and EE, so repulsion rows, dampers and separation rows are active on
many ticks) are replayed through every stage of a tick and every whole tick, after a
warm-up; each is reported as the median and the 99th percentile, µs. The JSON keys are
stable (docs/performance.md):

* ``stages``: ``kinematics``, ``human_geometry``, ``sphere_table``, ``capsule_table``,
  ``perception`` (tracker update: lost joints, velocities), ``fusion`` (two sensors, one
  person: add + fuse), ``analytic_law`` (eqs. 4-9 after the prelude), ``prelude``,
  ``qp_assembly`` (piece by piece, the assembler), ``qp_assembly/one_pass`` (the standard
  pieces in one compiled call, as the loop writes them), ``qp_solve/persistent_osqp``,
  ``qp_solve/daqp_direct`` (the ``daqp``
  backend, when daqp is installed) and ``qp_solve/<solver>`` for each qpsolvers solver;
* ``ticks``: ``<controller>/<distance>/<safety>`` for both controllers (``analytic``,
  ``qp``; and ``qp_daqp``, the QP controller on the ``daqp`` backend, when
  installed), both methods, the three safety modes (paper, ssm, pfl);
* ``scaling``: ``robot_points/<n>`` (sphere table, n robot spheres) and ``people/<n>``
  (QP tick, capsules, SSM, n people, a new camera frame every other tick);
* ``paper_budget_us``: the paper's 33 ms frame, 21 ms for distances and avoidance,
  9 ms distances, 2 ms avoidance.

Timing belongs here, never in tests; run it on an idle machine.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from functools import partial
from types import SimpleNamespace
from typing import Any

import numpy as np

from qpavoid.arm.model import load_robot
from qpavoid.control.analytic import AnalyticController
from qpavoid.control.controller import Controller
from qpavoid.control.qp import QPConfig, QPController
from qpavoid.control.qp.backends import qpsolvers
from qpavoid.control.tick import ControllerConfig
from qpavoid.distance.methods import CapsuleDistance, SphereDistance
from qpavoid.fusion.fuser import Fuser
from qpavoid.human.body import KinectHuman
from qpavoid.human.frames import HumanFrame
from qpavoid.human.people import People
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.perception.tracker import Tracker
from qpavoid.scenarios.generated import make_scenario
from qpavoid.sensing.synthetic_pair import TwoSensorConfig, two_sensor_data

__all__ = ["PAPER_BUDGET_US", "format_bench", "run_bench"]

#: The paper's time budget (Sect. 4), µs.
PAPER_BUDGET_US = {
    "frame": 33_000,
    "distances_and_avoidance": 21_000,
    "distances": 9_000,
    "avoidance": 2_000,
}


def _timed(fn: Callable[[Any], object], items: Sequence[Any], repeat: int) -> dict[str, float]:
    """Median and p99 of ``fn(item)`` over the items, µs, after one warm-up pass."""
    for item in items[: max(len(items) // 10, 1)]:
        fn(item)
    out = []
    for _ in range(repeat):
        for item in items:
            t0 = time.perf_counter_ns()
            fn(item)
            out.append((time.perf_counter_ns() - t0) / 1e3)
    return {"median_us": float(np.median(out)), "p99_us": float(np.percentile(out, 99))}


def _has_daqp() -> bool:
    """daqp installed (the solvers extra)."""
    return "daqp" in qpsolvers().available_solvers


def _controller(kind: str, distance: str, safety: str, **qp: Any) -> Callable[..., Controller]:
    config = ControllerConfig(distance=distance, safety=safety, control_period_s=0.01)
    if kind == "analytic":
        return lambda robot: AnalyticController(robot, config=config)
    return lambda robot: QPController(robot, config=config, qp=QPConfig(**qp))


def run_bench(quick: bool = False, robot: str = "iiwa14") -> dict[str, Any]:
    """Every timing of the module docstring on ``robot`` (a bundled description's name or
    a folder; ``quick``: fewer states, one repeat)."""
    warnings.simplefilter("ignore")
    arm = load_robot(robot)
    motion = make_scenario("test1", arm)
    log = simulate(
        QPController(arm, config=ControllerConfig(control_period_s=0.01, safety="ssm")),
        motion,
        SimConfig(control_rate_hz=100.0, max_time_s=20.0),
    ).log
    step = 4 if quick else 1
    repeat = 1 if quick else 3
    # one frame object per camera frame, shared by its ticks (as a live loop holds it)
    frames: dict[bytes, Any] = {}
    states = []
    for k in range(0, len(log["t"]), step):
        key = log["joints"][k].tobytes()
        frame = frames.setdefault(key, HumanFrame.check(log["joints"][k], log["state"][k]))
        states.append((log["q"][k], frame, log["tau"][k]))
    human = KinectHuman()
    result: dict[str, Any] = {"robot": arm.name, "states": len(states), "repeat": repeat}
    stages: dict[str, dict[str, float]] = {}
    kins = [arm.kinematics(s[0]) for s in states]
    made: dict[int, Any] = {}  # one geometry per camera frame, as a controller keeps it
    geos = [made.setdefault(id(s[1]), human.geometry(s[1])) for s in states]
    idx = list(range(len(states)))
    stages["kinematics"] = _timed(lambda k: arm.kinematics(states[k][0]), idx, repeat)
    stages["human_geometry"] = _timed(lambda k: human.geometry(states[k][1]), idx, repeat)
    spheres, capsules = SphereDistance(arm, human), CapsuleDistance(arm, human)
    stages["sphere_table"] = _timed(lambda k: spheres(kins[k], geos[k]), idx, repeat)
    stages["capsule_table"] = _timed(lambda k: capsules(kins[k], geos[k]), idx, repeat)
    tracker = Tracker()
    clock = iter(np.arange(0.0, 1e6, 1.0 / 30.0))
    stages["perception"] = _timed(lambda k: tracker.update(states[k][1], next(clock)), idx, repeat)
    stages["fusion"] = _fusion_timing(motion, quick)
    qp = QPController(arm, config=ControllerConfig(control_period_s=0.01, safety="ssm"))
    analytic = AnalyticController(arm, config=ControllerConfig(control_period_s=0.01, safety="ssm"))
    ticks = [qp.measure(s[0], s[1], None, s[2]) for s in states]
    ticks = [t for t in ticks if not t.reason]
    stages["prelude"] = _timed(partial(_measure, qp), states, repeat)
    stages["analytic_law"] = _timed(analytic.act, ticks, repeat)
    stages["qp_assembly"] = _timed(qp.problem, ticks, repeat)
    if qp.one_pass is not None:
        fill = qp.one_pass.fill
        stages["qp_assembly/one_pass"] = _timed(lambda t: fill(t, 0.01), ticks, repeat)
    problems = [qp.problem(t) for t in ticks]
    stages["qp_solve/persistent_osqp"] = _timed(qp.backend.solve, problems, repeat)
    kinds = ["analytic", "qp"]
    if _has_daqp():
        fast = QPController(arm, config=qp.config, qp=QPConfig(backend="daqp"))
        stages["qp_solve/daqp_direct"] = _timed(fast.backend.solve, problems, repeat)
        kinds.append("qp_daqp")
    for name in sorted(qpsolvers().available_solvers):
        other = QPController(arm, qp=QPConfig(backend="qpsolvers", solver=name))
        stages[f"qp_solve/{name}"] = _timed(other.backend.solve, problems, repeat)
    result["stages"] = stages
    result["ticks"] = {}
    for kind in kinds:
        for distance in ("spheres", "capsules"):
            for safety in ("paper", "ssm", "pfl"):
                ctrl = (  # qp_daqp: the QP controller on the daqp backend
                    _controller("qp", distance, safety, backend="daqp")
                    if kind == "qp_daqp"
                    else _controller(kind, distance, safety)
                )(arm)
                result["ticks"][f"{kind}/{distance}/{safety}"] = _timed(
                    partial(_step, ctrl), states, repeat
                )
    result["scaling"] = _scaling(arm, human, states, quick)
    result["paper_budget_us"] = PAPER_BUDGET_US
    return result


def _fusion_timing(motion: Any, quick: bool) -> dict[str, float]:
    """``Fuser.add`` + ``Fuser.fuse`` per body frame: two sensors, one person."""
    data = two_sensor_data([motion], 2.0 if quick else 6.0, TwoSensorConfig(seed=0))
    rows = sorted(
        (f.t + data.calibration[f.sensor].time_offset_s, f)
        for rec in data.recordings.values()
        for f in rec.frames()
    )
    fuser = Fuser(data.calibration)

    def one(row: tuple[float, Any]) -> None:
        fuser.add(row[1])
        fuser.fuse(row[0])

    return _timed(one, rows, 1)


def _scaling(
    robot: Any, human: KinectHuman, states: list, quick: bool
) -> dict[str, dict[str, float]]:
    """Time against robot spheres and people."""
    out: dict[str, dict[str, float]] = {}
    geos = [human.geometry(s[1]) for s in states[:50]]
    rng = np.random.default_rng(0)
    n_sets = len(robot.sets)
    for n in (9, 30, 100, 300, 1000):  # n robot spheres over the robot's sets, on a 1 m arm
        per = [list(range(k, n, n_sets)) for k in range(n_sets)]
        fake = SimpleNamespace(
            sets=[SimpleNamespace(points=p, sphere_radius_m=0.08) for p in per],
            point_set=np.arange(n) % n_sets,
            set_names=robot.set_names,
        )
        table = SphereDistance(fake, human)  # type: ignore[arg-type]  # duck-typed robot
        kin = SimpleNamespace(points=rng.uniform(-0.5, 0.5, (n, 3)) + np.array([0, 0.5, 0.5]))
        out[f"robot_points/{n}"] = _timed(partial(_call, table, kin), geos, 1)
    for n in (1, 2, 4, 6):
        ctrl = QPController(robot, config=ControllerConfig(control_period_s=0.01, safety="ssm"))
        crowd: list[tuple] = []
        made: dict[int, People] = {}  # one People per camera frame, as a live loop holds it
        for s in states[:: 4 if quick else 2]:
            joints, state = s[1].joints, s[1].state
            people = made.get(id(s[1])) or People(
                tuple(range(n)),
                tuple(
                    HumanFrame.check(joints + np.array([0.7 * i, 0.4 * i, 0.0]), state)
                    for i in range(n)
                ),
            )
            made[id(s[1])] = people
            crowd.append((s[0], people, s[2]))
        out[f"people/{n}"] = _timed(partial(_step, ctrl), crowd, 1)
    return out


def _call(table: SphereDistance, kin: Any, geo: Any) -> object:
    return table(kin, geo)


def _step(ctrl: Controller, c: tuple) -> object:
    return ctrl.step(c[0], c[1], None, c[2])


def _measure(ctrl: Controller, c: tuple) -> object:
    return ctrl.measure(c[0], c[1], None, c[2])


def format_bench(result: dict[str, Any]) -> str:
    """The timings as one readable table (the JSON's keys, µs)."""
    lines = [
        f"{result.get('robot', 'iiwa14')}: {result['states']} recorded states (test1, 100 Hz, "
        "real bench), "
        f"{result['repeat']} repeat(s); median and p99, µs",
        "",
        f"{'':44s} {'median':>9s} {'p99':>9s}",
    ]
    for group in ("stages", "ticks", "scaling"):
        lines.append(group)
        for key, v in result[group].items():
            lines.append(f"  {key:42s} {v['median_us']:9.0f} {v['p99_us']:9.0f}")
    budget = result["paper_budget_us"]
    lines.append(
        "paper's budget: frame {frame}, distances + avoidance {distances_and_avoidance}, "
        "distances {distances}, avoidance {avoidance}".format(**budget)
    )
    return "\n".join(lines)
