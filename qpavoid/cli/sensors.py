"""The sensor commands of ``qpavoid``: ``fuse`` (offline), ``replay`` (streams over UDP)
and ``keygen`` (a sensor's key file).

    qpavoid fuse A.npz B.npz --sensors calib.toml --out fused.npz
    qpavoid replay A.npz B.npz --to HOST:PORT --sensors calib.toml [--rate 30]
    qpavoid keygen SENSOR --out SENSOR.key [--rotate]

Like :mod:`qpavoid.cli.commands` they parse, call the library and print.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from qpavoid.cli.args import HelpFormatter, positive_float
from qpavoid.core.errors import InputError
from qpavoid.fusion.offline import fuse_recordings, save_fused_npz
from qpavoid.loop.live_input import parse_address
from qpavoid.output.run_files import check_output_dir, check_output_file
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.keys import new_key_file, sensor_name_error
from qpavoid.sensing.per_sensor import load_sensor_recording
from qpavoid.sensing.streamer import stream

__all__ = ["add_sensor_commands", "fuse_command", "keygen_command", "replay_command"]


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
