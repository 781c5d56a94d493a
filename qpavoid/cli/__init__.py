"""The command line: it parses, calls and prints; nothing imports it.

May import: every stage. ``qpavoid.cli.main`` is :func:`qpavoid.cli.commands.main`, imported
on first use (the console script's :mod:`qpavoid.launch` imports this package while it
still holds Ctrl-C for the library's loading).
"""

import importlib


def __getattr__(name: str) -> object:
    """``main``, the command line (:func:`qpavoid.cli.commands.main`), on first use."""
    if name == "main":
        return importlib.import_module("qpavoid.cli.commands").main
    raise AttributeError(f"module 'qpavoid.cli' has no attribute {name!r}")
