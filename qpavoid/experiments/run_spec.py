"""What one run is: :class:`RunSpec`, checked when it is made, and the names it may use.

The names a run can take live in one registry each: :data:`CONTROLLERS`,
:data:`DISTANCES`, :data:`BENCHES`, the limit modes of the analytic controller and the
scenarios of :mod:`qpavoid.scenarios.generated`. :mod:`qpavoid.experiments.runs` turns a spec into
a run.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

from qpavoid.arm.dynamics import MAX_PAYLOAD_KG
from qpavoid.arm.model import Robot, load_robot
from qpavoid.control.analytic import LIMIT_MODES
from qpavoid.control.qp.backends import check_solver
from qpavoid.control.task import Task, load_task
from qpavoid.control.tick import SAFETY_MODES
from qpavoid.core.checks import check_choice, check_range
from qpavoid.core.errors import InputError, RobotDescriptionError, SkeletonFormatError
from qpavoid.drive.connect import parse_arm
from qpavoid.human.body import BodyModel, body_model
from qpavoid.human.landmarks import FORMAT_NAMES, format_file, skeleton_format
from qpavoid.laws.pfl import PFLConfig
from qpavoid.loop.live_input import parse_address
from qpavoid.scenarios import motions
from qpavoid.scenarios.generated import SCENARIOS, check_scenario_name
from qpavoid.sensing.calibration import DEFAULT_FORMAT, Calibration
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.dds_input import check_trust
from qpavoid.sensing.ros2_cell import load_cell

__all__ = ["BENCHES", "CONTROLLERS", "DISTANCES", "DISTANCE_METHODS", "LIMIT_MODES", "RunSpec"]

#: Controllers by name.
CONTROLLERS = ("analytic", "qp")
#: The distance methods a comparison runs: exact capsules (compiled, the default) and the
#: paper's spheres (eq. 1).
DISTANCES = ("capsules", "spheres")
#: Every distance method a run may use: also ``capsules-coal``, the capsules by coal (the
#: compiled ones' judge, the same table within 1e-9 m).
DISTANCE_METHODS = (*DISTANCES, "capsules-coal")
#: Benches: ``real`` (Kinect v2, the iiwa's reaction and braking) or ``ideal`` (the paper's).
BENCHES = ("real", "ideal")
#: Accepted ranges: control rate (Hz) from the camera's 30 Hz to 10 kHz; a run's cap (s)
#: from a few frames to an hour (an hour at 500 Hz logs 1.8 M ticks, about 1.5 GB).
RATE_RANGE_HZ, MAX_TIME_RANGE_S = (30.0, 10_000.0), (0.1, 3600.0)


@dataclass(frozen=True)
class RunSpec:
    """Everything that defines one run.

    Attributes
    ----------
    scenario
        A generated scenario (``test1``, ``test2``, ``free``, ``random:SEED``,
        ``closework:SEED`` or a fixed close-work case: ``rest_near``, ``work_near``,
        ``reach_across``, ``handover``; :mod:`qpavoid.scenarios.generated`); or None with
        ``human_file``.
    human_file
        A recording to replay (NPZ or CSV, docs/formats.md) instead of a scenario.
    controller
        ``"analytic"`` (the paper's) or ``"qp"``.
    distance
        ``"capsules"`` (exact, compiled; covers the shoulder), ``"capsules-coal"`` (the
        same by coal) or ``"spheres"`` (the paper's eq. 1, as published: use it to
        reproduce the paper's figures).
    safety
        ``"paper"`` (the paper's rules as written) or ``"ssm"`` (speed and separation
        monitoring on top of them, :mod:`qpavoid.laws.ssm`).
    bench
        ``"real"``: the controller sees a Kinect v2 (latency, noise; :mod:`qpavoid.loop.camera`)
        and the arm reacts and brakes like an iiwa (:mod:`qpavoid.arm.braking`); ``"ideal"``:
        the paper's bench, the true skeleton every frame and an arm that follows its
        command at once (the frozen-frame check is off: a perfect sensor films a still
        person bit for bit).
    latency_s
        The cameras' latency, s (None, the default: each camera's, from its format file;
        the Kinect v2's 0.06 s, docs/safety.md): the simulated camera's, and with
        ``sensors`` that of each sensor whose calibration names no ``latency_s`` (one that
        names another is refused). A frame older than its camera's age limit (the latency,
        a frame period and 6.7 ms: :meth:`~qpavoid.human.camera_spec.CameraSpec.age_limit_s`)
        is stale.
    camera
        The skeleton format of the real bench's simulated camera (``kinect_v2``,
        ``k4abt``, ``zed_body_34``, ``zed_body_38``, ``mediapipe_pose``:
        :data:`~qpavoid.human.landmarks.FORMAT_NAMES`), its latency, noise, joint set and
        failure modes (:mod:`qpavoid.loop.camera`). "" (the default): the cell's, i.e.
        with ``sensors`` their calibrated format (the Kinect v2's for a cell mixing
        formats, where the fusion's landmarks are the body), else ``kinect_v2``. With
        ``sensors`` the calibration's formats rule: a camera that is not every sensor's
        format is refused.
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
        :mod:`qpavoid.loop.truth`); on by default, it doubles the simulation's time.
    sensor_files, sensors
        Per-sensor recordings and their calibration file (docs/sensors.md): fused, and
        the fusion replayed as the truth (``human_file`` is then the first of them).
    listen
        ``HOST:PORT``: drive the controller in real time from live frames on UDP
        (:mod:`qpavoid.loop.live_input`, with ``sensors``), the robot simulated; no truth.
        ``ros2:CELL.toml``: from the sensors' ROS 2 topics instead (docs/ros2.md).
    allow_unauthenticated
        With ``listen`` on a loopback address: also accept unsigned (version 1)
        datagrams (docs/security.md).
    trust_ros_graph
        Take input from a ROS 2 graph (``listen`` or ``arm`` ``ros2:``): the explicit opt-in.
    arm
        The arm to drive in real time instead of the offline simulation
        (:func:`~qpavoid.drive.connect.open_arm`): ``"sim"`` (the kinematic arm on the wall
        clock), ``"franka:HOST"`` (an FR3, or franky-sim, through franky-control) or
        ``"panda:HOST"`` (a Panda through panda-python), ``"ros2:CELL.toml"`` (ros2_control);
        None: the offline simulation (a live run's: the simulated arm in real time).
    payload_kg
        The payload at the end effector, kg (``--payload``): power and force limiting
        counts it in the arm's effective mass (:class:`~qpavoid.laws.pfl.PFLConfig`), and
        so does the judge of every true contact; above the arm's rated payload the run
        is refused.
    task
        A task file (``--task``, docs/tasks.md) for the robot to follow instead of its
        description's ``task.toml``: its waypoints are the path, its ``[operator]`` the
        seat of the generated scenarios' person. Read and checked against the robot (its
        joints, every waypoint reachable) when the spec is made.
    """

    scenario: str | None = None
    human_file: str | None = None
    controller: str = "analytic"
    distance: str = "capsules"
    safety: str = "paper"
    bench: str = "real"
    latency_s: float | None = None
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
    listen: str | None = None
    allow_unauthenticated: bool = False
    trust_ros_graph: bool = False
    arm: str | None = None
    camera: str = ""
    payload_kg: float = 0.0
    task: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "sensor_files", tuple(str(f) for f in self.sensor_files))
        if self.sensor_files and self.human_file is None:
            object.__setattr__(self, "human_file", self.sensor_files[0])
        if self.listen is not None:
            if self.listen.startswith("ros2:"):  # a ROS 2 cell: read, checked, trusted?
                check_trust(self.trust_ros_graph, load_cell(self.listen[5:]).domain_id)
            else:
                parse_address(self.listen)
            if self.scenario is not None or self.human_file is not None or not self.sensors:
                raise InputError(
                    "--listen takes live frames: give --sensors CALIBRATION.toml and no "
                    "SCENARIO or --human",
                    name="--listen",
                    value=self.listen,
                )
            object.__setattr__(self, "measure_truth", False)  # live: no truth to measure
        elif self.allow_unauthenticated:
            raise InputError(
                "--allow-unauthenticated is for --listen",
                name="--allow-unauthenticated",
                value=True,
            )
        elif self.scenario is None and self.human_file is None:
            raise InputError(
                f"give a SCENARIO ({', '.join(SCENARIOS)}, random:SEED, closework:SEED) "
                "or --human FILE",
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
        check_choice("distance method", self.distance, DISTANCE_METHODS)
        check_choice("safety mode (--safety)", self.safety, SAFETY_MODES)
        check_choice("bench (--bench)", self.bench, BENCHES)
        if self.latency_s is not None:
            check_range("the sensor latency (--latency)", self.latency_s, 0.0, 1.0, "s")
        object.__setattr__(self, "camera", self._cell_camera())
        if format_file(self.camera) is None:
            check_choice("camera (--camera)", self.camera, FORMAT_NAMES)
        fmt = skeleton_format(self.camera)  # a format file: read and checked (one line)
        if fmt.body:
            check_regions(body_model(fmt))  # its body model on its own joints, checked
        check_choice("limit mode", self.limit_mode, LIMIT_MODES)
        check_range("the payload (--payload)", self.payload_kg, 0.0, MAX_PAYLOAD_KG, "kg")
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
        if self.listen is None:
            motions.check_human_files(self.sensor_files, self.sensors)
        if self.task is not None:  # read and checked now: the arm's joints, its reach
            self.task_for(load_robot(self.robot, locked=() if self.redundant else None))
        if self.arm is not None:
            kind, where = parse_arm(self.arm)
            if kind == "ros2" and where is not None:
                check_trust(self.trust_ros_graph, load_cell(where).domain_id)
            if self.bench == "ideal":
                raise InputError(
                    "--arm drives a real arm (or the simulated one in real time): the "
                    "ideal bench's arm is the offline simulation's",
                    name="--arm",
                    value=self.arm,
                )

    def _cell_camera(self) -> str:
        """``camera`` resolved (its docstring): the calibration's format with ``sensors``,
        where a contradicting one is refused; else ``kinect_v2`` for ""."""
        if self.sensors is None:
            return self.camera or DEFAULT_FORMAT
        calibration = self.calibration()
        formats = sorted(set(calibration.formats))
        cell = formats[0] if len(formats) == 1 else DEFAULT_FORMAT  # a mixed cell: landmarks
        if not self.camera or self.camera == cell:  # (resolved: a spec's copy passes again)
            return cell
        if formats != [self.camera]:
            raise InputError(
                f"--camera {self.camera} contradicts the calibration {self.sensors}, whose "
                f"sensors are {self._sensor_formats(calibration)}: with --sensors the "
                "calibration's format keys rule; drop --camera",
                name="--camera",
                value=self.camera,
            )
        return self.camera

    @staticmethod
    def _sensor_formats(calibration: Calibration) -> str:
        """ "name (format), ..." of the calibration's sensors."""
        return ", ".join(f"{name} ({cal.format})" for name, cal in calibration.sensors.items())

    def calibration(self) -> Calibration:
        """The sensors' calibration (``sensors``) with ``latency_s`` for each sensor that
        names none (:meth:`~qpavoid.sensing.calibration.Calibration.with_latency`).

        Raises
        ------
        InputError
            Without ``sensors``; for a file that cannot be read, or a sensor whose own
            latency contradicts ``latency_s``.
        """
        if self.sensors is None:
            raise InputError("the run has no sensors (--sensors)", name="--sensors")
        return self._calibration

    @functools.cached_property
    def _calibration(self) -> Calibration:
        """The file read once per spec (the spec checks it, the run builds from it)."""
        return load_calibration(str(self.sensors)).with_latency(self.latency_s)

    @property
    def frame_age_limit_s(self) -> float:
        """The oldest a frame may be before the controller stops on it, s: with
        ``sensors``, the largest of their age limits (each camera's latency, a frame and
        a margin), else the simulated camera's (a 30 Hz camera's: its latency + 40 ms)."""
        if self.sensors is not None:
            return max(self.calibration().age_limits_s.values())
        return skeleton_format(self.camera).sensor.age_limit_s(self.latency_s)

    @property
    def sensor_latency_s(self) -> float:
        """The real bench's sensor latency, s: ``latency_s``, or the camera's own."""
        if self.latency_s is not None:
            return self.latency_s
        return skeleton_format(self.camera).sensor.latency_s

    @property
    def human_files(self) -> tuple[str, ...]:
        """The recordings the run replays: the per-sensor ones, or the base-frame one."""
        if self.sensor_files:
            return self.sensor_files
        return (self.human_file,) if self.human_file else ()

    @property
    def label(self) -> str:
        """The run's name: the scenario, or the recording's file stem."""
        if self.listen is not None:
            return "live"
        return self.scenario if self.scenario is not None else Path(str(self.human_file)).stem

    def task_for(self, robot: Robot) -> Task | None:
        """The task file's task for ``robot`` (:func:`~qpavoid.control.task.load_task`),
        or None without ``task`` (the robot's own, its description's ``task.toml``).

        Raises
        ------
        InputError
            ``--task <file>: <key>: <what is wrong>``, in one line: a file that cannot be
            read or is not a task file, a joint the arm lacks, a waypoint out of its reach.
        """
        return None if self.task is None else task_option(self.task, robot)


def task_option(path: str, robot: Robot) -> Task:
    """``--task``'s task for ``robot`` (:func:`~qpavoid.control.task.load_task`), as
    ``qpavoid run`` and ``qpavoid send`` read it.

    Raises
    ------
    InputError
        ``--task <file>: <key>: <what is wrong>``, in one line.
    """
    try:
        return load_task(path, robot)
    except RobotDescriptionError as exc:
        raise InputError(f"--task {exc}", name="--task", value=path) from None


def check_regions(body: BodyModel) -> None:
    """Each part's ISO/TS 15066 region is a region of ``qpavoid/laws/body_regions.toml``
    (power and force limiting reads them; checked when a run is specified, whatever its
    safety mode), else :class:`~qpavoid.core.errors.SkeletonFormatError` naming the body's
    file."""
    try:
        PFLConfig().part_limits(body.regions)
    except InputError as exc:
        source = body.skeleton.source
        where = (
            Path(source).with_name(f"{body.skeleton.name}_body.toml")
            if source
            else f"the {body.skeleton.name} body model"
        )
        raise SkeletonFormatError(f"{where}: {exc}", name="region", value=exc.value) from None
