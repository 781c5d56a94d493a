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

Every run depends on its seed alone, so a sweep is a map over seeds
(:func:`~qpavoid.experiments.jobs.map_jobs`): a local process pool or any executor with
``map`` (Ray's, a cluster's), results in seed order whatever the number of workers.
:func:`summarize` sums either kind up.
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
from qpavoid.scenarios.strikes import StrikeCase, strike_camera, strike_case, strike_motion

__all__ = [
    "KINDS",
    "ApproachCheck",
    "Check",
    "StrikeCheck",
    "SweepSpec",
    "as_dicts",
    "check_log",
    "run_case",
    "safety_sweep",
    "strike_sweep",
    "summarize",
    "sweep",
]

#: The kinds of case a sweep runs.
KINDS = ("approach", "strike")
#: An approach lasts this long unless the spec says otherwise, s.
APPROACH_MAX_TIME_S = 25.0
#: The progress bar's label and unit, per kind.
_PROGRESS = {"approach": ("safety sweep", "approach"), "strike": ("strike sweep", "strike")}


@dataclass(frozen=True)
class SweepSpec:
    """What every run of a sweep shares; a run is this and its seed.

    Checked when it is made (as the :class:`~qpavoid.experiments.run_spec.RunSpec` of
    its runs), so that bad settings fail before any run starts.

    Attributes
    ----------
    kind
        ``"approach"`` or ``"strike"`` (module docstring).
    controller, distance, safety
        As in :class:`~qpavoid.experiments.run_spec.RunSpec`.
    rate_hz
        Control rate, Hz.
    max_time_s
        Cap on each run, s; None: an approach's 25 s, a strike's own duration (the
        hand's approach, 1.5 s of holding and 0.5 s more).
    max_speed_mps
        Strikes only: the fastest peak hand speed drawn, m/s (from 0.5 m/s up).
    latency_s
        The camera's latency, s (None: its format file's).
    robot
        The robot description (a bundled name or a folder).
    camera
        The simulated camera's skeleton format (:class:`~qpavoid.experiments.run_spec.
        RunSpec`'s ``camera``).
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

    def __post_init__(self) -> None:
        check_choice("sweep kind", self.kind, KINDS)
        self.run_spec(0, APPROACH_MAX_TIME_S)  # checks every other setting

    def run_spec(self, seed: int, duration_s: float | None = None) -> RunSpec:
        """The run of ``seed``, lasting ``max_time_s`` or else the case's own
        ``duration_s`` (a strike's, s); a strike's motion and camera aside
        (:func:`run_case`)."""
        if self.kind == "approach":
            scenario, truth = f"random:{seed}", False  # checked on what the controller saw
            duration_s = APPROACH_MAX_TIME_S
        else:
            scenario, truth = "free", True  # the strike is its motion; judged on the truth
        max_time_s = self.max_time_s if self.max_time_s is not None else duration_s
        if max_time_s is None:
            raise InputError(
                "a strike's run needs its duration or a cap", name="max_time_s", value=None
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


@dataclass(frozen=True)
class StrikeCheck:
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


#: What a sweep's run gives: an approach's or a strike's check.
Check: TypeAlias = ApproachCheck | StrikeCheck


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


def _strike_check(case: StrikeCase, run: RunResult) -> StrikeCheck:
    m, log = run.sim.metrics, run.sim.log
    moving = np.any(log["dq"] != 0.0, axis=1)
    clearance = m["min_true_clearance_moving_m"]
    return StrikeCheck(
        case.seed,
        run.spec.controller,
        run.spec.safety,
        case.target,
        case.speed_mps,
        case.side,
        case.both_hands,
        case.fault,
        int(m["ticks_moving_in_true_contact"]),
        float("inf") if clearance is None else float(clearance),
        float(moving.sum() / run.spec.rate_hz),
        float(m["stopped_s"]),
        max((e.get("robot_speed_mps", 0.0) for e in m["stop_events"]), default=0.0),
        int(m["ticks_moving_below_stop_distance"] or 0),
        bool(m["reached_goal"]),
        float(m["duration_s"]),
        int(m["joint_velocity_limit_violations"] + m["joint_position_limit_violations"]),
        float(m["tick_us"]["median"]),
        float(m["tick_us"]["p99"]),
        sum(m["command_limit_violations"].values()),
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
    """A sweep's totals (the ``qpavoid sweep`` summary for strikes); everything but a
    strike sweep's ``timing`` is reproducible from the seeds.

    Raises
    ------
    InputError
        If there is nothing to sum up.
    """
    if not checks:
        raise InputError("a sweep's summary needs at least one run", name="checks", value=[])
    if checks[0].kind == "approach":
        return _approach_totals(cast(Sequence[ApproachCheck], checks))
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


def _strike_totals(runs: Sequence[StrikeCheck]) -> dict[str, Any]:
    clear = np.array([r.min_true_clearance_moving_m for r in runs])
    moved = np.isfinite(clear)

    def mm(x: float) -> float:
        return round(float(x) * 1e3, 3)

    return {
        "runs": len(runs),
        "runs_moving_in_true_contact": sum(r.ticks_moving_in_true_contact > 0 for r in runs),
        "runs_moving_below_stop_distance": sum(
            r.ticks_moving_below_stop_distance > 0 for r in runs
        ),
        "true_clearance_moving_mm": {
            "min": mm(clear[moved].min()) if moved.any() else None,
            "p01": mm(np.percentile(clear[moved], 1)) if moved.any() else None,
            "median": mm(np.median(clear[moved])) if moved.any() else None,
        },
        "fraction_reaching_goal": sum(r.reached_goal for r in runs) / len(runs),
        "mean_time_stopped_s": round(float(np.mean([r.stopped_s for r in runs])), 6),
        "mean_duration_s": round(float(np.mean([r.duration_s for r in runs])), 6),
        "runs_with_limit_violations": sum(r.limit_violations > 0 for r in runs),
        "runs_with_command_limit_violations": sum(r.command_limit_violations > 0 for r in runs),
        "timing": {
            "tick_us_median": float(np.median([r.tick_us_median for r in runs])),
            "tick_us_p99": float(np.percentile([r.tick_us_p99 for r in runs], 99)),
        },
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
