"""Per-tick time of every controller path, next to the paper's 2 ms + 9 ms.

Replays the states of one closed-loop run (test1, QP controller, 100 Hz: the hand near L2
and EE, so repulsion rows and dampers are active on many ticks) through

* the analytic tick (AnalyticController.step),
* the QP tick through qpsolvers with every installed solver (a new problem each tick),
* the QP tick with the persistent OSQP problem (updated, warm started),

and times the parts of a tick: kinematics, human geometry, both distance methods,
assembling the QP and solving it. Prints a markdown table; ``--json FILE`` writes it.

    python benchmarks/ticks.py [--repeat 3] [--json out.json]

Timing lives here, never in tests. The machine is noisy: run it on an idle machine.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings

import numpy as np
import qpsolvers

import qpavoid
from qpavoid.control.analytic import AnalyticController
from qpavoid.control.qp import QPConfig, QPController
from qpavoid.control.tick import ControllerConfig
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario


def timed(fn, states, repeat: int) -> np.ndarray:
    """Microseconds per call of ``fn(state)`` over every state, ``repeat`` times."""
    out = []
    for _ in range(repeat):
        for s in states:
            t0 = time.perf_counter_ns()
            fn(s)
            out.append((time.perf_counter_ns() - t0) / 1e3)
    return np.array(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", help="write the numbers to this file")
    args = ap.parse_args()
    warnings.simplefilter("ignore")

    robot = qpavoid.load_robot()
    cfg = ControllerConfig(control_period_s=0.01)
    log = simulate(
        QPController(robot, config=cfg),
        make_scenario("test1", robot),
        SimConfig(control_rate_hz=100),
    ).log
    # One HumanFrame object per camera frame, shared by the ticks that see it (as in the
    # simulation): a controller builds a frame's geometry once.
    frames: dict[bytes, qpavoid.HumanFrame] = {}
    for k in range(len(log["t"])):
        key = log["joints"][k].tobytes() + log["state"][k].tobytes()
        frames.setdefault(key, qpavoid.HumanFrame.check(log["joints"][k], log["state"][k]))
    states = [
        (
            log["q"][k],
            frames[log["joints"][k].tobytes() + log["state"][k].tobytes()],
            None,
            log["tau"][k],
        )
        for k in range(len(log["t"]))
    ]
    rows: dict[str, np.ndarray] = {}

    analytic = AnalyticController(robot, config=cfg)
    rows["analytic tick (eqs. 2-9)"] = timed(lambda s: analytic.step(*s), states, args.repeat)
    for name in sorted(qpsolvers.available_solvers):
        ctrl = QPController(robot, config=cfg, qp=QPConfig(backend="qpsolvers", solver=name))
        rows[f"QP tick, qpsolvers + {name}"] = timed(
            lambda s, c=ctrl: c.step(*s), states, args.repeat
        )
    qp = QPController(robot, config=cfg)
    rows["QP tick, persistent OSQP"] = timed(lambda s: qp.step(*s), states, args.repeat)
    qp_caps = QPController(
        robot, config=ControllerConfig(distance="capsules", control_period_s=0.01)
    )
    rows["QP tick, persistent OSQP, capsules"] = timed(
        lambda s: qp_caps.step(*s), states, args.repeat
    )

    # Parts of the persistent QP tick.
    human = qpavoid.KinectHuman()
    spheres, capsules = qpavoid.SphereDistance(robot, human), qpavoid.CapsuleDistance(robot, human)
    kins = [robot.kinematics(s[0]) for s in states]
    geos = [human.geometry(s[1]) for s in states]
    idx = list(range(len(states)))
    rows["  kinematics + Jacobians (Pinocchio)"] = timed(
        lambda k: robot.kinematics(states[k][0]), idx, args.repeat
    )
    rows["  human geometry (once per camera frame)"] = timed(
        lambda k: human.geometry(states[k][1]), idx, args.repeat
    )
    rows["  sphere table (eq. 1)"] = timed(lambda k: spheres(kins[k], geos[k]), idx, args.repeat)
    rows["  capsule table (coal)"] = timed(lambda k: capsules(kins[k], geos[k]), idx, args.repeat)
    ticks = [qp.measure(*s) for s in states]
    ticks = [t for t in ticks if not t.reason]
    rows["  shared prelude (measure)"] = timed(lambda s: qp.measure(*s), states, args.repeat)
    rows["  QP assembly (all pieces)"] = timed(lambda t: qp.problem(t), ticks, args.repeat)
    problems = [qp.problem(t) for t in ticks]
    rows["  QP solve, persistent OSQP"] = timed(
        lambda p: qp.backend.solve(p), problems, args.repeat
    )

    table = ["| path | median (µs) | p99 (µs) |", "|---|---|---|"]
    table += [f"| {k} | {np.median(v):.0f} | {np.percentile(v, 99):.0f} |" for k, v in rows.items()]
    table.append("| paper: avoidance law / distances | 2000 / 9000 | |")
    print(f"{len(states)} recorded states (test1, 100 Hz), {args.repeat} repeats\n")
    print("\n".join(table))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(
                {
                    k: {"median_us": float(np.median(v)), "p99_us": float(np.percentile(v, 99))}
                    for k, v in rows.items()
                },
                fh,
                indent=2,
            )


if __name__ == "__main__":
    main()
