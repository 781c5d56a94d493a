"""The command line's building blocks: a parser whose errors are one line, argument types.

Kept apart from :mod:`qpavoid.cli` so that each command's module can use them.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from importlib.metadata import PackageNotFoundError, version
from typing import Any, NoReturn

from . import __version__


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
count = _number(int, lambda n: n >= 0, "a whole number >= 0")
workers = _number(int, lambda n: n >= 1, "a whole number >= 1")


def package_version() -> str:
    try:
        return version("qpavoid")
    except PackageNotFoundError:  # running from a source tree
        return __version__
