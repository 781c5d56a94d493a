"""The ``qpavoid`` command line: it parses, calls the library and prints, nothing more.

    qpavoid run SCENARIO [--controller analytic|qp] [--distance capsules|capsules-coal|spheres]
                         [--safety paper|ssm] [--bench real|ideal] [--task FILE] [--out DIR]
    qpavoid run --human FILE [...]
    qpavoid run --human A.npz B.npz --sensors calib.toml [...]
    qpavoid run --listen HOST:PORT --sensors calib.toml --out DIR [...]
    qpavoid compare [--scenarios NAME ...] [--human FILE ...] [--random N] [--out DIR]
    qpavoid fuse A.npz B.npz --sensors calib.toml --out fused.npz
    qpavoid replay A.npz B.npz --to HOST:PORT [--rate 30]
    qpavoid latency --camera-recording FILE --arm-log FILE [--robot NAME] [--sensors calib.toml]
    qpavoid sweep --n N --controller analytic|qp [--executor local|ray] --out DIR
    qpavoid bench [--json FILE] [--quick]
    qpavoid robot fit URDF --out DIR | qpavoid robot check NAME|PATH

Every argument is checked before any work starts; every failure is one line
``qpavoid: error: ...`` on standard error with exit status 2 (130 when interrupted),
never a traceback (``QPAVOID_DEBUG=1`` shows one for an internal error).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Sequence
from pathlib import Path

from qpavoid.arm._kernels import frame_jacobians
from qpavoid.cli.args import (
    HelpFormatter,
    Parser,
    add_camera_option,
    add_payload_option,
    add_robot_option,
    count,
    folder,
    package_version,
    positive_float,
    run_command,
    whole_number,
    workers,
)
from qpavoid.cli.bench import add_bench_command
from qpavoid.cli.campaign import add_campaign_command
from qpavoid.cli.check import add_check_command
from qpavoid.cli.latency import add_latency_command
from qpavoid.cli.robot import add_robot_command
from qpavoid.cli.sensors import add_sensor_commands
from qpavoid.cli.view import add_view_command
from qpavoid.control.qp.one_pass import standard_problem
from qpavoid.control.tick import SAFETY_MODES
from qpavoid.core.compiling import cold
from qpavoid.distance._kernels import capsule_table
from qpavoid.experiments.compare import compare
from qpavoid.experiments.jobs import progress_bar
from qpavoid.experiments.reproduce import reproduce_bag
from qpavoid.experiments.run_spec import BENCHES, CONTROLLERS, DISTANCE_METHODS, LIMIT_MODES
from qpavoid.experiments.runs import RunSpec, live_view, run_one, spec_robot
from qpavoid.human._kernels import tracked_body
from qpavoid.loop.live_input import check_listening, parse_address
from qpavoid.loop.metrics import describe
from qpavoid.output.bag_writer import check_bag_path, write_run_bag
from qpavoid.output.run_files import check_output_dir
from qpavoid.scenarios.generated import SCENARIOS
from qpavoid.scenarios.motions import check_inputs
from qpavoid.sensing.bags import has_run, is_bag
from qpavoid.sensing.calibration_file import load_calibration

DESCRIPTION = (
    "Collision avoidance between a cobot arm and the person beside it: simulate the "
    "paper's controller or its QP variant against generated or recorded human motion."
)


def build_parser() -> Parser:
    """The ``qpavoid`` argument parser."""
    fmt = HelpFormatter
    parser = Parser(prog="qpavoid", description=DESCRIPTION, formatter_class=fmt)
    parser.add_argument("--version", action="version", version=f"qpavoid {package_version()}")
    sub = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", parser_class=Parser
    )

    run = sub.add_parser(
        "run",
        help="simulate one scenario or recording",
        formatter_class=fmt,
        description="Simulate the robot against one scenario or recording and "
        "write metrics.json, log.npz and the figures into --out.",
    )
    run.add_argument(
        "scenario",
        nargs="?",
        metavar="SCENARIO",
        help=f"{', '.join(SCENARIOS)}, random:SEED or closework:SEED (or give --human FILE)",
    )
    run.add_argument(
        "--human",
        nargs="+",
        metavar="FILE",
        help="replay a recording (NPZ or CSV, docs/formats.md) instead of a scenario; "
        "with --sensors, per-sensor recordings, fused",
    )
    run.add_argument(
        "--listen",
        metavar="HOST:PORT",
        help="drive the simulated robot in real time from live skeletons on UDP "
        "(docs/sensors.md), or ros2:CELL.toml from the cameras' ROS 2 topics (docs/ros2.md, "
        "with --trust-ros-graph), with --sensors; Ctrl-C ends the run and writes it",
    )
    run.add_argument(
        "--trust-ros-graph",
        action="store_true",
        help="take input from a ROS 2 graph (--listen ros2:, --arm ros2:), where anyone on "
        "the DDS domain can publish: fence the domain first (docs/security.md)",
    )
    run.add_argument(
        "--arm",
        metavar="ARM",
        help="drive an arm in real time: sim (the simulated arm on the wall clock), "
        "franka:HOST (an FR3, or franky-sim, through franky-control: pip install "
        '"qpavoid[franka]") or panda:HOST (a Panda through panda-python: pip install '
        '"qpavoid[panda]"), or ros2:CELL.toml (an arm under ros2_control, docs/ros2.md, '
        "with --trust-ros-graph); an arm that is not the --robot is refused "
        "(docs/real-robot.md); "
        "Ctrl-C ramps it to rest and writes the run",
    )
    run.add_argument(
        "--sensors",
        metavar="TOML",
        help="calibration of the sensors (docs/sensors.md), for per-sensor --human files "
        "or --listen (with key files: docs/security.md)",
    )
    run.add_argument(
        "--allow-unauthenticated",
        action="store_true",
        help="with --listen on a loopback address only: also accept unsigned (version 1) "
        "datagrams, which anybody who can send to the port could forge",
    )
    for flag, choices, help_text in (
        ("--controller", CONTROLLERS, "the paper's controller or its QP variant"),
        (
            "--distance",
            DISTANCE_METHODS,
            "exact capsules (cover the shoulder; capsules-coal: the same by coal) or the "
            "paper's spheres",
        ),
        (
            "--safety",
            SAFETY_MODES,
            "the paper's rules; ISO/TS 15066 SSM on top of them; or SSM for the head and "
            "trunk with power and force limiting (transient contact within Annex A's "
            "limits) for the arms and hands (docs/safety.md)",
        ),
        (
            "--bench",
            BENCHES,
            "real: camera latency and noise, the arm's braking; ideal: the paper's",
        ),
        ("--limit-mode", LIMIT_MODES, "analytic only: enforce eq. (3) by scaling or clipping"),
    ):
        run.add_argument(flag, choices=choices, default=choices[0], help=help_text)
    add_camera_option(run, with_sensors=True)
    add_payload_option(run)
    run.add_argument(
        "--latency",
        type=float,
        default=None,
        metavar="S",
        help="the camera's latency, s (default: the camera's, from its format file); "
        "with --sensors, of each sensor whose calibration names no latency_s: a frame "
        "older than the latency + a frame + 6.7 ms is refused, and stops the robot",
    )
    run.add_argument(
        "--solver",
        metavar="NAME",
        help="QP only: a qpsolvers solver (osqp, daqp, ...); default: persistent OSQP",
    )
    run.add_argument(
        "--redundant",
        action="store_true",
        help="QP only: free the joints the robot description locks and keep the elbow away "
        "from the person",
    )
    run.add_argument(
        "--task",
        metavar="FILE",
        help="a task file (TOML, docs/tasks.md): the waypoints the robot follows and where "
        "the operator sits, instead of the robot description's task.toml",
    )
    run.add_argument("--out", type=folder, metavar="DIR", help="output folder (default: runs/NAME)")
    run.add_argument(
        "--bag",
        metavar="FILE.mcap",
        help="also write the run as a ROS 2 bag: joint states, commands, the people's markers "
        'and diagnostics (docs/ros2.md; pip install "qpavoid[ros2]")',
    )
    run.add_argument(
        "--view",
        nargs="?",
        const="127.0.0.1:0",
        metavar="HOST:PORT",
        help="follow the run in a browser as it happens: serve a live view on localhost "
        "(any free port unless given) and print its address",
    )
    _add_common(run)
    run.set_defaults(parser=run)

    cmp = sub.add_parser(
        "compare",
        formatter_class=fmt,
        help="analytic vs QP, spheres vs capsules, on the same inputs",
        description="Run every input with both controllers and both distance "
        "methods; write compare.json, compare.md and one plot "
        "per input into --out.",
    )
    cmp.add_argument(
        "--out", type=folder, metavar="DIR", default="runs/compare", help="output folder"
    )
    cmp.add_argument(
        "--scenarios",
        nargs="*",
        metavar="NAME",
        default=["test1", "test2", "free"],
        help="generated scenarios",
    )
    cmp.add_argument(
        "--human", nargs="*", default=[], metavar="FILE", help="recordings to replay too"
    )
    cmp.add_argument(
        "--random",
        type=whole_number(0, 10_000),  # each run keeps its log for the plots
        default=0,
        metavar="N",
        help="also N random hand approaches (seeds SEED .. SEED+N-1)",
    )
    cmp.add_argument("--seed", type=count, default=0, help="first seed of --random")
    cmp.add_argument(
        "--workers",
        type=workers,
        default=None,
        metavar="N",
        help="parallel processes (default: all cores)",
    )
    add_camera_option(cmp)
    _add_common(cmp)
    cmp.set_defaults(parser=cmp)
    add_sensor_commands(sub)
    add_latency_command(sub)
    add_check_command(sub)
    add_campaign_command(sub)
    add_bench_command(sub)
    add_view_command(sub)
    add_robot_command(sub)
    return parser


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--max-time",
        type=positive_float,
        default=40.0,
        metavar="S",
        help="cap on each run, s (0.1 to 3600)",
    )
    p.add_argument(
        "--rate",
        type=positive_float,
        default=500.0,
        metavar="HZ",
        help="control rate, Hz (30 to 10000)",
    )
    p.add_argument(
        "--goal-tolerance",
        type=positive_float,
        default=1e-3,
        metavar="M",
        help="the goal counts as reached within this end-effector error, m",
    )
    p.add_argument("--no-plots", action="store_true", help="do not write the figures")
    p.add_argument(
        "--no-view", action="store_true", help="do not write the browser replay (replay.html)"
    )
    add_robot_option(p)
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")


def _run(args: argparse.Namespace, parser: Parser) -> str:
    if args.scenario and args.human:
        parser.error("give either SCENARIO or --human FILE, not both")
    files = tuple(args.human or ())
    if len(files) == 1 and not args.sensors and is_bag(files[0]) and has_run(files[0]):
        return reproduce_bag(files[0]).line(files[0])  # a run qpavoid wrote: given again
    spec = RunSpec(
        scenario=args.scenario,
        human_file=files[0] if files and not args.sensors else None,
        sensor_files=files if args.sensors else (),
        sensors=args.sensors,
        listen=args.listen,
        allow_unauthenticated=args.allow_unauthenticated,
        trust_ros_graph=args.trust_ros_graph,
        arm=args.arm,
        controller=args.controller,
        distance=args.distance,
        safety=args.safety,
        bench=args.bench,
        latency_s=args.latency,
        camera=args.camera,
        max_time_s=args.max_time,
        rate_hz=args.rate,
        limit_mode=args.limit_mode,
        robot=args.robot,
        solver=args.solver,
        redundant=args.redundant,
        goal_tolerance_m=args.goal_tolerance,
        payload_kg=args.payload,
        task=args.task,
    )
    out = Path(args.out or Path("runs") / spec.label.replace(":", "-"))
    check_output_dir(out)
    if args.bag:
        check_bag_path(args.bag)
    if args.listen and args.listen.startswith("ros2:"):  # checked by RunSpec (cell, trust)
        load_calibration(args.sensors)
    elif args.listen:  # a bad file, a missing key, unsigned off loopback: before the run
        check_listening(
            parse_address(args.listen), load_calibration(args.sensors), spec.allow_unauthenticated
        )
    else:
        check_inputs(files, args.sensors)
    with contextlib.ExitStack() as stack:
        watch, clear = None, None
        if args.view is not None:
            live = stack.enter_context(live_view(spec, args.view))
            print(f"live view: {live.url} (open it in a browser)", flush=True)
            watch, clear = live.update, live.clear_requested
        bar = stack.enter_context(progress_bar(spec.max_time_s, spec.label, "s", not args.quiet))

        def advance(t: float) -> None:
            bar.update(t - bar.n)

        def say(line: str) -> None:  # a live run's lines, above the progress bar
            bar.write(line, file=sys.stdout)
            sys.stdout.flush()

        m = run_one(
            spec,
            out,
            plots=not args.no_plots,
            progress=advance,
            view=not args.no_view,
            watch=watch,
            clear=clear,
            say=say,
        )
    lines = [describe(m)]
    for what in ("plots", "view"):
        if m.get(f"{what}_skipped"):
            lines.append(
                f"  {'figures' if what == 'plots' else 'replay'} skipped: {m[f'{what}_skipped']}"
            )
    written = ["metrics.json", "log.npz"] + [f"{len(m['plots'])} figures"] * bool(m["plots"])
    written += ["replay.html (open it in a browser)"] * bool(m.get("view"))
    lines.append(f"wrote {', '.join(written[:-1])} and {written[-1]} to {out}/")
    if args.bag:
        counts = write_run_bag(args.bag, out, spec_robot(spec))
        n = sum(counts.values())
        lines.append(f"wrote the bag {args.bag} ({n} messages on {len(counts)} topics)")
    return "\n".join(lines)


def _compare(args: argparse.Namespace) -> str:
    table = compare(
        args.out,
        args.scenarios,
        args.human,
        args.random,
        args.seed,
        args.max_time,
        args.rate,
        not args.no_plots,
        args.robot,
        workers=args.workers,
        progress=not args.quiet,
        view=not args.no_view,
        camera=args.camera,
    )
    written = ["compare.json", "compare.md"] + ["the plots"] * (not args.no_plots)
    written += ["the replays"] * (not args.no_view)
    return f"{table}\nwrote {', '.join(written[:-1])} and {written[-1]} to {args.out}/"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status (:func:`~qpavoid.cli.args.run_command`)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if cold(capsule_table, standard_problem, frame_jacobians, tracked_body):
        print(
            "qpavoid: compiling its kernels for this install (once, about 30 s; later runs "
            "load them from the disk cache)",
            file=sys.stderr,
            flush=True,
        )
    if args.command == "run":
        return run_command(lambda: _run(args, args.parser))
    if args.command == "compare":
        return run_command(lambda: _compare(args))
    return run_command(lambda: args.handler(args))


if __name__ == "__main__":
    sys.exit(main())
