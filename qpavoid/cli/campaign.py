"""``qpavoid sweep``: a randomized safety campaign, on local processes or on Ray.

    qpavoid sweep --n N --controller analytic|qp [--distance ...] [--safety ...] [--seed S]
                  [--motion strikes|closework] [--robot NAME|PATH] [--camera FORMAT] [--payload KG]
                  [--latency S] [--workers W] [--executor local|ray] --out DIR

Like :mod:`qpavoid.cli.commands` it parses, calls the library and prints.
"""

from __future__ import annotations

import argparse
from concurrent.futures import Executor

from qpavoid.cli.args import (
    HelpFormatter,
    add_camera_option,
    add_payload_option,
    add_robot_option,
    count,
    folder,
    positive_float,
    whole_number,
    workers,
)
from qpavoid.control.tick import SAFETY_MODES
from qpavoid.experiments.campaign import (
    CAMPAIGN_MAX_TIME_S,
    MAX_RUNS,
    MOTIONS,
    RayExecutor,
    campaign_spec,
    run_campaign,
    write_campaign,
)
from qpavoid.experiments.run_spec import CONTROLLERS, DISTANCE_METHODS
from qpavoid.output.run_files import check_output_dir, strict_json

__all__ = ["add_campaign_command", "sweep_command"]

EXECUTORS = ("local", "ray")


def add_campaign_command(sub: argparse._SubParsersAction) -> None:
    """Add ``sweep`` to the ``qpavoid`` sub-commands."""
    sweep = sub.add_parser(
        "sweep",
        formatter_class=HelpFormatter,
        help="randomized safety campaign: strikes or close work judged against the truth",
        description="Run N randomized strikes (hands into every robot set at up to 2 m/s, "
        "with sensor faults; docs/safety.md) or close-work cases (--motion closework) "
        "along the whole path, judged against the true motion; write summary.json, "
        "runs.json and the worst runs into --out.",
    )
    sweep.add_argument("--n", type=whole_number(1, MAX_RUNS), required=True, help="number of runs")
    sweep.add_argument("--controller", choices=CONTROLLERS, required=True)
    sweep.add_argument("--distance", choices=DISTANCE_METHODS, default=DISTANCE_METHODS[0])
    sweep.add_argument(
        "--safety",
        choices=SAFETY_MODES,
        default="ssm",
        help="ssm: ISO/TS 15066 speed and separation on top of the paper's rules; pfl: "
        "speed and separation for the head and trunk, transient contact within Annex A's "
        "limits for the arms and hands; paper: the paper's rules alone",
    )
    sweep.add_argument("--seed", type=count, default=0, help="seed of the first run")
    sweep.add_argument(
        "--motion",
        choices=tuple(MOTIONS),
        default="strikes",
        help="strikes: hands driven into the robot at up to 2 m/s with sensor faults, each "
        f"run until the goal or {CAMPAIGN_MAX_TIME_S:g} s; closework: the seated operator "
        "working within reach of the path, never at the robot (hands resting or working "
        "0.1-0.3 m from it, reaching across it, handing over a part: scenario "
        "closework:SEED) on a clean camera, each run until the goal or the path's "
        "duration and 15 s more, summed up for productivity too (reaching the goal, "
        "time to it, time stopped, per variant)",
    )
    sweep.add_argument(
        "--workers", type=workers, default=None, metavar="W", help="processes (default: all cores)"
    )
    sweep.add_argument("--executor", choices=EXECUTORS, default="local")
    add_robot_option(sweep)
    add_camera_option(sweep)
    add_payload_option(sweep)
    sweep.add_argument(
        "--latency",
        type=positive_float,
        default=None,
        metavar="S",
        help="the camera's latency, s (default: its format file's)",
    )
    sweep.add_argument("--out", type=folder, required=True, metavar="DIR", help="output folder")
    sweep.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    sweep.set_defaults(parser=sweep, handler=sweep_command)


def sweep_command(args: argparse.Namespace) -> str:
    """``qpavoid sweep``: check, run, write, print the summary."""
    out = check_output_dir(args.out)
    spec = campaign_spec(
        args.controller,
        args.distance,
        args.safety,
        robot=args.robot,
        camera=args.camera,
        latency_s=args.latency,
        motion=args.motion,
        payload_kg=args.payload,
    )
    executor: Executor | None = RayExecutor(args.workers) if args.executor == "ray" else None
    try:
        runs = run_campaign(
            spec,
            args.n,
            args.seed,
            workers=args.workers,
            executor=executor,
            progress=not args.quiet,
        )
    finally:  # a local Ray goes with the campaign, however it ends
        if executor is not None:
            executor.shutdown()
    summary = write_campaign(out, spec, args.n, args.seed, runs)
    shown = {k: v for k, v in summary.items() if k != "settings"}
    return f"{strict_json(shown, indent=1)}\nwrote summary.json, runs.json and worst/ to {out}/"
