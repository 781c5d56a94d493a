"""Head to head: both controllers, both distance methods, on the same inputs.

``qpavoid compare`` runs every input (generated scenarios, recordings, random approaches)
with the analytic and the QP controller, each with spheres and with capsules, and writes

* ``compare.json``: the metrics of every run, keyed ``[input][controller][distance]``;
* ``compare.md``: one side-by-side table (random approaches summarised in one row each);
* ``compare_<input>.png``: per named input, both controllers' minimum distance and path
  error over time.

Runs are independent, so they are mapped over a process pool (``workers``, default all
cores); a sweep over thousands of approaches is the same map over more cases.
"""

from __future__ import annotations

import json
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

CONTROLLERS = ("analytic", "qp")
DISTANCES = ("spheres", "capsules")


@dataclass(frozen=True)
class Case:
    """One run: an input (scenario name or recording path), a controller, a method."""

    label: str
    scenario: str | None
    human_file: str | None
    controller: str
    distance: str
    max_time_s: float
    rate_hz: float
    robot: str


def run_case(case: Case) -> tuple[Case, dict, dict]:
    """Simulate one case; return its metrics and the time series the plots need."""
    from .cli import simulate_one
    result, *_ = simulate_one(case.scenario, case.human_file, case.controller, case.distance,
                              case.max_time_s, case.rate_hz, robot_name=case.robot)
    log = result.log
    series = {"t": log["t"][::10], "min_distance": log["distance"].min(axis=1)[::10],
              "path_error": np.linalg.norm(log["ee_pos"] - log["ee_ref"], axis=1)[::10]}
    return case, result.metrics, series


def _row(label, ctrl, dist, m) -> str:
    md = m["min_distance_m"]
    return (f"| {label} | {ctrl} | {dist} | {'yes' if m['reached_goal'] else 'no'} | "
            f"{m['duration_s']:.2f} | {md['spheres']:.3f} | {md['capsules']:.3f} | "
            f"{m['rms_path_error_m'] * 1e3:.2f} | {m['max_path_error_m'] * 1e3:.1f} | "
            f"{m['stopped_s']:.2f} | {len(m['stop_events'])} | "
            f"{m['joint_velocity_limit_violations']}/{m['joint_position_limit_violations']} | "
            f"{m['tick_us']['median']:.0f} / {m['tick_us']['p99']:.0f} |")


def _random_row(label, ctrl, dist, runs: list[dict]) -> str:
    md_s = min(m["min_distance_m"]["spheres"] for m in runs)
    md_c = min(m["min_distance_m"]["capsules"] for m in runs)
    reached = sum(m["reached_goal"] for m in runs)
    dur = np.mean([m["duration_s"] for m in runs])
    rms = np.mean([m["rms_path_error_m"] for m in runs]) * 1e3
    mx = max(m["max_path_error_m"] for m in runs) * 1e3
    stopped = np.mean([m["stopped_s"] for m in runs])
    stops = sum(len(m["stop_events"]) for m in runs)
    vv = sum(m["joint_velocity_limit_violations"] for m in runs)
    pv = sum(m["joint_position_limit_violations"] for m in runs)
    tick = np.median([m["tick_us"]["median"] for m in runs])
    p99 = np.median([m["tick_us"]["p99"] for m in runs])
    return (f"| {label} | {ctrl} | {dist} | {reached}/{len(runs)} | {dur:.2f} (mean) | {md_s:.3f} | "
            f"{md_c:.3f} | {rms:.2f} (mean) | {mx:.1f} | {stopped:.2f} (mean) | {stops} | "
            f"{vv}/{pv} | {tick:.0f} / {p99:.0f} |")


HEADER = ("| input | controller | distances | goal | time (s) | min d spheres (m) | "
          "min d capsules (m) | rms path err (mm) | max path err (mm) | stopped (s) | stops | "
          "limit viol. vel/pos | tick µs median / p99 |\n" + "|---" * 13 + "|")


def compare(out: str | Path, scenarios: list[str], human_files: list[str], n_random: int = 0,
            seed: int = 0, max_time_s: float = 40.0, rate_hz: float = 500.0, plots: bool = True,
            robot: str = "iiwa14", workers: int | None = None) -> str:
    """Run the comparison, write its files into ``out``; return the markdown table."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    inputs = [(s, s, None) for s in scenarios]
    inputs += [(Path(f).stem, None, str(f)) for f in human_files]
    randoms = [f"random:{seed + k}" for k in range(n_random)]
    inputs += [(r, r, None) for r in randoms]
    cases = [Case(label, scen, hf, c, d, max_time_s, rate_hz, robot)
             for label, scen, hf in inputs for c in CONTROLLERS for d in DISTANCES]
    workers = workers or os.cpu_count() or 1
    if workers > 1 and len(cases) > 1:
        with ProcessPoolExecutor(max_workers=min(workers, len(cases))) as pool:
            done = list(pool.map(run_case, cases))
    else:
        done = [run_case(c) for c in cases]

    metrics: dict = {}
    series: dict = {}
    for case, m, s in done:
        metrics.setdefault(case.label, {}).setdefault(case.controller, {})[case.distance] = m
        series[(case.label, case.controller, case.distance)] = s
    (out / "compare.json").write_text(json.dumps(metrics, indent=2) + "\n")

    lines = [HEADER]
    for label, _, _ in inputs:
        if label in randoms:
            continue
        for c in CONTROLLERS:
            for d in DISTANCES:
                lines.append(_row(label, c, d, metrics[label][c][d]))
    if randoms:
        for c in CONTROLLERS:
            for d in DISTANCES:
                lines.append(_random_row(f"random ×{len(randoms)}", c, d,
                                         [metrics[r][c][d] for r in randoms]))
    table = "\n".join(lines)
    (out / "compare.md").write_text(
        "# qpavoid compare\n\nEvery input run with both controllers and both distance methods "
        f"({rate_hz:g} Hz control, {max_time_s:g} s cap). Limit violations: ticks over a joint "
        "velocity / position limit.\n\n" + table + "\n")
    from . import plots as plotting
    if plots and plotting.available():
        for label, _, _ in inputs:
            if label not in randoms:
                plotting.write_comparison(out / f"compare_{label}.png", label,
                                          {(c, d): series[(label, c, d)]
                                           for c in CONTROLLERS for d in DISTANCES})
    return table
