"""The real-time loop on franky-sim's FR3: its timing at several avoidance rates.

    python benchmarks/arm_loop.py [--rates 500 250 100] [--seconds 10] [--out FILE.json]
                                  [--controller analytic|qp] [--beyond-smooth-rate]

For each rate: franky-sim started headless on a loopback address, the FR3 moved to its
task's start, then ``--seconds`` of the ``free`` scenario (nobody near: the loop's own
cost) and of Test 1 through the loop of every run (``simulate`` with ``arm=``); reported:
the controller's time per tick, the loop's missed deadlines, the longest gap between two
commands, the command period and the time from a frame's capture to its first command
(the simulated Kinect's 60 ms latency included). libfranka's own loop runs at 1 kHz and
franky ramps the arm to each new command within its limits: the interpolation between
qpavoid's commands. The numbers of docs/real-robot.md §3.

``--beyond-smooth-rate`` lifts, for this measurement only, the command line's refusal of
``--arm`` above :func:`~qpavoid.control.smoothing.smooth_rate_limit_hz` (1 kHz on the
Franka arms, the rate their commands are shown to keep their limits at: docs/real-robot.md):
the loop's own timing above it, not a rate a run may use.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from qpavoid.drive.franka_sim import FrankySim
from qpavoid.experiments import runs
from qpavoid.experiments.runs import RunSpec, simulate_one


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", type=float, nargs="+", default=[500.0, 250.0, 100.0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--out", default="benchmarks/results/arm_loop.json")
    ap.add_argument("--controller", default="analytic", choices=("analytic", "qp"))
    ap.add_argument("--beyond-smooth-rate", action="store_true")
    args = ap.parse_args()
    if args.beyond_smooth_rate:
        runs.smooth_rate_limit_hz = lambda robot: float("inf")  # this measurement only
    pid = os.getpid()
    out: dict = {
        "load_average": os.getloadavg(),
        "cpus": os.cpu_count(),
        "controller": args.controller,
    }
    for n, rate in enumerate(args.rates):
        for scenario in ("free", "test1"):
            host = f"127.{(pid >> 8) % 256}.{pid % 256}.{10 + 2 * n + (scenario == 'test1')}"
            spec = RunSpec(
                scenario=scenario,
                robot="fr3",
                rate_hz=rate,
                max_time_s=args.seconds,
                arm=f"franka:{host}",
                controller=args.controller,
            )
            with FrankySim(host):
                m = simulate_one(spec).metrics
            key = f"{scenario}/{rate:.0f}hz"
            out[key] = {
                "tick_us": m["tick_us"],
                "loop": m["loop"],
                "command_limit_violations": m["command_limit_violations"],
                "ticks_moving_in_true_contact": m["ticks_moving_in_true_contact"],
                "min_true_clearance_moving_m": m["min_true_clearance_moving_m"],
                "end_reason": m["end_reason"],
            }
            print(key, json.dumps(out[key]), flush=True)
    out["load_average_after"] = os.getloadavg()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
