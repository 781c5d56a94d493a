"""``qpavoid bench``: where a tick's time goes (:mod:`qpavoid.experiments.bench`).

    qpavoid bench [--json FILE] [--quick] [--robot NAME|PATH]

Like :mod:`qpavoid.cli.commands` it parses, calls the library and prints.
"""

from __future__ import annotations

import argparse

from qpavoid.cli.args import HelpFormatter, add_robot_option
from qpavoid.experiments.bench import format_bench, run_bench
from qpavoid.output.run_files import check_output_file, strict_json

__all__ = ["add_bench_command", "bench_command"]


def add_bench_command(sub: argparse._SubParsersAction) -> None:
    """Add ``bench`` to the ``qpavoid`` sub-commands."""
    bench = sub.add_parser(
        "bench",
        formatter_class=HelpFormatter,
        help="time every stage of a tick, every controller, and how they scale",
        description="Replay a recorded run through every stage of a tick and every "
        "controller; print median and p99 (µs) and the paper's budget; --json writes the "
        "same numbers (keys in docs/performance.md). Run it on an idle machine.",
    )
    bench.add_argument("--json", metavar="FILE", help="also write the numbers as JSON")
    bench.add_argument("--quick", action="store_true", help="fewer states, one repeat")
    add_robot_option(bench)
    bench.set_defaults(parser=bench, handler=bench_command)


def bench_command(args: argparse.Namespace) -> str:
    """``qpavoid bench``: run, print, and write the JSON if asked."""
    target = None if args.json is None else check_output_file(args.json, "--json")
    result = run_bench(quick=args.quick, robot=args.robot)
    if target is not None:
        target.write_text(strict_json(result, indent=1))
    return format_bench(result) + (f"\nwrote {target}" if target else "")
