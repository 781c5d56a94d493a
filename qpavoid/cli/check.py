"""``qpavoid check``: before the first motion, where the arm will stop beside its seated
operator (:mod:`qpavoid.experiments.cell_check`; exit 0 if nowhere, 1 if somewhere)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from qpavoid.cli.args import (
    HelpFormatter,
    Verdict,
    add_camera_option,
    add_robot_option,
    positive_float,
)
from qpavoid.control.tick import SAFETY_MODES
from qpavoid.experiments.cell_check import PHASES, CellCheck, Stretch, check_cell
from qpavoid.experiments.jobs import progress_bar
from qpavoid.experiments.run_spec import CONTROLLERS, RunSpec
from qpavoid.experiments.runs import spec_robot
from qpavoid.output.check_figure import check_figure
from qpavoid.output.plots import available
from qpavoid.output.run_files import check_output_dir, strict_json

__all__ = ["add_check_command"]


def add_check_command(sub: argparse._SubParsersAction) -> None:
    """Add ``check`` to the ``qpavoid`` sub-commands."""
    check = sub.add_parser(
        "check",
        formatter_class=HelpFormatter,
        help="before the first motion: where the arm will stop beside its seated operator",
        description="Follow the task's path beside its seated operator at work, as the "
        "camera at its latency sees them, and say each stretch where speed and separation "
        "(or the safety mode's stop rules) will stop the arm: the body part, by how much, "
        "between which waypoints, the latency at which it would pass and how far the seat "
        "or the waypoints must move. Exit 0 if the arm will not stop, 1 if it will. Writes "
        "check.json and check.png to --out. docs/safety.md §7c",
    )
    add_robot_option(check)
    check.add_argument(
        "--task",
        metavar="FILE",
        help="the task file: the path and the operator's seat (default: the arm's own, "
        "docs/tasks.md)",
    )
    add_camera_option(check)
    check.add_argument(
        "--latency",
        type=float,
        default=None,
        metavar="S",
        help="the camera's latency, s, as qpavoid latency measured it (default: its format's)",
    )
    check.add_argument(
        "--safety",
        choices=[m for m in SAFETY_MODES if m != "pfl"],
        default="ssm",
        help="the safety mode (default: ssm; pfl slows near hands instead of holding, which "
        "the check does not model)",
    )
    check.add_argument("--controller", choices=CONTROLLERS, default="analytic")
    check.add_argument(
        "--rate", type=positive_float, default=500.0, metavar="HZ", help="control rate, Hz"
    )
    check.add_argument("--out", metavar="DIR", help="where to write (default: runs/check-ROBOT)")
    check.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    check.set_defaults(handler=check_command)


def check_command(args: argparse.Namespace) -> Verdict:
    spec = RunSpec(
        scenario="free",
        robot=args.robot,
        task=args.task,
        camera=args.camera,
        latency_s=args.latency,
        safety=args.safety,
        controller=args.controller,
        rate_hz=args.rate,
    )
    out = Path(args.out or Path("runs") / f"check-{Path(args.robot).name}")
    check_output_dir(out)
    if not args.quiet:  # the check takes seconds: say what it does before the bar
        print(
            f"checking {Path(args.robot).name}'s task beside its seated operator, "
            f"{PHASES} phases of the operator's work ...",
            file=sys.stderr,
        )
    with progress_bar(PHASES, "cell check", "phase", not args.quiet) as bar:
        result = check_cell(spec, lambda done, _total: bar.update(done - bar.n))
    out.mkdir(parents=True, exist_ok=True)
    (out / "check.json").write_text(strict_json(as_json(result)) + "\n")
    lines = [describe_check(result)]
    if available():
        title = f"{spec_robot(spec).name}: {spec.camera} at {spec.sensor_latency_s:.3f} s"
        check_figure(
            out / "check.png",
            result.times_s,
            result.clearance_m,
            result.needed_m,
            [(s.start_s, s.end_s) for s in result.stretches],
            result.waypoint_times_s.tolist(),
            title,
        )
        lines.append(f"wrote check.json and check.png to {out}/")
    else:
        lines.append(f"wrote check.json to {out}/ (the figure needs matplotlib)")
    return Verdict("\n".join(lines), 1 if result.stops else 0)


def describe_check(c: CellCheck) -> str:
    spec = c.spec
    head = (
        f"cell check: {spec.robot} on {spec.task or 'its own task'}, {spec.camera} at "
        f"{spec.sensor_latency_s:.3f} s (frames up to {c.frame_age_s:.3f} s old), "
        f"safety {spec.safety}, {spec.controller} controller"
    )
    if not c.stretches:
        spare = c.clearance_m - c.needed_m
        if np.isfinite(spare).any():
            k = int(np.nanargmin(spare))
            closest = f"{spare[k]:.3f} m to spare at path time {c.times_s[k]:.2f} s, the "
        else:
            k = int(c.clearance_m.argmin())
            closest = f"at path time {c.times_s[k]:.2f} s, the "
        return (
            f"{head}\n  the arm will not stop for the still operator: the nearest it comes "
            f"is {closest}clearance {c.clearance_m[k]:.3f} m"
        )
    n = len(c.stretches)
    lines = [f"{head}\n  the arm will stop for the still operator on {n} stretch(es):"]
    lines += [f"  {k + 1}. {_stretch_line(s)}" for k, s in enumerate(c.stretches)]
    return "\n".join(lines)


def _stretch_line(s: Stretch) -> str:
    where = (
        f"path time {s.start_s:.2f}-{s.end_s:.2f} s (between waypoints {s.waypoints[0]} "
        f"and {s.waypoints[1]})"
    )
    if s.reason:
        return f"{where}: {s.reason}"
    latency = (
        f"passes at a latency of {s.passing_latency_s:.3f} s or less"
        if s.passing_latency_s is not None
        else "passes at no latency"
    )
    return (
        f"{where}: the operator's {s.part} comes within {s.clearance_m:.3f} m of robot link "
        f"'{s.link}', {s.shortfall_m:.3f} m short of the {s.needed_m:.3f} m it needs; "
        f"{latency}, or with the seat (or the waypoints) {s.shortfall_m:.3f} m further "
        f"apart: the operator moved towards ({s.away[0]:+.2f}, {s.away[1]:+.2f}) in the "
        "base frame's xy"
    )


def as_json(c: CellCheck) -> dict:
    """check.json: the spec, the frame age counted, each stretch."""
    return {
        "robot": c.spec.robot,
        "task": c.spec.task,
        "camera": c.spec.camera,
        "latency_s": c.spec.sensor_latency_s,
        "frame_age_s": c.frame_age_s,
        "safety": c.spec.safety,
        "controller": c.spec.controller,
        "stops": c.stops,
        "stretches": [
            {
                "start_s": s.start_s,
                "end_s": s.end_s,
                "waypoints": list(s.waypoints),
                "part": s.part,
                "link": s.link,
                "clearance_m": s.clearance_m,
                "needed_m": s.needed_m,
                "shortfall_m": s.shortfall_m,
                "passing_latency_s": s.passing_latency_s,
                "away_xy": s.away.tolist(),
                "reason": s.reason,
            }
            for s in c.stretches
        ],
        "tightest_clearance_m": float(c.clearance_m.min()),
    }
