"""Ctrl-C (and SIGTERM) during a real-time run: a request to end it, not a crash.

A live run must end cleanly when its operator presses Ctrl-C or a supervisor (systemd, a
container runtime) sends SIGTERM: the loop ends at its next tick and the run is written
as usual, with ``end_reason`` "interrupted".
"""

from __future__ import annotations

import signal
import threading
from typing import Any

__all__ = ["Interruption"]

#: The signals that end a real-time run cleanly.
SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interruption:
    """While ``active``, Ctrl-C and SIGTERM set :attr:`requested` instead of raising or
    killing (the handlers are ours only in the main thread, and :meth:`restore` gives the
    previous ones back). A signal the process was started to ignore (a background job of
    a shell script ignores Ctrl-C) stays ignored."""

    def __init__(self, active: bool):
        self.requested = False
        self._previous: dict[int, Any] = {}
        if active and threading.current_thread() is threading.main_thread():
            self._previous = {
                s: signal.signal(s, self._note)
                for s in SIGNALS
                if signal.getsignal(s) is not signal.SIG_IGN  # ignored by who started us
            }

    def _note(self, signum: int, frame: object) -> None:
        self.requested = True

    def restore(self) -> None:
        """The handlers as they were before."""
        for s, previous in self._previous.items():
            signal.signal(s, previous)
        self._previous = {}
