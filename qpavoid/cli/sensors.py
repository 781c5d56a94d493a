"""The sensor commands of ``qpavoid``: ``fuse`` (offline), ``replay`` (streams over UDP),
``send`` (a simulated sensor of any format, over UDP) and ``keygen`` (a sensor's key file).

    qpavoid fuse A.npz B.npz --sensors calib.toml --out fused.npz
    qpavoid replay A.npz B.npz --to HOST:PORT --sensors calib.toml [--rate 30]
    qpavoid send SENSOR --to HOST:PORT --sensors calib.toml [--scenario NAME | --human FILE]
    qpavoid keygen SENSOR --out SENSOR.key [--rotate]

Like :mod:`qpavoid.cli.commands` they parse, call the library and print.
"""

from __future__ import annotations

import argparse
import socket
from pathlib import Path

import numpy as np

from qpavoid.arm.model import load_robot
from qpavoid.cli.args import HelpFormatter, add_robot_option, count, positive_float
from qpavoid.control.task import default_task
from qpavoid.core.checks import check_range, is_loopback
from qpavoid.core.errors import InputError
from qpavoid.experiments.run_spec import task_option
from qpavoid.fusion.offline import fuse_recordings, save_fused_npz
from qpavoid.human.frames import HumanMotion
from qpavoid.human.landmarks import FORMAT_NAMES
from qpavoid.loop.live_input import parse_address
from qpavoid.loop.sender import AtRest, send, sensor_frames, sensor_latency_s
from qpavoid.output.run_files import check_output_dir, check_output_file
from qpavoid.scenarios.generated import check_scenario_name
from qpavoid.scenarios.motions import load_motion
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.keys import new_key_file, sensor_name_error
from qpavoid.sensing.per_sensor import (
    SensorRecording,
    is_sensor_recording,
    load_sensor_recording,
)
from qpavoid.sensing.streamer import stream

__all__ = [
    "add_sensor_commands",
    "fuse_command",
    "keygen_command",
    "replay_command",
    "send_command",
]

#: How long ``qpavoid send`` sends a generated motion by default, s: the paper's Test 1
#: (its hand back at rest after 14 s) and some.
SEND_SECONDS = 20.0
#: The longest it sends, s: a day.
MAX_SEND_SECONDS = 86_400.0


def add_sensor_commands(sub: argparse._SubParsersAction) -> None:
    """Add ``fuse``, ``replay`` and ``keygen`` to the ``qpavoid`` sub-commands."""
    fmt = HelpFormatter
    fuse = sub.add_parser(
        "fuse",
        formatter_class=fmt,
        help="fuse per-sensor recordings into one base-frame recording",
        description="Fuse per-sensor recordings (joints in each camera's frame, "
        "docs/formats.md) into one base-frame recording per person, with a per-joint "
        "confidence (docs/sensors.md).",
    )
    fuse.add_argument("files", nargs="+", metavar="FILE", help="per-sensor recordings")
    fuse.add_argument(
        "--sensors", required=True, metavar="TOML", help="the sensors' calibration file"
    )
    fuse.add_argument(
        "--out", default="fused.npz", metavar="FILE", help="the fused recording (NPZ)"
    )
    fuse.set_defaults(parser=fuse, handler=fuse_command)

    replay = sub.add_parser(
        "replay",
        formatter_class=fmt,
        help="stream per-sensor recordings over UDP, as live sensors would",
        description="Send per-sensor recordings as UDP datagrams in the wire format of "
        "docs/sensors.md, paced in real time, to a 'qpavoid run --listen', each signed with "
        "its sensor's key (the calibration's key files, docs/security.md).",
    )
    replay.add_argument("files", nargs="+", metavar="FILE", help="per-sensor recordings")
    replay.add_argument("--to", required=True, metavar="HOST:PORT", help="where to send")
    replay.add_argument(
        "--sensors",
        metavar="TOML",
        help="the sensors' calibration: their keys sign the datagrams, their clock offsets "
        "set the order",
    )
    replay.add_argument(
        "--unsigned",
        action="store_true",
        help="send unsigned (version 1) datagrams, for a listener that accepts them "
        "(--allow-unauthenticated, loopback only)",
    )
    replay.add_argument(
        "--rate",
        type=positive_float,
        default=30.0,
        metavar="HZ",
        help="frames per second of each sensor (the recordings' own times set the order)",
    )
    replay.set_defaults(parser=replay, handler=replay_command)

    send_parser = sub.add_parser(
        "send",
        formatter_class=fmt,
        help="be a sensor of any format: stream a simulated camera's frames over UDP",
        description="Play a calibrated sensor for a 'qpavoid run --listen': the seated "
        "operator at rest (or --scenario, or --human) filmed by the simulated camera of the "
        "sensor's format (its joints, noise, rate), in the sensor's own frame (its "
        "base_from_camera inverted), each frame sent when the camera would deliver it, "
        "stamped with its capture time (the send time less the camera's latency) and signed "
        "with the sensor's key (docs/sensors.md §7, §11).",
    )
    send_parser.add_argument("sensor", metavar="SENSOR", help="the sensor's name in --sensors")
    send_parser.add_argument("--to", required=True, metavar="HOST:PORT", help="where to send")
    send_parser.add_argument(
        "--sensors",
        required=True,
        metavar="TOML",
        help="the calibration: the sensor's place, format and key file",
    )
    send_parser.add_argument(
        "--camera",
        metavar="FORMAT",
        help="the sensor's skeleton format, if you want it checked: it must be the one the "
        f"calibration names for SENSOR (one of {', '.join(FORMAT_NAMES)}; default: that one)",
    )
    what = send_parser.add_mutually_exclusive_group()
    what.add_argument(
        "--scenario",
        metavar="NAME",
        help="a scenario's motion instead of the operator at rest: test1 (the paper's hand "
        "motion), test2, free, random:SEED, closework:SEED, ... (qpavoid run --help)",
    )
    what.add_argument(
        "--human",
        metavar="FILE",
        help="a recording instead: a base-frame one (docs/formats.md), filmed by the "
        "simulated camera, or a per-sensor one holding SENSOR's frames, sent as recorded "
        "(as qpavoid replay does, stamped with the latency)",
    )
    add_robot_option(send_parser)
    send_parser.add_argument(
        "--task",
        metavar="FILE",
        help="a task file (docs/tasks.md): the operator sits at its [operator] seat and a "
        "scenario runs along its path, as in 'qpavoid run --task FILE' (give both the same)",
    )
    send_parser.add_argument(
        "--latency",
        type=float,
        metavar="S",
        help="the camera's latency, s: each frame is stamped this long before it is sent "
        "(default: the calibration's latency_s for SENSOR, else its format's; another plays "
        "a camera slower or faster than the listener's calibration says, and the start line "
        "says so)",
    )
    send_parser.add_argument(
        "--seconds",
        type=positive_float,
        metavar="S",
        help=f"how long to send, s (default: a recording's length, else {SEND_SECONDS:g})",
    )
    send_parser.add_argument(
        "--seed", type=count, default=0, metavar="N", help="the camera's noise seed"
    )
    send_parser.add_argument(
        "--unsigned",
        action="store_true",
        help="unsigned (version 1) datagrams, for a listener started with "
        "--allow-unauthenticated on loopback (a calibration without keys)",
    )
    send_parser.set_defaults(parser=send_parser, handler=send_command)

    keygen = sub.add_parser(
        "keygen",
        formatter_class=fmt,
        help="write a sensor's key file (256 bits, mode 0600)",
        description="Write a new key for a sensor into a key file readable by its owner "
        "only; name it in the calibration file (key_file) of the listener and of the "
        "sensor's sender. --rotate puts a new key first in an existing file and keeps the "
        "current one second, accepted until the next rotation (docs/security.md).",
    )
    keygen.add_argument("sensor", metavar="SENSOR", help="the sensor's name in the calibration")
    keygen.add_argument("--out", required=True, metavar="FILE", help="the key file to write")
    keygen.add_argument(
        "--rotate", action="store_true", help="add a new key to an existing key file"
    )
    keygen.set_defaults(parser=keygen, handler=keygen_command)


def fuse_command(args: argparse.Namespace) -> str:
    """``qpavoid fuse``: read, check, fuse, write; a one-paragraph summary."""
    out = Path(args.out)
    if out.suffix.lower() != ".npz":
        raise InputError(f"--out {str(out)!r}: the fused recording is an .npz file", name="--out")
    check_output_dir(out.parent if str(out.parent) else Path("."))
    if out.is_dir():
        raise InputError(f"--out {str(out)!r} is a folder, not a file", name="--out")
    if out.resolve() in [Path(f).resolve() for f in args.files]:
        raise InputError(f"--out {str(out)!r} is one of the recordings read", name="--out")
    check_distinct(args.files)
    calibration = load_calibration(args.sensors)
    recordings = [load_sensor_recording(f) for f in args.files]
    for rec in recordings:
        calibration.check_names(rec.sensors)
    fused = fuse_recordings(recordings, calibration)
    save_fused_npz(out, fused)
    seen = np.isfinite(fused.joints).all(axis=2)
    return (
        f"fused {sum(r.n_rows for r in recordings)} body frames of "
        f"{len({s for r in recordings for s in r.sensors})} sensors into "
        f"{len(np.unique(fused.t))} frames of {len(fused.ids)} "
        f"{'person' if len(fused.ids) == 1 else 'people'}; joints seen "
        f"{100 * seen.mean():.1f} %, mean confidence {fused.confidence[seen].mean():.2f}\n"
        f"wrote {out}"
    )


def check_distinct(files: list[str]) -> None:
    """:class:`InputError` if a recording is given twice (the same file by two names too)."""
    inputs = [Path(f).resolve() for f in files]
    if len(set(inputs)) < len(inputs):
        twice = next(str(f) for f in files if inputs.count(Path(f).resolve()) > 1)
        raise InputError(f"{twice!r} is given twice", name="files", value=twice)


def replay_command(args: argparse.Namespace) -> str:
    """``qpavoid replay``: stream recordings over UDP (:func:`qpavoid.sensing.streamer.stream`)."""
    address = parse_address(args.to, "--to")
    if not 1.0 <= args.rate <= 1000.0:
        raise InputError(f"--rate must be 1 to 1000 Hz, got {args.rate}", name="--rate")
    check_distinct(args.files)
    calibration = load_calibration(args.sensors) if args.sensors else None
    recordings = [load_sensor_recording(f) for f in args.files]
    if calibration is not None:
        for rec in recordings:
            calibration.check_names(rec.sensors)
    try:
        sent = stream(recordings, address, args.rate, calibration, unsigned=args.unsigned)
    except OSError as exc:
        raise InputError(
            f"cannot send to {args.to}: {exc.strerror or exc}", name="--to", value=args.to
        ) from None
    kind = "unsigned" if args.unsigned else "signed"
    return f"sent {sent} datagrams to {address[0]}:{address[1]} ({kind})"


def send_command(args: argparse.Namespace) -> str:
    """``qpavoid send``: every argument checked, one line on starting, the sensor played
    (:func:`qpavoid.loop.sender.send`), a summary."""
    address = parse_address(args.to, "--to")
    calibration = load_calibration(args.sensors)
    cal = calibration[args.sensor]  # CalibrationError: no such sensor (naming those there)
    if args.camera is not None and args.camera != cal.format:
        raise InputError(
            f"--camera {str(args.camera)[:80]!r}: sensor {args.sensor!r} is calibrated as "
            f"{cal.format} (the format key of {args.sensors}); its listener drops any other "
            "format (dropped_wrong_format)",
            name="--camera",
            value=args.camera,
        )
    check_signing(calibration, args.sensor, args.to, address[0], args.unsigned)
    latency = (
        sensor_latency_s(calibration, args.sensor)
        if args.latency is None
        else check_range("the latency (--latency)", args.latency, 0.0, 1.0, "s")
    )
    if args.seconds is not None:
        check_range("the time to send (--seconds)", args.seconds, 0.0, MAX_SEND_SECONDS, "s")
    try:  # the host resolved now: a name that does not resolve is refused before sending
        socket.getaddrinfo(address[0], address[1], type=socket.SOCK_DGRAM)
    except (OSError, UnicodeError) as exc:
        raise InputError(
            f"--to {args.to!r}: cannot resolve {address[0]!r} ({exc})", name="--to", value=args.to
        ) from None
    motion, what = send_motion(args, calibration)
    seconds = args.seconds
    if seconds is None and not isinstance(motion, SensorRecording):
        seconds = getattr(motion, "duration_s", SEND_SECONDS)  # a recording's, filmed
    frames = sensor_frames(motion, calibration, args.sensor, seconds, args.seed)
    kind = "unsigned" if args.unsigned else f"signed with its key (cell {calibration.cell!r})"
    where = f"{address[0]}:{address[1]}"
    span = "its length" if seconds is None else f"{seconds:g} s"
    expected = cal.latency_used_s  # what the listener of this calibration expects
    unlike = (
        ""
        if abs(latency - expected) < 1e-9
        else f" (a camera slower or faster than the calibration's {expected:.3f} s: its "
        f"listener takes frames up to {cal.age_limit_s:.3f} s old)"
    )
    print(
        f"sending {args.sensor} ({cal.format}, {cal.skeleton.sensor.frame_rate_hz:g} Hz, "
        f"latency {latency:.3f} s{unlike}: each frame stamped that long before it is sent) to "
        f"{where} for {span}: {what}, {kind}; Ctrl-C stops it",
        flush=True,
    )
    try:
        sent = send(
            frames, calibration, args.sensor, address, latency_s=latency, unsigned=args.unsigned
        )
    except OSError as exc:
        raise InputError(
            f"cannot send to {args.to}: {exc.strerror or exc}", name="--to", value=args.to
        ) from None
    bodies = f", {sent.bodies} bodies" if sent.bodies != sent.frames else ""
    return (
        f"sent {sent.frames} frames of {args.sensor} ({cal.format}{bodies}) to {where}: "
        f"{sent.datagrams} {'unsigned' if args.unsigned else 'signed'} datagrams, each "
        f"stamped {sent.latency_s:.3f} s before it was sent (the listener's summary says how "
        "many it took)"
    )


def check_signing(
    calibration: Calibration, sensor: str, to: str, host: str, unsigned: bool
) -> None:
    """:class:`InputError` for datagrams the listener of ``calibration`` would drop
    unread: unsigned ones of sensors that have keys, or sent off loopback; signed ones
    without keys."""
    where = calibration.path or "the calibration"
    if unsigned and calibration.authenticated:
        raise InputError(
            f"--unsigned: the sensors of {where} have keys, and a listener with it drops "
            "every unsigned datagram (dropped_unauthenticated): leave out --unsigned",
            name="--unsigned",
            value=True,
        )
    if unsigned and not is_loopback(host):
        raise InputError(
            f"--unsigned to {to}: a listener takes unsigned datagrams on loopback only "
            "(--allow-unauthenticated); sign them (qpavoid keygen, key_file)",
            name="--to",
            value=to,
        )
    if not unsigned and not calibration.authenticated:
        raise InputError(
            f"{where} gives {sensor!r} no key to sign with: give each sensor a key_file "
            f"(qpavoid keygen {sensor} --out {sensor}.key), or --unsigned for a listener "
            "with --allow-unauthenticated on loopback",
            name="--sensors",
            value=where,
        )


def send_motion(
    args: argparse.Namespace, calibration: Calibration
) -> tuple[HumanMotion | SensorRecording, str]:
    """What ``qpavoid send`` films (or sends as recorded) and how to say it: the seated
    operator at rest where the arm's task seats them, a scenario, or a recording."""
    if args.human is not None:
        if is_sensor_recording(args.human):
            rec = load_sensor_recording(args.human)
            return rec, f"{args.sensor}'s frames recorded in {args.human}"
        return load_motion(load_robot(args.robot), None, [args.human]), f"{args.human} filmed"
    robot = load_robot(args.robot)
    task = default_task(robot) if args.task is None else task_option(args.task, robot)
    seat = f"{robot.name}'s seat" if args.task is None else f"the seat of {args.task}"
    if args.scenario is not None:
        check_scenario_name(args.scenario)
        motion = load_motion(robot, args.scenario, task=task)
        return motion, f"scenario {args.scenario} ({robot.name}, {seat})"
    return AtRest(task.operator), f"the seated operator at rest ({seat})"


def keygen_command(args: argparse.Namespace) -> str:
    """``qpavoid keygen``: a new key file, or a rotated one
    (:func:`qpavoid.sensing.keys.new_key_file`)."""
    name = str(args.sensor)
    bad_name = sensor_name_error(name)
    if bad_name is not None:
        raise InputError(f"SENSOR {repr(name)[:80]}: {bad_name}", name="sensor", value=name)
    out = check_output_file(str(args.out), "--out")
    keys = new_key_file(out, name, rotate=args.rotate)
    ids = " and ".join(map(str, keys.ids))
    return (
        f"wrote {out}: key {keys.ids[0]} of sensor {name!r} signs"
        + (f", key {keys.ids[1]} still accepted" if len(keys.ids) > 1 else "")
        + f" (ids {ids}; mode 0600: keep it secret)"
    )
