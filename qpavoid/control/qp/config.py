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
    posture_weight, posture_gain_per_s
        Redundancy mode: a cost (:class:`~qpavoid.control.qp.tasks.posture.PostureTask`)
        pulling q towards the rest posture at ``posture_gain_per_s × (q_rest − q)``, only in
        the end effector's null space (it never moves the end effector); 0 (the default)
        disables it, as a 6-joint arm has no null space. The rest posture is the start
        configuration (:class:`~qpavoid.control.qp.controller.QPController`). w = 1e-3 per
        (rad/s)² (the redundancy mode's, ``REDUNDANT.posture_weight``) is ten times the
        redundancy mode's regularisation, so the null-space motion is 91 % of the pull,
        and a third of the elbow cost's curvature along the swivel (0.05 × (0.25 m/rad)²),
        so a person near the elbow still pushes it away; k = 0.5 /s returns a posture in
        about 2 s (time constant) at no more than 0.5 rad/s per rad of error.
    backend
        ``"persistent"`` (the default): one ``osqp.OSQP`` problem set up once and updated
        each tick (warm started); ``"daqp"``: daqp called directly each tick, cold
        (faster than OSQP on these small problems: docs/qp.md); ``"qpsolvers"``: a new
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
    posture_weight: float = 0.0
    posture_gain_per_s: float = 0.5
    backend: str = "persistent"
    solver: str = "osqp"
    eps_abs: float = 1e-7
    eps_rel: float = 1e-7
    max_iter: int = 4000
    polish: bool = False


#: The redundancy mode (``qpavoid run ... --controller qp --redundant``, docs/qp.md): the
#: elbow kept away from the person (weight 0.05) and the posture task (weight 1e-3), both
#: in the null space of a redundant arm's end effector, with a regularisation large enough
#: to give that direction curvature (with 1e-7 OSQP cannot reach its tolerance there).
REDUNDANT = QPConfig(elbow_weight=0.05, regularization=1e-4, posture_weight=1e-3)
