"""Sweeps: many seeded runs of one kind, each judged, then summed up.

The one engine behind ``qpavoid sweep`` (:mod:`qpavoid.experiments.campaign`),
:func:`safety_sweep` and :func:`strike_sweep`. A sweep is a :class:`SweepSpec` (what its
runs share) and seeds; the spec's *kind* chooses the motion and the check:

``"approach"`` (:class:`ApproachCheck`)
    A random hand approach (scenario ``random:SEED``,
    :func:`~qpavoid.scenarios.generated.random_approach`) on the real bench, each tick
    checked (:func:`check_log`) for what must never happen:

    * a joint outside its position limits, or faster than its (eq. 3 scaled) velocity
      limit;
    * a non-zero command while one of the paper's stop rules holds;
    * the robot moving while the *exact capsule* distance of a set is below that set's
      stop threshold (0.05 m for L2 and EE; for L1 the distance where f = 0.8),
      whichever distance method the controller itself uses.

``"strike"`` (:class:`StrikeCheck`)
    A hand, or both, driven from rest into a robot set, the shoulder or the base
    (:mod:`qpavoid.scenarios.strikes`: up to ``max_speed_mps``, lost, inferred or frozen
    limbs, frame gaps and jitter) on the real bench, judged against the truth: ticks in
    which the arm moved while a robot capsule touched the true person, and the true
    clearance while moving.

``"closework"`` (:class:`CloseWorkCheck`)
    The operator working within reach of the path, never at the robot
    (:mod:`qpavoid.scenarios.closework`: hands resting or working 0.1-0.3 m from it,
    reaching across it, handing over a part; scenario ``closework:SEED``) on the real
    bench with a clean camera, judged against the truth as strikes are, and for
    productivity: whether and when the goal was reached, the time stopped.

Every run depends on its seed alone, so a sweep is a map over seeds
(:func:`~qpavoid.experiments.jobs.map_jobs`): a local process pool or any executor with
``map`` (Ray's, a cluster's), results in seed order whatever the number of workers.
:func:`summarize` sums any kind up.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from concurrent.futures import Executor
from dataclasses import asdict, dataclass
from typing import Any, ClassVar, TypeAlias, cast

import numpy as np

from qpavoid.arm.model import Robot, joint_columns, load_robot
from qpavoid.control.tick import ControllerConfig
from qpavoid.core.checks import check_choice
from qpavoid.core.errors import InputError
from qpavoid.experiments.jobs import map_jobs
from qpavoid.experiments.runs import RunResult, RunSpec, simulate_one
from qpavoid.laws.avoidance import (
    scaled_velocity_limits,
    set_stop_distances,
    stop_rule_holds,
)
from qpavoid.loop.camera import CameraConfig
from qpavoid.scenarios.closework import (
    VARIANTS,
    CloseWorkCase,
    closework_case,
    closework_motion,
)
from qpavoid.scenarios.strikes import StrikeCase, strike_camera, strike_case, strike_motion

__all__ = [
    "KINDS",
    "ApproachCheck",
    "Check",
    "CloseWorkCheck",
    "StrikeCheck",
    "SweepSpec",
    "as_dicts",
    "check_log",
    "run_case",
    "safety_sweep",
    "strike_sweep",
    "summarize",
    "sweep",
    "true_contact_fields",
]

#: The kinds of case a sweep runs.
KINDS = ("approach", "strike", "closework")
#: An approach lasts this long unless the spec says otherwise, s.
APPROACH_MAX_TIME_S = 25.0
#: The progress bar's label and unit, per kind.
_PROGRESS = {
    "approach": ("safety sweep", "approach"),
    "strike": ("strike sweep", "strike"),
    "closework": ("close-work sweep", "case"),
}


@dataclass(frozen=True)
class SweepSpec:
    """What every run of a sweep shares; a run is this and its seed.

    Checked when it is made (as the :class:`~qpavoid.experiments.run_spec.RunSpec` of
    its runs), so that bad settings fail before any run starts.

    Attributes
    ----------
    kind
        ``"approach"``, ``"strike"`` or ``"closework"`` (module docstring).
    controller, distance, safety
        As in :class:`~qpavoid.experiments.run_spec.RunSpec`.
    rate_hz
        Control rate, Hz.
    max_time_s
        Cap on each run, s; None: an approach's 25 s, a strike's own duration (the
        hand's approach, 1.5 s of holding and 0.5 s more), a close-work case's (the
        path and 15 s more).
    max_speed_mps
        Strikes only: the fastest peak hand speed drawn, m/s (from 0.5 m/s up).
    latency_s
        The camera's latency, s (None: its format file's).
    robot
        The robot description (a bundled name or a folder).
    camera
        The simulated camera's skeleton format (:class:`~qpavoid.experiments.run_spec.
        RunSpec`'s ``camera``).
    payload_kg
        The payload at the end effector, kg (:class:`~qpavoid.experiments.run_spec.
        RunSpec`'s).
    """

    kind: str
    controller: str = "qp"
    distance: str = "capsules"
    safety: str = "ssm"
    rate_hz: float = 100.0
    max_time_s: float | None = None
    max_speed_mps: float = 2.0
    latency_s: float | None = None
    robot: str = "iiwa14"
    camera: str = "kinect_v2"
    payload_kg: float = 0.0

    def __post_init__(self) -> None:
        check_choice("sweep kind", self.kind, KINDS)
        self.run_spec(0, APPROACH_MAX_TIME_S)  # checks every other setting

    def run_spec(self, seed: int, duration_s: float | None = None) -> RunSpec:
        """The run of ``seed``, lasting ``max_time_s`` or else the case's own
        ``duration_s`` (a strike's or a close-work case's, s); a strike's motion and
        camera, a close-work case's motion aside (:func:`run_case`)."""
        if self.kind == "approach":
            scenario, truth = f"random:{seed}", False  # checked on what the controller saw
            duration_s = APPROACH_MAX_TIME_S
        elif self.kind == "closework":
            scenario, truth = f"closework:{seed}", True  # judged on the truth
        else:
            scenario, truth = "free", True  # the strike is its motion; judged on the truth
        max_time_s = self.max_time_s if self.max_time_s is not None else duration_s
        if max_time_s is None:
            raise InputError(
                f"a {self.kind} run needs its duration or a cap", name="max_time_s", value=None
            )
        return RunSpec(
            scenario=scenario,
            controller=self.controller,
            distance=self.distance,
            safety=self.safety,
            rate_hz=self.rate_hz,
            max_time_s=max_time_s,
            latency_s=self.latency_s,
            robot=self.robot,
            measure_truth=truth,
            camera=self.camera,
            payload_kg=self.payload_kg,
        )


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
    """Tick counts of every broken invariant in a simulation log (module docstring).

    Returns a dict with ``position_violations``, ``velocity_violations``,
    ``moving_under_stop_rule``, ``moving_below_capsule_threshold`` (tick counts) and
    ``min_capsule_distance_moving_m`` (per set, by name, m).

    Every set is held to its stop distance (:func:`set_stop_distances`: contact for a set
    that plays no part in the laws, as the controller holds it).
    """
    avo, roles = config.avoidance, robot.roles
    capsule = log["distance"] if distance == "capsules" else log["distance_other"]
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


def run_case(spec: SweepSpec, seed: int) -> Check:
    """Simulate the case ``seed`` of ``spec``'s kind and judge it (module docstring)."""
    if spec.kind == "approach":  # the scenario random:SEED, seen through the bench's Kinect
        return _approach_check(seed, simulate_one(spec.run_spec(seed)))
    if spec.kind == "closework":  # the operator at work beside the path, a clean camera
        return _closework_run(spec, seed)
    robot = load_robot(spec.robot)  # the strike, aimed at its sets, seen through a faulty Kinect
    case = strike_case(seed, spec.max_speed_mps, robot)
    run_spec = spec.run_spec(seed, case.duration_s)
    camera = strike_camera(
        case,
        CameraConfig.of(spec.camera, latency_s=run_spec.sensor_latency_s, seed=case.seed),
    )
    run = simulate_one(
        run_spec,
        strike_motion(case, robot),
        robot=robot,
        camera=camera,
    )
    return _strike_check(case, run)


def _closework_run(spec: SweepSpec, seed: int) -> CloseWorkCheck:
    """The close-work case ``seed`` of ``spec``, simulated and judged."""
    robot = load_robot(spec.robot)
    case = closework_case(seed, robot)
    run_spec = spec.run_spec(seed, case.duration_s)
    camera = CameraConfig.of(spec.camera, latency_s=run_spec.sensor_latency_s, seed=case.seed)
    run = simulate_one(run_spec, closework_motion(case, robot), robot=robot, camera=camera)
    return _closework_check(case, run)


def _approach_check(seed: int, run: RunResult) -> ApproachCheck:
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


def _strike_check(case: StrikeCase, run: RunResult) -> StrikeCheck:
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


def _closework_check(case: CloseWorkCase, run: RunResult) -> CloseWorkCheck:
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


def _run_case(job: tuple[SweepSpec, int]) -> Check:
    return run_case(*job)


def sweep(
    spec: SweepSpec,
    seeds: Iterable[int],
    workers: int | None = None,
    executor: Executor | None = None,
    progress: bool = False,
) -> list[Check]:
    """:func:`run_case` of every seed, in parallel.

    Parameters
    ----------
    spec
        What the runs share.
    seeds
        One run each.
    workers
        Local processes (default: all cores); 1 runs in this process.
    executor
        Any object with ``map`` (Ray's, a cluster's) to use instead of a local pool.
    progress
        Show a progress bar (on a terminal only).

    Returns
    -------
    list of ApproachCheck or of StrikeCheck
        In the order of ``seeds``, whatever the number of workers.
    """
    desc, unit = _PROGRESS[spec.kind]
    jobs = [(spec, int(s)) for s in seeds]
    return map_jobs(
        _run_case, jobs, workers=workers, executor=executor, progress=progress, desc=desc, unit=unit
    )


def summarize(checks: Sequence[Check]) -> dict[str, Any]:
    """A sweep's totals (the ``qpavoid sweep`` summary for strikes and close work);
    everything but a strike or close-work sweep's ``timing`` is reproducible from the
    seeds.

    Raises
    ------
    InputError
        If there is nothing to sum up.
    """
    if not checks:
        raise InputError("a sweep's summary needs at least one run", name="checks", value=[])
    if checks[0].kind == "approach":
        return _approach_totals(cast(Sequence[ApproachCheck], checks))
    if checks[0].kind == "closework":
        return _closework_totals(cast(Sequence[CloseWorkCheck], checks))
    return _strike_totals(cast(Sequence[StrikeCheck], checks))


def _approach_totals(checks: Sequence[ApproachCheck]) -> dict[str, Any]:
    return {
        "approaches": len(checks),
        "unsafe": sum(not c.safe for c in checks),
        "position_violations": sum(c.position_violations for c in checks),
        "velocity_violations": sum(c.velocity_violations for c in checks),
        "moving_under_stop_rule": sum(c.moving_under_stop_rule for c in checks),
        "command_limit_violations": sum(c.command_limit_violations for c in checks),
        "moving_below_capsule_threshold": sum(c.moving_below_capsule_threshold for c in checks),
        "min_capsule_distance_moving_m": {
            name: min(c.min_capsule_distance_moving_m[name] for c in checks)
            for name in checks[0].min_capsule_distance_moving_m
        },
        "reached_goal": sum(c.reached_goal for c in checks),
        "mean_stopped_s": float(np.mean([c.stopped_s for c in checks])),
    }


def _mm(x: float) -> float:
    """``x`` m in mm, to the µm."""
    return round(float(x) * 1e3, 3)


def _clearance_totals(runs: Sequence[StrikeCheck | CloseWorkCheck]) -> dict[str, float | None]:
    """The true clearance while moving over the runs that moved, mm: min, p01, median."""
    clear = np.array([r.min_true_clearance_moving_m for r in runs])
    moved = np.isfinite(clear)
    return {
        "min": _mm(clear[moved].min()) if moved.any() else None,
        "p01": _mm(np.percentile(clear[moved], 1)) if moved.any() else None,
        "median": _mm(np.median(clear[moved])) if moved.any() else None,
    }


def _timing(runs: Sequence[StrikeCheck | CloseWorkCheck]) -> dict[str, float]:
    """The controller's tick times over the runs, µs: the median of the runs' medians,
    the 99th percentile of their p99s."""
    return {
        "tick_us_median": float(np.median([r.tick_us_median for r in runs])),
        "tick_us_p99": float(np.percentile([r.tick_us_p99 for r in runs], 99)),
    }


def _contact_totals(runs: Sequence[StrikeCheck | CloseWorkCheck]) -> dict[str, Any]:
    """Power and force limiting over the runs (issue 29): runs whose arm moved while
    touching the head, face, neck or trunk, runs touching an arm or hand region above its
    limit (both must be zero), runs touching one within it (allowed with ``pfl``), runs
    clamping, the contact ticks within limit, and the fastest touch, its ratio to its
    limit, the deepest advance into a part (mm) and the largest force, with the medians
    over the runs that touched."""
    touched = [r for r in runs if r.ticks_contact_within_limit or r.ticks_contact_above_limit]

    def spread(values: list[float]) -> dict[str, float | None]:
        return {
            "max": round(float(np.max(values)), 6) if values else None,
            "median": round(float(np.median(values)), 6) if values else None,
        }

    return {
        "runs_touching_protected_regions": sum(r.ticks_moving_protected_contact > 0 for r in runs),
        "runs_touching_above_limit": sum(r.ticks_contact_above_limit > 0 for r in runs),
        "runs_touching_within_limit": sum(r.ticks_contact_within_limit > 0 for r in runs),
        "runs_clamping": sum(r.ticks_clamped > 0 for r in runs),
        "runs_pushing": sum(r.ticks_pushed > 0 for r in runs),
        "ticks_touching_within_limit": sum(r.ticks_contact_within_limit for r in runs),
        "contact_speed_mps": spread([r.max_contact_speed_mps for r in touched]),
        "contact_speed_ratio": spread([r.max_contact_speed_ratio for r in touched]),
        "contact_advance_mm": spread([1e3 * r.max_contact_advance_m for r in touched]),
        "contact_force_n": spread([r.max_contact_force_n for r in touched]),
    }


def _strike_totals(runs: Sequence[StrikeCheck]) -> dict[str, Any]:
    return {
        "runs": len(runs),
        "runs_moving_in_true_contact": sum(r.ticks_moving_in_true_contact > 0 for r in runs),
        "runs_moving_below_stop_distance": sum(
            r.ticks_moving_below_stop_distance > 0 for r in runs
        ),
        "true_clearance_moving_mm": _clearance_totals(runs),
        "fraction_reaching_goal": sum(r.reached_goal for r in runs) / len(runs),
        "mean_time_stopped_s": round(float(np.mean([r.stopped_s for r in runs])), 6),
        "mean_duration_s": round(float(np.mean([r.duration_s for r in runs])), 6),
        "runs_with_limit_violations": sum(r.limit_violations > 0 for r in runs),
        "runs_with_command_limit_violations": sum(r.command_limit_violations > 0 for r in runs),
        "contacts": _contact_totals(runs),
        "timing": _timing(runs),
    }


def _goal_times(runs: Sequence[CloseWorkCheck]) -> list[float]:
    """The times to goal of the runs that reached it, s."""
    return [r.time_to_goal_s for r in runs if r.time_to_goal_s is not None]


def _closework_totals(runs: Sequence[CloseWorkCheck]) -> dict[str, Any]:
    """Safety as strikes' (true contact, clearance), then productivity: the fraction of
    runs reaching the goal, the time to it over those that did (None if none did), the
    time stopped, per variant too."""
    times = _goal_times(runs)
    per_variant = {}
    for variant in VARIANTS:
        these = [r for r in runs if r.variant == variant]
        if not these:
            continue
        reached = _goal_times(these)
        per_variant[variant] = {
            "runs": len(these),
            "fraction_reaching_goal": sum(r.reached_goal for r in these) / len(these),
            "time_to_goal_s_median": round(float(np.median(reached)), 6) if reached else None,
            "mean_time_stopped_s": round(float(np.mean([r.stopped_s for r in these])), 6),
            "runs_moving_in_true_contact": sum(r.ticks_moving_in_true_contact > 0 for r in these),
        }
    return {
        "runs": len(runs),
        "runs_moving_in_true_contact": sum(r.ticks_moving_in_true_contact > 0 for r in runs),
        "true_clearance_moving_mm": _clearance_totals(runs),
        "fraction_reaching_goal": sum(r.reached_goal for r in runs) / len(runs),
        "time_to_goal_s": {
            "median": round(float(np.median(times)), 6) if times else None,
            "mean": round(float(np.mean(times)), 6) if times else None,
        },
        "mean_time_stopped_s": round(float(np.mean([r.stopped_s for r in runs])), 6),
        "mean_duration_s": round(float(np.mean([r.duration_s for r in runs])), 6),
        "per_variant": per_variant,
        "runs_with_limit_violations": sum(r.limit_violations > 0 for r in runs),
        "runs_with_command_limit_violations": sum(r.command_limit_violations > 0 for r in runs),
        "contacts": _contact_totals(runs),
        "timing": _timing(runs),
    }


def as_dicts(checks: Sequence[Check]) -> list[dict[str, Any]]:
    """The checks as plain dicts (JSON)."""
    return [asdict(c) for c in checks]


def safety_sweep(
    seeds: Iterable[int],
    controller: str = "qp",
    distance: str = "spheres",
    rate_hz: float = 50.0,
    max_time_s: float = APPROACH_MAX_TIME_S,
    workers: int | None = None,
    executor: Executor | None = None,
    progress: bool = False,
) -> list[ApproachCheck]:
    """Random approaches checked for the safety invariants (:func:`sweep` of approaches
    with the paper's rules: docs/qp.md's table).

    Parameters
    ----------
    seeds
        Seeds of :func:`qpavoid.scenarios.generated.random_approach`.
    controller, distance
        ``"analytic"`` or ``"qp"``; ``"spheres"`` or ``"capsules"``.
    rate_hz, max_time_s
        Control rate, Hz, and cap of each run, s.
    workers, executor, progress
        As for :func:`sweep`.

    Returns
    -------
    list of ApproachCheck
        In the order of ``seeds``.
    """
    spec = SweepSpec("approach", controller, distance, "paper", rate_hz, max_time_s)
    return cast(list[ApproachCheck], sweep(spec, seeds, workers, executor, progress))


def strike_sweep(
    seeds: Iterable[int],
    controller: str = "qp",
    safety: str = "ssm",
    rate_hz: float = 100.0,
    max_speed_mps: float = 2.0,
    latency_s: float | None = None,
    workers: int | None = None,
    executor: Executor | None = None,
    progress: bool = False,
    distance: str = "capsules",
    max_time_s: float | None = None,
    camera: str = "kinect_v2",
) -> list[StrikeCheck]:
    """Strikes judged against the truth (:func:`sweep` of strikes: docs/safety.md's
    tables, ``benchmarks/safety.py``), in the order of ``seeds``; each lasts the strike
    (``max_time_s=None``) or until the goal, capped at ``max_time_s`` (s)."""
    spec = SweepSpec(
        "strike",
        controller,
        distance,
        safety,
        rate_hz,
        max_time_s,
        max_speed_mps,
        latency_s,
        camera=camera,
    )
    return cast(list[StrikeCheck], sweep(spec, seeds, workers, executor, progress))
