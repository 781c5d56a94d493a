"""What every controller shares: configuration, the tick's measurements, the command.

A tick (:meth:`Controller.step`) takes the joint angles, the latest human frame and the
path time, and returns a :class:`Command`: joint velocities plus everything needed to see
why. The shared prelude measures (kinematics, distance table, f of eq. 2, the reference
pose and twist) and applies the paper's stop rules; the shared epilogue is the last-resort
layer (never cross a joint position limit, never command a non-finite velocity). Between
them each controller computes its joint velocities (:meth:`Controller.act`):
:class:`~qpavoid.control.analytic.AnalyticController` with eqs. (3)-(9),
:class:`~qpavoid.control.qp.controller.QPController` with one QP. A numerical failure there (a
:class:`~qpavoid.core.errors.SolverError`, or a ``LinAlgError``) stops the robot with the
error as the reason; it is never raised. Invalid inputs (a wrong shape, a non-finite
joint angle or path time) raise :class:`~qpavoid.core.errors.InputError` before any of it.
"""

from __future__ import annotations

import functools
import inspect
import math
import typing
from collections.abc import Callable, Hashable
from dataclasses import replace
from typing import ParamSpec, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from qpavoid.arm.model import Robot
from qpavoid.control.journal import Journal
from qpavoid.control.path import PlannedPath
from qpavoid.control.smoothing import CommandRamp
from qpavoid.control.stages import (
    Clearances,
    ClearanceStage,
    LimitsStage,
    PerceptionStage,
    ReferenceStage,
    Seen,
)
from qpavoid.control.task import default_task
from qpavoid.control.tick import Command, ControllerConfig, Tick
from qpavoid.core.checks import finite_number
from qpavoid.core.compiling import kernel_input
from qpavoid.core.errors import InputError, SolverError
from qpavoid.distance.methods import DistanceMethod
from qpavoid.human.body import BodyModel, HumanGeometry, KinectHuman
from qpavoid.human.frames import HumanFrame
from qpavoid.human.people import People
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.laws._kernels import NOT_FINITE, limit_crossed, warm_up
from qpavoid.laws.avoidance import l1_factor, modified_ik, stop_reason
from qpavoid.laws.ssm import SSMConfig, StopTimeBudget, reaction_time
from qpavoid.perception.perceiver import Perceiver

__all__ = ["Controller", "robot_then_keywords"]

_P = ParamSpec("_P")
_R = TypeVar("_R")


def robot_then_keywords(init: Callable[_P, _R]) -> Callable[_P, _R]:
    """A controller's ``__init__`` whose parameters after the robot are keyword-only
    (``def __init__(self, robot, *, path=None, config=None, ...)``), refusing them by
    position with a :class:`TypeError` that says which keyword each one is.

    ``QPController(robot, cfg)`` once took ``cfg`` for the path and failed only at the
    first tick; with keyword-only settings Python refuses it at once, but says only
    "takes 2 positional arguments but 3 were given". This says how to write it:
    ``QPController(robot, config=...)``. Type checkers see the keyword-only signature.
    """

    @functools.wraps(init)
    def checked(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        if len(args) > 2:  # self, robot, and more
            raise TypeError(_by_keyword_message(init, type(args[0]).__name__, args[2:]))
        return init(*args, **kwargs)

    return checked


def _by_keyword_message(init: Callable[..., object], cls: str, extra: tuple) -> str:
    """The error of :func:`robot_then_keywords`: each extra argument's keyword, guessed
    from its type against the annotations of ``init``'s keyword-only parameters."""
    params = inspect.signature(init).parameters
    keywords = [n for n, p in params.items() if p.kind is inspect.Parameter.KEYWORD_ONLY]
    try:
        hints = typing.get_type_hints(init)
    except (NameError, TypeError):  # an annotation that does not resolve: no guesses
        hints = {}

    def keyword(value: object) -> str:
        for name in keywords:
            for kind in typing.get_args(hints.get(name)) or (hints.get(name),):
                if isinstance(kind, type) and kind is not type(None):
                    try:
                        if isinstance(value, kind):
                            return name
                    except TypeError:  # a protocol that cannot be checked at run time
                        continue
        return "<keyword>"

    named = ", ".join(f"{keyword(v)}=<your {type(v).__name__}>" for v in extra)
    return (
        f"{cls} takes the robot alone by position and its settings by keyword "
        f"({', '.join(keywords)}): write {cls}(robot, {named})"
    )


def _frame_times(frame_age_s: object, frame_time_s: object) -> tuple[float | None, float | None]:
    """The frame's age (a real number ≥ 0; NaN or +inf: unknown, stale) and capture time (a
    real number; -inf: no frame yet), as floats, or None where not given.

    Raises
    ------
    InputError
        For anything else (a string, an array, a complex number, a negative age, a NaN
        time).
    """
    age = None if frame_age_s is None else _real(frame_age_s, "frame_age_s")
    if age is not None and age < 0.0:
        raise InputError(f"frame_age_s must be >= 0 s, got {age}", name="frame_age_s", value=age)
    time_s = None if frame_time_s is None else _real(frame_time_s, "frame_time_s")
    if time_s is not None and math.isnan(time_s):
        raise InputError("frame_time_s is NaN", name="frame_time_s", value=time_s)
    return age, time_s


def _real(value: object, name: str) -> float:
    """``value`` as a float if it is a real number (NaN included), else InputError."""
    if isinstance(value, (bool, str, bytes)) or not isinstance(value, (int, float, np.number)):
        raise InputError(f"{name} must be a number, got {value!r}", name=name, value=value)
    if isinstance(value, complex | np.complexfloating):
        raise InputError(f"{name} must be a real number, got {value!r}", name=name, value=value)
    return float(value)


class Controller:
    """Base of the controllers: the shared prelude, stop rules and last-resort layer.

    Parameters
    ----------
    robot
        The arm, the only argument taken by position: the others, and those of the
        controllers, are keyword-only (``QPController(robot, config=cfg)``); a setting
        given by position is refused with a :class:`TypeError` naming its keyword
        (:func:`robot_then_keywords`).
    path
        The planned end-effector path (default: the arm's own task's,
        :func:`~qpavoid.control.task.default_task`: the paper's arc for the iiwa).
    config
        Shared settings (:class:`ControllerConfig`).
    human
        The body model (default: the paper's upper body on the Kinect v2,
        :class:`~qpavoid.human.body.KinectHuman`).
    """

    name = "base"

    @robot_then_keywords
    def __init__(
        self,
        robot: Robot,
        *,
        path: PlannedPath | None = None,
        config: ControllerConfig | None = None,
        human: BodyModel | None = None,
    ):
        self.robot = robot
        self.path = path or default_task(robot).path
        self.config = config or ControllerConfig()
        self.human = human or KinectHuman()
        self.K = np.r_[[self.config.gain_position] * 3, [self.config.gain_orientation] * 3]
        #: Which set plays which part (the robot description's), and their names in order.
        self.roles = robot.roles
        self.role_names = robot.role_names
        #: The sets that play no part in the laws: the robot stops when one touches the
        #: person (their dampers in the QP stop them at contact too).
        self._roleless = np.setdiff1d(np.arange(len(robot.sets)), list(robot.roles.rows))
        ssm = self.config.ssm.resolve(robot.arm)  # the arm's reaction and accelerations
        period, compute = self.config.control_period_s, self.config.compute_budget_s
        ssm = replace(ssm, reaction_time_s=reaction_time(ssm, period, compute))
        warm_up()  # law_kernels, before the first tick
        #: The commands so far and the reach of the next (None: the paper's steps).
        self.ramp = (
            CommandRamp(
                robot,
                self.config.control_period_s,
                ssm.max_acceleration_radps2 or (),
                reaction_time_s=robot.arm.reaction_time_s,
            )
            if self.config.smooth
            else None
        )
        # the tick's stages, in the order the data flows (control.stages)
        self.perception = PerceptionStage(self.human, self.config)
        self.clearance = ClearanceStage(robot, self.human, self.config)
        self.reference = ReferenceStage(self.path, self.K)
        self.limits = LimitsStage(robot, self.human, self.config, ssm, self.ramp)
        #: With ``safety="pfl"``: the parts the paper's stop rules still hold for (head,
        #: trunk).
        contact = self.limits.contact
        self._protected = None if contact is None else np.flatnonzero(contact.protected())
        self._scale_at_stop = 0.0  # the path clock's rate when a stop ramp began
        self._ticks = 0  # the controller's own clock: control periods since it started
        self._clock_s = 0.0  # = _ticks × control_period_s, s
        self.closest_frame: HumanFrame | None = None  # the closest person's, last tick
        self._last: Command | None = None  # the last command returned
        #: What it is handed, call by call, if kept (:mod:`~qpavoid.control.journal`: a
        #: run's commands reproduced from its log or bag).
        self.journal: Journal | None = None

    @property
    def last_command(self) -> Command | None:
        """The last command returned (by :meth:`step` or :meth:`brake`), if any."""
        return self._last

    @property
    def perceiver(self) -> Perceiver:
        """The trackers (the perception stage's)."""
        return self.perception.perceiver

    @property
    def distances(self) -> DistanceMethod:
        """The distance method (the clearance stage's)."""
        return self.clearance.distances

    @property
    def ssm(self) -> SSMConfig:
        """Speed and separation's constants, resolved for the arm (the limits stage's)."""
        return self.limits.ssm

    @property
    def stop_budget(self) -> StopTimeBudget:
        """Speed and separation's stopping-time budget (the limits stage's)."""
        return self.limits.stop_budget

    def accept_limits(
        self,
        velocity_radps: np.ndarray,
        acceleration_radps2: np.ndarray,
        jerk_radps3: np.ndarray,
    ) -> None:
        """Command only what an arm's interface accepts, where it is tighter than the
        description ((nv,) each; franky-control caps an FR3 at the Panda's limits,
        :attr:`~qpavoid.drive.franka.FrankaArm.limits`): the velocity and the reach of each
        command (:meth:`~qpavoid.control.smoothing.CommandRamp.tighten`), and the braking
        deceleration speed and separation counts on, ``b_j ≤ a_j``. Call it before the
        first tick."""
        if self.journal is not None:
            self.journal.limits(velocity_radps, acceleration_radps2, jerk_radps3)
        self.limits.accept(velocity_radps, acceleration_radps2)
        if self.ramp is not None:
            braking = self.limits.braking()
            self.ramp.tighten(velocity_radps, acceleration_radps2, jerk_radps3, braking)

    def body_of(
        self, joints: object, state: object, camera_format: str | SkeletonFormat | None
    ) -> People:
        """The people of a frame as the body's landmarks
        (:meth:`~qpavoid.control.stages.PerceptionStage.body_of`)."""
        return self.perception.body_of(joints, state, camera_format)

    def geometry(self, frame: HumanFrame | People) -> list[HumanGeometry]:
        """The geometries used for ``frame`` if last perceived, else its own (raw)."""
        return self.perceiver.geometries(frame)

    def measure(
        self,
        q: ArrayLike,
        joints: object,
        state: object,
        t: float,
        frame_age_s: float | None = None,
        frame_time_s: float | None = None,
        frame_id: Hashable | None = None,
        camera_format: str | SkeletonFormat | None = None,
    ) -> Tick:
        """The tick's measurements, stage by stage (:mod:`qpavoid.control.stages`): the
        people as perceived, the clearances and the laws (eqs. 2, 4-5, 7), the reference
        (eq. 8's target), the limits (eq. 3, speed and separation), then the stop rules.

        Raises
        ------
        InputError
            If ``q``, ``joints`` or ``state`` is malformed or ``t`` is not finite.
        """
        t = finite_number(t, "t (path time, s)")
        kin = self.robot.kinematics(q)
        people = self.perception.body_of(joints, state, camera_format)
        self._ticks += 1
        self._clock_s = self._ticks * self.config.control_period_s
        frame_age_s, frame_time_s = _frame_times(frame_age_s, frame_time_s)
        seen = self.perception(people, self._clock_s, frame_age_s, frame_time_s, frame_id)
        clear, who = self.clearance(kin, seen)
        self.closest_frame = clear.frame
        bounds = self.limits(kin, clear, who, seen)
        return Tick(
            q=kin.q,
            kin=kin,
            roles=self.roles,
            frame_age_s=seen.frame_age_s,
            reason=self._stop_reason(seen, clear),
            **clear._asdict(),
            **self.reference(t, kin)._asdict(),
            **bounds._asdict(),
        )

    def _stop_reason(self, seen: Seen, clear: Clearances) -> str:
        """Why the robot must stop this tick ("" if it may move): a stale or frozen frame,
        nobody tracked, the paper's stop rules (Sect. 5.4), a set with no role touching.
        With ``safety="pfl"`` the stop rules and the touch hold for the parts that permit
        no contact (head, trunk): the arms and hands may be touched within their limit."""
        age, percs, dmin, f = seen.frame_age_s, seen.perceived, clear.distance, clear.f
        frozen = self.config.perception.max_identical_frames
        if not age <= self.config.max_frame_age_s:  # NaN too
            limit = f"max {1e3 * self.config.max_frame_age_s:.1f} ms"
            if age == math.inf:
                return f"human frame is stale (none taken yet, {limit})"
            return f"human frame is stale ({1e3 * age:.1f} ms old, {limit})"
        if frozen is not None and (repeats := max(p.identical for p in percs)) > frozen:
            return f"human frame is frozen ({repeats + 1} identical skeletons in a row)"
        if self.config.require_human and not np.isfinite(dmin).any():
            return "no body part of the operator is tracked"
        if self._protected is not None:  # pfl: the rules judge the head and trunk only
            dmin = clear.table.distance[:, self._protected].min(axis=1, initial=np.inf)
            f = float(l1_factor(dmin[self.roles.scaled], self.config.avoidance))
        d_rep, d_ee = dmin[self.roles.repelled], dmin[self.roles.end_effector]
        cfg = self.config.avoidance
        return stop_reason(f, d_rep, d_ee, cfg, self.role_names) or self._contact(dmin)

    def _contact(self, dmin: np.ndarray) -> str:
        """Why a set that plays no part in the laws stops the robot: it touches the person
        ("" if none does)."""
        for i in self._roleless:
            if dmin[i] <= 0.0:
                return f"{self.robot.set_names[i]} touches the person (d = {dmin[i]:.3f} m)"
        return ""

    def task_joint_velocities(self, tick: Tick) -> np.ndarray:
        """Eq. (8): ``q̇ = J⁻¹ (v_PL + K e + v_EE)``, damped near singularities, rad/s (nv,)."""
        assert tick.kin.ee_jacobian is not None  # a tick's kinematics carry the Jacobians
        cfg = self.config
        return modified_ik(
            tick.kin.ee_jacobian,
            tick.ref_twist,
            self.K,
            tick.error,
            tick.v_end_effector,
            cfg.sigma_min,
            cfg.lambda_max,
        )

    def command(
        self,
        tick: Tick,
        dq: np.ndarray | None,
        time_scale: float = 1.0,
        v_repelled: np.ndarray | None = None,
        v_end_effector: np.ndarray | None = None,
        reason: str = "",
        info: dict | None = None,
    ) -> Command:
        """Shared epilogue: the last-resort layer, then the :class:`Command`.

        ``dq = None`` or a non-empty ``reason`` (or the tick's own) means stop. A command
        that is not finite, or that would carry a joint past its position limit within one
        control period, becomes a stop too.
        """
        reason = tick.reason or reason
        if dq is not None:
            dq = np.asarray(dq, dtype=float)
        if not reason and dq is not None and dq.shape != tick.q.shape:  # never sent nor read
            reason = f"joint velocity of shape {dq.shape} computed, not {tick.q.shape}"
        elif not reason and dq is not None:
            k = limit_crossed(  # one compiled pass (law_kernels)
                kernel_input(tick.q, np.float64),
                kernel_input(dq, np.float64),
                float(self.config.control_period_s),
                self.robot.q_min,
                self.robot.q_max,
            )
            if k == NOT_FINITE:
                reason = "non-finite joint velocity computed"
            elif k >= 0:
                reason = (
                    f"joint {self.robot.joint_names[k]} would cross its position limit "
                    f"(q = {tick.q[k]:.4f} rad)"
                )
        stopped = bool(reason) or dq is None
        if self.ramp is None:  # the paper's: a step
            applied = np.zeros(self.robot.nv) if stopped or dq is None else dq
        elif stopped or dq is None:  # a braking ramp from the last command
            applied = self.ramp.brake()
            time_scale = self._scale_at_stop * self.ramp.commit(applied, stopping=True)
        else:  # as far towards dq as the arm may go this tick
            assert tick.command_box is not None
            applied = self.ramp.limit(dq, *tick.command_box)
            self.ramp.commit(applied, stopping=False)
            self._scale_at_stop = float(time_scale)
        self.limits.record(applied)
        zero3 = np.zeros(3)
        self._last = Command(
            dq=applied,
            stopped=stopped,
            reason=reason if stopped else "",
            time_scale=float(time_scale) if self.ramp is not None or not stopped else 0.0,
            f=tick.f,
            distance=tick.distance,
            table=tick.table,
            v_repelled=zero3 if v_repelled is None else v_repelled,
            v_end_effector=zero3 if v_end_effector is None else v_end_effector,
            limits=tick.limits,
            ee_pos=tick.kin.ee_placement[:3, 3].copy(),
            ee_ref=tick.ref_pose[:3, 3].copy(),
            info=info or {},
        )
        return self._last

    def at_rest(self) -> None:
        """The arm stopped on its own (its loop stalled past the arm's hold of a command):
        the next command starts again from rest."""
        if self.journal is not None:
            self.journal.rest()
        if self.ramp is not None:
            self.ramp.reset()

    def brake(self, reason: str, instead: bool = False) -> Command:
        """A stop decided outside the controller (a missed deadline, Ctrl-C, the end of a
        run): the next command of the braking ramp from the last command (zero with
        ``smooth=False``), as a stopped :class:`Command` with ``reason``; the rest of it
        (distances, limits) is the last tick's. ``instead``: the last command was never
        sent, and this one replaces it (the ramp starts from the one before).

        Raises
        ------
        InputError
            Before the first tick (there is nothing to brake from).
        """
        last = self._last
        if last is None:
            raise InputError(
                "brake before any tick: nothing to brake from", name="reason", value=reason
            )
        if self.journal is not None:
            self.journal.brake(instead)
        if self.ramp is None:
            applied = np.zeros(self.robot.nv)
            time_scale = 0.0
        else:
            if instead:
                self.ramp.undo()
            applied = self.ramp.brake()
            time_scale = self._scale_at_stop * self.ramp.commit(applied, stopping=True)
        self.limits.record(applied)
        self._last = replace(last, dq=applied, stopped=True, reason=reason, time_scale=time_scale)
        return self._last

    def step(
        self,
        q: ArrayLike,
        joints: object,
        state: object = None,
        t: float = 0.0,
        frame_age_s: float | None = None,
        frame_time_s: float | None = None,
        frame_id: Hashable | None = None,
        camera_format: str | SkeletonFormat | None = None,
    ) -> Command:
        """One control tick: :meth:`measure`, then (unless a stop rule holds) :meth:`act`.

        Parameters
        ----------
        q
            (nq,) joint angles, rad.
        joints
            (J, 3) joints of the latest frame, m, robot base frame; NaN = lost: the body's
            25 landmarks (a Kinect v2 frame), or a frame of ``camera_format``; or
            :class:`~qpavoid.human.people.People` (several people: every distance, rule and
            constraint uses the closest of them).
        state
            (J,) tracking states (0 not tracked, 1 inferred, 2 tracked), or None (every
            joint tracked); a camera's own confidence becomes these with
            :func:`~qpavoid.human.landmarks.camera_frame`.
        t
            Path time, s (the clock of the planned path, which waits while stopped).
        frame_age_s
            Age of the human frame, s (now minus its capture time); too old
            (``config.max_frame_age_s``), or NaN, stops the robot. None (the default): the
            controller measures it on its own clock (``config.control_period_s`` per call)
            from the tick the frame first arrived.
        frame_time_s
            The frame's capture time on any clock, s, if the caller has it: a frame with the
            time of the frame in hand is that frame, held (the tracker's velocities use it
            too); without it the controller's own clock minus the age.
        frame_id
            The caller's id of the frame (a camera's frame counter), if it has one: a frame
            with the id of the frame in hand is that frame, held. Without an id or a time, a
            frame is new when its content (any joint or state) changes
            (:class:`~qpavoid.perception.freshness.FrameClock`).

        camera_format
            The skeleton format of ``joints`` (``"k4abt"``, ``"zed_body_34"``,
            ``"mediapipe_pose"``, a :class:`~qpavoid.human.skeleton.SkeletonFormat`); None:
            the body's own. Its frames are mapped onto the body's landmarks and its derived
            landmarks' uncertainty widens the body (:meth:`body_of`).

        A held frame is never a frozen sensor, whatever the number of calls; the same
        skeleton under new ids or times is (``config.perception.max_identical_frames``).

        Raises
        ------
        InputError
            On malformed inputs (see :meth:`measure`). A numerical failure while computing
            the command is not raised: the robot stops with it as the reason.
        """
        tick = self.measure(q, joints, state, t, frame_age_s, frame_time_s, frame_id, camera_format)
        if self.journal is not None:  # (measured: a tick the controller refused is not kept)
            if state is not None or camera_format is not None:
                self.journal.unsupported = "a tick with its own tracking states or format"
            self.journal.step(tick.q, joints, t, frame_age_s, frame_time_s, frame_id)
        if tick.reason:
            return self.command(tick, None)
        try:
            return self.act(tick)
        except (SolverError, np.linalg.LinAlgError) as exc:
            info = (
                {"solver": exc.solver, "status": exc.status}
                if isinstance(exc, SolverError)
                else {"error": type(exc).__name__}
            )
            return self.command(tick, None, reason=f"numerical failure: {exc}", info=info)

    def act(self, tick: Tick) -> Command:
        """The command of a tick on which no stop rule holds (each controller's own part).

        It ends with :meth:`command`; it may raise :class:`~qpavoid.core.errors.SolverError`
        (or ``LinAlgError``), which :meth:`step` turns into a stop.
        """
        raise NotImplementedError
