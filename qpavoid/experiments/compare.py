"""Head to head: both controllers, both distance methods, on the same inputs.

``qpavoid compare`` runs every input (generated scenarios, recordings, random approaches)
with the analytic and the QP controller, each with spheres and with capsules, and writes

* ``compare.json``: the metrics of every run, keyed ``[input][controller][distance]``;
* ``compare.md``: one side-by-side table (random approaches summarised in one row each);
* ``compare_<input>.png``: per named input, both controllers' minimum distance and path
  error over time.

Runs are independent, so they are mapped over a process pool
(:func:`qpavoid.experiments.jobs.map_jobs`,
``workers`` default all cores); a sweep over thousands of approaches is the same map over
more cases.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from qpavoid.arm.description import description_reference
from qpavoid.arm.model import load_robot
from qpavoid.core.errors import InputError
from qpavoid.experiments.jobs import map_jobs
from qpavoid.experiments.run_spec import CONTROLLERS, DISTANCES
from qpavoid.experiments.runs import RunSpec, simulate_one
from qpavoid.output import plots as plotting
from qpavoid.output import replay_html as view_html
from qpavoid.output.run_files import check_output_dir, staged_output, strict_json
from qpavoid.output.view_data import replay_data
from qpavoid.sensing.recording import load_recording

Series = dict[str, np.ndarray]


def run_case(spec: RunSpec, view: bool = False) -> tuple[RunSpec, dict, Series, dict | None]:
    """Simulate one case; return its metrics, the time series the plots need and (with
    ``view``, for a named input) its replay's data."""
    run = simulate_one(spec)
    log = run.sim.log
    series = {
        "t": log["t"][::10],
        "min_distance": log["distance"].min(axis=1)[::10],
        "path_error": np.linalg.norm(log["ee_pos"] - log["ee_ref"], axis=1)[::10],
    }
    named = not spec.label.startswith("random:")
    data = (
        replay_data(log, run.metrics, run.robot, human=run.controller.human)
        if view and named
        else None
    )
    return spec, run.metrics, series, data


def _row(label: str, ctrl: str, dist: str, m: dict[str, Any]) -> str:
    md = m["min_distance_m"]
    return (
        f"| {label} | {ctrl} | {dist} | {'yes' if m['reached_goal'] else 'no'} | "
        f"{m['duration_s']:.2f} | {md['spheres']:.3f} | {md['capsules']:.3f} | "
        f"{m['rms_path_error_m'] * 1e3:.2f} | {m['max_path_error_m'] * 1e3:.1f} | "
        f"{m['stopped_s']:.2f} | {len(m['stop_events'])} | "
        f"{m['joint_velocity_limit_violations']}/{m['joint_position_limit_violations']} | "
        f"{m['tick_us']['median']:.0f} / {m['tick_us']['p99']:.0f} |"
    )


def _random_row(label: str, ctrl: str, dist: str, runs: list[dict[str, Any]]) -> str:
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
    return (
        f"| {label} | {ctrl} | {dist} | {reached}/{len(runs)} | {dur:.2f} (mean) | {md_s:.3f} | "
        f"{md_c:.3f} | {rms:.2f} (mean) | {mx:.1f} | {stopped:.2f} (mean) | {stops} | "
        f"{vv}/{pv} | {tick:.0f} / {p99:.0f} |"
    )


HEADER = (
    "| input | controller | distances | goal | time (s) | min d spheres (m) | "
    "min d capsules (m) | rms path err (mm) | max path err (mm) | stopped (s) | stops | "
    "limit viol. vel/pos | tick µs median / p99 |\n" + "|---" * 13 + "|"
)


def compare_specs(
    scenarios: Sequence[str],
    human_files: Sequence[str],
    n_random: int = 0,
    seed: int = 0,
    max_time_s: float = 40.0,
    rate_hz: float = 500.0,
    robot: str = "iiwa14",
    camera: str = "kinect_v2",
) -> list[RunSpec]:
    """Every case of a comparison, checked: each input × controller × distance method,
    seen through the simulated ``camera`` (a skeleton format's name).

    Raises
    ------
    InputError
        No input at all, a negative count or seed, a bad scenario name, an unreadable
        recording (each recording is read once here, so a bad file fails before any run).
    RobotDescriptionError
        An unknown robot.
    """
    if n_random < 0 or seed < 0:
        bad = ("--random", n_random) if n_random < 0 else ("--seed", seed)
        raise InputError(
            f"{bad[0]} must be a whole number >= 0, got {bad[1]}", name=bad[0], value=bad[1]
        )
    if not (scenarios or human_files or n_random):
        raise InputError(
            "nothing to compare: give --scenarios NAME..., --human FILE... or --random N",
            name="--scenarios",
            value=list(scenarios),
        )
    labels = [Path(f).stem for f in human_files]
    if len(set(labels)) < len(labels):
        raise InputError(
            f"recordings must have distinct file names, got {list(human_files)}",
            name="--human",
            value=list(human_files),
        )
    load_robot(robot)
    for f in human_files:
        load_recording(f)
    inputs = [dict(scenario=s) for s in scenarios]
    inputs += [dict(human_file=str(f)) for f in human_files]
    inputs += [dict(scenario=f"random:{seed + k}") for k in range(n_random)]
    return [
        RunSpec(
            **i,  # type: ignore[arg-type]
            controller=c,
            distance=d,
            max_time_s=max_time_s,
            rate_hz=rate_hz,
            robot=robot,
            camera=camera,
        )
        for i in inputs
        for c in CONTROLLERS
        for d in DISTANCES
    ]


def compare(
    out: str | Path,
    scenarios: Sequence[str],
    human_files: Sequence[str],
    n_random: int = 0,
    seed: int = 0,
    max_time_s: float = 40.0,
    rate_hz: float = 500.0,
    plots: bool = True,
    robot: str = "iiwa14",
    workers: int | None = None,
    progress: bool = False,
    view: bool = True,
    camera: str = "kinect_v2",
) -> str:
    """Run the comparison, write its files into ``out``; return the markdown table.

    With ``view`` (and meshcat installed), each named input's four runs also get a browser
    replay, ``replay_<input>_<controller>_<distance>.html``.

    Every case is checked before the first run starts (:func:`compare_specs`); the files
    appear in ``out`` only when all of them are written.
    """
    check_output_dir(out)
    specs = compare_specs(
        scenarios, human_files, n_random, seed, max_time_s, rate_hz, robot, camera
    )
    view = view and view_html.available()
    case = partial(run_case, view=view)
    done = map_jobs(case, specs, workers=workers, progress=progress, desc="compare", unit="run")
    metrics: dict = {}
    series: dict = {}
    replays: dict = {}
    for spec, m, s, data in done:
        metrics.setdefault(spec.label, {}).setdefault(spec.controller, {})[spec.distance] = m
        series[(spec.label, spec.controller, spec.distance)] = s
        if data is not None:
            name = f"replay_{spec.label}_{spec.controller}_{spec.distance}.html"
            replays[name.replace(":", "-").replace("/", "-")] = (
                data,
                view_html.replay_title(m, spec.label),
            )
    labels = list(dict.fromkeys(spec.label for spec in specs))
    randoms = [label for label in labels if label.startswith("random:")]
    named = [label for label in labels if label not in randoms]

    lines = [HEADER]
    lines += [
        _row(label, c, d, metrics[label][c][d])
        for label in named
        for c in CONTROLLERS
        for d in DISTANCES
    ]
    if randoms:
        lines += [
            _random_row(f"random ×{len(randoms)}", c, d, [metrics[r][c][d] for r in randoms])
            for c in CONTROLLERS
            for d in DISTANCES
        ]
    table = "\n".join(lines)
    with staged_output(out) as stage:
        (stage / "compare.json").write_text(strict_json(metrics) + "\n")
        (stage / "compare.md").write_text(
            f"# qpavoid compare\n\nOn the arm {description_reference(robot)}: every input "
            "run with both controllers and both distance "
            f"methods ({rate_hz:g} Hz control, {max_time_s:g} s cap). Limit violations: ticks "
            "over a joint velocity / position limit.\n\n" + table + "\n"
        )
        for name, (data, title) in replays.items():
            view_html.write_html(stage / name, view_html.replay_html(data, title))
        if plots and plotting.available():
            arm = load_robot(robot)
            for label in named:
                plotting.write_comparison(
                    stage / f"compare_{label}.png",
                    label,
                    {(c, d): series[(label, c, d)] for c in CONTROLLERS for d in DISTANCES},
                    arm,
                )
    return table
