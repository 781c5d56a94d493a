"""Sweeps: many seeded runs of one kind, each judged, then summed up.

The one engine behind ``qpavoid sweep`` (:mod:`qpavoid.experiments.campaign`),
:func:`safety_sweep` and :func:`strike_sweep`. A sweep is a :class:`SweepSpec` (what its
runs share) and seeds; the spec's *kind* chooses the motion and the check:

``"approach"`` (:class:`ApproachCheck`)
    A random hand approach (scenario ``random:SEED``,
    :func:`~qpavoid.scenarios.generated.random_approach`) on the real bench, each tick
    checked (:func:`~qpavoid.experiments.sweep_checks.check_log`) for what must never happen:

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
``map`` (Ray's, a cluster's), results in seed order whatever the number of workers. Each
case is judged by :mod:`~qpavoid.experiments.sweep_checks`;
:func:`~qpavoid.experiments.sweep_summary.summarize` sums any kind up.
"""

from __future__ import annotations

from collections.abc import Iterable
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import cast

from qpavoid.arm.model import load_robot
from qpavoid.core.checks import check_choice
from qpavoid.core.errors import InputError
from qpavoid.experiments.jobs import map_jobs
from qpavoid.experiments.runs import RunSpec, simulate_one
from qpavoid.experiments.sweep_checks import (
    ApproachCheck,
    Check,
    CloseWorkCheck,
    StrikeCheck,
    approach_check,
    closework_check,
    strike_check,
)
from qpavoid.loop.camera import CameraConfig
from qpavoid.scenarios.closework import closework_case, closework_motion
from qpavoid.scenarios.strikes import strike_camera, strike_case, strike_motion

__all__ = [
    "APPROACH_MAX_TIME_S",
    "KINDS",
    "SweepSpec",
    "run_case",
    "safety_sweep",
    "strike_sweep",
    "sweep",
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


def run_case(spec: SweepSpec, seed: int) -> Check:
    """Simulate the case ``seed`` of ``spec``'s kind and judge it (module docstring)."""
    if spec.kind == "approach":  # the scenario random:SEED, seen through the bench's Kinect
        return approach_check(seed, simulate_one(spec.run_spec(seed)))
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
    return strike_check(case, run)


def _closework_run(spec: SweepSpec, seed: int) -> CloseWorkCheck:
    """The close-work case ``seed`` of ``spec``, simulated and judged."""
    robot = load_robot(spec.robot)
    case = closework_case(seed, robot)
    run_spec = spec.run_spec(seed, case.duration_s)
    camera = CameraConfig.of(spec.camera, latency_s=run_spec.sensor_latency_s, seed=case.seed)
    run = simulate_one(run_spec, closework_motion(case, robot), robot=robot, camera=camera)
    return closework_check(case, run)


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
