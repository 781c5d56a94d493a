"""Compiling the numba kernels without losing a Ctrl-C.

The first use of a kernel after an install compiles it (a few seconds; later processes
load it from the disk cache in milliseconds). Numba's compiler calls back into Python
through ctypes, and a ``KeyboardInterrupt`` raised there is printed and dropped: a Ctrl-C
during the compile was lost and the run went on (seen in CI). :func:`ctrl_c_deferred`
holds Ctrl-C back while the kernels compile and delivers it right after.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["ctrl_c_deferred"]


@contextmanager
def ctrl_c_deferred() -> Iterator[None]:
    """Block SIGINT in this thread for the block's duration (the main thread only: other
    threads never receive Python's signals anyway)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)
