"""``qpavoid view``: a run's 3D replay in the browser (:mod:`qpavoid.output.replay_html`).

    qpavoid view RUN_DIR [--out FILE]

Like :mod:`qpavoid.cli.commands` it parses, calls the library and prints.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from qpavoid.cli.args import HelpFormatter
from qpavoid.core.errors import InputError
from qpavoid.output.replay_html import write_replay

__all__ = ["add_view_command", "view_command"]


def add_view_command(sub: argparse._SubParsersAction) -> None:
    """Add ``view`` to the ``qpavoid`` sub-commands."""
    view = sub.add_parser(
        "view",
        formatter_class=HelpFormatter,
        help="write a run's interactive 3D replay (one HTML file, opens offline)",
        description="Write RUN_DIR/replay.html: the robot's and the person's shapes, the "
        "closest pairs, the path and the end-effector trace, with a time slider and the "
        "numbers of every tick (docs/replay.md). It needs no network and no server.",
    )
    view.add_argument("run_dir", metavar="RUN_DIR", help="a folder written by qpavoid run")
    view.add_argument("--out", metavar="FILE", help="where to write (default: RUN_DIR/replay.html)")
    view.set_defaults(parser=view, handler=view_command)


def view_command(args: argparse.Namespace) -> str:
    """``qpavoid view``: write the replay and say where."""
    run_dir = Path(args.run_dir)
    if not (run_dir / "log.npz").is_file():
        raise InputError(
            f"{args.run_dir!r} is not a run folder (no such folder, or no log.npz in it)",
            name="RUN_DIR",
            value=args.run_dir,
        )
    target = Path(args.out) if args.out is not None else None
    if target is not None and (
        target.suffix != ".html" or target.is_dir() or not target.parent.is_dir()
    ):
        raise InputError(
            f"--out {args.out!r}: must be a .html file in an existing folder", name="--out"
        )
    path = write_replay(run_dir, target)
    return f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB): open it in a browser"
