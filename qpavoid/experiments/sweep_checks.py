"""What a sweep's case is judged for: an approach's invariants, a strike's or a close-work
case's contact with the true person, and the times a run reports.

Each kind of case (:mod:`qpavoid.experiments.sweep`) has its check: :class:`ApproachCheck`
(the invariants of each tick, :func:`check_log`), :class:`StrikeCheck` and
:class:`CloseWorkCheck` (judged against the truth, with power and force limiting's
:class:`TouchCounts`), each made from its simulated run (:func:`approach_check`,
:func:`strike_check`, :func:`closework_check`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, TypeAlias

import numpy as np

from qpavoid.arm.model import Robot, joint_columns
from qpavoid.control.tick import ControllerConfig
from qpavoid.distance.methods import geometry
from qpavoid.experiments.runs import RunResult
from qpavoid.laws.avoidance import (
    scaled_velocity_limits,
    set_stop_distances,
    stop_rule_holds,
)
from qpavoid.scenarios.closework import CloseWorkCase
from qpavoid.scenarios.strikes import StrikeCase

__all__ = [
    "ApproachCheck",
    "Check",
    "CloseWorkCheck",
    "StrikeCheck",
    "TouchCounts",
    "approach_check",
    "braking_ticks",
    "check_log",
    "closework_check",
    "strike_check",
    "true_contact_fields",
]


@dataclass(frozen=True)
class ApproachCheck:
    """The outcome of one random approach (counts are ticks).

    Attributes
    ----------
    seed, controller, distance
        What was run.
    ticks
        Number of control ticks simulated.
    position_violations, velocity_violations
        Ticks with a joint outside its position limits / over its scaled velocity limit.
    moving_under_stop_rule
        Ticks with a non-zero command while a stop rule held, other than a braking ramp's
        (:func:`braking_ticks`).
    moving_below_capsule_threshold
        Ticks with a non-zero command while a set's capsule distance was below its
        threshold, other than a braking ramp's.
    min_capsule_distance_moving_m
        Per set, by name: the smallest capsule distance over the ticks where the robot
        moved, m.
    stopped_s, reached_goal
        Time spent stopped, s, and whether the goal was reached.
    command_limit_violations
        Commands beyond the arm's velocity, acceleration or jerk limits
        (:class:`~qpavoid.drive.limits.CommandCheck`).
    """

    kind: ClassVar[str] = "approach"

    seed: int
    controller: str
    distance: str
    ticks: int
    position_violations: int
    velocity_violations: int
    moving_under_stop_rule: int
    moving_below_capsule_threshold: int
    min_capsule_distance_moving_m: dict[str, float]
    stopped_s: float
    reached_goal: bool
    command_limit_violations: int = 0

    @property
    def safe(self) -> bool:
        """True if no invariant was broken."""
        return not (
            self.command_limit_violations
            or self.position_violations
            or self.velocity_violations
            or self.moving_under_stop_rule
            or self.moving_below_capsule_threshold
        )


@dataclass(frozen=True, kw_only=True)
class TouchCounts:
    """What power and force limiting's judge says of a run's true contacts (fields of
    :class:`StrikeCheck` and :class:`CloseWorkCheck`, :func:`true_contact_fields`).

    Attributes
    ----------
    ticks_moving_protected_contact, ticks_contact_above_limit, ticks_contact_within_limit
        Power and force limiting judged against the truth (``true_contacts`` of the run's
        metrics, :func:`~qpavoid.loop.metrics.contact_metrics`): ticks the arm moved while
        touching the head, face, neck or trunk; ticks an arm or hand region was touched
        faster than its Annex A limit; ticks every touch was within it.
    ticks_clamped
        Ticks an arm or hand region was touched where it could be pinned against the table.
    ticks_pushed
        Ticks the robot had advanced into a free arm or hand region further than its
        allowance δ = F_T / k over one contact (pushed it along: reported, not a limit).
    max_contact_speed_mps, max_contact_speed_ratio, max_contact_advance_m, max_contact_force_n
        Over the touches of arm and hand regions: the robot point's fastest speed towards
        the part (m/s), its largest ratio to the region's limit, the robot's deepest
        advance into a part over one contact (m), the largest impact force (N); 0 without
        any.
    """

    ticks_moving_protected_contact: int = 0
    ticks_contact_above_limit: int = 0
    ticks_contact_within_limit: int = 0
    ticks_clamped: int = 0
    ticks_pushed: int = 0
    max_contact_speed_mps: float = 0.0
    max_contact_speed_ratio: float = 0.0
    max_contact_advance_m: float = 0.0
    max_contact_force_n: float = 0.0


@dataclass(frozen=True)
class StrikeCheck(TouchCounts):
    """One strike (:func:`~qpavoid.scenarios.strikes.strike_case`) judged against the truth.

    Attributes
    ----------
    seed, controller, safety
        What was run.
    target, speed_mps, side, both_hands, fault
        The strike.
    ticks_moving_in_true_contact
        Ticks in which the arm moved (its real velocity, braking included) while a robot
        capsule touched the true person.
    min_true_clearance_moving_m
        Smallest true capsule distance over the ticks in which the arm moved, m (+inf if
        it never moved).
    moving_s, stopped_s
        Time the arm moved / the controller held a stop, s.
    max_stop_speed_mps
        The fastest robot point when a stop began, m/s (0 if none).
    ticks_moving_below_stop_distance
        Ticks in which the arm moved while a set was truly closer than its stop distance.
    reached_goal, duration_s
        Whether the path's goal was reached, and when the run ended, s.
    limit_violations
        Ticks over a joint's velocity or position limit.
    command_limit_violations
        Commands beyond the arm's velocity, acceleration or jerk limits.
    tick_us_median, tick_us_p99
        The controller's time per tick, µs (measured: not reproducible).

    The contacts' judgement by power and force limiting: :class:`TouchCounts`'s fields.
    """

    kind: ClassVar[str] = "strike"

    seed: int
    controller: str
    safety: str
    target: str
    speed_mps: float
    side: str
    both_hands: bool
    fault: str
    ticks_moving_in_true_contact: int
    min_true_clearance_moving_m: float
    moving_s: float
    stopped_s: float
    max_stop_speed_mps: float
    ticks_moving_below_stop_distance: int = 0
    reached_goal: bool = False
    duration_s: float = 0.0
    limit_violations: int = 0
    tick_us_median: float = 0.0
    tick_us_p99: float = 0.0
    command_limit_violations: int = 0


@dataclass(frozen=True)
class CloseWorkCheck(TouchCounts):
    """One close-work case (:func:`~qpavoid.scenarios.closework.closework_case`) judged
    against the truth, and for productivity.

    Attributes
    ----------
    seed, controller, safety
        What was run.
    variant, side
        The case: one of :data:`~qpavoid.scenarios.closework.VARIANTS`, and its hand.
    time_to_goal_s
        When the goal was reached (the run ends there), s; None if it was not.

    The others as :class:`StrikeCheck`'s (:func:`true_contact_fields`, :func:`_run_fields`).

    The contacts' judgement by power and force limiting: :class:`TouchCounts`'s fields.
    """

    kind: ClassVar[str] = "closework"

    seed: int
    controller: str
    safety: str
    variant: str
    side: str
    ticks_moving_in_true_contact: int
    min_true_clearance_moving_m: float
    moving_s: float
    stopped_s: float
    reached_goal: bool
    time_to_goal_s: float | None
    duration_s: float
    limit_violations: int = 0
    command_limit_violations: int = 0
    tick_us_median: float = 0.0
    tick_us_p99: float = 0.0


#: What a sweep's run gives: an approach's, a strike's or a close-work case's check.
Check: TypeAlias = ApproachCheck | StrikeCheck | CloseWorkCheck


def braking_ticks(dq_command: np.ndarray) -> np.ndarray:
    """(T,) the ticks whose command brakes: every joint as fast as the tick before or slower,
    in the same direction (``u_k,j u_{k−1},j ≥ 0`` and ``|u_k,j| ≤ |u_{k−1},j|``), and the
    command no longer the same (a hold is not braking) or zero. A stop ramp
    (:meth:`~qpavoid.control.smoothing.CommandRamp.brake`) is braking at every tick; so is
    the slowing that a lowered velocity limit (eq. 3) asks for, which the arm cannot do at
    once. A zero command always is (and is not moving)."""
    u = np.asarray(dq_command, dtype=float)
    before = np.vstack([np.zeros((1, u.shape[1])), u[:-1]])
    slower = np.all((u * before >= 0.0) & (np.abs(u) <= np.abs(before) + 1e-12), axis=1)
    changed = np.any(u != before, axis=1)
    return (slower & changed) | ~np.any(u != 0.0, axis=1)


def check_log(
    log: dict[str, np.ndarray], robot: Robot, config: ControllerConfig, distance: str
) -> dict[str, Any]:
    """Tick counts of every broken invariant in a simulation log (the approach's, in
    :mod:`qpavoid.experiments.sweep`'s docstring).

    Returns a dict with ``position_violations``, ``velocity_violations``,
    ``moving_under_stop_rule``, ``moving_below_capsule_threshold`` (tick counts) and
    ``min_capsule_distance_moving_m`` (per set, by name, m).

    Every set is held to its stop distance (:func:`set_stop_distances`: contact for a set
    that plays no part in the laws, as the controller holds it).
    """
    avo, roles = config.avoidance, robot.roles
    capsule = log["distance"] if geometry(distance) == "capsules" else log["distance_other"]
    threshold = set_stop_distances(avo, roles, len(robot.sets))
    moving = np.any(log["dq_command"] != 0.0, axis=1)  # the controller's decisions
    braking = braking_ticks(log["dq_command"])
    seen = log["distance"]
    rule = stop_rule_holds(log["f"], seen[:, roles.repelled], seen[:, roles.end_effector], avo)
    cols = joint_columns(robot, config.scaled_joints, "scaled_joints")
    limits = scaled_velocity_limits(robot.dq_max, log["f"], cols)  # eq. (3)
    over = np.any(np.abs(log["dq_command"]) > limits * (1 + 1e-9) + 1e-12, axis=1) & ~braking
    outside = np.any((log["q"] > robot.q_max) | (log["q"] < robot.q_min), axis=1)
    below = np.any(capsule < threshold, axis=1)
    closest = capsule[moving].min(axis=0) if moving.any() else np.full(len(robot.sets), np.inf)
    return {
        "position_violations": int(outside.sum()),
        "velocity_violations": int(over.sum()),
        "moving_under_stop_rule": int((moving & rule & ~braking).sum()),
        "moving_below_capsule_threshold": int((moving & below & ~braking).sum()),
        "min_capsule_distance_moving_m": {
            name: float(x) for name, x in zip(robot.set_names, closest, strict=True)
        },
    }


def approach_check(seed: int, run: RunResult) -> ApproachCheck:
    """The check of the random approach ``seed``, simulated as ``run``."""
    spec = run.spec
    return ApproachCheck(
        seed,
        spec.controller,
        spec.distance,
        len(run.sim.log["t"]),
        **check_log(run.sim.log, run.robot, run.config, spec.distance),
        stopped_s=run.metrics["stopped_s"],
        reached_goal=run.metrics["reached_goal"],
        command_limit_violations=sum(run.metrics["command_limit_violations"].values()),
    )


def true_contact_fields(run: RunResult) -> dict[str, Any]:
    """What a run judged against the truth says of contact, as fields of a check
    (:class:`StrikeCheck`, :class:`CloseWorkCheck`): ``ticks_moving_in_true_contact``
    (ticks in which the arm moved while a robot capsule touched the true person),
    ``min_true_clearance_moving_m`` (the smallest true distance while it moved, m; +inf
    if it never moved), and power and force limiting's judgement of each touch
    (``ticks_moving_protected_contact``, ``ticks_contact_above_limit``,
    ``ticks_contact_within_limit``, ``ticks_clamped``, ``ticks_pushed``, ``max_contact_speed_mps``,
    ``max_contact_speed_ratio``, ``max_contact_advance_m``, ``max_contact_force_n``)."""
    m = run.sim.metrics
    clearance = m["min_true_clearance_moving_m"]
    touched = m.get("true_contacts") or {}
    return {
        "ticks_moving_in_true_contact": int(m["ticks_moving_in_true_contact"]),
        "min_true_clearance_moving_m": float("inf") if clearance is None else float(clearance),
        "ticks_moving_protected_contact": int(touched.get("ticks_moving_protected", 0)),
        "ticks_contact_above_limit": int(touched.get("ticks_above_limit", 0)),
        "ticks_contact_within_limit": int(touched.get("ticks_within_limit", 0)),
        "ticks_clamped": int(touched.get("ticks_clamped", 0)),
        "ticks_pushed": int(touched.get("ticks_pushed", 0)),
        "max_contact_speed_mps": float(touched.get("max_speed_mps") or 0.0),
        "max_contact_speed_ratio": float(touched.get("max_speed_ratio") or 0.0),
        "max_contact_advance_m": float(touched.get("max_advance_m") or 0.0),
        "max_contact_force_n": float(touched.get("max_force_n") or 0.0),
    }


def _run_fields(run: RunResult) -> dict[str, Any]:
    """What every judged run reports besides contact: time moving and stopped, the goal,
    the duration, limits broken and the controller's tick times."""
    m, log = run.sim.metrics, run.sim.log
    moving = np.any(log["dq"] != 0.0, axis=1)
    return {
        "moving_s": float(moving.sum() / run.spec.rate_hz),
        "stopped_s": float(m["stopped_s"]),
        "reached_goal": bool(m["reached_goal"]),
        "duration_s": float(m["duration_s"]),
        "limit_violations": int(
            m["joint_velocity_limit_violations"] + m["joint_position_limit_violations"]
        ),
        "tick_us_median": float(m["tick_us"]["median"]),
        "tick_us_p99": float(m["tick_us"]["p99"]),
        "command_limit_violations": sum(m["command_limit_violations"].values()),
    }


def strike_check(case: StrikeCase, run: RunResult) -> StrikeCheck:
    """The check of the strike ``case``, simulated as ``run``."""
    m = run.sim.metrics
    return StrikeCheck(
        seed=case.seed,
        controller=run.spec.controller,
        safety=run.spec.safety,
        target=case.target,
        speed_mps=case.speed_mps,
        side=case.side,
        both_hands=case.both_hands,
        fault=case.fault,
        max_stop_speed_mps=max(
            (e.get("robot_speed_mps", 0.0) for e in m["stop_events"]), default=0.0
        ),
        ticks_moving_below_stop_distance=int(m["ticks_moving_below_stop_distance"] or 0),
        **true_contact_fields(run),
        **_run_fields(run),
    )


def closework_check(case: CloseWorkCase, run: RunResult) -> CloseWorkCheck:
    """The check of the close-work case ``case``, simulated as ``run``."""
    fields = _run_fields(run)
    return CloseWorkCheck(
        seed=case.seed,
        controller=run.spec.controller,
        safety=run.spec.safety,
        variant=case.variant,
        side=case.side,
        # the run ends at the goal: its duration is the time to reach it
        time_to_goal_s=fields["duration_s"] if fields["reached_goal"] else None,
        **true_contact_fields(run),
        **fields,
    )
