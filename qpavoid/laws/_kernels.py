"""One tick's avoidance terms, compiled (numba): the minima and eqs. (4), (5), (7).

:class:`~qpavoid.control.controller.Controller.measure` needs, from the distance table, each
set's minimum distance, the part closest to L2 and the repulsive velocities of eqs. (5)
and (7): a dozen numpy calls on arrays of eight parts, whose call overhead outweighed
their arithmetic (docs/performance.md §2a). :func:`avoidance_terms` makes them one call.
The logistic of eq. (4) is :func:`qpavoid.laws.avoidance.logistic` itself, compiled from its
source; the rest composes it as :func:`~qpavoid.laws.avoidance.repulsive_velocity` and
:func:`~qpavoid.laws.avoidance.ee_repulsive_velocity` do, and ``tests/test_laws.py`` checks the
two against each other. f of eq. (2) stays :func:`~qpavoid.laws.avoidance.l1_factor`'s: numba's
tanh and numpy's differ in the last bit for some distances, and f decides a stop.

The last-resort check of every command (:meth:`~qpavoid.control.controller.Controller.command`:
finite, and no joint past its position limit after one control period) is one call too,
:func:`limit_crossed`.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.core.compiling import ctrl_c_deferred, recompile_if_stale
from qpavoid.laws import avoidance as laws
from qpavoid.laws.avoidance import AvoidanceConfig, logistic

__all__ = ["NOT_FINITE", "avoidance_terms", "law_constants", "limit_crossed", "warm_up"]

_logistic = njit(cache=True)(logistic)  # the law's own source, compiled


@njit(cache=True)
def avoidance_terms(
    distance: np.ndarray,
    vector: np.ndarray,
    i_L2: int,
    i_EE: int,
    rho_rep: float,
    alpha_rep: float,
    v_max: float,
) -> tuple[np.ndarray, int, np.ndarray, np.ndarray]:
    """The avoidance terms of one tick.

    Parameters
    ----------
    distance, vector
        The distance table's (S, K) distances, m, and (S, K, 3) unit directions human →
        robot (+inf and anything for a part not seen).
    i_L2, i_EE
        Rows of the sets L2 and EE.
    rho_rep, alpha_rep, v_max
        ρ (m) and α of eq. (4) and V_max (m/s): an
        :class:`~qpavoid.laws.avoidance.AvoidanceConfig`'s (:func:`law_constants`).

    Returns
    -------
    dmin, j, v_rep_L2, v_rep_EE
        (S,) each set's minimum distance (``DistanceTable.min_per_set``); the column of
        the part closest to L2 (``closest_part``); eq. (5)'s velocity (3,) of L2 away
        from that part (0 if it is not seen) and eq. (7)'s sum (3,) over the parts EE
        sees, m/s.
    """
    S = distance.shape[0]
    dmin = np.empty(S)
    for s in range(S):
        dmin[s] = distance[s].min()
    j = np.argmin(distance[i_L2])
    v_rep_L2 = np.zeros(3)
    d = distance[i_L2, j]
    if np.isfinite(d):  # eqs. (4)-(5)
        v_rep_L2[:] = v_max * _logistic(d, rho_rep, alpha_rep) * vector[i_L2, j]
    v_rep_EE = np.zeros(3)
    for k in range(distance.shape[1]):  # eq. (7): 0 for a part not seen (d = +inf)
        speed = v_max * _logistic(distance[i_EE, k], rho_rep, alpha_rep)
        if speed > 0.0 or np.isnan(speed):  # a NaN distance spoils the sum, as in laws.py
            v_rep_EE += speed * vector[i_EE, k]
    return dmin, int(j), v_rep_L2, v_rep_EE


def law_constants(cfg: AvoidanceConfig) -> tuple[float, float, float]:
    """``cfg``'s constants in :func:`avoidance_terms`' order, as floats (an int would make
    numba compile a second specialisation at the first tick)."""
    return float(cfg.rho_rep_m), float(cfg.alpha_rep), float(cfg.v_max_mps)


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
    """Compile (or load from the disk cache) the kernel, once per process."""
    with ctrl_c_deferred():
        avoidance_terms(np.ones((3, 2)), np.zeros((3, 2, 3)), 1, 2, 0.2, 9.0, 0.25)
        limit_crossed(np.zeros(2), np.zeros(2), 0.01, -np.ones(2), np.ones(2))
        recompile_if_stale(avoidance_terms, laws)  # it compiles laws.logistic in
