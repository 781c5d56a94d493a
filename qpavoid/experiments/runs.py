"""One run, from its description to its files: what the command line, ``compare`` and sweeps share.

A run is described by a :class:`RunSpec` (a frozen dataclass, checked when it is made, so a
bad value fails before any work starts). :func:`simulate_one` builds the robot, the
controller and the human motion it names and simulates them; :func:`run_one` does the same
and writes ``metrics.json``, ``log.npz`` and the figures into a folder.

The names a run can take live in :mod:`qpavoid.experiments.run_spec`, with :class:`RunSpec`. A
``--listen`` run takes its frames live (:func:`live_source`) and ticks in real time.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from qpavoid.arm.braking import BrakingConfig
from qpavoid.arm.description import description_reference
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import Robot, load_robot
from qpavoid.control.analytic import AnalyticConfig, AnalyticController
from qpavoid.control.controller import Controller
from qpavoid.control.qp import QPConfig, QPController
from qpavoid.control.qp.config import REDUNDANT
from qpavoid.control.smoothing import smooth_rate_limit_hz
from qpavoid.control.tick import ControllerConfig
from qpavoid.core.errors import InputError
from qpavoid.drive.connect import open_arm
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.human.body import BodyModel, body_model
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import landmark_map, skeleton_format
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.laws.pfl import PFLConfig
from qpavoid.laws.ssm import SSMConfig
from qpavoid.loop.camera import CameraConfig
from qpavoid.loop.live_input import Listener, LiveSource, parse_address
from qpavoid.loop.simulation import HumanMotion, SimConfig, SimResult, simulate
from qpavoid.output import plots as plotting
from qpavoid.output import replay_html as view_html
from qpavoid.output.live_status import LiveStatus
from qpavoid.output.live_view import LiveView
from qpavoid.output.ros2_out import Ros2Outputs, ros2_cell
from qpavoid.output.run_files import staged_output, write_run
from qpavoid.output.view_data import replay_data
from qpavoid.perception.tracker import PerceptionConfig
from qpavoid.scenarios import motions
from qpavoid.scenarios.generated import closework_seed
from qpavoid.sensing.dds_input import DdsListener
from qpavoid.sensing.recording_files import recording_format
from qpavoid.sensing.ros2_cell import load_cell


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


#: With ``--arm``: how long a tick may take from reading the arm to sending its command, s
#: (the loop's deadline, counted in speed and separation's reaction time: 2.0 m/s × 10 ms
#: = 20 mm more protective distance). On 2 loaded cores a 500 Hz tick's p99 reached 10 ms;
#: a deadline of one period (2 ms) braked most ticks there.
ARM_COMPUTE_BUDGET_S = 0.01


def build_controller(spec: RunSpec, robot: Robot) -> Controller:
    """The controller ``spec`` names, on ``robot``, at the spec's control rate, along the
    path of its ``--task`` (else the robot's own task's), with the body model of the
    cell's camera on its own joints where it has one format (:func:`cell_body`), else the
    paper's on the body's landmarks."""
    cameras = cell_formats(spec)
    human = cell_body(spec)
    task = spec.task_for(robot)  # --task's (None: the robot's own)
    path = None if task is None else task.path
    uncertainty = () if human is not None else cell_uncertainty_m(cameras)
    config = ControllerConfig(
        distance=spec.distance,
        control_period_s=1.0 / spec.rate_hz,
        compute_budget_s=ARM_COMPUTE_BUDGET_S if spec.arm is not None else 0.0,
        max_frame_age_s=spec.frame_age_limit_s,
        safety=spec.safety,
        perception=PerceptionConfig(max_identical_frames=None)
        if spec.bench == "ideal"
        else PerceptionConfig(landmark_uncertainty_m=uncertainty),
        # Z_d: the position error of a tracked joint of the cell's cameras, the largest
        ssm=SSMConfig(sensing_uncertainty_m=max(c.sensor.tracked_uncertainty_m for c in cameras)),
        pfl=PFLConfig(payload_kg=spec.payload_kg),
    )
    if spec.controller == "analytic":
        return AnalyticController(
            robot,
            path=path,
            config=config,
            human=human,
            analytic=AnalyticConfig(limit_mode=spec.limit_mode),
        )
    qp = QPConfig(
        backend="qpsolvers" if spec.solver else "persistent", solver=spec.solver or "osqp"
    )
    if spec.redundant:  # the redundancy mode's weights (docs/qp.md), same solver
        qp = replace(REDUNDANT, backend=qp.backend, solver=qp.solver)
    return QPController(robot, path=path, config=config, human=human, qp=qp)


def cell_body(spec: RunSpec) -> BodyModel | None:
    """The body model on the run's camera's own joints (:func:`~qpavoid.human.body.body_model`)
    where the cell sees the person through cameras of one format other than the Kinect
    v2's (the simulated camera of ``--camera``; a live cell's sensors, fused on their own
    joints; a replayed recording of the body's own landmarks); None: the paper's model on
    the body's landmarks, which the fusion of several formats, per-sensor recordings and a
    recording's derived landmarks need."""
    fmt = skeleton_format(spec.camera)
    if spec.bench != "real" or not fmt.body:
        return None
    if spec.sensors is not None and (
        spec.listen is None or len(set(spec.calibration().formats)) > 1
    ):
        return None  # recordings fused on the landmarks, or a live cell mixing formats
    if spec.human_file is not None and recording_format(spec.human_file).body:
        return None  # a recording's derived landmarks: the landmarks' path, widened
    return body_model(fmt)


def cell_formats(spec: RunSpec) -> list[SkeletonFormat]:
    """The skeleton formats of a run's cameras: the simulated camera's (``--camera``) and,
    with ``--sensors``, each calibrated sensor's, or a replayed recording's (``--human``:
    the landmarks its camera derived are no truer for being recorded)."""
    if spec.sensors is not None:  # the calibration's formats rule (the camera is theirs)
        return [skeleton_format(name) for name in sorted(set(spec.calibration().formats))]
    names = {spec.camera}
    if spec.human_file is not None:  # a recording's derived landmarks: as seen, not truth
        names.add(recording_format(spec.human_file).name)
    return [skeleton_format(name) for name in sorted(names)]


def cell_uncertainty_m(cameras: list[SkeletonFormat]) -> tuple[float, ...]:
    """Each of the body's landmarks' uncertainty from the cell's ``cameras``, m
    (:attr:`~qpavoid.perception.tracker.PerceptionConfig.landmark_uncertainty_m`): the
    largest over them (empty: every landmark measured, a Kinect v2 cell)."""
    worst = np.max([landmark_map(c).uncertainty_m for c in cameras], axis=0)
    return tuple(float(u) for u in worst) if worst.any() else ()


@contextmanager
def live_source(
    spec: RunSpec,
    clear: threading.Event | None = None,
    say: Callable[[str], None] | None = None,
) -> Iterator[LiveSource | None]:
    """The live source of a ``--listen`` run (listening while the run lasts), else None;
    ``clear``: the live view's request to clear flagged people; ``say``: told the ready
    line once listening, and what the source says (:class:`LiveSource`)."""
    if spec.listen is None:
        yield None
        return
    calibration = spec.calibration()
    body = cell_body(spec)  # one camera format: fused on its own joints, for its own body
    skeleton = KINECT_V2 if body is None else body.skeleton
    with (
        DdsListener(load_cell(spec.listen[5:]), calibration, spec.trust_ros_graph, say)
        if spec.listen.startswith("ros2:")  # the cameras' ROS 2 topics (docs/ros2.md)
        else Listener(
            parse_address(spec.listen),
            calibration,
            accept_unauthenticated=spec.allow_unauthenticated,
        )
    ) as listener:
        source = LiveSource(listener, clear=clear, say=say, skeleton=skeleton)
        if say is not None:  # (the ready line: at the loop's first tick, by the source)
            oldest = max(source.fuser.max_age_s.values())
            if not ControllerConfig(safety=spec.safety).monitors_separation and oldest > 0.1:
                say(  # the paper's bench: 0.1 s
                    f"the {spec.safety} rules do not count a frame's age: frames up to "
                    f"{1e3 * oldest:.0f} ms old drive the robot at their fixed distances; "
                    "speed and separation (--safety ssm) counts each frame's age"
                )
        yield source


def cameras_used(spec: RunSpec) -> dict[str, Any]:
    """What the controller saw the person through (``metrics.json``): ``camera`` (the
    format, or the cell's formats joined by "+"; "ideal" on the ideal bench),
    ``latency_s`` (the largest camera latency counted, s) and ``frame_age_limit_s``
    (the age at which the controller stops on a frame, s)."""
    if spec.bench == "ideal":
        return {"camera": "ideal", "latency_s": 0.0, "frame_age_limit_s": spec.frame_age_limit_s}
    if spec.sensors is not None:
        sensors = spec.calibration().sensors.values()
        camera = "+".join(sorted({c.format for c in sensors}))
        latency = max(c.latency_used_s for c in sensors)
    else:
        camera, latency = spec.camera, spec.sensor_latency_s
    return {"camera": camera, "latency_s": latency, "frame_age_limit_s": spec.frame_age_limit_s}


def spec_robot(spec: RunSpec) -> Robot:
    """The robot ``spec`` names (with ``redundant``, the joints its description locks
    freed: the iiwa's A3).

    Raises
    ------
    InputError
        For ``redundant`` on a description that locks no joint (nothing to free).
    """
    robot = load_robot(spec.robot)
    if not spec.redundant:
        return robot
    freed = load_robot(spec.robot, locked=())
    if freed.nv == robot.nv:
        raise InputError(
            f"--redundant frees the joints a description locks; {robot.name!r} locks none "
            f"(its {robot.nv} joints all move already)",
            name="redundant",
            value=spec.robot,
        )
    return freed


@contextmanager
def live_view(spec: RunSpec, address: str) -> Iterator[LiveView]:
    """A browser view of ``spec``'s run, served at ``address`` (HOST:PORT) while it lasts."""
    title = f"qpavoid live: {spec.label}, {spec.controller} controller, {spec.distance}"
    where = parse_address(address, "--view", any_port=True)
    with LiveView(where, spec_robot(spec), spec.distance, title) as v:
        yield v


def simulate_one(
    spec: RunSpec,
    motion: HumanMotion | None = None,
    progress: Callable[[float], None] | None = None,
    watch: Callable[[dict[str, Any]], None] | None = None,
    clear: threading.Event | None = None,
    *,
    robot: Robot | None = None,
    camera: CameraConfig | None = None,
    controller: Controller | None = None,
    say: Callable[[str], None] | None = None,
) -> RunResult:
    """Build the robot, controller and motion of ``spec`` and simulate them.

    Parameters
    ----------
    spec
        The run.
    motion
        The human motion if already made (else the one ``spec`` names,
        :func:`qpavoid.scenarios.motions.load_motion`). For a live run (``spec.listen``):
        the truth the senders film, if known (their run clock's: the run's time 0 is the
        first tick), against which each tick's clearance is then measured.
    progress
        Called with the simulated time, s, at every human frame.
    watch
        Called with ticks as they are logged (:func:`~qpavoid.loop.simulation.simulate`), e.g.
        :meth:`LiveView.update <qpavoid.output.live_view.LiveView.update>`.
    clear
        A live run's request to clear the people flagged as suspect
        (:attr:`LiveView.clear_requested <qpavoid.output.live_view.LiveView.clear_requested>`).
    robot
        ``spec``'s robot if already loaded (:func:`spec_robot`).
    camera
        What the controller sees, if not the camera of ``spec``'s bench (a strike's faulty
        Kinect).
    controller
        The controller, if not the one ``spec`` names (:func:`build_controller`): one built
        with other settings (``benchmarks/smooth_stops.py``: the paper's steps).
    say
        A live run's lines for the operator (:func:`live_source`): printed by the
        command line as they come.
    """
    robot = spec_robot(spec) if robot is None else robot
    if spec.arm is not None and spec.rate_hz > (top := smooth_rate_limit_hz(robot)) + 1e-9:
        raise InputError(
            f"--arm at {spec.rate_hz:g} Hz: the commands of {robot.name!r}, a jerk-limited "
            f"arm, are shown to keep its limits up to {top:g} Hz (docs/real-robot.md); "
            f"use --rate {top:g} or lower",
            name="--rate",
            value=spec.rate_hz,
        )
    controller = build_controller(spec, robot) if controller is None else controller
    live = spec.listen is not None
    if motion is None and not live:
        motion = motions.load_motion(
            robot, spec.scenario, spec.human_files, spec.sensors, spec.task_for(robot)
        )
    if camera is None:  # a close-work case's noise from its seed, as its sweep draws it
        seed = None if spec.scenario is None else closework_seed(spec.scenario)
        camera = (
            CameraConfig.ideal()
            if spec.bench == "ideal"
            else CameraConfig.of(spec.camera, latency_s=spec.sensor_latency_s, seed=seed or 0)
        )
    with contextlib.ExitStack() as stack:
        source = stack.enter_context(live_source(spec, clear, say))
        if source is not None and say is not None:  # a line every few seconds, too
            watch = _both(watch, LiveStatus(say, source.report))
        arm = None
        if spec.arm is not None:  # at the path's start, as the offline simulation starts
            q0 = inverse_kinematics(robot, controller.path.reference(0.0)[0])
            arm = stack.enter_context(
                open_arm(spec.arm, robot, q0, 1.0 / spec.rate_hz, spec.trust_ros_graph)
            )
        if ros2_cell(spec) is not None:  # diagnostics and capsules for RViz, off the loop
            outputs = stack.enter_context(Ros2Outputs(ros2_cell(spec), robot, controller))  # type: ignore[arg-type]
            watch = _both(watch, outputs.update)
        sim = simulate(
            controller,
            motion,
            SimConfig(
                control_rate_hz=spec.rate_hz,
                camera=camera,
                braking=None if spec.bench == "ideal" else BrakingConfig(),
                max_time_s=spec.max_time_s,
                goal_tolerance_m=spec.goal_tolerance_m,
                measure_truth=spec.measure_truth or (live and motion is not None),
            ),
            progress=progress,
            source=source,
            realtime=live,
            watch=watch,
            arm=arm,
        )
        metrics = dict(sim.metrics)
        if source is not None:
            metrics["input"] = source.report()
            metrics["input_unit"] = source.unit
            metrics["sensors"] = source.sensors_report()
    metrics.update(cameras_used(spec))
    metrics.update(
        scenario=spec.label,
        safety=spec.safety,
        bench=spec.bench,
        payload_kg=spec.payload_kg,
        redundant=bool(spec.redundant),
        robot=description_reference(spec.robot),
        arm=spec.arm or ("the simulated arm in real time" if live else "offline simulation"),
        task=spec.task,
        trust_ros_graph=bool(spec.trust_ros_graph),
        solver=getattr(getattr(controller, "backend", None), "name", None),
        run_spec=asdict(spec),
    )
    return RunResult(spec, sim, robot, controller, metrics)


def _both(
    first: Callable[[dict[str, Any]], None] | None, second: Callable[[dict[str, Any]], None]
) -> Callable[[dict[str, Any]], None]:
    """One watcher calling ``first`` (if any), then ``second``."""
    if first is None:
        return second

    def both(row: dict[str, Any]) -> None:
        first(row)
        second(row)

    return both


def write_outputs(run: RunResult, out: str | Path, plots: bool = True, view: bool = True) -> dict:
    """Write ``metrics.json``, ``log.npz``, (with ``plots``) the figures and (with
    ``view``) the browser replay ``replay.html`` of ``run``.

    The files are written into a staging folder first and moved into ``out`` only when
    all of them are written, so a failure leaves no half-written ``out``.

    Returns
    -------
    dict
        The metrics written, with ``plots`` (figure file names), ``view`` (the replay's file
        name, or None) and, when figures or the replay were not made, ``plots_skipped``
        and ``view_skipped`` (why).
    """
    extra: dict = {"plots": [], "view": None}
    if not plots:
        extra["plots_skipped"] = "disabled by --no-plots"
    elif not plotting.available():
        extra["plots_skipped"] = "matplotlib is not installed (pip install 'qpavoid[plot]')"
    if not view:
        extra["view_skipped"] = "disabled by --no-view"
    elif not view_html.available():
        extra["view_skipped"] = "meshcat is not installed (pip install 'qpavoid[view]')"
    else:
        extra["view"] = "replay.html"
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
                human=run.controller.human,
            )
            extra["plots"] = [p.name for p in figures]
        write_run(stage, run.sim, {**run.metrics, **extra})
        if extra["view"]:
            data = replay_data(run.sim.log, run.metrics, run.robot, human=run.controller.human)
            title = view_html.replay_title(run.metrics, Path(out).name)
            view_html.write_html(stage / "replay.html", view_html.replay_html(data, title))
    return {**run.metrics, **extra}


def run_one(
    spec: RunSpec,
    out: str | Path,
    plots: bool = True,
    progress: Callable[[float], None] | None = None,
    view: bool = True,
    watch: Callable[[dict[str, Any]], None] | None = None,
    clear: threading.Event | None = None,
    say: Callable[[str], None] | None = None,
) -> dict:
    """Simulate ``spec`` and write its files into ``out``; return its metrics (``watch``,
    ``clear``, ``say``: :func:`simulate_one`)."""
    run = simulate_one(spec, progress=progress, watch=watch, clear=clear, say=say)
    return write_outputs(run, out, plots, view)
