"""The paper's avoidance laws (Sect. 5, eqs. 2-9) as small pure functions.

Equations (2) and (4) are read as in the reading notes (§5), after Flacco et al. 2012:

    f    = 1 / (1 + exp((‖d_L1,H‖ · 2/ρ − 1) · α))          (2)
    v_L2 = V_max / (1 + exp((‖d_L2,H‖ · 2/ρ − 1) · α))      (4)

The paper names its sets after the iiwa's links; here each law takes the sets by the part
they play (:class:`~qpavoid.arm.roles.Roles`): the *scaled* set (L1: eqs. 2-3), the
*repelled* set (L2: eqs. 4-6, 9) and the *end-effector* set (EE: eqs. 7-8). The constants
keep the paper's names (``rho_L1_m``, ``d_stop_L2_m``, ...), one per part.

The repulsion of one tick (eqs. 4, 5 and 7 with the minima they need) is compiled
(numba, :func:`avoidance_terms`): a dozen numpy calls on arrays of eight parts cost more
in call overhead than in arithmetic (docs/performance.md §2a). It composes the compiled
:func:`logistic` of this very file, so numba's disk cache, keyed on this file, is never
stale. Every constant lives in :class:`AvoidanceConfig`; nothing here keeps state.
"""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Real

import numpy as np
from numba import njit
from numpy.typing import ArrayLike
from scipy.linalg import lapack

from qpavoid.arm.roles import Roles
from qpavoid.core.checks import finite_number
from qpavoid.core.errors import InputError, SolverError


@dataclass(frozen=True)
class AvoidanceConfig:
    """Constants of the avoidance laws. Distances in m, speeds in m/s.

    The names are the paper's: L1 is the scaled set, L2 the repelled set, EE the
    end-effector set of the robot description (:class:`~qpavoid.arm.roles.Roles`).

    Attributes
    ----------
    rho_L1_m, alpha_L1
        ρ and α of eq. (2) for the factor f of the scaled set. The paper's values: 0.1 m
        and 9.
    rho_rep_m, alpha_rep
        ρ and α of eq. (4) for the repulsion of the repelled and end-effector sets. Not
        given by the paper. With
        ρ = 0.1 m the repulsion is below 1 % of V_max beyond 0.075 m, a band too narrow
        to deflect before the 0.05 m stop; ρ = 0.2 m makes it V_max/2 at 0.1 m and
        1 % at 0.15 m.
    v_max_mps
        V_max of eq. (4): repulsive speed at contact. Not given by the paper; 0.25 m/s,
        the speed commonly used for collaborative operation (ISO 10218-1 reduced speed).
    f_stop
        Stop the robot when f exceeds this (paper Sect. 5.4: 0.8).
    d_stop_L2_m, d_stop_EE_m
        Stop the robot when the repelled (L2) or end-effector (EE) set is this close or
        closer (paper: 0.05 m).

    Raises
    ------
    InputError
        If a ρ or α is not positive and finite, V_max or a stop distance is negative or
        not finite, or ``f_stop`` is not strictly between 0 and 1.
    """

    rho_L1_m: float = 0.1
    alpha_L1: float = 9.0
    rho_rep_m: float = 0.2
    alpha_rep: float = 9.0
    v_max_mps: float = 0.25
    f_stop: float = 0.8
    d_stop_L2_m: float = 0.05
    d_stop_EE_m: float = 0.05

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if isinstance(value, bool) or not isinstance(value, Real):
                raise InputError(f"{name} must be a number, got {value!r}", name=name, value=value)
        for name in ("rho_L1_m", "alpha_L1", "rho_rep_m", "alpha_rep"):  # eqs. (2), (4)
            finite_number(getattr(self, name), name, positive=True)
        for name in ("v_max_mps", "d_stop_L2_m", "d_stop_EE_m", "f_stop"):
            value = finite_number(getattr(self, name), name)
            if value < 0.0 or (name == "f_stop" and not 0.0 < value < 1.0):  # eq. (2): f in (0, 1)
                kind = "between 0 and 1 (exclusive)" if name == "f_stop" else "at least 0"
                raise InputError(f"{name} must be {kind}, got {value!r}", name=name, value=value)

    def d_stop_L1_m(self) -> float:
        """The scaled set's distance at which f reaches ``f_stop`` (eq. 2 solved for d), m."""
        return distance_at_factor(self.f_stop, self.rho_L1_m, self.alpha_L1)


def logistic(d: ArrayLike, rho: float, alpha: float) -> np.ndarray:
    """``1 / (1 + exp((d · 2/ρ − 1) · α))``, the common shape of eqs. (2) and (4).

    Evaluated as ``(1 − tanh(x/2)) / 2`` so that it neither overflows far away nor
    turns NaN at d = +inf (a part that is not seen): it is 1 at d = −inf, 1/2 at d = ρ/2
    and 0 at d = +inf.
    """
    # ½ (1 − tanh(x/2)) with x = (2d/ρ − 1) α, folded into one affine map and one tanh.
    return 0.5 - 0.5 * np.tanh(np.multiply(d, alpha / rho) - 0.5 * alpha)


def distance_at_factor(f: float, rho: float, alpha: float) -> float:
    """Inverse of :func:`logistic`: the distance (m) at which it equals ``f``."""
    return 0.5 * rho * (1.0 + np.log(1.0 / f - 1.0) / alpha)


def l1_factor(d_L1: ArrayLike, cfg: AvoidanceConfig) -> np.ndarray:
    """Eq. (2): the factor f in [0, 1] from the scaled set's (L1's) minimum distance (m)."""
    return logistic(d_L1, cfg.rho_L1_m, cfg.alpha_L1)


def scaled_velocity_limits(
    dq_max: np.ndarray, f: float | np.ndarray, joints: np.ndarray | None = None
) -> np.ndarray:
    """Eq. (3): joint velocity limits with those of ``joints`` scaled by (1 − f), rad/s (±).

    Parameters
    ----------
    dq_max
        (nv,) nominal joint velocity limits, rad/s.
    f
        The L1 factor of eq. (2): a number, or (T,) for T ticks at once.
    joints
        Columns scaled (the joints that move the scaled set, ``Roles.scaled_joints``);
        None scales all.

    Returns
    -------
    np.ndarray
        (nv,) limits, or (T, nv) for (T,) ``f``.
    """
    cols = slice(None) if joints is None else joints
    if isinstance(f, float):  # one tick (the controllers' case): no broadcasting needed
        limits = np.array(dq_max, dtype=float)
        limits[cols] *= 1.0 - f
        return limits
    f = np.asarray(f, dtype=float)
    limits = np.repeat(np.asarray(dq_max, dtype=float)[None], f.size, axis=0).reshape(*f.shape, -1)
    limits[..., cols] *= (1.0 - f)[..., None]
    return limits


def repulsive_speed(d: ArrayLike, cfg: AvoidanceConfig) -> np.ndarray:
    """Eq. (4): repulsive speed (m/s) at distance ``d`` (m); V_max/2 at d = ρ/2."""
    return cfg.v_max_mps * logistic(d, cfg.rho_rep_m, cfg.alpha_rep)


#: :func:`logistic` compiled from its own source (numba), for :func:`avoidance_terms`.
_logistic = njit(cache=True)(logistic)


@njit(cache=True)
def repulsive_velocity(
    d: float, direction: np.ndarray, rho_rep: float, alpha_rep: float, v_max: float
) -> np.ndarray:
    """Eqs. (4)-(5): repulsive velocity (3,) m/s along the unit ``direction`` human → robot
    at distance ``d`` (m); zero for a part not seen (``d`` not finite). Compiled.

    ``rho_rep`` (m), ``alpha_rep`` and ``v_max`` (m/s): :func:`law_constants`.
    """
    v = np.zeros(3)
    if np.isfinite(d):
        v[:] = v_max * _logistic(d, rho_rep, alpha_rep) * direction
    return v


@njit(cache=True)
def ee_repulsive_velocity(
    d: np.ndarray, directions: np.ndarray, rho_rep: float, alpha_rep: float, v_max: float
) -> np.ndarray:
    """Eq. (7): sum over all human parts of the end effector's repulsive velocities (3,),
    m/s. Compiled.

    Parameters
    ----------
    d
        (K,) the end-effector set's distance to each part, m (+inf for parts not seen:
        they add nothing; a NaN spoils the sum).
    directions
        (K, 3) unit directions human → robot.
    rho_rep, alpha_rep, v_max
        :func:`law_constants`.
    """
    v = np.zeros(3)
    for k in range(d.shape[0]):  # 0 for a part not seen (d = +inf)
        speed = v_max * _logistic(d[k], rho_rep, alpha_rep)
        if speed > 0.0 or np.isnan(speed):
            v += speed * directions[k]
    return v


@njit(cache=True)
def avoidance_terms(
    distance: np.ndarray,
    vector: np.ndarray,
    repelled: int,
    end_effector: int,
    rho_rep: float,
    alpha_rep: float,
    v_max: float,
) -> tuple[np.ndarray, int, np.ndarray, np.ndarray]:
    """The avoidance terms of one tick, in one compiled call: the minima, eqs. (4)-(5), (7).

    f of eq. (2) stays :func:`l1_factor`'s (numpy): numba's tanh and numpy's differ in the
    last bit for some distances, and f decides a stop.

    Parameters
    ----------
    distance, vector
        The distance table's (S, K) distances, m, and (S, K, 3) unit directions human →
        robot (+inf and anything for a part not seen).
    repelled, end_effector
        Rows of the repelled and end-effector sets (``Roles.repelled``,
        ``Roles.end_effector``).
    rho_rep, alpha_rep, v_max
        ρ (m) and α of eq. (4) and V_max (m/s): an :class:`AvoidanceConfig`'s
        (:func:`law_constants`).

    Returns
    -------
    dmin, j, v_repelled, v_end_effector
        (S,) each set's minimum distance (``DistanceTable.min_per_set``); the column of
        the part closest to the repelled set (``closest_part``); eq. (5)'s velocity (3,)
        of the repelled set away from that part (0 if it is not seen) and eq. (7)'s sum
        (3,) over the parts the end-effector set sees, m/s.
    """
    S = distance.shape[0]
    dmin = np.empty(S)
    for s in range(S):
        dmin[s] = distance[s].min()
    j = np.argmin(distance[repelled])
    v_repelled = repulsive_velocity(
        distance[repelled, j], vector[repelled, j], rho_rep, alpha_rep, v_max
    )
    v_end_effector = ee_repulsive_velocity(
        distance[end_effector], vector[end_effector], rho_rep, alpha_rep, v_max
    )
    return dmin, int(j), v_repelled, v_end_effector


def law_constants(cfg: AvoidanceConfig) -> tuple[float, float, float]:
    """``cfg``'s constants of eqs. (4)-(7) in the compiled laws' order, as floats (an int
    would make numba compile a second specialisation at the first tick)."""
    return float(cfg.rho_rep_m), float(cfg.alpha_rep), float(cfg.v_max_mps)


def damped_pinv(J: np.ndarray, sigma_min: float, lambda_max: float) -> np.ndarray:
    """Damped pseudo-inverse ``V diag(σ/(σ² + λ²)) Uᵀ`` for eqs. (6) and (8).

    The damping is zero while the smallest singular value is above ``sigma_min`` (the
    exact inverse, as in the paper) and grows smoothly to ``lambda_max`` at a
    singularity: ``λ² = (1 − (σ_min/sigma_min)²) lambda_max²`` (Nakamura and Hanafusa).

    Raises
    ------
    SolverError
        If the SVD fails (``solver="lapack.dgesdd"``, ``status`` LAPACK's ``info``): it
        did not converge (info > 0) or ``J`` has a non-finite entry (info < 0). A
        controller tick turns it into a stop.
    """
    U, s, Vt, info = lapack.dgesdd(J, full_matrices=0)  # numpy's svd costs 2x in overhead
    if info != 0:
        why = "did not converge" if info > 0 else "the matrix has a non-finite entry"
        raise SolverError(
            f"SVD of the {J.shape[0]}x{J.shape[1]} Jacobian failed: {why} "
            f"(LAPACK dgesdd info {info})",
            solver="lapack.dgesdd",
            status=int(info),
        )
    lam2 = 0.0 if s[-1] >= sigma_min else (1.0 - (s[-1] / sigma_min) ** 2) * lambda_max**2
    return (Vt.T * (s / (s * s + lam2))) @ U.T


def repelled_joint_velocity(
    J_p: np.ndarray, v_rep: np.ndarray, sigma_min: float, lambda_max: float
) -> np.ndarray:
    """Eq. (6): velocities of the repelled set's joints that move its closest point at
    ``v_rep`` (m/s), rad/s.

    ``J_p`` is the (3, k) position Jacobian of the repelled set's point closest to the
    person with respect to its k joints (``Roles.repelled_joints``: for the iiwa the 3×3
    of A1, A2 and A4, the only joints that move the L2 points, reading notes §2).
    """
    return damped_pinv(J_p, sigma_min, lambda_max) @ v_rep


def modified_ik(
    J: np.ndarray,
    v_pl: np.ndarray,
    K: np.ndarray,
    e: np.ndarray,
    v_ee: np.ndarray,
    sigma_min: float,
    lambda_max: float,
) -> np.ndarray:
    """Eq. (8): ``q̇ = J⁻¹ (v_PL + K e + v_EE)`` with a damped inverse.

    Parameters
    ----------
    J
        (6, n) end-effector Jacobian, twist ``[v; ω]`` in the base frame.
    v_pl
        (6,) planned twist (m/s, rad/s).
    K
        (6,) diagonal gain (1/s).
    e
        (6,) pose error: position (m) and rotation vector (rad) of the desired pose
        relative to the current one, both in the base frame.
    v_ee
        (3,) EE repulsive velocity of eq. (7), m/s (it has no angular part).
    """
    target = v_pl + K * e
    target[:3] += v_ee
    return damped_pinv(J, sigma_min, lambda_max) @ target


def stop_rule_holds(
    f: float | np.ndarray,
    d_repelled: float | np.ndarray,
    d_end_effector: float | np.ndarray,
    cfg: AvoidanceConfig,
) -> bool | np.ndarray:
    """The paper's stop rules (Sect. 5.4), element-wise: f > 0.8, or the repelled (L2) or
    end-effector (EE) set's distance at most 0.05 m.

    Works on numbers or on arrays of ticks (checkers use it on whole logs).
    """
    return (
        (np.asarray(f) > cfg.f_stop)
        | (np.asarray(d_repelled) <= cfg.d_stop_L2_m)
        | (np.asarray(d_end_effector) <= cfg.d_stop_EE_m)
    )


def stop_distances(cfg: AvoidanceConfig) -> np.ndarray:
    """(3,) the distance at which the paper's rules stop the robot for the scaled,
    repelled and end-effector sets (``Roles.rows`` order), m.

    For the scaled set the distance where f reaches ``f_stop`` (eq. 2 inverted, 0.0423 m by
    default).
    """
    return np.array([cfg.d_stop_L1_m(), cfg.d_stop_L2_m, cfg.d_stop_EE_m])


def set_stop_distances(cfg: AvoidanceConfig, roles: Roles, n_sets: int) -> np.ndarray:
    """(S,) each robot set's stop distance (:func:`stop_distances` by role), m: 0 (contact)
    for a set that plays no part, the largest of its parts' for a set that plays several."""
    out = np.zeros(n_sets)
    np.maximum.at(out, list(roles.rows), stop_distances(cfg))
    return out


def stop_reason(
    f: float,
    d_repelled: float,
    d_end_effector: float,
    cfg: AvoidanceConfig,
    names: tuple[str, str, str],
) -> str | None:
    """The paper's stop rules (Sect. 5.4): a reason to stop, or None.

    Stop if f > 0.8, or if the repelled or end-effector set is 0.05 m or closer to the
    operator (:func:`stop_rule_holds` for arrays). ``names`` are the scaled, repelled and
    end-effector sets' names (the iiwa's: L1, L2, EE), which the reason quotes.
    """
    scaled, repelled, end_effector = names
    if f > cfg.f_stop:
        return f"f = {f:.3f} > {cfg.f_stop} ({scaled})"
    if d_repelled <= cfg.d_stop_L2_m:
        return f"d_{repelled} = {d_repelled:.3f} m <= {cfg.d_stop_L2_m} m"
    if d_end_effector <= cfg.d_stop_EE_m:
        return f"d_{end_effector} = {d_end_effector:.3f} m <= {cfg.d_stop_EE_m} m"
    return None


def stop_rule_prefixes(names: tuple[str, str, str]) -> tuple[str, str, str]:
    """How each reason of :func:`stop_reason` begins, for the sets ``names``."""
    return ("f = ", f"d_{names[1]}", f"d_{names[2]}")
