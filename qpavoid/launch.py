"""The ``qpavoid`` program's entry point: Ctrl-C while the library loads is one line too.

Loading Pinocchio, coal, OSQP and scipy takes about a second; a Ctrl-C then would show
Python's traceback. This module (the console script's target, light to import because
``qpavoid/__init__`` imports lazily) answers Ctrl-C during that second with the command
line's own line and status 130, then hands Ctrl-C back to Python (the command line turns
it into the same line, and a live run into a clean end) before running the command.
"""

from __future__ import annotations

import signal
import sys
from types import FrameType


def _interrupted_while_loading(signum: int, frame: FrameType | None) -> None:
    sys.stderr.write("qpavoid: interrupted; nothing written\n")
    raise SystemExit(130)


# Process-wide, but only for the entry point's own loading: restored right below. A
# program started with Ctrl-C ignored (a background job of a script, nohup) keeps it so.
_previous = signal.getsignal(signal.SIGINT)
if _previous is not signal.SIG_IGN:
    signal.signal(signal.SIGINT, _interrupted_while_loading)
from .cli import main as _main  # noqa: E402  (after the handler, on purpose)

if _previous is not signal.SIG_IGN:
    signal.signal(signal.SIGINT, _previous)


def main() -> int:
    """Run the command line (:func:`qpavoid.cli.main`); return the exit status."""
    return _main()


if __name__ == "__main__":
    sys.exit(main())
