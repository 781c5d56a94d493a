"""``qpavoid robot``: fit a first description to a URDF, check a description's coverage.

    qpavoid robot fit URDF --out DIR [--merge JOINT ...] [--lock JOINT=ANGLE ...]
                                     [--mesh-dir DIR ...]
    qpavoid robot check NAME|PATH

Like :mod:`qpavoid.cli.commands` it parses, calls the library and prints.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from qpavoid.arm.control_points import CONFIG_NAME
from qpavoid.arm.coverage import check_coverage, coverage, coverage_table
from qpavoid.arm.fit import fit_description
from qpavoid.arm.model import load_robot
from qpavoid.arm.urdf import mesh_dirs, package_entry
from qpavoid.cli.args import HelpFormatter, Parser
from qpavoid.core.errors import InputError

__all__ = ["add_robot_command", "check_command", "fit_command"]


def _lock(text: str) -> tuple[str, float]:
    """``JOINT=ANGLE`` (rad) or ``JOINT`` (at 0) of ``--lock``."""
    joint, _, angle = text.partition("=")
    try:
        value = float(angle) if angle else 0.0
    except ValueError:
        value = math.nan
    if not joint or not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not JOINT or JOINT=ANGLE (rad)")
    return joint, value


def add_robot_command(sub: argparse._SubParsersAction) -> None:
    """Add ``robot fit`` and ``robot check`` to the ``qpavoid`` sub-commands."""
    robot = sub.add_parser(
        "robot",
        formatter_class=HelpFormatter,
        help="fit a first robot description to a URDF; check a description's coverage",
        description="Fit capsules and spheres to a URDF's collision meshes (fit), or "
        "measure how many collision-mesh vertices a description's capsules and spheres "
        "hold (check). docs/robot.md",
    )
    actions = robot.add_subparsers(
        dest="action", required=True, metavar="ACTION", parser_class=Parser
    )
    fit = actions.add_parser(
        "fit",
        formatter_class=HelpFormatter,
        help="write DIR/control_points.toml fitted to a URDF's collision meshes",
        description="Write DIR/control_points.toml for the URDF (referenced by its path): "
        "per moving link with collision geometry, the smallest capsule holding every "
        "vertex and spheres covering it. Name the roles, the arm's dynamics and the IK "
        "seed in the file (its TO DO lines), then load it with --robot DIR.",
    )
    fit.add_argument("urdf", metavar="URDF", help="the URDF, with collision meshes or shapes")
    fit.add_argument("--out", required=True, metavar="DIR", help="folder to write into")
    fit.add_argument(
        "--merge",
        nargs="+",
        default=[],
        metavar="JOINT",
        help="joints whose child links join their parent's set (a gripper's fingers; a "
        "moving one is locked, at 0 unless --lock says otherwise)",
    )
    fit.add_argument(
        "--lock",
        nargs="+",
        type=_lock,
        default=[],
        metavar="JOINT=ANGLE",
        help="joints the file locks and their angle (rad)",
    )
    fit.add_argument(
        "--mesh-dir",
        nargs="+",
        default=[],
        metavar="DIR",
        help="folders holding the URDF's package:// meshes (default: the folders above it)",
    )
    fit.add_argument(
        "--force", action="store_true", help="overwrite an existing control_points.toml"
    )
    fit.set_defaults(parser=fit, handler=fit_command)
    check = actions.add_parser(
        "check",
        formatter_class=HelpFormatter,
        help="print how many collision-mesh vertices the capsules and spheres hold",
        description="Print, per collision object and distance method, the vertices "
        "checked (at the neutral and three fixed random configurations), those inside the "
        "model and the worst excess; an uncovered object that the description does not "
        "exclude is an error after the table.",
    )
    check.add_argument("robot", metavar="NAME|PATH", help="a bundled description or a folder")
    check.set_defaults(parser=check, handler=check_command)


def fit_command(args: argparse.Namespace) -> str:
    """``qpavoid robot fit``: write the fitted file and say what is in it."""
    urdf = Path(args.urdf)
    if not urdf.is_file():
        raise InputError(f"URDF {args.urdf!r}: no such file", name="URDF", value=args.urdf)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {args.out!r}: not a folder", name="--out", value=args.out)
    target = out / CONFIG_NAME
    if target.exists() and not args.force:
        raise InputError(
            f"--out {args.out!r} already holds {CONFIG_NAME}: give another folder, or --force",
            name="--out",
            value=args.out,
        )
    dirs = [Path(d) for d in args.mesh_dir] or list(mesh_dirs(urdf))
    entry = package_entry(urdf) or str(urdf.resolve())  # an installed package's: by name
    text = fit_description(urdf.resolve(), entry, dirs, args.merge, dict(args.lock))
    out.mkdir(parents=True, exist_ok=True)
    target.write_text(text, encoding="utf-8")
    sets = text.count("[[sets]]")
    return (
        f"wrote {target}: {sets} set(s) fitted to {urdf.name}'s collision geometry; name the "
        f"roles, [arm] and [ik_seed] (its TO DO lines), then run with --robot {out}"
    )


def check_command(args: argparse.Namespace) -> str:
    """``qpavoid robot check``: the coverage table (then the failure, if any)."""
    robot = load_robot(args.robot, coverage=False)
    rows = coverage(robot)
    print(coverage_table(rows), flush=True)
    check_coverage(robot, robot.path or Path(args.robot), rows)
    return (
        f"{robot.name}: every collision-mesh vertex but those of [coverage] exclude lies "
        "inside the capsules and inside the spheres"
    )
