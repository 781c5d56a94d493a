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
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
import pinocchio as pin

from qpavoid.arm.braking import ArmResponse, BrakingConfig, WallClockArm
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.control.controller import Controller
from qpavoid.core.errors import ArmError, InputError
from qpavoid.core.signals import Interruption
from qpavoid.distance.methods import distance_method
from qpavoid.drive.interface import Arm
from qpavoid.drive.limits import CommandCheck, CommandLimits
from qpavoid.drive.watchdog import Watchdog
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
from qpavoid.loop.run_log import TEXT_KEYS, finished, new_log, repulsion_keys
from qpavoid.loop.timing import LoopTiming, StallCheck
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
    """A run: per-tick ``log`` arrays (see :func:`simulate`) and summary ``metrics``."""

    log: dict[str, np.ndarray]
    metrics: dict = field(default_factory=dict)


class FrameSource(Protocol):
    """What the controller is shown: ``frame_at(t)`` → (frame or people, capture time), s.
    A source may also say, in an ``alert`` attribute, why its input is suspect (logged
    every tick as ``input_alert``: :class:`~qpavoid.loop.live_input.LiveSource`)."""

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
        the watchdog; however the run ends (goal, time cap, Ctrl-C, SIGTERM, an error),
        the controller's braking ramp brings the arm to rest before :meth:`Arm.stop`.

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
        capture time), ``true_distance`` (T, S) exact capsule distance per set to where the
        person really is (NaN without ``measure_truth``), ``robot_point`` and
        ``human_point`` (T, S, 3) the witness points of each set's closest pair (NaN if no
        part is seen), ``stop_reason`` (T,) str why the robot stops ("" while it moves),
        ``input_alert`` (T,) str why the source's input is suspect ("" while it is not).
        In real time the metrics add ``realtime_overruns``, ``min_true_clearance_in_gaps_m``.
    """
    cfg = config or SimConfig()
    robot, path = controller.robot, controller.path
    dt = 1.0 / cfg.control_rate_hz
    q = (
        inverse_kinematics(robot, path.reference(0.0)[0])
        if q0 is None
        else robot.check_q(q0).astype(float).copy()
    )
    n_max = math.floor(cfg.max_time_s * cfg.control_rate_hz + 1e-9) + 1
    other_name = "capsules" if controller.config.distance == "spheres" else "spheres"
    other = distance_method(other_name, robot, controller.human)
    feed: FrameSource
    realtime = realtime or arm is not None
    if arm is not None:
        q = arm.read().q.copy()  # the arm is where it is
    if source is not None:
        feed = source
    elif motion is not None:
        feed = Camera(motion, cfg.camera, controller.human.skeleton)
    else:
        raise InputError("simulate needs a motion or a frame source", name="motion")
    arm_model = (
        None
        if cfg.braking is None or arm is not None
        else ArmResponse(cfg.braking.resolve(robot.arm), robot.joint_names, dt)
    )
    truth = (
        TrueClearance(robot, truth_body(controller.human), motion, controller.config.pfl)
        if cfg.measure_truth and motion is not None
        else None
    )
    goal = path.reference(path.duration_s)[0]
    wall = WallClockArm(arm_model, dt, robot, record=truth is not None and arm is None)
    if arm is not None:  # what the arm's interface accepts, if tighter
        lim = arm.limits
        controller.accept_limits(lim.velocity_radps, lim.acceleration_radps2, lim.jerk_radps3)
    checked = CommandCheck(  # every command vs the arm's limits
        CommandLimits.of(robot, dt) if arm is None else replace(arm.limits, dt_s=dt)
    )

    log = new_log(n_max, robot, controller.human.skeleton)
    v_repelled, v_end_effector = repulsion_keys(robot)
    texts: dict[str, list[str]] = {key: [] for key in TEXT_KEYS}
    stop_events = []
    vel_violations = pos_violations = 0
    tau, was_stopped, last_progress, last_watch = 0.0, False, -1.0, -1.0
    reached, overruns, n = False, 0, 0
    interrupt = Interruption(realtime)
    budget = controller.config.compute_budget_s  # what speed and separation counted
    deadline_s = cfg.deadline_s if cfg.deadline_s is not None else budget if budget > 0 else dt
    timing = LoopTiming(dt, deadline_s)
    ended_by = ""  # an arm's error, if one ended the run
    measured = np.zeros(robot.nv)  # the arm's reported velocity
    stall = StallCheck(cfg.stall_timeout_s)
    dog = Watchdog(cfg.watchdog_s, arm.stop) if arm is not None else None
    held = _Held(cfg.watchdog_s, controller, checked)  # the arm's hold of the last command
    wall0 = time.perf_counter()
    watching = False  # the watchdog starts with the first command (not the warm-up tick)
    try:
        began, tick_start, not_before = -math.inf, -math.inf, -math.inf  # (no tick yet)
        for k in range(n_max):
            t = k * dt
            if realtime:
                if interrupt.requested and k > 0:
                    break
                due = wall0 + t
                if arm is not None:  # never two commands within a period: a late loop
                    due = max(due, tick_start + dt, not_before)  # skips ticks rather
                    # than bursting them (a late tick's command: the next a period after it)
                    if due - wall0 > cfg.max_time_s:
                        break
                wait = due - time.perf_counter()
                if wait > 0:
                    time.sleep(wait)
                else:
                    overruns += wait < -dt
                # the run clock is the wall clock: a late tick sees the time it really is,
                # so the frames it holds are as old as they really are
                t = max(t, time.perf_counter() - wall0)
            began = tick_start = time.perf_counter()
            if arm is not None:
                try:
                    state = stall(arm.read(), began)
                    began = time.perf_counter()  # the command's deadline runs from its state
                    if (gap := held.ran_out(began)) is not None:  # the loop itself stalled:
                        timing.stalled(gap)  # the arm stopped on its own; start from rest
                except ArmError as exc:
                    ended_by = f"arm {exc.reason or 'error'}: {exc}"
                    break
                q, measured = state.q, state.dq
            human, captured_s = feed.frame_at(t)
            alert = getattr(feed, "alert", "")  # a live source's suspect input, if any
            if realtime:  # getting the frame took time too: the age is judged now
                t = max(t, time.perf_counter() - wall0)
                if arm is None:
                    q, moved_tau = wall.advance(q, t)  # the arm kept moving until now
                else:  # the arm held the last command at most watchdog_s
                    moved_tau = wall.path_advance(t, cfg.watchdog_s)
                tau = min(tau + moved_tau, path.duration_s)
            if progress is not None and t - last_progress >= 1.0 / 30.0:
                progress(t)
                last_progress = t
            t0 = time.perf_counter_ns()
            try:
                cmd = controller.step(q, human, None, tau, t - captured_s, captured_s)
            except InputError as exc:  # (a real arm reporting NaN): stop it, then say why
                if arm is None:
                    raise
                ended_by = f"input error: {exc}"
                break
            tick_us = (time.perf_counter_ns() - t0) / 1e3
            late = None
            if arm is not None and (late := timing.late(began, now := time.perf_counter())):
                why = f"missed deadline ({late * 1e3:.1f} ms late)"
                if (gap := held.ran_out(now)) is not None:  # so late that the arm stopped
                    timing.stalled(gap)  # on its own meanwhile: its ramp is over, at rest
                    cmd = controller.brake(why)
                else:  # the arm still follows the last command: this is a step from it
                    cmd = controller.brake(why, instead=True)
            if arm is not None and checked(cmd.dq):  # never sent (the arm would fault); logged
                ended_by = f"command beyond the arm's limits: {checked.last}"
            elif arm is not None:
                try:
                    arm.send(cmd.dq)
                except ArmError as exc:
                    ended_by = f"arm {exc.reason or 'error'}: {exc}"
                    break
                held.sent(sent_at := time.perf_counter())
                timing.sent(sent_at - wall0, captured_s)
                if sent_at - tick_start > 0.5 * dt:  # late in its period (a slow read or
                    not_before = sent_at + dt  # step): the next is not due at once
                assert dog is not None
                if not watching:
                    dog.__enter__()
                    watching = True
                dog.kick()
            kin = robot.kinematics(q, jacobians=False)
            other_table = other.closest(kin, controller.geometry(human))[0]
            if truth is not None and arm is None:  # (an arm's: after the run, off its loop)
                log["true_distance"][k] = truth(kin, t)

            if arm is not None:
                dq = measured  # what the arm reports
            elif realtime:
                dq = wall.command(cmd.dq, t)
            else:
                dq = cmd.dq if arm_model is None else arm_model(cmd.dq)
            if np.any(np.abs(dq) > robot.dq_max * (1 + 1e-9)):
                vel_violations += 1
                dq = np.clip(dq, -robot.dq_max, robot.dq_max)
            if np.any(q > robot.q_max + 1e-12) or np.any(q < robot.q_min - 1e-12):
                pos_violations += 1
            if cmd.stopped and not was_stopped:
                stop_events.append({"t": round(t, 6), "reason": cmd.reason})
            was_stopped = cmd.stopped

            log["t"][k], log["q"][k], log["dq"][k], log["dq_command"][k] = t, q, dq, cmd.dq
            log["joints"][k], log["state"][k] = controller.closest_frame or human
            log["stopped"][k], log["f"][k] = cmd.stopped, cmd.f
            log["distance"][k], log["distance_other"][k] = cmd.distance, other_table.min_per_set()
            log[v_repelled][k], log[v_end_effector][k] = cmd.v_repelled, cmd.v_end_effector
            log["ee_pos"][k], log["ee_ref"][k] = cmd.ee_pos, cmd.ee_ref
            log["tau"][k], log["tick_us"][k], log["frame_age_s"][k] = tau, tick_us, t - captured_s
            closest = np.argmin(cmd.table.distance, axis=1)  # each set's closest pair
            sets = np.arange(len(closest))
            log["robot_point"][k] = cmd.table.robot_point[sets, closest]
            log["human_point"][k] = cmd.table.human_point[sets, closest]
            texts["stop_reason"].append(cmd.reason if cmd.stopped else "")
            texts["input_alert"].append(alert)
            if watch is not None and t - last_watch >= 1.0 / 30.0:
                watch(
                    {key: v[k].copy() for key, v in log.items()} | {x: texts[x][k] for x in texts}
                )
                last_watch = t
            n = k + 1
            if ended_by:
                break

            if tau >= path.duration_s and not cmd.stopped:
                T = robot.end_effector(q)
                pos_err = np.linalg.norm(T[:3, 3] - goal[:3, 3])
                rot_err = _rot_err(goal, T)
                if pos_err < cfg.goal_tolerance_m and rot_err < cfg.goal_tolerance_rad:
                    reached = True
                    break
            if realtime:  # the arm moves on when the next tick comes, however late
                wall.hold(t, dq, cmd.time_scale)
            else:
                q = q + dq * dt
                tau = min(tau + cmd.time_scale * dt, path.duration_s)

        if arm is not None and not ended_by:  # however it ended: a ramp to rest, on time
            assert dog is not None
            ended_by = _ramp_down(controller, arm, checked, dt, dog.kick, held)
    finally:
        interrupt.restore()
        if dog is not None and watching:
            dog.__exit__(None, None, None)
        if arm is not None:
            try:
                arm.stop()
            except ArmError as exc:
                ended_by = ended_by or f"arm {exc.reason or 'error'}: {exc}"
    log = finished(log, n, texts)
    if truth is not None and arm is not None:  # where the arm really was, when it was there
        kinematics = robot.kinematics
        for k in range(n):
            log["true_distance"][k] = truth(kinematics(log["q"][k], jacobians=False), log["t"][k])
    if watch is not None and n:  # the last tick too, whenever it came
        watch({key: v[n - 1].copy() for key, v in log.items()})
    avoidance = controller.config.avoidance
    ending = end_of_run(reached, cmd, robot, avoidance, log, goal)
    if interrupt.requested:
        ending["end_reason"] = "interrupted"
    if ended_by and ended_by != "at rest":
        ending["end_reason"] = ended_by
    if realtime:
        ending["realtime_overruns"] = int(overruns)
        ending["min_true_clearance_in_gaps_m"] = wall.least_clearance(truth)
        ending["loop"] = timing.report()
    if dog is not None and dog.fired:
        ending["watchdog_fired"] = True
    moving = None if arm is None else measured_motion(robot, log["q"], log["t"])
    ending |= truth_metrics(log, robot, avoidance, stop_events, dt, moving)
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
    if arm is None:  # offline: the whole stream at once, after the run
        checked.stream(log["dq_command"])
    ending["command_limit_violations"] = dict(checked.counts)
    ending["command_limit_worst_ratio"] = {k: round(v, 6) for k, v in checked.worst.items()}
    return SimResult(
        log,
        run_metrics(
            log,
            robot,
            goal,
            reached,
            stop_events,
            vel_violations + wall.vel_violations,
            pos_violations + wall.pos_violations,
            controller.name,
            controller.config.distance,
            cfg.control_rate_hz,
        )
        | ending,
    )


class _Held:
    """When the last command went to the arm, and whether the arm still follows it.

    An arm holds a command for ``hold_s`` (franky's hold, the watchdog's timeout,
    :class:`~qpavoid.drive.simulated.SimulatedArm`'s ``hold_s``), then brakes to rest on its
    own. A command sent after that is the first of a new stream, from rest: the
    controller's ramp and the command check start again from rest, together. Judged from
    the time of the last *send*, as the arm judges it, not from when a tick began: a late
    tick sends long after it began, and the arm still follows that command after it.
    """

    def __init__(self, hold_s: float, controller: Controller, checked: CommandCheck):
        self.hold_s, self.controller, self.checked = hold_s, controller, checked
        self.at: float | None = None  # when the command the arm holds was sent, if one
        self.last = -math.inf  # when the last command was sent (the next: a period later)

    def sent(self, now: float) -> None:
        """A command went to the arm at ``now`` (wall clock, s)."""
        self.at = self.last = now

    def ran_out(self, now: float) -> float | None:
        """If the arm's hold of the last command ran out by ``now``: the controller and
        the check then start from rest; the time since that command, s (else None)."""
        if self.at is None or now - self.at <= self.hold_s:
            return None
        gap, self.at = now - self.at, None
        self.controller.at_rest()
        self.checked.restart()
        return gap


def _ramp_down(
    controller: Controller,
    arm: Arm,
    checked: CommandCheck,
    dt: float,
    kick: Callable[[], None],
    held: _Held,
) -> str:
    """The controller's braking ramp sent to ``arm`` once a period (a period after the last
    command, the loop's included) until it commands rest (at most 10 s); "at rest", or why
    it could not finish. Where the arm's hold of the last command ran out meanwhile, it
    stopped on its own: the ramp is over."""
    start = max(time.perf_counter(), held.last + dt)
    for k in range(int(10.0 / dt)):
        wait = start + k * dt - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        held.ran_out(time.perf_counter())
        cmd = controller.brake("end of run")
        if checked(cmd.dq):
            return f"command beyond the arm's limits: {checked.last}"
        try:
            arm.send(cmd.dq)
        except ArmError as exc:
            return f"arm {exc.reason or 'error'}: {exc}"
        held.sent(time.perf_counter())
        kick()  # (the watchdog, if it runs)
        if not np.any(cmd.dq):
            return "at rest"
    return "at rest"


def _rot_err(A: np.ndarray, B: np.ndarray) -> float:
    return float(np.linalg.norm(pin.log3(A[:3, :3] @ B[:3, :3].T)))
