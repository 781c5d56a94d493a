"""Compiling the numba kernels without losing a Ctrl-C, and calling them only with the
argument types they were compiled for.

The first use of a kernel after an install compiles it (a few seconds; later processes
load it from the disk cache in milliseconds). Numba's compiler calls back into Python
through ctypes, and a ``KeyboardInterrupt`` raised there is printed and dropped: a Ctrl-C
during the compile was lost and the run went on (seen in CI). :func:`ctrl_c_deferred`
holds Ctrl-C and SIGTERM back until the compile ends (:func:`qpavoid.core.signals.held`).
"""

from __future__ import annotations

import os
from contextlib import AbstractContextManager
from types import ModuleType
from typing import Any

import numpy as np

from qpavoid.core.signals import held

__all__ = ["cold", "ctrl_c_deferred", "kernel_input", "recompile_if_stale"]


def ctrl_c_deferred() -> AbstractContextManager[None]:
    """Ctrl-C and SIGTERM during the block (a compile) handled right after it
    (:func:`qpavoid.core.signals.held`)."""
    return held()


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


def cold(*kernels: Any) -> bool:
    """True if one of ``kernels`` has nothing in its disk cache yet (the first run after an
    install compiles it: tens of seconds in all); False if each has its cache's index, or
    numba keeps it where this cannot look (then nothing is known)."""
    for kernel in kernels:
        cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
        index = getattr(cache_file, "_index_path", None)
        if index is not None and not os.path.exists(index):
            return True
    return False


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
