"""What commands a real arm accepts cost: smooth commands against the paper's steps.

    python benchmarks/smooth_stops.py [--random 20] [--robot iiwa14] [--out FILE.json]

For each controller and rule set (the paper's, SSM), on the real bench at 500 Hz: the time
to the goal and the time stopped in ``free``, ``test1``, ``test2`` and ``--random`` random
approaches, and every command checked against the arm's limits, with
``ControllerConfig.smooth`` on (each command within reach of the last, stops as braking
ramps: :mod:`qpavoid.control.smoothing`) and off (the paper's: a stop is a step to zero).
The numbers of docs/safety.md §7.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from qpavoid.control.analytic import AnalyticController
from qpavoid.control.qp import QPController
from qpavoid.experiments.runs import RunSpec, build_controller, simulate_one, spec_robot


def run(spec: RunSpec, smooth: bool) -> dict:
    """One run of ``spec`` with ``smooth`` commands or not: its productivity and limits."""
    robot = spec_robot(spec)
    base = build_controller(spec, robot)
    config = replace(base.config, smooth=smooth)
    controller = (
        AnalyticController(robot, config=config, analytic=base.analytic)
        if isinstance(base, AnalyticController)
        else QPController(robot, config=config, qp=base.qp)
    )
    m = simulate_one(spec, robot=robot, controller=controller).metrics
    return {
        "reached_goal": m["reached_goal"],
        "duration_s": m["duration_s"],
        "stopped_s": m["stopped_s"],
        "ticks_moving_in_true_contact": m["ticks_moving_in_true_contact"],
        "command_limit_violations": sum(m["command_limit_violations"].values()),
        "worst_acceleration_ratio": m["command_limit_worst_ratio"]["acceleration"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--random", type=int, default=20, help="random approaches")
    ap.add_argument("--robot", default="iiwa14")
    ap.add_argument("--out", default="benchmarks/results/smooth_stops.json")
    args = ap.parse_args()
    names = ["free", "test1", "test2"] + [f"random:{s}" for s in range(args.random)]
    out: dict = {}
    for controller in ("qp", "analytic"):
        for safety in ("paper", "ssm"):
            for smooth in (False, True):
                rows = {
                    name: run(
                        RunSpec(
                            scenario=name,
                            controller=controller,
                            safety=safety,
                            robot=args.robot,
                            max_time_s=60.0,
                        ),
                        smooth,
                    )
                    for name in names
                }
                rnd = [rows[n] for n in names[3:]]
                key = f"{controller}/{safety}/{'smooth' if smooth else 'steps'}"
                out[key] = {
                    "runs": rows,
                    "random_mean_duration_s": float(np.mean([r["duration_s"] for r in rnd])),
                    "random_mean_stopped_s": float(np.mean([r["stopped_s"] for r in rnd])),
                    "random_reached_goal": sum(r["reached_goal"] for r in rnd),
                    "runs_beyond_limits": sum(
                        r["command_limit_violations"] > 0 for r in rows.values()
                    ),
                    "ticks_moving_in_true_contact": sum(
                        r["ticks_moving_in_true_contact"] or 0 for r in rows.values()
                    ),
                }
                print(key, {k: v for k, v in out[key].items() if k != "runs"}, flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
