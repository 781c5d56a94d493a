"""One run, from its description to its files: what the command line, ``compare`` and sweeps share.

A run is described by a :class:`RunSpec` (a frozen dataclass, checked when it is made, so a
bad value fails before any work starts). :func:`simulate_one` builds the robot, the
controller and the human motion it names and simulates them; :func:`run_one` does the same
and writes ``metrics.json``, ``log.npz`` and the figures into a folder.

The names a run can take live in one registry each: :data:`CONTROLLERS`,
:data:`DISTANCES`, :data:`LIMIT_MODES` and the scenarios of :mod:`qpavoid.scenarios`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from . import motions
from . import plots as plotting
from ._checks import check_choice, check_range
from .analytic import LIMIT_MODES, AnalyticConfig, AnalyticController
from .braking import BrakingConfig
from .controller import Controller, ControllerConfig
from .errors import InputError
from .io import staged_output, write_run
from .perception import PerceptionConfig
from .qp import QPConfig, QPController
from .qp.backends import check_solver
from .robot import Robot, load_robot
from .scenarios import check_scenario_name
from .sensor import KINECT_V2_LATENCY_S, SensorConfig
from .simulation import HumanMotion, SimConfig, SimResult, simulate
from .tick import SAFETY_MODES

#: Controllers by name.
CONTROLLERS = ("analytic", "qp")
#: Distance methods by name: exact capsules (coal, the default) and the paper's spheres (eq. 1).
DISTANCES = ("capsules", "spheres")
#: Benches: ``real`` (Kinect v2, the iiwa's reaction and braking) or ``ideal`` (the paper's).
BENCHES = ("real", "ideal")
#: A frame is stale once older than the latency plus this, s: a frame (33 ms) and 7 ms.
STALE_AFTER_LATENCY_S = 0.04

#: Accepted ranges: control rate (Hz) from the camera's 30 Hz to 10 kHz; a run's cap (s)
#: from a few frames to an hour (an hour at 500 Hz logs 1.8 M ticks, about 1.5 GB).
RATE_RANGE_HZ, MAX_TIME_RANGE_S = (30.0, 10_000.0), (0.1, 3600.0)

#: Redundancy mode (docs/qp.md): weight of the elbow-clearance cost, and a regularisation
#: large enough to give the end effector's null-space direction curvature (with 1e-7
#: OSQP cannot reach its tolerance there).
REDUNDANT_ELBOW_WEIGHT = 0.05
REDUNDANT_REGULARIZATION = 1e-4


@dataclass(frozen=True)
class RunSpec:
    """Everything that defines one run.

    Attributes
    ----------
    scenario
        A generated scenario (``test1``, ``test2``, ``free``, ``random:SEED``); or None
        with ``human_file``.
    human_file
        A recording to replay (NPZ or CSV, docs/formats.md) instead of a scenario.
    controller
        ``"analytic"`` (the paper's) or ``"qp"``.
    distance
        ``"capsules"`` (exact, coal; covers the shoulder) or ``"spheres"`` (the paper's eq. 1,
        as published: use it to reproduce the paper's figures).
    safety
        ``"paper"`` (the paper's rules as written) or ``"ssm"`` (speed and separation
        monitoring on top of them, :mod:`qpavoid.ssm`).
    bench
        ``"real"``: the controller sees a Kinect v2 (latency, noise; :mod:`qpavoid.sensor`)
        and the arm reacts and brakes like an iiwa (:mod:`qpavoid.braking`); ``"ideal"``:
        the paper's bench, the true skeleton every frame and an arm that follows its
        command at once (the frozen-frame check is off: a perfect sensor films a still
        person bit for bit).
    latency_s
        The real bench's sensor latency, s (default: the Kinect v2's, docs/safety.md); a
        frame older than the latency plus 40 ms (one frame and 7 ms) is stale.
    max_time_s
        Cap on the run, s (default 40: the 15 s path plus room for stops).
    rate_hz
        Control rate, Hz (default 500: a typical cobot interface rate).
    limit_mode
        Analytic controller only: how eq. (3)'s limits are enforced (``scale``, ``clip``).
    robot
        A bundled robot description or the folder of one.
    solver
        QP only: a qpsolvers solver (a new problem each tick); None for the persistent
        OSQP problem.
    redundant
        QP only: free A3 (7 joints) and keep the elbow away from the person.
    goal_tolerance_m
        The goal counts as reached within this end-effector position error, m (default
        1 mm). A run that ends short of it says why (``end_reason``, ``held_by_person``).
    measure_truth
        Measure every tick's clearance to where the person really is (``true_*`` metrics,
        :mod:`qpavoid.truth`); on by default, it doubles the simulation's time.
    sensor_files, sensors
        Per-sensor recordings and their calibration file (docs/sensors.md): fused, and
        the fusion replayed as the truth (``human_file`` is then the first of them).
    """

    scenario: str | None = None
    human_file: str | None = None
    controller: str = "analytic"
    distance: str = "capsules"
    safety: str = "paper"
    bench: str = "real"
    latency_s: float = KINECT_V2_LATENCY_S
    max_time_s: float = 40.0
    rate_hz: float = 500.0
    limit_mode: str = "scale"
    robot: str = "iiwa14"
    solver: str | None = None
    redundant: bool = False
    goal_tolerance_m: float = 1e-3
    measure_truth: bool = True
    sensor_files: tuple[str, ...] = ()
    sensors: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "sensor_files", tuple(str(f) for f in self.sensor_files))
        if self.sensor_files and self.human_file is None:
            object.__setattr__(self, "human_file", self.sensor_files[0])
        if self.scenario is None and self.human_file is None:
            raise InputError(
                "give a SCENARIO (test1, test2, free, random:SEED) or --human FILE",
                name="scenario",
                value=None,
            )
        if self.scenario is not None and self.human_file is not None:
            raise InputError(
                "give either SCENARIO or --human FILE, not both",
                name="scenario",
                value=self.scenario,
            )
        if self.scenario is not None:
            check_scenario_name(self.scenario)
        check_choice("controller", self.controller, CONTROLLERS)
        check_choice("distance method", self.distance, DISTANCES)
        check_choice("safety mode (--safety)", self.safety, SAFETY_MODES)
        check_choice("bench (--bench)", self.bench, BENCHES)
        check_range("the sensor latency (--latency)", self.latency_s, 0.0, 1.0, "s")
        check_choice("limit mode", self.limit_mode, LIMIT_MODES)
        check_range("the run's cap (--max-time)", self.max_time_s, *MAX_TIME_RANGE_S, "s")
        check_range("the control rate (--rate)", self.rate_hz, *RATE_RANGE_HZ, "Hz")
        check_range("the goal tolerance (--goal-tolerance)", self.goal_tolerance_m, 1e-6, 1.0, "m")
        if self.controller != "qp":
            for flag, given in (("--solver", self.solver), ("--redundant", self.redundant)):
                if given:
                    raise InputError(f"{flag} needs --controller qp", name=flag, value=given)
        elif self.limit_mode != "scale":
            raise InputError(
                "--limit-mode needs --controller analytic (the QP enforces eq. (3) as bounds)",
                name="--limit-mode",
                value=self.limit_mode,
            )
        if self.solver is not None:
            check_solver(self.solver)
        motions.check_human_files(self.sensor_files, self.sensors)

    @property
    def label(self) -> str:
        """The run's name: the scenario, or the recording's file stem."""
        return self.scenario if self.scenario is not None else Path(str(self.human_file)).stem


@dataclass
class RunResult:
    """A simulated run and what produced it."""

    spec: RunSpec
    sim: SimResult
    robot: Robot
    controller: Controller
    metrics: dict = field(default_factory=dict)

    @property
    def config(self) -> ControllerConfig:
        """The controller's shared configuration."""
        return self.controller.config


def build_controller(spec: RunSpec, robot: Robot) -> Controller:
    """The controller ``spec`` names, on ``robot``, at the spec's control rate."""
    config = ControllerConfig(
        distance=spec.distance,
        control_period_s=1.0 / spec.rate_hz,
        max_frame_age_s=spec.latency_s + STALE_AFTER_LATENCY_S,
        safety=spec.safety,
        perception=PerceptionConfig(max_identical_frames=None)
        if spec.bench == "ideal"
        else PerceptionConfig(),
    )
    if spec.controller == "analytic":
        return AnalyticController(
            robot, config=config, analytic=AnalyticConfig(limit_mode=spec.limit_mode)
        )
    qp = QPConfig(
        backend="qpsolvers" if spec.solver else "persistent", solver=spec.solver or "osqp"
    )
    if spec.redundant:
        qp = QPConfig(
            backend=qp.backend,
            solver=qp.solver,
            elbow_weight=REDUNDANT_ELBOW_WEIGHT,
            regularization=REDUNDANT_REGULARIZATION,
        )
    return QPController(robot, config=config, qp=qp)


def load_motion(spec: RunSpec, robot: Robot) -> HumanMotion:
    """The human motion ``spec`` names (:func:`qpavoid.motions.load_motion`)."""
    files = spec.sensor_files or ((spec.human_file,) if spec.human_file else ())
    return motions.load_motion(robot, spec.scenario, files, spec.sensors)


def simulate_one(
    spec: RunSpec,
    motion: HumanMotion | None = None,
    progress: Callable[[float], None] | None = None,
) -> RunResult:
    """Build the robot, controller and motion of ``spec`` and simulate them.

    Parameters
    ----------
    spec
        The run.
    motion
        The human motion if already loaded (else :func:`load_motion`).
    progress
        Called with the simulated time, s, at every human frame.
    """
    robot = load_robot(spec.robot, locked=() if spec.redundant else None)
    controller = build_controller(spec, robot)
    motion = motion if motion is not None else load_motion(spec, robot)
    sim = simulate(
        controller,
        motion,
        SimConfig(
            control_rate_hz=spec.rate_hz,
            sensor=SensorConfig.ideal()
            if spec.bench == "ideal"
            else SensorConfig(latency_s=spec.latency_s),
            braking=None if spec.bench == "ideal" else BrakingConfig(),
            max_time_s=spec.max_time_s,
            goal_tolerance_m=spec.goal_tolerance_m,
            measure_truth=spec.measure_truth,
        ),
        progress=progress,
    )
    metrics = dict(sim.metrics)
    metrics.update(
        scenario=spec.label,
        safety=spec.safety,
        bench=spec.bench,
        latency_s=spec.latency_s if spec.bench == "real" else 0.0,
        redundant=bool(spec.redundant),
        solver=getattr(getattr(controller, "backend", None), "name", None),
    )
    return RunResult(spec, sim, robot, controller, metrics)


def write_outputs(run: RunResult, out: str | Path, plots: bool = True) -> dict:
    """Write ``metrics.json``, ``log.npz`` and (with ``plots``) the figures of ``run``.

    The files are written into a staging folder first and moved into ``out`` only when
    all of them are written, so a failure leaves no half-written ``out``.

    Returns
    -------
    dict
        The metrics written, with ``plots`` (figure file names) and, when figures were not
        drawn, ``plots_skipped`` (why).
    """
    extra: dict = {"plots": []}
    if not plots:
        extra["plots_skipped"] = "disabled by --no-plots"
    elif not plotting.available():
        extra["plots_skipped"] = "matplotlib is not installed (pip install 'qpavoid[plot]')"
    with staged_output(out) as stage:
        if plots and plotting.available():
            figures = plotting.write_figures(
                stage,
                run.sim.log,
                run.robot,
                run.config.avoidance,
                run.spec.distance,
                scenario=run.spec.label,
                controller=run.spec.controller,
            )
            extra["plots"] = [p.name for p in figures]
        write_run(stage, run.sim, {**run.metrics, **extra})
    return {**run.metrics, **extra}


def run_one(
    spec: RunSpec,
    out: str | Path,
    plots: bool = True,
    progress: Callable[[float], None] | None = None,
) -> dict:
    """Simulate ``spec`` and write its files into ``out``; return its metrics."""
    return write_outputs(simulate_one(spec, progress=progress), out, plots)
