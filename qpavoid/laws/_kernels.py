"""The last-resort check of every command, compiled (numba), and the laws' warm-up.

:meth:`~qpavoid.control.controller.Controller.command` checks each command before it is
sent: finite, and no joint past its position limit after one control period. As numpy
that was several calls on arrays of six or seven joints; :func:`limit_crossed` makes it
one. The repulsion of a tick is compiled beside the laws it composes
(:func:`qpavoid.laws.avoidance.avoidance_terms`); :func:`warm_up` compiles (or loads) both.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.core.compiling import ctrl_c_deferred
from qpavoid.laws.avoidance import avoidance_terms
from qpavoid.laws.ssm import approach_bounds

__all__ = ["NOT_FINITE", "limit_crossed", "warm_up"]

#: :func:`limit_crossed`'s answer for a command that is not finite.
NOT_FINITE = -2


@njit(cache=True)
def limit_crossed(
    q: np.ndarray, dq: np.ndarray, dt: float, q_min: np.ndarray, q_max: np.ndarray
) -> int:
    """The first joint that ``q + dq dt`` would carry past ``[q_min, q_max]`` (rad),
    :data:`NOT_FINITE` if the sum of ``dq`` (rad/s) is not finite (an entry is NaN or
    infinite, or they overflow), else −1."""
    total = 0.0
    for v in dq:
        total += v
    if not np.isfinite(total):
        return NOT_FINITE
    for k in range(q.shape[0]):
        q_next = q[k] + dq[k] * dt
        if q_next > q_max[k] or q_next < q_min[k]:
            return k
    return -1


@functools.cache
def warm_up() -> None:
    """Compile (or load from the disk cache) the kernels, once per process."""
    with ctrl_c_deferred():
        avoidance_terms(np.ones((3, 2)), np.zeros((3, 2, 3)), 1, 2, 0.2, 9.0, 0.25)
        limit_crossed(np.zeros(2), np.zeros(2), 0.01, -np.ones(2), np.ones(2))
        approach_bounds(
            np.ones((2, 2)),
            np.zeros((2, 2, 3)),
            np.zeros((2, 2), dtype=np.int64),
            np.zeros((1, 2, 3)),
            np.zeros(2, dtype=np.bool_),
            0.1,
            *(0.1, 0.2, 0.5, 2.0, 1.6, 1.6, 0.1, np.nan, 0.5),
        )
