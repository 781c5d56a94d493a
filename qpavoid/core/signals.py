"""Ctrl-C and SIGTERM: the one place the package handles them.

Everything is built on :func:`handled_by` (a handler for a while, the previous one put
back):

* :func:`stops_raise`: a command's: the first Ctrl-C raises ``KeyboardInterrupt``, the
  first SIGTERM :class:`~qpavoid.core.errors.Terminated`; from then on the process is
  ending and both are ignored until it exits (:func:`ignore_until_exit`);
* :func:`held`: held back during a critical section (a folder's move, a numba compile),
  then handled as they would have been;
* :class:`Interruption`: a request to end a real-time run at its next tick;
* :func:`blocked` and :func:`worker_process`: child processes that leave Ctrl-C to their
  parent and end on SIGTERM, from their first instruction.

Python runs signal handlers in the main thread only, so the handlers are set there and
nowhere else (elsewhere these are no-ops). A handler set from outside Python
(``getsignal`` gives None) is never replaced: it could not be put back.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from types import FrameType, TracebackType
from typing import Any

from qpavoid.core.errors import Terminated

__all__ = [
    "CTRL_C",
    "STOPS",
    "Interruption",
    "blocked",
    "handled_by",
    "held",
    "ignore_until_exit",
    "stops_raise",
    "worker_process",
]

#: The signals that end a command: Ctrl-C and ``kill``.
STOPS = (signal.SIGINT, signal.SIGTERM)
#: Ctrl-C alone.
CTRL_C = (signal.SIGINT,)

Handler = Callable[[int, FrameType | None], Any]

#: Set by :func:`ignore_until_exit`: the process is ending, no handler is set or put back.
_ending = False


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _not_ignored(previous: Any) -> bool:
    """A handler other than SIG_IGN: a signal the process was started to ignore (a
    background job of a shell script ignores Ctrl-C, ``nohup`` SIGHUP) stays ignored."""
    return previous is not signal.SIG_IGN


@contextmanager
def handled_by(
    handler: Handler | None,
    signals: tuple[signal.Signals, ...] = STOPS,
    replace: Callable[[Any], bool] = lambda previous: True,
) -> Iterator[dict[signal.Signals, Any]]:
    """Inside, ``handler`` handles each of ``signals`` whose handler ``replace`` accepts
    (None: keep them, and put back whatever a library sets meanwhile); on leaving, the
    previous handlers again. Yields them.

    Once the process is ending (:func:`ignore_until_exit`), nothing is set or put back.
    """
    if not _in_main_thread() or _ending:
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
        if not _ending:
            for s in replaced:
                signal.signal(s, previous[s])


def ignore_until_exit() -> None:
    """From now until the process exits, Ctrl-C and SIGTERM are ignored (from the main
    thread; elsewhere a no-op).

    For a process that is already ending, with its exit status decided: a second Ctrl-C
    must cut short neither its clean-up nor its one line, nor change its status. SIG_IGN,
    not a Python handler: when Python finalizes it puts every Python handler back to the
    default, and a signal in the last moments of the exit (a tenth of a second with
    numba and Pinocchio loaded) would kill the process (status -2) after its line.
    """
    global _ending
    if not _in_main_thread():
        return
    _ending = True
    for s in STOPS:
        if signal.getsignal(s) is not None:
            signal.signal(s, signal.SIG_IGN)


@contextmanager
def stops_raise() -> Iterator[list[int]]:
    """Inside, the first Ctrl-C raises ``KeyboardInterrupt`` and the first SIGTERM
    :class:`~qpavoid.core.errors.Terminated` (where Python's defaults hold: a signal the
    program ignores or handles itself is left to it). Yields the signals received: a
    library's blocking call (Ray's ``get``) may hand ``Terminated`` on as a plain
    ``KeyboardInterrupt``.

    The first of them ends the command, so the process is then ending: both are ignored
    until it exits (:func:`ignore_until_exit`), and a second Ctrl-C (a terminal's user
    pressing it again) lands neither in the clean-up the exception runs (workers
    terminated, a staging folder removed) nor after the command's line.
    """
    received: list[int] = []

    def stop(signum: int, frame: FrameType | None) -> None:
        received.append(signum)
        ignore_until_exit()
        raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt

    def python_default(previous: Any) -> bool:
        return previous is signal.default_int_handler or previous is signal.SIG_DFL

    with handled_by(stop, replace=python_default):
        yield received


@contextmanager
def held(signals: tuple[signal.Signals, ...] = STOPS) -> Iterator[None]:
    """``signals`` held back while inside, then handled as they would have been (the
    first of them): a critical section.

    Python-level handlers, not a signal mask: a mask is per thread, and another thread
    (tqdm's, a BLAS pool) would take the signal, Python then running its handler in the
    main thread anyway. Also what keeps a Ctrl-C during a numba compile: numba's compiler
    calls back into Python through ctypes, where a ``KeyboardInterrupt`` is printed and
    dropped.
    """
    pending: list[tuple[int, FrameType | None]] = []
    previous: dict[signal.Signals, Any] = {}
    try:
        with handled_by(
            lambda signum, frame: pending.append((signum, frame)), signals, _not_ignored
        ) as previous:
            yield
    finally:
        for signum, frame in pending[:1]:
            handler = previous[signal.Signals(signum)]
            if callable(handler):
                handler(signum, frame)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(signum)


class Interruption:
    """Ctrl-C and SIGTERM as a request to end a real-time run, not a crash.

    A live run must end cleanly when its operator presses Ctrl-C or a supervisor
    (systemd, a container runtime) sends SIGTERM: the loop ends at its next tick and the
    run is written as usual. While ``active`` (and until :meth:`restore`, or the end of a
    ``with`` block), either sets :attr:`requested` instead of raising or killing; a signal
    the process was started to ignore stays ignored.
    """

    def __init__(self, active: bool):
        self.requested = False
        self._handlers = ExitStack()
        if active:
            self._handlers.enter_context(handled_by(self._note, replace=_not_ignored))

    def _note(self, signum: int, frame: FrameType | None) -> None:
        self.requested = True

    def restore(self) -> None:
        """The handlers as they were before."""
        self._handlers.close()

    def __enter__(self) -> Interruption:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.restore()


@contextmanager
def blocked(signals: tuple[signal.Signals, ...] = STOPS) -> Iterator[None]:
    """``signals`` blocked in this thread while inside (a signal mask), then delivered.

    For starting child processes: one forked inside starts with them blocked, so that
    neither a Ctrl-C to the terminal's whole process group nor a SIGTERM reaches it with
    its parent's handlers before it has set its own (:func:`worker_process`), however
    slowly a loaded machine runs it. Threads started inside inherit the mask too (a
    pool's, which forks its replacement workers).
    """
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, signals)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def worker_process() -> None:
    """A worker process's signals (its first call, e.g. a pool's ``initializer``):
    Ctrl-C is its parent's to handle (ignored here: a terminal sends it to the whole
    process group, and the parent ends its workers), SIGTERM ends it (the parent's
    handler, inherited on fork, is not for it); both unblocked (:func:`blocked`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOPS)
