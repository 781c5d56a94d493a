"""Ctrl-C and SIGTERM: handlers set for a while and put back, and signals held back.

Python runs signal handlers in the main thread only, so everything here acts there and
is a no-op in any other thread. A handler set from outside Python (``getsignal`` gives
None) is never replaced: it could not be put back.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

__all__ = ["handled_by", "held"]

#: The signals that end a command: Ctrl-C and ``kill``.
STOPS = (signal.SIGINT, signal.SIGTERM)

Handler = Callable[[int, FrameType | None], Any]


@contextmanager
def handled_by(
    handler: Handler | None,
    signals: tuple[signal.Signals, ...] = STOPS,
    replace: Callable[[Any], bool] = lambda previous: True,
) -> Iterator[dict[signal.Signals, Any]]:
    """Inside, ``handler`` handles each of ``signals`` whose handler ``replace`` accepts
    (None: keep them, and put back whatever a library sets meanwhile); on leaving, the
    previous handlers again. Yields them."""
    if threading.current_thread() is not threading.main_thread():
        yield {}
        return
    previous = {s: signal.getsignal(s) for s in signals}
    replaced = [s for s, h in previous.items() if h is not None and replace(h)]
    if handler is not None:
        for s in replaced:
            signal.signal(s, handler)
    try:
        yield previous
    finally:
        for s in replaced:
            signal.signal(s, previous[s])


@contextmanager
def held() -> Iterator[None]:
    """Ctrl-C and SIGTERM held back while inside, then handled as they would have been
    (the first of them): a critical section. Python-level handlers, not a signal mask: a
    mask is per thread, and another thread (tqdm's) would take the signal."""
    pending: list[tuple[int, FrameType | None]] = []
    previous: dict[signal.Signals, Any] = {}
    try:
        with handled_by(lambda signum, frame: pending.append((signum, frame))) as previous:
            yield
    finally:
        for signum, frame in pending[:1]:
            handler = previous[signal.Signals(signum)]
            if callable(handler):
                handler(signum, frame)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(signum)
