"""Constants of the QP controller, in one place."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class QPConfig:
    """Weights, gains and solver settings of :class:`~qpavoid.control.qp.controller.QPController`.

    Attributes
    ----------
    weight_position, weight_orientation
        Weights of the linear (per m/s) and angular (per rad/s) rows of the end-effector
        task of eq. (8). Where the task can be met exactly (nobody near) they do not change
        the answer; they set the trade-off once constraints bind.
    weight_repulsion
        Weight of the slack of each repulsion cost (per m/s): how hard the repelled set's
        closest point and the end effector are asked to move away at least as fast as
        eqs. (4)-(7) say.
    regularization
        Weight of ‖q̇‖² (per rad/s): keeps the problem strictly convex; small enough that
        the answer stays within 1e-5 rad/s of eq. (8) when nothing binds.
    damper_influence_m
        Pairs closer than this get a velocity damper row, m.
    damper_gain_mps
        ξ: the approach speed a damper allows at the influence distance, m/s; it falls
        linearly to 0 at the set's stop distance.
    position_limit_gain
        γ in (0, 1]: a joint may close at most this fraction of its distance to a position
        limit in one control period.
    elbow_weight, elbow_influence_m, elbow_speed_mps
        Redundancy mode only (7 joints): a cost asking the elbow (the robot description's
        ``[roles] elbow``; A4 for the iiwa) to move away from the closest person point at
        ``elbow_speed_mps`` times eq. (4)'s shape with ρ = ``elbow_influence_m``; 0
        disables it.
    backend
        ``"persistent"`` (the default): one ``osqp.OSQP`` problem set up once and updated
        each tick (warm started); ``"daqp"``: daqp called directly each tick, cold
        (docs/qp.md: 11 µs a solve against persistent OSQP's 53); ``"qpsolvers"``: a new
        problem each tick through qpsolvers.
    solver
        Solver name for the qpsolvers backend (``osqp``, ``proxqp``, ``daqp``, ...).
    eps_abs, eps_rel, max_iter, polish
        OSQP settings (both backends). OSQP's default 1e-3 is far too loose for a problem
        this small; 1e-7 matches an active-set solver (daqp) to the tolerance of
        docs/qp.md. Polishing stays off: osqp 1.x can accept a polished solution far outside
        the tolerances and still report "solved" (osqp/osqp#790), and it prints a line on
        every solve without an active set whatever ``verbose`` says (osqp/osqp#785).
    """

    weight_position: float = 1.0
    weight_orientation: float = 1.0
    weight_repulsion: float = 10.0
    regularization: float = 1e-7
    damper_influence_m: float = 0.15
    damper_gain_mps: float = 0.25
    position_limit_gain: float = 0.5
    elbow_weight: float = 0.0
    elbow_influence_m: float = 0.4
    elbow_speed_mps: float = 0.1
    backend: str = "persistent"
    solver: str = "osqp"
    eps_abs: float = 1e-7
    eps_rel: float = 1e-7
    max_iter: int = 4000
    polish: bool = False
