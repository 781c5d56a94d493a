"""Safety against the true motion, and what it costs: the numbers of docs/safety.md.

    python benchmarks/safety.py [--strikes 1000] [--out benchmarks/results/safety.json]

1. Strikes (:func:`qpavoid.experiments.sweep.strike_sweep`): ``--strikes`` random cases at
   up to 2.0 m/s for each controller with ``--safety ssm``; a fifth of that at up to 2.5 m/s
   (beyond the ISO 13855 speeds SSM is sized for); and the same first fifth with the
   paper's rules.
2. Productivity: time to goal and time stopped in ``free``, ``test1``, ``test2`` and
   random approaches, paper rules against SSM, both controllers, on the real bench.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from qpavoid.experiments.runs import RunSpec, simulate_one
from qpavoid.experiments.sweep import strike_sweep
from qpavoid.experiments.sweep_summary import as_dicts, summarize

CONTROLLERS = ("qp", "analytic")


def strikes(n: int) -> dict:
    out: dict = {}
    for controller in CONTROLLERS:
        for safety, count, speed in (("ssm", n, 2.0), ("ssm", n // 5, 2.5), ("paper", n // 5, 2.0)):
            t0 = time.time()
            checks = strike_sweep(
                range(count), controller, safety, max_speed_mps=speed, progress=True
            )
            key = f"{controller}/{safety}/{speed:.1f}"
            out[key] = {
                **summarize(checks),
                # the docs' "ticks" and "mean moving" columns, beyond the sweep's summary
                "ticks_moving_in_true_contact": sum(c.ticks_moving_in_true_contact for c in checks),
                "mean_moving_s": float(np.mean([c.moving_s for c in checks])),
                "wall_s": round(time.time() - t0, 1),
            }
            out[key + "/runs"] = as_dicts(checks)
            print(key, out[key], flush=True)
    return out


def productivity(random_seeds: int) -> dict:
    out: dict = {}
    names = ["free", "test1", "test2"] + [f"random:{s}" for s in range(random_seeds)]
    for controller in CONTROLLERS:
        for safety in ("paper", "ssm"):
            rows = {}
            for name in names:
                spec = RunSpec(
                    scenario=name,
                    controller=controller,
                    safety=safety,
                    rate_hz=100.0,
                    max_time_s=60.0,
                )
                m = simulate_one(spec).metrics
                rows[name] = {
                    "reached_goal": m["reached_goal"],
                    "duration_s": m["duration_s"],
                    "stopped_s": m["stopped_s"],
                    "end_reason": m["end_reason"],
                    "ticks_moving_in_true_contact": m["ticks_moving_in_true_contact"],
                    "min_true_clearance_moving_m": m["min_true_clearance_moving_m"],
                }
            out[f"{controller}/{safety}"] = rows
            print(
                controller,
                safety,
                {k: (v["duration_s"], v["stopped_s"]) for k, v in rows.items()},
                flush=True,
            )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strikes", type=int, default=1000)
    ap.add_argument("--random", type=int, default=20, help="random approaches for productivity")
    ap.add_argument("--out", default="benchmarks/results/safety.json")
    args = ap.parse_args()
    result = {"productivity": productivity(args.random), "strikes": strikes(args.strikes)}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1))
    print("wrote", args.out)


if __name__ == "__main__":
    main()
