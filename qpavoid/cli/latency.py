"""``qpavoid latency``: a camera's latency measured from a recording of the robot's own flange
(:mod:`qpavoid.sensing.latency`).

    qpavoid latency --camera-recording FILE --arm-log FILE [--robot NAME|PATH]
                    [--sensors TOML [--sensor NAME]] [--landmark right_hand] [--max-lag S]

Like :mod:`qpavoid.cli.commands` it parses, calls the library and prints; it writes nothing.
"""

from __future__ import annotations

import argparse

from qpavoid.arm.model import load_robot
from qpavoid.cli.args import HelpFormatter, add_robot_option
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.hand_track import LANDMARKS
from qpavoid.sensing.latency import measure_latency
from qpavoid.sensing.latency_fit import LatencyConfig, LatencyEstimate

__all__ = ["add_latency_command", "format_estimate", "latency_command"]


def add_latency_command(sub: argparse._SubParsersAction) -> None:
    """Add ``latency`` to the ``qpavoid`` sub-commands."""
    latency = sub.add_parser(
        "latency",
        formatter_class=HelpFormatter,
        help="measure a camera's latency from a recording of the robot's flange",
        description="Fit the lag between a camera's recording of a hand holding the robot's "
        "flange and the arm's log of its joint angles over the same time, on one clock "
        "(docs/sensors.md §10, 'Measuring your camera's latency'); print it, its "
        "uncertainty and the --latency to run with. Writes nothing.",
    )
    latency.add_argument(
        "--camera-recording",
        required=True,
        metavar="FILE",
        help="the camera's frames (NPZ or CSV, docs/formats.md), each stamped when it "
        "reached the program that recorded it: a base-frame recording, or a per-sensor one "
        "with --sensors",
    )
    latency.add_argument(
        "--arm-log",
        required=True,
        metavar="FILE",
        help="the arm's joint angles on the same clock: NPZ t, q (a run's log.npz, "
        "examples/latency_excitation.py's) or CSV t,<joint>,... of the robot's active joints",
    )
    add_robot_option(latency)
    latency.add_argument(
        "--sensors",
        metavar="TOML",
        help="the sensors' calibration, for a per-sensor recording (docs/sensors.md §1)",
    )
    latency.add_argument(
        "--sensor",
        metavar="NAME",
        help="which sensor of a per-sensor recording of several (default: its only one)",
    )
    latency.add_argument(
        "--landmark",
        choices=LANDMARKS,
        default=LatencyConfig.landmark,
        metavar="NAME",
        help=f"the landmark of the hand that held the flange: {', '.join(LANDMARKS)}",
    )
    latency.add_argument(
        "--max-lag",
        type=float,
        default=LatencyConfig.max_lag_s,
        metavar="S",
        help="the largest lag searched, s",
    )
    latency.set_defaults(parser=latency, handler=latency_command)


def latency_command(args: argparse.Namespace) -> str:
    """``qpavoid latency``: read, fit, print (:func:`~qpavoid.sensing.latency.measure_latency`)."""
    config = LatencyConfig(landmark=args.landmark, max_lag_s=args.max_lag)
    calibration = load_calibration(args.sensors) if args.sensors else None
    robot = load_robot(args.robot)
    estimate = measure_latency(
        args.camera_recording, args.arm_log, robot, calibration, args.sensor, config
    )
    return format_estimate(estimate)


def format_estimate(estimate: LatencyEstimate) -> str:
    """Three lines: the latency and its uncertainty, how well the hand followed the flange,
    the ``--latency`` to use."""
    e = estimate
    hand = e.landmark.replace("_", " ")
    left_out = f", {e.outliers} left out as outliers" if e.outliers else ""
    return (
        f"camera latency {e.latency_s * 1e3:.1f} ms ± {e.uncertainty_s * 1e3:.1f} ms (one "
        f"standard error), from {e.frames} frames of the {hand}{left_out}\n"
        f"the {hand} followed the flange within {e.residual_m * 1e3:.1f} mm RMS "
        f"({e.explained:.0%} of its motion explained; the flange moved "
        f"{e.motion_m * 1e3:.0f} mm RMS)\n"
        f"use --latency {e.suggested_latency_s:.3f} (the estimate plus two standard errors, "
        "rounded up to the millisecond; frames stamped on arrival, docs/sensors.md §10)"
    )
