"""A watchdog: the arm is stopped when the loop stops sending commands."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

__all__ = ["Watchdog"]


class Watchdog:
    """Calls ``on_timeout`` when :meth:`kick` is not called for ``timeout_s`` s: once per
    such silence, and again after the next kick's (until 2026-12-02 it fired once a run,
    and a second stall found the arm held by its own hold only).

    The loop kicks it after every command it sends; a loop stuck anywhere (a tick that
    never returns, a blocked call) is then stopped from this thread within ``timeout_s``
    plus one poll (``timeout_s / 4``). Use it as a context manager.

    Attributes
    ----------
    fired, fires
        Whether it called ``on_timeout``, and how many times.
    error
        What ``on_timeout`` raised, if it did.
    """

    def __init__(self, timeout_s: float, on_timeout: Callable[[], None]):
        self.timeout_s, self.on_timeout = float(timeout_s), on_timeout
        self.fired, self.fires = False, 0
        self.error: Exception | None = None  # what on_timeout raised, if anything
        self._last = time.monotonic()
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="qpavoid-watchdog", daemon=True)

    def __enter__(self) -> Watchdog:
        self._last = time.monotonic()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._done.set()
        self._thread.join()

    def kick(self) -> None:
        """A command was sent now."""
        self._last = time.monotonic()

    def silent_s(self) -> float:
        """How long since the last :meth:`kick`, s."""
        return time.monotonic() - self._last

    def _watch(self) -> None:
        fired_after: float | None = None  # the kick the last silence followed
        while not self._done.wait(self.timeout_s / 4.0):
            last = self._last
            if last != fired_after and time.monotonic() - last > self.timeout_s:
                fired_after = last  # once per silence; armed again by the next kick
                self.fired = True
                self.fires += 1
                try:
                    self.on_timeout()
                except Exception as exc:  # reported by the loop, never a thread's traceback
                    self.error = exc
