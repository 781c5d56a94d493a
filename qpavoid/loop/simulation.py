"""Closed-loop kinematic simulation: a controller, the planned path and a moving person.

Truth and perception are kept apart. The motion (a scenario, or a recording taken as
ground truth) is where the person really is; the controller sees it only through a
:class:`~qpavoid.loop.camera.Camera` (30 Hz frames, a latency, noise, dropouts and faults,
``SimConfig.camera``), each frame with its true age: now minus its capture time. A
recording keeps its own frame times, so during a gap in the recording, and once it has
ended, the frame in hand grows old and the controller stops on it (it resumes only on a
fresh frame).

The control loop runs at ``control_rate_hz`` (default 500 Hz). The arm follows the
commanded joint velocities after a reaction time and with bounded acceleration
(``SimConfig.braking``, :class:`~qpavoid.arm.braking.ArmResponse`: a stop is a ramp, not a
jump); the joint angles integrate the arm's velocity (explicit Euler:
``q[k+1] = q[k] + dq[k] · dt``). ``braking=None`` makes the arm follow its command exactly.
In real time a late tick does not stop the arm: it and the path clock τ advance by the real
time between ticks, the last command held (:class:`~qpavoid.arm.braking.WallClockArm`).

The path has its own clock τ. It advances at the rate the controller returns
(``Command.time_scale``): 0 while stopped, so resuming causes no jump, and the factor by
which the velocity limits shrank the command, so that a slowed robot is not left behind by
its reference. A deflection does not stop the clock: while the repulsion pushes the end
effector off the path the reference runs on, and when the person withdraws the K·e term
of eq. (8) pulls it back to where the reference is by then (the delay is absorbed as path
error, never as a jump of the reference).

As a last guard the simulation saturates each joint velocity at its nominal limit (and
counts the ticks where that was needed: ``joint_velocity_limit_violations``, which a
correct controller keeps at 0).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import pinocchio as pin

from qpavoid.arm import braking
from qpavoid.arm.braking import ArmResponse, BrakingConfig
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import Robot
from qpavoid.control.controller import Controller
from qpavoid.control.journal import Journal
from qpavoid.control.path import PlannedPath
from qpavoid.control.tick import Command
from qpavoid.core.errors import ArmError, InputError
from qpavoid.core.signals import Interruption
from qpavoid.drive.interface import Arm
from qpavoid.human.frames import HumanFrame, HumanMotion
from qpavoid.human.people import People
from qpavoid.loop.camera import Camera, CameraConfig
from qpavoid.loop.metrics import (
    contact_metrics,
    end_of_run,
    measured_motion,
    run_metrics,
    truth_metrics,
)
from qpavoid.loop.plants import DrivenArm, KinematicArm, Plant, WallClockArm, offline_limits
from qpavoid.loop.run_log import RunLogger
from qpavoid.loop.timing import LoopTiming
from qpavoid.loop.truth import TrueClearance, truth_body


@dataclass(frozen=True)
class SimConfig:
    """Simulation settings.

    Attributes
    ----------
    control_rate_hz
        Control loop rate, Hz.
    camera
        What the controller sees of the true motion (default: a Kinect v2, docs/safety.md);
        ``CameraConfig.ideal()`` for the true skeleton at 30 Hz with no latency or noise.
    braking
        How the arm follows its command (default: the robot description's reaction time
        and acceleration limits, for the iiwa 14 those of docs/safety.md); None: exactly
        and at once.
    max_time_s
        Cap on the run's duration, s.
    goal_tolerance_m, goal_tolerance_rad
        The goal counts as reached when the path clock is over and the end effector is
        this close to the final pose (position, m; orientation, rad).
    measure_truth
        Measure, every tick, the exact capsule distance from each robot set to where the
        person really is (:mod:`qpavoid.loop.truth`): ``true_distance`` in the log and the
        ``true_*`` metrics. Off by default here because it doubles a simulation's time
        (the true person and a capsule table every tick, about 1.5 ms); runs made through
        :mod:`qpavoid.experiments.runs` (the command line, ``compare``) turn it on.
    deadline_s
        With an arm: a tick whose command is ready later than this after it read the arm's
        state missed its deadline; its command becomes the next step of a braking ramp
        (counted: ``deadline_misses``; logged as its stop reason). None (the default): the
        controller's ``compute_budget_s`` (the time speed and separation counted for it),
        or one control period if that is 0.
    stall_timeout_s
        With an arm (``arm=``): its state may stand still this long, s, before the arm
        counts as stalled (the run stops and ends with ``end_reason`` "arm stalled: ...").
    watchdog_s
        With an arm: a loop that sends no command for this long, s, has the arm stopped
        from a watchdog thread (:class:`~qpavoid.drive.watchdog.Watchdog`).
    """

    control_rate_hz: float = 500.0
    camera: CameraConfig = field(default_factory=CameraConfig)
    braking: BrakingConfig | None = field(default_factory=BrakingConfig)
    max_time_s: float = 40.0
    goal_tolerance_m: float = 1e-3
    goal_tolerance_rad: float = 1e-2
    measure_truth: bool = False
    deadline_s: float | None = None
    stall_timeout_s: float = 0.05
    watchdog_s: float = 0.1


@dataclass
class SimResult:
    """A run: per-tick ``log`` arrays (see :func:`simulate`), summary ``metrics`` and what
    the controller was handed (:meth:`Journal.arrays <qpavoid.control.journal.Journal.
    arrays>`: empty where it cannot be reproduced, ``metrics["reproducible"]`` says why)."""

    log: dict[str, np.ndarray]
    metrics: dict = field(default_factory=dict)
    journal: dict[str, np.ndarray] = field(default_factory=dict)


class FrameSource(Protocol):
    """What the controller is shown: ``frame_at(t)`` → (frame or people, capture time), s.
    A source may also say, in an ``alert`` attribute, why its input is suspect (logged
    every tick as ``input_alert``), and, in a ``frame_id`` attribute, which fusion the
    frame is (a new id: a new frame, whatever its capture time; the age is then the one
    given: :class:`~qpavoid.loop.live_input.LiveSource`)."""

    def frame_at(self, t: float) -> tuple[HumanFrame | People, float]: ...


def simulate(
    controller: Controller,
    motion: HumanMotion | None,
    config: SimConfig | None = None,
    q0: np.ndarray | None = None,
    progress: Callable[[float], None] | None = None,
    source: FrameSource | None = None,
    realtime: bool = False,
    watch: Callable[[dict[str, Any]], None] | None = None,
    arm: Arm | None = None,
) -> SimResult:
    """Run the controller in closed loop against ``motion`` along ``controller.path``.

    Parameters
    ----------
    controller
        Analytic or QP controller (its ``control_period_s`` should equal 1/control rate).
    motion
        The person (see :class:`HumanMotion`).
    config
        Simulation settings.
    q0
        Start configuration (default: inverse kinematics of the path's start pose).
    progress
        Called with the simulated time (s) at every new human frame, e.g. to move a
        progress bar; ``None`` for none.
    source
        Where the controller's frames come from instead of a camera filming ``motion``
        (a live source, :class:`~qpavoid.loop.live_input.LiveSource`, or fused sensors); ``motion``,
        if given, is then only the truth the run is judged against.
    watch
        Called with the tick just logged (its row of every log key, copied, and its
        ``stop_reason``), at most 30 times a second of run time (a live view).
    realtime
        Tick on the wall clock (a live run): a tick that comes late is stamped with the
        wall time, so frame ages stay true when the loop falls behind, and the arm keeps
        executing its last command until the next tick, however late; τ advances by
        ``time_scale ×`` that real time too, so the reference keeps up with the arm; Ctrl-C
        ends the run, which is summed up as usual with ``end_reason`` "interrupted".
    arm
        An arm to drive instead of the kinematic simulation (:class:`~qpavoid.drive.
        interface.Arm`: a Franka through :class:`~qpavoid.drive.franka.FrankaArm`): the run
        is then real time; each tick reads the arm's state (the joint angles the
        controller and the truth are given are the arm's, its physics' lag included),
        checks the command against the arm's limits and sends it. A missed deadline
        brakes for a tick (``deadline_misses``), a stalled state or an arm error ends the
        run (``end_reason`` "arm ..."), a loop that stops sending has the arm stopped by
        the watchdog; a run that ends on its goal, time cap, Ctrl-C, SIGTERM or bad input
        from the arm brings it to rest on the controller's braking ramp before
        :meth:`Arm.stop`, one that ends on an arm error or a refused command by
        :meth:`Arm.stop` alone (:class:`~qpavoid.loop.plants.DrivenArm`).

    Returns
    -------
    SimResult
        ``log`` keys (row k = state at t[k] and the command computed from it, so that
        ``q[k+1] = q[k] + dq[k] · (t[k+1] − t[k])``): ``t``, ``q`` (T, nq), ``dq`` (T, nv),
        ``joints`` (T, J, 3) and ``state`` (T, J) (J the joints of the body model's
        skeleton: 25 for the Kinect v2), ``stopped`` (T,), ``f`` (T,), ``distance``
        (T, S) per robot set (S of them, the description's order) of the method in use,
        ``distance_other`` (T, S) of the other method, ``v_rep_<set>``
        (T, 3) for the repelled set and the end effector (``v_rep_L2`` and ``v_rep_EE``
        for the iiwa: :func:`~qpavoid.loop.run_log.repulsion_keys`), ``ee_pos`` and
        ``ee_ref`` (T, 3),
        ``tau`` (T,) path clock, ``tick_us`` (T,) controller time per tick,
        ``dq_command`` (T, nv) the controller's command (``dq`` is what the arm did),
        ``frame_age_s`` (T,) the age of the frame the controller was given (now minus its
        capture time, plus its people's lag behind it: the age speed and separation
        counts), ``true_distance`` (T, S) exact capsule distance per set to where the
        person really is (NaN without ``measure_truth``), ``robot_point`` and
        ``human_point`` (T, S, 3) the witness points of each set's closest pair (NaN if no
        part is seen), ``stop_reason`` (T,) str why the robot stops ("" while it moves),
        ``input_alert`` (T,) str why the source's input is suspect ("" while it is not).
        In real time the metrics add ``realtime_overruns``, ``min_true_clearance_in_gaps_m``.
    """
    cfg = config or SimConfig()
    robot, path = controller.robot, controller.path
    dt = 1.0 / cfg.control_rate_hz
    n_max = math.floor(cfg.max_time_s * cfg.control_rate_hz + 1e-9) + 1
    feed: FrameSource
    if source is not None:
        feed = source
    elif motion is not None:
        feed = Camera(motion, cfg.camera, controller.human.skeleton)
    else:
        raise InputError("simulate needs a motion or a frame source", name="motion")
    truth = (
        TrueClearance(robot, truth_body(controller.human), motion, controller.config.pfl)
        if cfg.measure_truth and motion is not None
        else None
    )
    goal = path.reference(path.duration_s)[0]
    logger = RunLogger(n_max, controller, watch)
    tau, last_progress, reached = 0.0, -1.0, False
    cmd: Command | None = None
    plant: Plant | None = None
    interrupt = Interruption(realtime or arm is not None)
    controller.journal = journal = Journal()  # what it is handed: the run reproducible
    try:  # (from here on the signal handlers, and the arm, are always released)
        plant = _plant(controller, cfg, dt, realtime, arm, interrupt, record=truth is not None)
        q = (
            plant.start()
            if isinstance(plant, DrivenArm)
            else inverse_kinematics(robot, path.reference(0.0)[0])
            if q0 is None
            else robot.check_q(q0).astype(float).copy()
        )
        plant.begin()
        for k in range(n_max):
            t_tick = plant.wait(k, k * dt)
            read = None if t_tick is None else plant.read(q)
            if t_tick is None or read is None:
                break
            human, captured_s = feed.frame_at(t_tick)
            # a fused source's frames are new when the fusion's content changes (its own
            # id), not only when its newest capture time grows (a later camera's frame)
            frame_id = getattr(feed, "frame_id", None)
            alert = getattr(feed, "alert", "")  # a live source's suspect input, if any
            t, q, moved_tau = plant.catch_up(t_tick, read)
            tau = min(tau + moved_tau, path.duration_s)
            if progress is not None and t - last_progress >= 1.0 / 30.0:
                progress(t)
                last_progress = t
            t0 = time.perf_counter_ns()
            try:
                frame_time = captured_s if frame_id is None else None
                cmd = controller.step(q, human, None, tau, t - captured_s, frame_time, frame_id)
            except InputError as exc:
                if plant.input_error(exc):
                    break
                raise
            tick_us = (time.perf_counter_ns() - t0) / 1e3
            executed = plant.execute(controller, cmd, t, captured_s)
            if executed is None:
                break
            cmd, dq = executed
            kin = robot.kinematics(q, jacobians=False)
            if truth is not None and plant.measured_online:
                logger.log["true_distance"][k] = truth(kin, t)
            dq = logger.guard(q, dq)
            lag = human.max_lag_s if isinstance(human, People) else 0.0  # fused: the oldest
            logger.row(k, t, kin, dq, cmd, human, tau, tick_us, t - captured_s + lag, alert)
            journal.logged()
            if plant.ended_by:
                break
            if tau >= path.duration_s and not cmd.stopped and _at(goal, robot, q, cfg):
                reached = True
                break
            q, moved_tau = plant.move(q, dq, t, cmd)
            tau = min(tau + moved_tau, path.duration_s)
        plant.finish(controller)
    finally:
        interrupt.restore()
        controller.journal = None
        if plant is not None:
            plant.close()
    if cmd is None or logger.n == 0:  # an arm that ended the run before its first command
        raise ArmError(f"the run ended before its first tick: {plant.ended_by}", value=arm)
    log = logger.finished()
    n = logger.n
    if not reached and _at(goal, robot, log["q"][-1], cfg) and _rest_near(goal, path, tau, cfg):
        reached = True  # at the goal and held there (a person near, a stale frame): reached
    if truth is not None and not plant.measured_online:  # where the arm really was, then
        kinematics = robot.kinematics
        for k in range(n):
            log["true_distance"][k] = truth(kinematics(log["q"][k], jacobians=False), log["t"][k])
    avoidance = controller.config.avoidance
    ending = end_of_run(reached, cmd, robot, avoidance, log, goal)
    if interrupt.requested:
        ending["end_reason"] = "interrupted"
    if plant.ended_by and plant.ended_by != "at rest":
        ending["end_reason"] = plant.ended_by
    ending |= plant.report(truth)
    moving = None if arm is None else measured_motion(robot, log["q"], log["t"])
    ending |= truth_metrics(log, robot, avoidance, logger.stop_events, dt, moving)
    if truth is not None:  # each tick in true contact: its regions, speeds and limits
        touching = np.flatnonzero(np.any(log["true_distance"] <= 0.0, axis=1))
        contacts = {
            int(k): truth.contacts(
                log["q"][k], log["dq"][k], log["t"][k], log["dq"][k - 1] if k > 0 else None
            )
            for k in touching
        }
        moved = np.any(log["dq"] != 0.0, axis=1) if moving is None else moving
        ending["true_contacts"] = contact_metrics(contacts, moved, log["t"])
    checked = plant.checked
    if arm is None:  # offline: the whole stream at once, after the run
        checked.stream(log["dq_command"])
    ending["command_limit_violations"] = dict(checked.counts)
    ending["command_limit_worst_ratio"] = {k: round(v, 6) for k, v in checked.worst.items()}
    vel, pos = plant.violations()
    return SimResult(
        log,
        run_metrics(
            log,
            robot,
            goal,
            reached,
            logger.stop_events,
            logger.vel_violations + vel,
            logger.pos_violations + pos,
            controller.name,
            controller.config.distance,
            cfg.control_rate_hz,
        )
        | ending
        | {"reproducible": journal.unsupported or True},
        journal.arrays() if not journal.unsupported else {},
    )


def _plant(
    controller: Controller,
    cfg: SimConfig,
    dt: float,
    realtime: bool,
    arm: Arm | None,
    interrupt: Interruption,
    record: bool,
) -> Plant:
    """The arm the run drives: ``arm``, else the simulated arm on the wall clock
    (``realtime``) or offline; its response the description's (``cfg.braking``) or exact."""
    robot = controller.robot
    response = (
        None
        if cfg.braking is None or arm is not None
        else ArmResponse(cfg.braking.resolve(robot.arm), robot.joint_names, dt)
    )
    if arm is None and not realtime:
        return KinematicArm(robot, dt, offline_limits(robot, dt), response)
    budget = controller.config.compute_budget_s  # what speed and separation counted
    deadline_s = cfg.deadline_s if cfg.deadline_s is not None else budget if budget > 0 else dt
    timing = LoopTiming(dt, deadline_s)
    wall = braking.WallClockArm(response, dt, robot, record=record and arm is None)
    if arm is None:
        return WallClockArm(robot, dt, offline_limits(robot, dt), wall, interrupt, timing)
    return DrivenArm(
        robot,
        dt,
        controller,
        wall,
        interrupt,
        timing,
        arm,
        cfg.max_time_s,
        cfg.stall_timeout_s,
        cfg.watchdog_s,
    )


def _at(goal: np.ndarray, robot: Robot, q: np.ndarray, cfg: SimConfig) -> bool:
    """The end effector at ``q`` is at the goal pose, within the run's tolerances."""
    return _near(goal, robot.end_effector(q), cfg)


#: The rest of a path is judged at this many times between the path clock and its end.
REST_SAMPLES = 32


def _rest_near(goal: np.ndarray, path: PlannedPath, tau: float, cfg: SimConfig) -> bool:
    """What is left of ``path`` after its clock ``tau`` (s) lies within the run's tolerances
    of the goal (sampled, the end included): a path that passes its goal's pose earlier (a
    loop out and back) has not reached it there."""
    times = np.linspace(tau, path.duration_s, REST_SAMPLES)
    return all(_near(goal, path.reference(float(t))[0], cfg) for t in times)


def _near(goal: np.ndarray, T: np.ndarray, cfg: SimConfig) -> bool:
    """The pose ``T`` is the goal pose, within the run's tolerances."""
    pos_err = np.linalg.norm(T[:3, 3] - goal[:3, 3])
    return bool(pos_err < cfg.goal_tolerance_m and _rot_err(goal, T) < cfg.goal_tolerance_rad)


def _rot_err(A: np.ndarray, B: np.ndarray) -> float:
    return float(np.linalg.norm(pin.log3(A[:3, :3] @ B[:3, :3].T)))
