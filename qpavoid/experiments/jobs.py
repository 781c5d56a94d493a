"""Independent jobs mapped over processes, with a progress bar: what ``compare`` and sweeps share.

A job is a picklable function applied to each item of a list. :func:`map_jobs` runs them
in a local process pool (or any executor with ``map``, e.g. a cluster's) and returns the
results in the order of the items, whatever order they finish in, so a result never
depends on the number of workers. An error in a worker is raised again here, in the
caller's process, with its own type.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Executor
from contextlib import ExitStack
from typing import Any, TypeVar

from tqdm.auto import tqdm

from qpavoid.core import signals
from qpavoid.core.errors import InputError

T = TypeVar("T")
R = TypeVar("R")


def progress_bar(total: float | None, desc: str, unit: str, enabled: bool) -> Any:
    """A tqdm bar on standard error; silent when ``enabled`` is False or not on a terminal."""
    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        disable=None if enabled else True,
        leave=False,
        dynamic_ncols=True,
    )


def map_jobs(
    fn: Callable[[T], R],
    items: Sequence[T],
    *,
    workers: int | None = None,
    executor: Executor | None = None,
    progress: bool = False,
    desc: str = "",
    unit: str = "job",
) -> list[R]:
    """``[fn(x) for x in items]``, in parallel, in the order of ``items``.

    Parameters
    ----------
    fn
        A module-level (picklable) function.
    items
        Its arguments, one job each.
    workers
        Local processes (default: all cores); 1 runs in this process.
    executor
        Any executor with ``map`` to use instead of a local pool (it keeps the order).
    progress
        Show a progress bar (on a terminal only).
    desc, unit
        The bar's label and unit.
    """
    if workers is not None and workers < 1:
        raise InputError(f"workers must be >= 1, got {workers}", name="workers", value=workers)
    workers = min(workers or os.cpu_count() or 1, max(len(items), 1))
    with progress_bar(len(items), desc, unit, progress) as bar:
        if executor is not None:
            return list(_ticking(executor.map(fn, items), bar))
        if workers == 1:
            return list(_ticking(map(fn, items), bar))
        results: list[Any] = [None] * len(items)
        # Pool.__exit__ terminates the workers: a Ctrl-C, a SIGTERM turned into an
        # exception, or a worker's error ends the pool at once, with nothing left running.
        # Its workers start with both signals blocked until they have set their own.
        with ExitStack() as stack:
            with signals.blocked():
                pool = stack.enter_context(
                    multiprocessing.Pool(workers, initializer=signals.worker_process)
                )
            for i, result in pool.imap_unordered(_Indexed(fn), enumerate(items)):
                results[i] = result
                bar.update(1)
        return results


class _Indexed:
    """``fn`` of an ``(index, item)`` pair, returning ``(index, result)`` (picklable)."""

    def __init__(self, fn: Callable[[Any], Any]):
        self.fn = fn

    def __call__(self, pair: tuple[int, Any]) -> tuple[int, Any]:
        return pair[0], self.fn(pair[1])


def _ticking(results: Iterable[R], bar: Any) -> Iterable[R]:
    for r in results:
        bar.update(1)
        yield r
