"""The arm's excitation that measures a camera's latency, on a real arm and in simulation.

The person holds the robot's flange while the arm moves a few slow sinusoids on two
joints (:class:`Excitation`); the camera films their hand and the arm logs its joint
angles, both on one clock, and :func:`qpavoid.sensing.latency_fit.estimate_latency` finds the
lag between them (docs/sensors.md §10, "Measuring your camera's latency").

* :func:`drive_excitation` moves any :class:`~qpavoid.drive.interface.Arm` through it in
  real time (the simulated arm on the wall clock, a Franka through franky-control) and
  returns the arm's log, each state stamped on the wall clock when it was read;
* :func:`film_excitation` makes both files in simulation: the arm moving the excitation,
  a seated operator whose hand holds the flange (:class:`~qpavoid.human.posture.Operator`),
  and the library's simulated camera of any format, latency, noise and jitter
  (:class:`~qpavoid.loop.camera.Camera`) filming them, each frame stamped with its
  delivery time, as a recorder that stamps arrivals would: the true latency is known.

Sinusoids of incommensurate frequencies on two joints move the flange along a curve that
never repeats within the lags searched, in two directions (the first joint turns the arm
about the vertical, the second lifts it), so one lag fits the whole recording and a wrong
one fits no part of it; slow (under 0.25 m/s at the flange, ISO 10218-1's reduced speed)
so that a hand holding the flange is carried without slipping.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import Robot, joint_columns
from qpavoid.control.path import quintic
from qpavoid.control.task import default_task
from qpavoid.core.errors import InputError
from qpavoid.drive.interface import Arm
from qpavoid.drive.limits import CommandCheck
from qpavoid.human.frames import HumanFrame
from qpavoid.human.posture import Operator
from qpavoid.human.skeleton import TRACKED
from qpavoid.loop.camera import Camera, CameraConfig
from qpavoid.sensing.arm_log import ArmLog
from qpavoid.sensing.recording import Recording

__all__ = ["Excitation", "HandOnFlange", "drive_excitation", "film_excitation"]

#: How far behind the flange's start the simulated operator's shoulder is (along +y), m:
#: with the shoulder at the table's height the flange is 0.35-0.5 m from it, within the
#: arm's 0.6 m reach all along the excitation.
BEHIND_FLANGE_M = 0.35


@dataclass(frozen=True)
class Excitation:
    """A few sinusoids on two joints, faded in and out (units: rad, Hz, s).

    Joint ``j`` moves ``q_j(t) = q0_j + w(t) Σ_i a_ji sin(2π f_ji t)``, ``w`` rising from 0
    to 1 over ``ramp_s`` and back over the last ``ramp_s`` (the quintic of
    :func:`~qpavoid.control.path.quintic`: the arm starts and ends at rest, its velocity
    and acceleration continuous).

    Attributes
    ----------
    joints
        The joints moved, by name (default: the arm's first two active joints, which turn
        it about the vertical and lift it on every arm shipped).
    amplitudes_rad
        Each joint's sinusoids' amplitudes, rad. Default 0.08 and 0.04 on the first, 0.06
        and 0.03 on the second: the flange moves some 50-70 mm RMS on the arms shipped (far
        above any camera's noise) and stays under 0.25 m/s.
    frequencies_hz
        Their frequencies, Hz. Default 0.21 and 0.53, 0.29 and 0.71: no two in a simple
        ratio (the flange's curve does not repeat within 30 s), the fastest period (1.4 s)
        over twice the widest lag searched (0.6 s).
    duration_s
        How long it lasts, ramps included, s (default 30: 900 frames at 30 Hz, the
        estimate's standard error under 1 ms with a Kinect v2's noise).
    ramp_s
        The fade in and out, s (default 2).
    """

    joints: tuple[str, ...] | None = None
    amplitudes_rad: tuple[tuple[float, ...], ...] = ((0.08, 0.04), (0.06, 0.03))
    frequencies_hz: tuple[tuple[float, ...], ...] = ((0.21, 0.53), (0.29, 0.71))
    duration_s: float = 30.0
    ramp_s: float = 2.0

    def __post_init__(self) -> None:
        n = len(self.amplitudes_rad)
        if (self.joints is not None and len(self.joints) != n) or len(self.frequencies_hz) != n:
            raise InputError(
                f"the excitation needs as many joints, amplitude rows and frequency rows, got "
                f"{len(self.joints or ())} joints, {n} and {len(self.frequencies_hz)} rows",
                name="amplitudes_rad",
                value=self.amplitudes_rad,
            )
        for a, f in zip(self.amplitudes_rad, self.frequencies_hz, strict=True):
            values = np.asarray(a, dtype=float), np.asarray(f, dtype=float)
            if (
                values[0].shape != values[1].shape
                or not np.isfinite(np.concatenate(values)).all()
                or np.any(values[0] < 0.0)
                or np.any(values[1] <= 0.0)
            ):
                raise InputError(
                    f"each joint's amplitudes (>= 0 rad) and frequencies (> 0 Hz) must be as "
                    f"many finite numbers, got {a!r} and {f!r}",
                    name="frequencies_hz",
                    value=(a, f),
                )
        if not (
            math.isfinite(self.duration_s) and 0.0 < 2.0 * self.ramp_s <= self.duration_s < 3600
        ):
            raise InputError(
                f"duration_s ({self.duration_s!r} s) must hold both ramps of ramp_s "
                f"({self.ramp_s!r} s) and last under an hour",
                name="duration_s",
                value=self.duration_s,
            )

    def columns(self, robot: Robot) -> np.ndarray:
        """The joints moved, as columns of ``robot``'s joint vectors.

        Raises
        ------
        InputError
            For a joint that is not one of the arm's active joints.
        """
        names = self.joints or robot.joint_names[: len(self.amplitudes_rad)]
        return joint_columns(robot, tuple(names), "joints")

    def offsets(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(T, n) each joint's offset from its start at times ``t`` (s, from the start) and
        its rate: rad and rad/s. Zero before 0 and after ``duration_s``."""
        t = np.asarray(t, dtype=float)
        up = np.array([quintic(x / self.ramp_s) for x in t]).reshape(-1, 2)
        down = np.array([quintic((self.duration_s - x) / self.ramp_s) for x in t]).reshape(-1, 2)
        w = up[:, 0] * down[:, 0]
        dw = (up[:, 1] * down[:, 0] - up[:, 0] * down[:, 1]) / self.ramp_s
        offsets, rates = [], []
        for a, f in zip(self.amplitudes_rad, self.frequencies_hz, strict=True):
            phase = 2.0 * np.pi * np.outer(t, f)
            s = np.sin(phase) @ np.asarray(a, dtype=float)
            ds = np.cos(phase) @ (2.0 * np.pi * np.asarray(a, dtype=float) * np.asarray(f))
            offsets.append(w * s)
            rates.append(dw * s + w * ds)
        return np.stack(offsets, axis=1), np.stack(rates, axis=1)

    def trajectory(
        self, robot: Robot, q0: np.ndarray, t: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(T, nq) joint angles and (T, nv) velocities of ``robot`` moving the excitation
        from ``q0`` (rad), at times ``t`` (s, from its start).

        Raises
        ------
        InputError
            For a joint the arm does not have, or one driven beyond its limits.
        """
        cols = self.columns(robot)
        offsets, rates = self.offsets(t)
        q = np.tile(robot.check_q(q0), (len(offsets), 1))
        dq = np.zeros((len(offsets), robot.nv))
        q[:, cols] += offsets
        dq[:, cols] = rates
        beyond = (q < robot.q_min) | (q > robot.q_max)
        if beyond.any():
            j = int(np.flatnonzero(beyond.any(axis=0))[0])
            raise InputError(
                f"the excitation drives {robot.joint_names[j]} beyond its limits "
                f"({robot.q_min[j]:.3f} to {robot.q_max[j]:.3f} rad) from {q0[j]:.3f} rad: "
                "start elsewhere or move it less",
                name="amplitudes_rad",
                value=self.amplitudes_rad,
            )
        return q, dq


def drive_excitation(
    arm: Arm,
    robot: Robot,
    excitation: Excitation | None = None,
    period_s: float = 0.002,
    clock: Callable[[], float] = time.time,
) -> ArmLog:
    """Move ``arm`` through the excitation from where it stands, in real time, and log it.

    Every period the arm's state is read and stamped with ``clock`` (the wall clock, which
    the camera's recorder stamps its frames on) and the excitation's velocity sent; the
    whole command stream is checked against the arm's limits before the arm moves. However
    it ends (the excitation's end, Ctrl-C, an arm error) the arm is stopped by its own
    ramp (:meth:`~qpavoid.drive.interface.Arm.stop`).

    Parameters
    ----------
    arm
        The arm, at rest where the excitation starts (:func:`~qpavoid.drive.connect.open_arm`
        moves a real one there).
    robot
        Its description.
    excitation
        The motion (default :class:`Excitation`).
    period_s
        The command period, s (default 2 ms, the loop's 500 Hz).
    clock
        The time stamp of each state read, s: the clock the camera's frames are stamped on.

    Returns
    -------
    ArmLog
        Each state read: ``clock()`` just after the read returned, and its joint angles.

    Raises
    ------
    InputError
        Before the arm moves: an excitation beyond the arm's joint, velocity,
        acceleration or jerk limits at this period.
    ArmError
        From the arm (the arm is stopped first).
    """
    exc = excitation or Excitation()
    q0 = arm.read().q.copy()
    ticks = np.arange(math.ceil(exc.duration_s / period_s) + 1) * period_s
    _, commands = exc.trajectory(robot, q0, ticks)
    check = CommandCheck(replace(arm.limits, dt_s=period_s))
    check.stream(commands)
    if check.total():
        raise InputError(
            f"the excitation breaks the arm's limits at {period_s * 1e3:g} ms: {check.last}; "
            "move it less or more slowly",
            name="excitation",
            value=dict(check.counts),
        )
    stamps, angles = [], []
    start = time.perf_counter()
    try:
        for k, dq in enumerate(commands):
            wait = start + k * period_s - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            state = arm.read()
            stamps.append(clock())
            angles.append(state.q.copy())
            arm.send(dq)
        state = arm.read()
        stamps.append(clock())
        angles.append(state.q.copy())
    finally:
        arm.stop()
    return ArmLog(np.array(stamps), np.array(angles))


@dataclass(frozen=True)
class HandOnFlange:
    """The true motion of a seated operator whose hand holds the flange of an arm moving an
    excitation (a motion for :class:`~qpavoid.loop.camera.Camera`; times s, lengths m).

    The operator sits facing the arm, the shoulder of ``side`` :data:`BEHIND_FLANGE_M`
    behind the flange's start (along +y, as :class:`~qpavoid.human.posture.Operator` sits)
    at the flange's x: within the arm's reach all along. Their ``side`` hand is at
    ``grip_m`` in the flange's frame (the palm on the flange's side, 5 cm off its axis: its
    radius, 3-4 cm, and half a hand); with ``on_flange`` False it rests on the table where
    the seated pose has it (a recording that must be refused).

    Attributes
    ----------
    robot, excitation, q0
        The arm, its motion and where it starts (rad).
    start_s
        When the excitation starts on the motion's clock, s.
    duration_s
        How long the motion lasts, s (the camera films nothing after it).
    side
        ``"right"`` or ``"left"``: the hand on the flange.
    grip_m
        Where the hand's landmark is in the flange's frame, m.
    on_flange
        Whether the hand holds the flange at all.
    """

    robot: Robot
    excitation: Excitation
    q0: np.ndarray
    start_s: float
    duration_s: float
    side: str = "right"
    grip_m: tuple[float, float, float] = (0.05, 0.0, 0.0)
    on_flange: bool = True
    operator: Operator = field(init=False, repr=False, compare=False)
    rest: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.side not in ("right", "left"):
            raise InputError(
                f"side must be 'right' or 'left', got {self.side!r}", name="side", value=self.side
            )
        flange = self.robot.end_effector(self.q0)[:3, 3]
        half = Operator.shoulder_half_width_m
        x = flange[0] + (half if self.side == "right" else -half)  # facing -y: left is +x
        operator = Operator(x_m=float(x), distance_m=float(flange[1] + BEHIND_FLANGE_M))
        object.__setattr__(self, "operator", operator)
        object.__setattr__(self, "rest", operator.rest())

    def flange(self, t: float) -> np.ndarray:
        """(4, 4) the flange's pose at time ``t``."""
        q, _ = self.excitation.trajectory(self.robot, self.q0, np.array([t - self.start_s]))
        return self.robot.end_effector(q[0])

    def frame_at(self, t: float) -> HumanFrame:
        """The operator at time ``t``, every landmark tracked."""
        if not self.on_flange:
            joints = self.rest
        else:
            pose = self.flange(t)
            grip = pose[:3, 3] + pose[:3, :3] @ np.asarray(self.grip_m)
            joints = self.operator.reach(self.rest, self.side, grip)
        return HumanFrame(joints, np.full(len(joints), TRACKED, dtype=np.int8))


def film_excitation(
    robot: Robot,
    camera: CameraConfig,
    excitation: Excitation | None = None,
    q0: np.ndarray | None = None,
    side: str = "right",
    on_flange: bool = True,
    arm_rate_hz: float = 500.0,
    rest_s: float = 1.0,
    clock_s: float = 0.0,
) -> tuple[Recording, ArmLog]:
    """A latency measurement in simulation: the camera's recording and the arm's log.

    The arm rests ``rest_s``, moves the excitation, rests ``rest_s`` again; the camera
    (``camera``: its format, latency, noise, jitter, dropouts) films the operator holding
    its flange (:class:`HandOnFlange`) from the start to the end, and each frame it delivers
    is recorded with its delivery time (a frame delivered before one captured earlier is
    dropped, as a recorder that never goes back would). The arm's log samples its true
    joint angles at ``arm_rate_hz``. Both clocks start at ``clock_s``.

    Parameters
    ----------
    robot
        The arm.
    camera
        The simulated camera (:meth:`~qpavoid.loop.camera.CameraConfig.of` a format).
    excitation
        The arm's motion (default :class:`Excitation`).
    q0
        Where the arm starts, rad (default: its task's first pose,
        :func:`~qpavoid.control.task.default_task`).
    side
        The hand on the flange.
    on_flange
        False: the hand rests on the table instead (a recording to refuse).
    arm_rate_hz
        The arm log's rate, Hz (default the loop's 500 Hz).
    rest_s
        Rest before and after the excitation, s.
    clock_s
        The shared clock's time at the start, s.

    Returns
    -------
    Recording, ArmLog
        The camera's frames (base frame: the body's landmarks) stamped on arrival, and the
        arm's joint angles; their lag is ``camera.latency_s`` (plus half of ``jitter_s``).
    """
    exc = excitation or Excitation()
    if q0 is None:
        q0 = inverse_kinematics(robot, default_task(robot).path.reference(0.0)[0])
    total = exc.duration_s + 2.0 * rest_s
    motion = HandOnFlange(
        robot, exc, np.asarray(q0, dtype=float), rest_s, total, side, on_flange=on_flange
    )
    arm_t = np.arange(math.floor(total * arm_rate_hz) + 1) / arm_rate_hz
    q, _ = exc.trajectory(robot, motion.q0, arm_t - rest_s)
    filming = Camera(motion, camera)
    made = [filming.frame(k) for k in range(math.floor(total * camera.frame_rate_hz) + 1)]
    stamps: list[float] = []
    frames: list[HumanFrame] = []
    newest = -math.inf  # the capture time of the newest frame recorded
    for content, captured, delivered, dropped in sorted(made, key=lambda f: f[2]):
        if dropped or delivered > total or captured <= newest:
            continue
        assert isinstance(content, HumanFrame)
        newest = captured
        stamps.append(delivered)
        frames.append(content)
    recording = Recording(
        np.array(stamps) + clock_s,
        np.array([f.joints for f in frames]),
        np.array([f.state for f in frames]),
        camera.format,
    )
    return recording, ArmLog(arm_t + clock_s, q)
