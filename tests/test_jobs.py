"""Jobs over processes (qpavoid.experiments.jobs): in order, and workers that leave Ctrl-C
to their parent from their first instruction."""

from __future__ import annotations

import os
import signal

from qpavoid.core.signals import STOPS
from qpavoid.experiments.jobs import map_jobs


def worker_signals(_: int) -> tuple[int, bool, bool, bool]:
    """What a worker does with Ctrl-C and SIGTERM: (its pid, Ctrl-C ignored, SIGTERM
    ends it, neither blocked)."""
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    return (
        os.getpid(),
        signal.getsignal(signal.SIGINT) is signal.SIG_IGN,
        signal.getsignal(signal.SIGTERM) is signal.SIG_DFL,
        not any(s in mask for s in STOPS),
    )


def square(x: int) -> int:
    return x * x


def test_results_come_in_the_order_of_the_items_on_any_number_of_workers():
    items = list(range(7))
    assert map_jobs(square, items, workers=1) == map_jobs(square, items, workers=2)
    assert map_jobs(square, items, workers=2) == [x * x for x in items]


def test_workers_ignore_ctrl_c_end_on_sigterm_and_the_caller_keeps_its_mask():
    before = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    seen = map_jobs(worker_signals, list(range(4)), workers=2)
    assert all(pid != os.getpid() for pid, *_ in seen)
    assert all(ignored and ends and unblocked for _, ignored, ends, unblocked in seen)
    assert signal.pthread_sigmask(signal.SIG_BLOCK, []) == before
