"""The stages of a tick's measurement, in the order the data flows through them.

:meth:`~qpavoid.control.controller.Controller.measure` is this pipeline: each stage owns
its state and its settings, takes what the stages before it produced and returns a record
whose fields are :class:`~qpavoid.control.tick.Tick`'s own, so that the tick is built by
keyword from the records, never by position.

1. :class:`PerceptionStage`: a camera frame (any skeleton format) → everybody as the
   trackers see them (:class:`Seen`).
2. :class:`ClearanceStage`: the arm's kinematics and the people → the distance table, the
   closest person, the laws' minima and repulsions (eqs. 2, 4-5, 7) (:class:`Clearances`).
3. :class:`ReferenceStage`: the path time and the kinematics → eq. (8)'s target
   (:class:`Reference`).
4. :class:`LimitsStage`: the clearances → the joint velocity limits of eq. (3), speed and
   separation's bounds, the contact speeds of power and force limiting and the reach of
   this tick's command (:class:`Bounds`).
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from qpavoid.arm.model import Kinematics, Robot, joint_columns
from qpavoid.control.contact import ContactLimits
from qpavoid.control.path import PlannedPath, pose_error
from qpavoid.control.smoothing import CommandRamp
from qpavoid.control.tick import ControllerConfig
from qpavoid.core.compiling import kernel_input
from qpavoid.core.errors import InputError
from qpavoid.distance.methods import distance_method
from qpavoid.distance.table import DistanceTable
from qpavoid.human.body import BodyModel, HumanGeometry
from qpavoid.human.frames import HumanFrame, nobody
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import landmark_map, skeleton_format
from qpavoid.human.people import NOBODY, People, as_people
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.laws.avoidance import avoidance_terms, l1_factor, law_constants, scaled_velocity_limits
from qpavoid.laws.ssm import (
    SSMConfig,
    StopTimeBudget,
    approach_bounds,
    body_mask,
    joint_speed_limits,
    separation_constants,
    with_stop_time,
)
from qpavoid.perception.freshness import FrameClock
from qpavoid.perception.perceiver import Perceiver
from qpavoid.perception.tracker import Perceived

__all__ = [
    "Bounds",
    "ClearanceStage",
    "Clearances",
    "LimitsStage",
    "PerceptionStage",
    "Reference",
    "ReferenceStage",
    "Seen",
]


def nobody_of(human: BodyModel) -> HumanFrame:
    """Nobody in view, on the body's joints (:data:`~qpavoid.human.people.NOBODY` itself for
    the Kinect v2's, the paper's body)."""
    if human.skeleton.name == KINECT_V2.name and human.skeleton.n_joints == len(NOBODY.joints):
        return NOBODY
    return nobody(human.skeleton)


class Seen(NamedTuple):
    """What the perception stage made of a frame."""

    people: People
    """The frame's people, as the body's landmarks."""
    frame_age_s: float
    """Age of the newest frame the trackers accepted, plus the people's largest lag behind
    it (:attr:`~qpavoid.human.people.People.lag_s`: a person fused from a later camera's
    frame is as old as that), s (NaN or +inf: unknown, stale)."""
    perceived: list[Perceived]
    """Each person as the trackers see them (untracked: a stale frame as it is)."""
    geometries: list[HumanGeometry]
    """Each person's body."""
    part_velocity: np.ndarray
    """(P, K, 3) each person's parts' velocities, m/s."""


class PerceptionStage:
    """Stage 1: a camera frame → everybody as the trackers see them.

    Owns the frame clock (which frame is new, and the age of the one in hand), the
    trackers (:class:`~qpavoid.perception.perceiver.Perceiver`) and the mapping of a
    camera's skeleton onto the body's landmarks.

    Parameters
    ----------
    human
        The body model.
    config
        The controller's settings (its perception and ``max_frame_age_s``).
    """

    def __init__(self, human: BodyModel, config: ControllerConfig):
        self.human, self.max_frame_age_s = human, config.max_frame_age_s
        self.perceiver = Perceiver(human, config.perception)
        self._nobody = nobody_of(human)
        self.frames = FrameClock()
        self._lag_s = 0.0  # the lag behind its capture time of the frame in hand, s
        # the last camera frame of another format (its format, ids and content) and its
        # body (a frame held over ticks maps once), and that format's landmark uncertainty, m
        self._mapped: tuple[tuple[str, tuple[int, ...], tuple[bytes, ...]], People] | None = None
        self.camera_extra_m: np.ndarray | None = None

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
            self.camera_extra_m = None
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
        people = People(seen.ids, tuple(mapping.map(*f) for f in seen.frames), seen.lag_s)
        self._mapped = ((fmt.name, seen.ids, key), people)
        self.camera_extra_m = np.array(mapping.uncertainty_m)
        return people

    def perceive(self, people: People, captured_s: float, new: bool = True) -> Perceiver:
        """Everybody as the trackers see them, updated once per ``new`` frame captured at
        ``captured_s`` (s)."""
        return self.perceiver.update(people, captured_s, new, self.camera_extra_m)

    def __call__(
        self,
        people: People,
        clock_s: float,
        frame_age_s: float | None,
        frame_time_s: float | None,
        frame_id: Hashable | None,
    ) -> Seen:
        """``people`` (:meth:`body_of`) at the controller's clock ``clock_s`` (s), with the
        caller's age, capture time and id of the frame, if it has them. A stale or
        NaN-aged frame is taken as it is, and the trackers do not learn from it (the robot
        stops on it)."""
        new, age = self.frames.observe(people, clock_s, frame_age_s, frame_time_s, frame_id)
        if new:  # a person behind the frame's newest camera is that old; a frame held
            self._lag_s = people.max_lag_s  # keeps the lag of the people the trackers took
        age += self._lag_s
        if age <= self.max_frame_age_s and people.ids:
            captured = clock_s - age if frame_time_s is None else frame_time_s
            seen = self.perceive(people, captured, new)
            return Seen(people, age, seen.perceived, seen.geometry, seen.part_velocity)
        percs = [Perceived.untracked(f) for f in people.frames or (self._nobody,)]
        velocity = np.zeros((len(percs), len(self.human.parts), 3))
        return Seen(people, age, percs, self.perceiver.geometries(people), velocity)


class Clearances(NamedTuple):
    """What the clearance stage measured (fields of :class:`~qpavoid.control.tick.Tick`)."""

    frame: HumanFrame
    human: HumanGeometry
    perceived: Perceived
    table: DistanceTable
    distance: np.ndarray
    f: float
    repelled_part: int
    v_repelled: np.ndarray
    v_end_effector: np.ndarray


class ClearanceStage:
    """Stage 2: the arm and the people → the distance table and the laws' minima.

    Parameters
    ----------
    robot
        The arm (its sets and the parts they play).
    human
        The body model.
    config
        The controller's settings (the distance method and the avoidance laws).
    """

    def __init__(self, robot: Robot, human: BodyModel, config: ControllerConfig):
        self.roles, self.avoidance = robot.roles, config.avoidance
        self.distances = distance_method(config.distance, robot, human)
        self._law_constants = law_constants(config.avoidance)  # eqs. (4)-(7), as floats
        self._nobody = nobody_of(human)

    def __call__(self, kin: Kinematics, seen: Seen) -> tuple[Clearances, np.ndarray]:
        """The clearances, and (S, K) which person each pair's distance is to."""
        roles, geos = self.roles, seen.geometries
        table, who = self.distances.closest(kin, geos)
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
        people = seen.people
        frame = people.frames[nearest] if people.ids else self._nobody
        f = float(l1_factor(dmin[roles.scaled], self.avoidance))  # eq. (2)
        clear = Clearances(
            frame=frame,
            human=geos[nearest],
            perceived=seen.perceived[nearest],
            table=table,
            distance=dmin,
            f=f,
            repelled_part=j,
            v_repelled=v_repelled,
            v_end_effector=v_end_effector,
        )
        return clear, who


class Reference(NamedTuple):
    """Eq. (8)'s target at the path time (fields of :class:`~qpavoid.control.tick.Tick`)."""

    ref_pose: np.ndarray
    ref_twist: np.ndarray
    error: np.ndarray
    task_twist: np.ndarray


class ReferenceStage:
    """Stage 3: the path time and the arm → the reference pose and twist, the pose error
    and eq. (8)'s target without the repulsion, ``v_PL + K e``.

    Parameters
    ----------
    path
        The planned end-effector path.
    gain
        (6,) the diagonal of K, 1/s.
    """

    def __init__(self, path: PlannedPath, gain: np.ndarray):
        self.path, self.K = path, gain

    def __call__(self, t: float, kin: Kinematics) -> Reference:
        ref_pose, ref_twist = self.path.reference(t)
        error = pose_error(ref_pose, kin.ee_placement)
        return Reference(ref_pose, ref_twist, error, ref_twist + self.K * error)


class Bounds(NamedTuple):
    """This tick's limits (fields of :class:`~qpavoid.control.tick.Tick`)."""

    limits: np.ndarray
    approach_limit: np.ndarray
    human_approach: np.ndarray
    contact_limit: np.ndarray | None
    command_box: tuple[np.ndarray, np.ndarray] | None
    ssm: SSMConfig | None = None
    """Speed and separation's constants this tick (its stop time), None without it."""


class LimitsStage:
    """Stage 4: the clearances → the joint velocity limits of eq. (3), speed and
    separation's bounds (``safety="ssm"``, ``"pfl"``), power and force limiting's contact
    speeds (``"pfl"``) and the reach of this tick's command (``smooth``).

    Owns the joints' velocity limits, speed and separation's constants and its
    stopping-time budget (the commands sent so far, :meth:`record`).

    Parameters
    ----------
    robot
        The arm.
    human
        The body model.
    config
        The controller's settings.
    ssm
        Speed and separation's constants, resolved for the arm.
    ramp
        The controller's command ramp (None: the paper's steps).
    """

    def __init__(
        self,
        robot: Robot,
        human: BodyModel,
        config: ControllerConfig,
        ssm: SSMConfig,
        ramp: CommandRamp | None,
    ):
        self.robot, self.config, self.ramp = robot, config, ramp
        self.scaled_cols = joint_columns(robot, config.scaled_joints, "scaled_joints")
        self.ssm = ssm
        self._body = body_mask(human.part_names, ssm)  # the parts at the body's speed
        self.stop_budget = StopTimeBudget(ssm, robot.joint_names, config.control_period_s)
        self.accel = joint_speed_limits(replace(ssm, stop_time_s=1.0), robot.joint_names)  # a_j
        #: (nv,) the joints' velocity limits, rad/s: the description's (tighter with
        #: :meth:`accept`).
        self.dq_max = np.array(robot.dq_max, dtype=float)
        # the paper's rules: no separation bound, no part's own speed (read-only, shared)
        shape = (len(robot.sets), len(human.parts))
        self._no_bound, self._no_approach = np.full(shape, np.inf), np.zeros(shape)
        for a in (self._no_bound, self._no_approach):
            a.setflags(write=False)
        #: Power and force limiting (``safety="pfl"``): each pair's permitted contact speed.
        self.contact = ContactLimits(robot, human, config.pfl) if config.safety == "pfl" else None

    def braking(self) -> tuple[tuple[str, float], ...]:
        """``(joint, b_j)``: the braking deceleration of a stop (speed and separation's,
        resolved from the description), rad/s²."""
        braking = self.ssm.max_acceleration_radps2
        assert braking is not None  # resolved by the controller
        return braking

    def accept(self, velocity_radps: np.ndarray, acceleration_radps2: np.ndarray) -> None:
        """Only what an arm's interface accepts, where it is tighter: the velocities, and
        the braking deceleration speed and separation counts on, ``b_j ≤ a_j``."""
        names = self.robot.joint_names
        a = dict(zip(names, np.asarray(acceleration_radps2, dtype=float), strict=True))
        braking = tuple((n, min(b, a.get(n, b))) for n, b in self.braking())
        self.ssm = replace(self.ssm, max_acceleration_radps2=braking)
        self.stop_budget = StopTimeBudget(self.ssm, names, self.config.control_period_s)
        self.accel = joint_speed_limits(replace(self.ssm, stop_time_s=1.0), names)
        self.dq_max = np.minimum(self.dq_max, velocity_radps)

    def record(self, applied: np.ndarray) -> None:
        """A command was sent (rad/s): speed and separation's budget counts it."""
        if self.config.monitors_separation:
            self.stop_budget.record(applied)

    def __call__(self, kin: Kinematics, clear: Clearances, who: np.ndarray, seen: Seen) -> Bounds:
        limits = scaled_velocity_limits(self.dq_max, clear.f, self.scaled_cols)  # eq. (3)
        box = None if self.ramp is None else self.ramp.box(kin.q)
        if not self.config.monitors_separation:
            return Bounds(limits, self._no_bound, self._no_approach, None, box)
        ssm = with_stop_time(self.ssm, self.stop_budget.budget())
        table = clear.table
        # every pair's bound and its part's speed towards the set (laws.ssm), one call
        approach_limit, human_approach = approach_bounds(
            kernel_input(table.distance, np.float64),
            kernel_input(table.vector, np.float64),
            kernel_input(who, np.int64),
            kernel_input(seen.part_velocity, np.float64),
            self._body,
            float(seen.frame_age_s),
            *separation_constants(ssm),
        )
        limits = np.minimum(limits, self.accel * ssm.stop_time_s)  # |q̇_j| ≤ a_j T_s
        if self.contact is None:
            return Bounds(limits, approach_limit, human_approach, None, box, ssm)
        contact = self.contact(kin, table, seen.geometries, who, ssm, approach_limit)
        bound = np.maximum(approach_limit, contact)
        return Bounds(limits, bound, human_approach, contact, box, ssm)
