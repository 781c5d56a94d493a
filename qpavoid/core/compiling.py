"""Compiling the numba kernels without losing a Ctrl-C, and calling them only with the
argument types they were compiled for.

The first use of a kernel after an install compiles it (a few seconds; later processes
load it from the disk cache in milliseconds). Numba's compiler calls back into Python
through ctypes, and a ``KeyboardInterrupt`` raised there is printed and dropped: a Ctrl-C
during the compile was lost and the run went on (seen in CI). Blocking the signal is not
enough: the process's other threads (a BLAS pool) still receive it and Python then runs
its handler in the main thread, inside the callback. :func:`ctrl_c_deferred` swaps in a
handler that only notes the Ctrl-C, and calls the previous one right after the block.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType, ModuleType
from typing import Any

import numpy as np

__all__ = ["ctrl_c_deferred", "kernel_input", "recompile_if_stale"]


@contextmanager
def ctrl_c_deferred() -> Iterator[None]:
    """Note a Ctrl-C during the block and deliver it to the previous handler after (in the
    main thread only: Python runs signal handlers there and nowhere else)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    noted: list[FrameType | None] = []

    def note(signum: int, frame: FrameType | None) -> None:
        noted.append(frame)

    previous = signal.signal(signal.SIGINT, note)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if noted and callable(previous):  # Python's KeyboardInterrupt, or ours
            previous(signal.SIGINT, noted[0])
        elif noted and previous == signal.SIG_DFL:
            raise KeyboardInterrupt


def kernel_input(array: object, dtype: type) -> np.ndarray:
    """``array`` as the kernels were warmed up for it: C-contiguous, writeable, ``dtype``.

    numba compiles a new specialisation for each layout, dtype *and* read-only flag it
    meets; a read-only frame (a recording's arrays are) or a view would make the control
    loop wait for the compiler at its first frame. Such an array is copied (25 joints: well
    under a microsecond); the usual one is passed through.
    """
    if (
        isinstance(array, np.ndarray)
        and array.dtype == dtype
        and array.flags.c_contiguous
        and array.flags.writeable
    ):
        return array
    return np.array(array, dtype=dtype, order="C")


def recompile_if_stale(kernel: Any, *modules: ModuleType) -> bool:
    """Recompile ``kernel`` if one of ``modules`` (whose kernels or constants it compiles
    in) changed after ``kernel``'s disk cache was written; True if it did.

    numba keys a kernel's disk cache on the kernel's own source file alone: a cache made
    before an edit of a function it calls from another file keeps the old function
    (numba's documented limit). An install writes every file before any cache exists, so
    this matters while the package is edited. Without the cache's index file (nothing
    cached yet, or a numba that keeps it elsewhere) nothing is done.
    """
    cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
    index = getattr(cache_file, "_index_path", None)
    if index is None or not os.path.exists(index):
        return False
    written = os.stat(index).st_mtime
    if all(os.stat(str(m.__file__)).st_mtime <= written for m in modules):
        return False
    kernel.recompile()
    return True
