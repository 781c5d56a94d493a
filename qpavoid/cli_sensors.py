"""The sensor commands of ``qpavoid``: ``fuse`` (offline) and ``replay`` (streams over UDP).

    qpavoid fuse A.npz B.npz --sensors calib.toml --out fused.npz
    qpavoid replay A.npz B.npz --to HOST:PORT [--rate 30]

Like :mod:`qpavoid.cli` they parse, call the library and print.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .calibration import load_calibration
from .cli_args import HelpFormatter, positive_float
from .errors import InputError
from .fused import fuse_recordings, save_fused_npz
from .io import check_output_dir
from .live import parse_address, replay
from .sensor_recording import load_sensor_recording

__all__ = ["add_sensor_commands", "fuse_command"]


def add_sensor_commands(sub: argparse._SubParsersAction) -> None:
    """Add ``fuse`` and ``replay`` to the ``qpavoid`` sub-commands."""
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
        "docs/sensors.md, paced in real time, to a 'qpavoid run --listen'.",
    )
    replay.add_argument("files", nargs="+", metavar="FILE", help="per-sensor recordings")
    replay.add_argument("--to", required=True, metavar="HOST:PORT", help="where to send")
    replay.add_argument(
        "--sensors",
        metavar="TOML",
        help="the sensors' calibration: their clock offsets set the order (default: none)",
    )
    replay.add_argument(
        "--rate",
        type=positive_float,
        default=30.0,
        metavar="HZ",
        help="frames per second of each sensor (the recordings' own times set the order)",
    )
    replay.set_defaults(parser=replay, handler=replay_command)


def fuse_command(args: argparse.Namespace) -> str:
    """``qpavoid fuse``: read, check, fuse, write; a one-paragraph summary."""
    out = Path(args.out)
    if out.suffix.lower() != ".npz":
        raise InputError(f"--out {str(out)!r}: the fused recording is an .npz file", name="--out")
    check_output_dir(out.parent if str(out.parent) else Path("."))
    if out.is_dir():
        raise InputError(f"--out {str(out)!r} is a folder, not a file", name="--out")
    inputs = [Path(f).resolve() for f in args.files]
    if out.resolve() in inputs:
        raise InputError(f"--out {str(out)!r} is one of the recordings read", name="--out")
    if len(set(inputs)) < len(inputs):
        twice = next(str(f) for f in args.files if inputs.count(Path(f).resolve()) > 1)
        raise InputError(f"{twice!r} is given twice", name="files", value=twice)
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


def replay_command(args: argparse.Namespace) -> str:
    """``qpavoid replay``: stream recordings over UDP (:func:`qpavoid.live.replay`)."""
    address = parse_address(args.to, "--to")
    if not 1.0 <= args.rate <= 1000.0:
        raise InputError(f"--rate must be 1 to 1000 Hz, got {args.rate}", name="--rate")
    calibration = load_calibration(args.sensors) if args.sensors else None
    recordings = [load_sensor_recording(f) for f in args.files]
    if calibration is not None:
        for rec in recordings:
            calibration.check_names(rec.sensors)
    try:
        sent = replay(recordings, address, args.rate, calibration)
    except OSError as exc:
        raise InputError(
            f"cannot send to {args.to}: {exc.strerror or exc}", name="--to", value=args.to
        ) from None
    return f"sent {sent} datagrams to {address[0]}:{address[1]}"
