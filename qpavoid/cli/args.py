"""The command line's building blocks: a parser whose errors are one line, argument types.

Kept apart from :mod:`qpavoid.cli.commands` so that each command's module can use them.
"""

from __future__ import annotations

import argparse
import io
import os
import signal
import sys
from collections.abc import Callable
from importlib.metadata import PackageNotFoundError, version
from typing import Any, NoReturn

from qpavoid import __version__
from qpavoid.arm.description import bundled_robots
from qpavoid.core.errors import QpavoidError, Terminated
from qpavoid.core.signals import stops_raise
from qpavoid.human.landmarks import FORMAT_NAMES


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line, ``qpavoid: error: ...``, exit 2."""

    def error(self, message: str) -> NoReturn:
        where = self.prog.removeprefix("qpavoid").strip()
        hint = f"; see 'qpavoid {where} --help'" if where else "; see 'qpavoid --help'"
        self.exit(2, f"qpavoid: error: {message}{hint}\n")


class HelpFormatter(argparse.HelpFormatter):
    """Help texts that end with the option's default, where it has a meaningful one."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (
            default is None
            or default is False
            or default == []
            or default == argparse.SUPPRESS
            or "default" in text
        ):
            return text
        shown = " ".join(map(str, default)) if isinstance(default, list) else default
        return f"{text} (default: {shown})"


def _number(kind: type, check: Callable[[Any], bool], what: str) -> Callable[[str], Any]:
    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}") from None
        if not check(value):
            raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
        return value

    return parse


def _positive_finite(x: float) -> bool:
    return 0.0 < x < float("inf")


positive_float = _number(float, _positive_finite, "a positive finite number")
non_negative_float = _number(float, lambda x: 0.0 <= x < float("inf"), "a finite number >= 0")
count = _number(int, lambda n: n >= 0, "a whole number >= 0")
workers = _number(int, lambda n: n >= 1, "a whole number >= 1")


def add_robot_option(parser: argparse.ArgumentParser) -> None:
    """``--robot NAME|PATH``, the same on every command that runs an arm."""
    parser.add_argument(
        "--robot",
        default="iiwa14",
        metavar="NAME|PATH",
        help=f"the arm: a bundled description ({', '.join(bundled_robots())}; those whose "
        "URDF comes from a package need the extra 'robots') or a folder holding "
        "control_points.toml (docs/robot.md)",
    )


def add_camera_option(parser: argparse.ArgumentParser, with_sensors: bool = False) -> None:
    """``--camera FORMAT``, the simulated camera of every command that simulates one: a
    shipped format's name or a format file of the user's (checked by the run's spec).
    ``with_sensors``: the command also takes ``--sensors``, whose calibration's formats
    rule (the default is then the cell's, resolved by the run's spec)."""
    parser.add_argument(
        "--camera",
        metavar="FORMAT",
        default="" if with_sensors else FORMAT_NAMES[0],
        help="the simulated camera's skeleton format, with its latency, noise, joints and "
        f"failure modes: one of {', '.join(FORMAT_NAMES)}, or a format file FILE.toml with "
        "its body model FILE's <name>_body.toml beside it (docs/sensors.md, docs/formats.md)"
        + (
            f"; default {FORMAT_NAMES[0]}. With --sensors or --listen the calibration's "
            "format keys rule: leave it out (one that differs is refused)"
            if with_sensors
            else ""
        ),
    )


def add_payload_option(parser: argparse.ArgumentParser) -> None:
    """``--payload KG``, the load the arm carries, on every command that runs an arm."""
    parser.add_argument(
        "--payload",
        type=non_negative_float,
        default=0.0,
        metavar="KG",
        help="the payload at the end effector, kg, within the arm's rating: power and "
        "force limiting counts it in the arm's effective mass, and so does the judge of "
        "every true contact (default: 0)",
    )


def folder(text: str) -> str:
    """An argument type: a folder's path, not empty (``""`` would be the current folder)."""
    if not text:
        raise argparse.ArgumentTypeError("must name a folder, got an empty path")
    return text


def whole_number(low: int, high: int) -> Callable[[str], int]:
    """An argument type: a whole number from ``low`` to ``high``."""
    return _number(int, lambda n: low <= n <= high, f"a whole number from {low} to {high}")


def package_version() -> str:
    try:
        return version("qpavoid")
    except PackageNotFoundError:  # running from a source tree
        return __version__


class Verdict(str):
    """A command's text with the exit status it ends with (``qpavoid check``: 1 when the
    arm will stop), for scripts."""

    status: int = 0

    def __new__(cls, text: str, status: int) -> Verdict:
        out = super().__new__(cls, text)
        out.status = status
        return out


def run_command(command: Callable[[], str]) -> int:
    """Run a command and print its text: status 0 (a :class:`Verdict`'s own). Anything
    else is one line on standard error: bad input or a file error 2, a bug 2
    (``QPAVOID_DEBUG=1`` raises it), Ctrl-C 130, SIGTERM 143 (the first of them ends the
    command, and the process: later ones are ignored,
    :func:`~qpavoid.core.signals.stops_raise`), standard output closed (``| head`` done)
    1."""
    received: list[int] = []
    try:
        with stops_raise() as received:
            text = command()
    except QpavoidError as exc:
        return _fail(f"qpavoid: error: {exc}", 2)
    except OSError as exc:
        where = f": {exc.filename}" if exc.filename else ""
        return _fail(f"qpavoid: error: {exc.strerror or exc}{where}", 2)
    except KeyboardInterrupt as exc:
        term = isinstance(exc, Terminated) or signal.SIGTERM in received
        word, status = ("terminated", 143) if term else ("interrupted", 130)
        written = getattr(exc, "written", None)  # set by io.staged_output
        done = f" after writing its files to {written}/" if written else "; nothing written"
        return _fail(f"qpavoid: {word}{done}", status)
    except Exception as exc:  # a bug: one line, the traceback on request
        if os.environ.get("QPAVOID_DEBUG"):
            raise
        return _fail(
            f"qpavoid: error: internal error, please report it: "
            f"{type(exc).__name__}: {exc} (QPAVOID_DEBUG=1 shows the traceback)",
            2,
        )
    try:
        if isinstance(sys.stdout, io.TextIOWrapper):  # a terminal that cannot show µs
            sys.stdout.reconfigure(errors="backslashreplace")
        print(text, flush=True)
    except BrokenPipeError:  # the reader is gone: nothing more to say, nor at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    return text.status if isinstance(text, Verdict) else 0


def _fail(line: str, status: int) -> int:
    print(" ".join(line.split()), file=sys.stderr)
    return status
