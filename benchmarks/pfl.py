"""The three safety modes side by side where people work (issue 29): docs/safety.md §9.

    python benchmarks/pfl.py [--closework 100] [--random 20] [--workers 2]
                             [--out benchmarks/results/pfl.json]

For each controller and each of ``--safety paper``, ``ssm`` and ``pfl`` (iiwa 14, capsules,
the real bench at 100 Hz, the Kinect v2):

1. the named scenarios ``free``, ``test1``, ``test2`` and the close-work ones (``rest_near``,
   ``work_near``, ``reach_across``, ``handover``): time to the goal, time stopped, and the
   true contacts as power and force limiting judges them;
2. ``--random`` random approaches (``random:SEED``, hands towards a random set at up to
   1.6 m/s): the fraction reaching the goal, time to it, time stopped, true contacts;
3. a close-work sweep (``qpavoid sweep --motion closework``) of ``--closework`` cases: its
   summary (reaching the goal, time to it, time stopped, per variant, contacts).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from qpavoid.experiments.jobs import map_jobs
from qpavoid.experiments.runs import RunSpec, simulate_one
from qpavoid.experiments.sweep import SweepSpec, sweep
from qpavoid.experiments.sweep_summary import summarize

CONTROLLERS = ("qp", "analytic")
MODES = ("paper", "ssm", "pfl")
NAMED = ("free", "test1", "test2", "rest_near", "work_near", "reach_across", "handover")


def _row(job: tuple[str, str, str]) -> dict:
    """One run's productivity and contacts."""
    scenario, controller, safety = job
    spec = RunSpec(
        scenario=scenario, controller=controller, safety=safety, rate_hz=100.0, max_time_s=60.0
    )
    m = simulate_one(spec).metrics
    c = m["true_contacts"]
    return {
        "reached_goal": m["reached_goal"],
        "duration_s": m["duration_s"],
        "stopped_s": m["stopped_s"],
        "ticks_moving_in_true_contact": m["ticks_moving_in_true_contact"],
        "ticks_moving_protected": c["ticks_moving_protected"],
        "ticks_above_limit": c["ticks_above_limit"],
        "ticks_within_limit": c["ticks_within_limit"],
        "max_contact_speed_mps": c["max_speed_mps"],
        "max_contact_force_n": c["max_force_n"],
    }


def runs(names: list[str], workers: int) -> dict:
    """Every named run under every controller and mode."""
    jobs = [(n, c, s) for c in CONTROLLERS for s in MODES for n in names]
    rows = map_jobs(_row, jobs, workers=workers, progress=True, desc="runs", unit="run")
    out: dict = {}
    for (name, controller, safety), row in zip(jobs, rows, strict=True):
        out.setdefault(f"{controller}/{safety}", {})[name] = row
    return out


def random_totals(rows: dict) -> dict:
    """The random approaches of one controller and mode, summed up."""
    these = [r for name, r in rows.items() if name.startswith("random:")]
    reached = [r["duration_s"] for r in these if r["reached_goal"]]
    return {
        "runs": len(these),
        "fraction_reaching_goal": len(reached) / len(these),
        "mean_time_to_goal_s": round(float(np.mean(reached)), 3) if reached else None,
        "mean_time_stopped_s": round(float(np.mean([r["stopped_s"] for r in these])), 3),
        "runs_moving_in_true_contact": sum(r["ticks_moving_in_true_contact"] > 0 for r in these),
        "runs_touching_above_limit": sum(r["ticks_above_limit"] > 0 for r in these),
        "runs_touching_protected_regions": sum(r["ticks_moving_protected"] > 0 for r in these),
    }


def closework(n: int, workers: int) -> dict:
    """The close-work sweep of ``n`` cases under every controller and mode."""
    out = {}
    for controller in CONTROLLERS:
        for safety in MODES:
            t0 = time.time()
            spec = SweepSpec("closework", controller, safety=safety)
            summary = summarize(sweep(spec, range(n), workers=workers, progress=True))
            summary["wall_s"] = round(time.time() - t0, 1)
            out[f"{controller}/{safety}"] = summary
            print(controller, safety, json.dumps(summary["per_variant"]), flush=True)
    return out


def table(result: dict) -> str:
    """The docs' tables: named runs (time to goal / stopped), then the sweeps."""
    lines = ["| controller | rules | " + " | ".join(NAMED) + " | random: reached, time, stopped |"]
    lines.append("|---" * (len(NAMED) + 3) + "|")
    for key, rows in result["runs"].items():
        cells = [
            f"{r['duration_s']:.2f} s ({r['stopped_s']:.2f})"
            + ("" if r["reached_goal"] else " not reached")
            for r in (rows[n] for n in NAMED)
        ]
        rt = result["random"][key]
        cells.append(
            f"{rt['fraction_reaching_goal']:.0%}, {rt['mean_time_to_goal_s']} s, "
            f"{rt['mean_time_stopped_s']} s"
        )
        lines.append(f"| {key.replace('/', ' | ')} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(
        "| controller | rules | reached | time to goal (median) | stopped (mean) | "
        "per variant: reached / stopped | moving in true contact | above limit | protected |"
    )
    lines.append("|---" * 9 + "|")
    for key, s in result["closework"].items():
        variants = "; ".join(
            f"{v}: {x['fraction_reaching_goal']:.0%} / {x['mean_time_stopped_s']:.2f} s"
            for v, x in s["per_variant"].items()
        )
        c = s["contacts"]
        lines.append(
            f"| {key.replace('/', ' | ')} | {s['fraction_reaching_goal']:.1%} | "
            f"{s['time_to_goal_s']['median']} s | {s['mean_time_stopped_s']:.2f} s | {variants} | "
            f"{s['runs_moving_in_true_contact']} | {c['runs_touching_above_limit']} | "
            f"{c['runs_touching_protected_regions']} |"
        )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--closework", type=int, default=100, help="close-work cases per mode")
    ap.add_argument("--random", type=int, default=20, help="random approaches per mode")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--out", default="benchmarks/results/pfl.json")
    args = ap.parse_args()
    names = [*NAMED, *(f"random:{s}" for s in range(args.random))]
    result: dict = {"runs": runs(names, args.workers)}
    result["random"] = {key: random_totals(rows) for key, rows in result["runs"].items()}
    result["closework"] = closework(args.closework, args.workers)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1))
    print(table(result))
    print("wrote", args.out)


if __name__ == "__main__":
    main()
