"""The ``qpavoid`` program's entry point: Ctrl-C while the library loads is one line too.

Loading Pinocchio, coal, OSQP and scipy takes about a second; a Ctrl-C or SIGTERM then
would show Python's traceback or end silently. This module (the console script's target,
light to import because ``qpavoid/__init__`` imports lazily) answers either during that
second with the command line's own line and status 130 (SIGTERM 143), then hands both
back (the command line turns them into the same lines, and a live run into a clean end)
before running the command. Once the command has answered (its line printed, its status
decided) the process only exits, and a further Ctrl-C or SIGTERM no longer changes that
(:func:`~qpavoid.core.signals.ignore_until_exit`).
"""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType

from qpavoid.core.signals import handled_by, ignore_until_exit


def _stopped_while_loading(signum: int, frame: FrameType | None) -> None:
    ignore_until_exit()  # the process is ending: a second one must not cut it short
    word, status = ("terminated", 143) if signum == signal.SIGTERM else ("interrupted", 130)
    sys.stderr.write(f"qpavoid: {word}; nothing written\n")
    sys.stderr.flush()
    # at once, not by SystemExit: raised inside an import, a library's bare ``except:``
    # (seen in the oldest releases pyproject allows, on a loaded machine) swallowed it,
    # and the command ran on after saying "nothing written"; nothing is open to close
    os._exit(status)


# Process-wide, but only for the entry point's own loading: put back right after it. A
# program started with Ctrl-C ignored (a background job of a script, nohup) keeps it so.
with handled_by(_stopped_while_loading, replace=lambda previous: previous is not signal.SIG_IGN):
    from qpavoid.cli.commands import main as _main


def main() -> int:
    """Run the command line (:func:`qpavoid.cli.commands.main`); return the exit status."""
    status = _main()
    ignore_until_exit()  # the command has answered: its status stands
    return status


if __name__ == "__main__":
    sys.exit(main())
