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

import math
from collections.abc import Hashable
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike

from qpavoid.arm.model import Kinematics, Robot, joint_columns
from qpavoid.control.contact import ContactLimits
from qpavoid.control.path import PlannedPath, pose_error
from qpavoid.control.smoothing import CommandRamp
from qpavoid.control.task import default_task
from qpavoid.control.tick import Command, ControllerConfig, Tick
from qpavoid.core.checks import finite_number
from qpavoid.core.compiling import kernel_input
from qpavoid.core.errors import InputError, SolverError
from qpavoid.distance.methods import distance_method
from qpavoid.distance.table import DistanceTable
from qpavoid.human.body import BodyModel, HumanGeometry, KinectHuman
from qpavoid.human.frames import HumanFrame
from qpavoid.human.landmarks import landmark_map, skeleton_format
from qpavoid.human.people import NOBODY, People, as_people
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.laws._kernels import NOT_FINITE, limit_crossed, warm_up
from qpavoid.laws.avoidance import (
    avoidance_terms,
    l1_factor,
    law_constants,
    modified_ik,
    scaled_velocity_limits,
    stop_reason,
)
from qpavoid.laws.ssm import (
    StopTimeBudget,
    joint_speed_limits,
    reaction_time,
    separation_bounds,
    with_stop_time,
)
from qpavoid.perception.freshness import FrameClock
from qpavoid.perception.perceiver import Perceiver
from qpavoid.perception.tracker import Perceived

__all__ = ["Controller"]


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
        The arm.
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

    def __init__(
        self,
        robot: Robot,
        path: PlannedPath | None = None,
        config: ControllerConfig | None = None,
        human: BodyModel | None = None,
    ):
        self.robot = robot
        self.path = path or default_task(robot).path
        self.config = config or ControllerConfig()
        self.human = human or KinectHuman()
        self.distances = distance_method(self.config.distance, robot, self.human)
        self.K = np.r_[[self.config.gain_position] * 3, [self.config.gain_orientation] * 3]
        #: Which set plays which part (the robot description's), and their names in order.
        self.roles = robot.roles
        self.role_names = robot.role_names
        self.scaled_cols = joint_columns(robot, self.config.scaled_joints, "scaled_joints")
        self._law_constants = law_constants(self.config.avoidance)  # eqs. (4)-(7), as floats
        #: The sets that play no part in the laws: the robot stops when one touches the
        #: person (their dampers in the QP stop them at contact too).
        self._roleless = np.setdiff1d(np.arange(len(robot.sets)), list(robot.roles.rows))
        self.perceiver = Perceiver(self.human, self.config.perception)
        self.frames = FrameClock()  # which frame is new, and the age of the one in hand
        ssm = self.config.ssm.resolve(robot.arm)  # the arm's reaction and accelerations
        period, compute = self.config.control_period_s, self.config.compute_budget_s
        self.ssm = replace(ssm, reaction_time_s=reaction_time(ssm, period, compute))
        self.stop_budget = StopTimeBudget(self.ssm, robot.joint_names, self.config.control_period_s)
        self.accel = joint_speed_limits(replace(ssm, stop_time_s=1.0), robot.joint_names)  # a_j
        #: (nv,) the joints' velocity limits, rad/s: the description's (tighter with
        #: :meth:`accept_limits`).
        self.dq_max = np.array(robot.dq_max, dtype=float)
        # the paper's rules: no separation bound, no part's own speed (read-only, shared)
        shape = (len(robot.sets), len(self.human.parts))
        self._no_bound, self._no_approach = np.full(shape, np.inf), np.zeros(shape)
        for a in (self._no_bound, self._no_approach):
            a.setflags(write=False)
        #: Power and force limiting (``safety="pfl"``): each pair's permitted contact
        #: speed, and the parts the paper's stop rules still hold for (head, trunk).
        self.contact = (
            ContactLimits(robot, self.human, self.config.pfl)
            if self.config.safety == "pfl"
            else None
        )
        self._protected = None if self.contact is None else np.flatnonzero(self.contact.protected())
        warm_up()  # law_kernels, before the first tick
        #: The commands so far and the reach of the next (None: the paper's steps).
        self.ramp = (
            CommandRamp(
                robot,
                self.config.control_period_s,
                self._braking(),
                reaction_time_s=robot.arm.reaction_time_s,
            )
            if self.config.smooth
            else None
        )
        self._scale_at_stop = 0.0  # the path clock's rate when a stop ramp began
        self._ticks = 0  # the controller's own clock: control periods since it started
        self._clock_s = 0.0  # = _ticks × control_period_s, s
        self.closest_frame: HumanFrame | None = None  # the closest person's, last tick
        # the last camera frame of another format (its format, ids and content) and its
        # body (a frame held over ticks maps once), and that format's landmark uncertainty, m
        self._mapped: tuple[tuple[str, tuple[int, ...], tuple[bytes, ...]], People] | None = None
        self._camera_extra_m: np.ndarray | None = None
        self._last: Command | None = None  # the last command returned

    def _braking(self) -> tuple[tuple[str, float], ...]:
        """``(joint, b_j)``: the braking deceleration of a stop (speed and separation's,
        resolved from the description), rad/s²."""
        braking = self.ssm.max_acceleration_radps2
        assert braking is not None  # resolved in __init__
        return braking

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
        names = self.robot.joint_names
        a = dict(zip(names, np.asarray(acceleration_radps2, dtype=float), strict=True))
        braking = tuple((n, min(b, a.get(n, b))) for n, b in self._braking())
        self.ssm = replace(self.ssm, max_acceleration_radps2=braking)
        self.stop_budget = StopTimeBudget(self.ssm, names, self.config.control_period_s)
        self.accel = joint_speed_limits(replace(self.ssm, stop_time_s=1.0), names)
        self.dq_max = np.minimum(self.dq_max, velocity_radps)
        if self.ramp is not None:
            self.ramp.tighten(velocity_radps, acceleration_radps2, jerk_radps3, braking)

    def perceive(
        self,
        people: People,
        frame_age_s: float,
        frame_time_s: float | None = None,
        new: bool = True,
    ) -> Perceiver:
        """Everybody as the trackers see them (:class:`~qpavoid.perception.perceiver.Perceiver`),
        updated once per ``new`` frame; captured at ``frame_time_s`` or, without one, the
        controller's clock minus ``frame_age_s``."""
        captured = self._clock_s - frame_age_s if frame_time_s is None else frame_time_s
        return self.perceiver.update(people, captured, new, self._camera_extra_m)

    def body_of(
        self, joints: object, state: object, camera_format: str | SkeletonFormat | None
    ) -> People:
        """The people of a frame as the body's landmarks: a frame (or :class:`People`) of
        ``camera_format`` mapped (:mod:`qpavoid.human.landmarks`; metres, base frame,
        states 0, 1, 2), or the body's own (None). The format's landmark uncertainty is
        the perception's from then on.

        Raises
        ------
        InputError
            For an unknown format, or a frame that is not one of it.
        """
        body = self.human.skeleton
        fmt = body if camera_format is None else skeleton_format(camera_format)
        if fmt.name == body.name:
            if fmt is not body and fmt != body:  # two formats of one name: not its joints
                raise InputError(
                    f"a frame of a format called {fmt.name!r} that is not the body model's "
                    f"{body.name!r} format (another file: {fmt.source or 'built in code'})",
                    name="camera_format",
                    value=fmt.name,
                )
            self._camera_extra_m = None
            return as_people(joints, state, body)
        seen = as_people(joints, state, fmt)
        key = tuple(f.joints.tobytes() + f.state.tobytes() for f in seen.frames)
        if self._mapped is not None and self._mapped[0] == (fmt.name, seen.ids, key):
            return self._mapped[1]  # the frame in hand, held (the same content): mapped once
        mapping = landmark_map(fmt)
        if mapping.target.name != body.name:
            raise InputError(
                f"{fmt.title} frames map onto {mapping.target.title} landmarks, not the body "
                f"model's {body.title}",
                name="camera_format",
                value=fmt.name,
            )
        people = People(seen.ids, tuple(mapping.map(*f) for f in seen.frames))
        self._mapped = ((fmt.name, seen.ids, key), people)
        self._camera_extra_m = np.array(mapping.uncertainty_m)
        return people

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
        """Shared prelude, one step each: the people as perceived, the distances, the laws
        (eqs. 2-5, 7), speed and separation, the reference, the stop rules.

        Raises
        ------
        InputError
            If ``q``, ``joints`` or ``state`` is malformed or ``t`` is not finite.
        """
        t = finite_number(t, "t (path time, s)")
        kin = self.robot.kinematics(q)
        people = self.body_of(joints, state, camera_format)
        self._ticks += 1
        self._clock_s = self._ticks * self.config.control_period_s
        frame_age_s, frame_time_s = _frame_times(frame_age_s, frame_time_s)
        new, age = self.frames.observe(people, self._clock_s, frame_age_s, frame_time_s, frame_id)
        percs, geos, v_people = self._perceived(people, age, frame_time_s, new)
        table, who = self.distances.closest(kin, geos)
        cfg, roles = self.config.avoidance, self.roles
        # the minima, eqs. (4)-(5) and (7) in one compiled call (laws.avoidance)
        dmin, j, v_repelled, v_end_effector = avoidance_terms(
            kernel_input(table.distance, np.float64),
            kernel_input(table.vector, np.float64),
            roles.repelled,
            roles.end_effector,
            *self._law_constants,
        )
        nearest = (
            int(who.flat[np.argmin(table.distance)])
            if len(geos) > 1 and np.isfinite(dmin).any()
            else 0
        )
        frame = self.closest_frame = people.frames[nearest] if people.ids else NOBODY
        f = float(l1_factor(dmin[roles.scaled], cfg))  # eq. (2)
        limits = scaled_velocity_limits(self.dq_max, f, self.scaled_cols)  # eq. (3)
        approach_limit, human_approach, limits, contact = self._separation(
            kin, table, who, geos, v_people, age, limits
        )
        ref_pose, ref_twist = self.path.reference(t)
        error = pose_error(ref_pose, kin.ee_placement)
        return Tick(
            kin.q,
            kin,
            frame,
            geos[nearest],
            table,
            dmin,
            f,
            limits,
            roles,
            j,
            v_repelled,
            v_end_effector,
            ref_pose,
            ref_twist,
            error,
            ref_twist + self.K * error,
            self._stop_reason(age, percs, dmin, f, table),
            percs[nearest],
            age,
            approach_limit,
            human_approach,
            None if self.ramp is None else self.ramp.box(kin.q),
            contact,
        )

    def _perceived(
        self, people: People, age: float, frame_time_s: float | None, new: bool
    ) -> tuple[list[Perceived], list[HumanGeometry], np.ndarray]:
        """Everybody as perceived (the trackers' frames, the bodies, their parts' velocities
        (P, K, 3), m/s); a stale or NaN-aged frame as it is, which the trackers do not learn
        from (the robot stops on it)."""
        if age <= self.config.max_frame_age_s and people.ids:
            seen = self.perceive(people, age, frame_time_s, new)
            return seen.perceived, seen.geometry, seen.part_velocity
        percs = [Perceived.untracked(f) for f in people.frames or (NOBODY,)]
        return percs, self.geometry(people), np.zeros((len(percs), len(self.human.parts), 3))

    def _separation(
        self,
        kin: Kinematics,
        table: DistanceTable,
        who: np.ndarray,
        geos: list[HumanGeometry],
        v_people: np.ndarray,
        age: float,
        limits: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """Speed and separation (``safety="ssm"``, ``"pfl"``): each pair's bound on the
        robot's approach speed and the part's own approach speed (S, K), m/s, the joint
        limits within the stopping-time budget (|q̇_j| ≤ a_j T_s), and with ``"pfl"`` each
        pair's permitted contact speed (:class:`~qpavoid.control.contact.ContactLimits`),
        which the bound is then at least; with the paper's rules, no bound."""
        if not self.config.monitors_separation:
            return self._no_bound, self._no_approach, limits, None
        ssm = with_stop_time(self.ssm, self.stop_budget.budget())
        v_parts = v_people[who, np.arange(who.shape[1])[None, :]]  # each pair's person
        approach_limit, human_approach = separation_bounds(table, v_parts, age, ssm)
        limits = np.minimum(limits, self.accel * ssm.stop_time_s)
        if self.contact is None:
            return approach_limit, human_approach, limits, None
        contact = self.contact(kin, table, geos, who, ssm, approach_limit)
        return np.maximum(approach_limit, contact), human_approach, limits, contact

    def _stop_reason(
        self,
        age: float,
        percs: list[Perceived],
        dmin: np.ndarray,
        f: float,
        table: DistanceTable,
    ) -> str:
        """Why the robot must stop this tick ("" if it may move): a stale or frozen frame,
        nobody tracked, the paper's stop rules (Sect. 5.4), a set with no role touching.
        With ``safety="pfl"`` the stop rules and the touch hold for the parts that permit
        no contact (head, trunk): the arms and hands may be touched within their limit."""
        frozen = self.config.perception.max_identical_frames
        if not age <= self.config.max_frame_age_s:  # NaN too
            return f"human frame is stale ({age:.3f} s old, max {self.config.max_frame_age_s} s)"
        if frozen is not None and (repeats := max(p.identical for p in percs)) > frozen:
            return f"human frame is frozen ({repeats + 1} identical skeletons in a row)"
        if self.config.require_human and not np.isfinite(dmin).any():
            return "no body part of the operator is tracked"
        if self._protected is not None:  # pfl: the rules judge the head and trunk only
            dmin = table.distance[:, self._protected].min(axis=1, initial=np.inf)
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
        if self.config.monitors_separation:
            self.stop_budget.record(applied)
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
        if self.ramp is None:
            applied = np.zeros(self.robot.nv)
            time_scale = 0.0
        else:
            if instead:
                self.ramp.undo()
            applied = self.ramp.brake()
            time_scale = self._scale_at_stop * self.ramp.commit(applied, stopping=True)
        if self.config.monitors_separation:
            self.stop_budget.record(applied)
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
