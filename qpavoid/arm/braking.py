"""How the real arm follows a velocity command: a reaction time and bounded acceleration.

A controller commands joint velocities; the arm starts to follow them ``reaction_time_s``
later and changes its joint velocities no faster than ``max_acceleration_radps2`` allows.
A change of command (a stop included) is a ramp along a straight line in joint-velocity
space: every joint reaches its new velocity at the same instant, at the rate of the joint
that needs longest, so a stop keeps the path (ISO 10218-1 stop category 1/2 behaviour)
and takes

    T_s = max_j |q̇_j| / a_j                                        (:func:`stop_time`)

during which the arm's points move at a speed falling linearly to zero: a point moving at
v travels ``v T_s / 2`` (the S_s of speed and separation monitoring, :mod:`qpavoid.laws.ssm`).

:class:`ArmResponse` runs in one of two modes. Called once per control period
(``arm(command)``), it counts the reaction time in periods and allows a velocity change of
``a_j · dt`` per call. On the wall clock (a real-time run, whose ticks may come late) the
arm instead steps at given times: :meth:`ArmResponse.send` a command at the tick's time
``t``, which becomes the target ``reaction_time_s`` (rounded up to whole periods, as in the
periodic mode) after ``t``, and :meth:`ArmResponse.step` in between, where the arm keeps
the newest target it has (a command is held until a newer one is sent); each step changes
the velocity by at most ``a_j ×`` the real time since the previous step. On ticks exactly
one period apart both modes agree. :class:`WallClockArm` moves the arm between such ticks.

The values are the robot description's (``[arm]`` of its control-point file) unless a
:class:`BrakingConfig` says otherwise; the bundled iiwa 14's, with their sources, are in
docs/safety.md ("Robot").
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from qpavoid.arm.description import ArmDynamics
from qpavoid.arm.model import Kinematics, Robot
from qpavoid.core.errors import InputError


@dataclass(frozen=True)
class BrakingConfig:
    """The arm's response to a velocity command.

    Each value left at None is the robot description's (``[arm]`` of its control-point
    file, :class:`~qpavoid.arm.description.ArmDynamics`: for the bundled iiwa 14 the FRI
    period and the accelerations measured by Larsen (2019), sources in docs/safety.md);
    :meth:`resolve` fills them in.

    Attributes
    ----------
    reaction_time_s
        Delay from a command to the arm starting to follow it, s (rounded up to whole
        control periods in the simulation).
    max_acceleration_radps2
        ``(joint name, limit)`` pairs: each joint's acceleration (and deceleration) limit,
        rad/s².
    """

    reaction_time_s: float | None = None
    max_acceleration_radps2: tuple[tuple[str, float], ...] | None = None

    def resolve(self, arm: ArmDynamics) -> BrakingConfig:
        """This config with every value left at None taken from the description's ``arm``."""
        return BrakingConfig(
            arm.reaction_time_s if self.reaction_time_s is None else self.reaction_time_s,
            (
                arm.max_acceleration_radps2
                if self.max_acceleration_radps2 is None
                else self.max_acceleration_radps2
            ),
        )


def per_joint(
    values: tuple[tuple[str, float], ...] | None, joint_names: Sequence[str]
) -> np.ndarray:
    """The values of ``(name, value)`` pairs for ``joint_names``, in that order.

    Raises
    ------
    InputError
        If a joint has no value, or there are no values at all (a config not yet resolved
        against the robot description: :meth:`BrakingConfig.resolve`).
    """
    if values is None:
        raise InputError(
            "no acceleration limits: take them from the robot description first "
            "(BrakingConfig.resolve(robot.arm))",
            name="max_acceleration_radps2",
            value=None,
        )
    table = dict(values)
    missing = [n for n in joint_names if n not in table]
    if missing:
        raise InputError(
            f"no acceleration limit for joints {missing} (given for {sorted(table)})",
            name="max_acceleration_radps2",
            value=values,
        )
    return np.array([table[n] for n in joint_names], dtype=float)


def stop_time(dq: ArrayLike, max_acceleration: ArrayLike) -> float:
    """T_s = max_j |q̇_j| / a_j: the time a path-keeping stop from ``dq`` takes, s."""
    return float(np.max(np.abs(np.asarray(dq, dtype=float)) / np.asarray(max_acceleration)))


class ArmResponse:
    """The simulated arm's joint velocity under a command stream (build once per run).

    Use it either periodically (call it once per control period) or on the wall clock
    (:meth:`send` and :meth:`step`), not both in one run.

    Parameters
    ----------
    cfg
        Reaction time and acceleration limits (resolved: :meth:`BrakingConfig.resolve`).
    joint_names
        The arm's active joints.
    dt
        Control period, s.

    Raises
    ------
    InputError
        If ``cfg`` leaves a value to the robot description (not resolved) or lacks a
        joint's acceleration limit.
    """

    def __init__(self, cfg: BrakingConfig, joint_names: Sequence[str], dt: float):
        self.a_max = per_joint(cfg.max_acceleration_radps2, joint_names)
        if cfg.reaction_time_s is None:
            raise InputError(
                "no reaction time: take it from the robot description first "
                "(BrakingConfig.resolve(robot.arm))",
                name="reaction_time_s",
                value=None,
            )
        self.a_dt = self.a_max * dt
        self.dt = dt
        nv = len(joint_names)
        delay = int(np.ceil(cfg.reaction_time_s / dt - 1e-9))
        self._pending: deque[np.ndarray] = deque([np.zeros(nv)] * delay)
        self.dq = np.zeros(nv)
        #: Wall-clock mode: from a command's send time to it becoming the target, s.
        self.delay_s = delay * dt
        self._sent: deque[tuple[float, np.ndarray]] = deque()
        self._target = np.zeros(nv)
        self._stepped_at: float | None = None

    def __call__(self, command: np.ndarray) -> np.ndarray:
        """The arm's joint velocity over the coming period, given this tick's command."""
        self._pending.append(np.asarray(command, dtype=float))
        return self._approach(self._pending.popleft(), self.a_dt)

    def _approach(self, target: np.ndarray, max_change: np.ndarray) -> np.ndarray:
        """Move the velocity towards ``target`` along a straight line in joint-velocity
        space, each joint by at most ``max_change``, rad/s; the new velocity."""
        change = target - self.dq
        worst = float((np.abs(change) / max_change).max(initial=0.0))
        self.dq = target.copy() if worst <= 1.0 else self.dq + change / worst
        return self.dq

    def send(self, command: np.ndarray, t: float) -> np.ndarray:
        """Wall-clock mode: ``command`` sent at time ``t``, s; the arm's velocity from ``t``.

        The command becomes the arm's target at ``t + delay_s`` and stays it until a newer
        command does (the arm keeps executing it however late the next one comes).
        """
        self._sent.append((t + self.delay_s, np.array(command, dtype=float)))
        return self.step(t)

    def step(self, t: float) -> np.ndarray:
        """Wall-clock mode: the arm's joint velocity from time ``t`` (s) to its next step.

        The target is the newest command whose reaction time has passed by ``t``; the
        velocity moves towards it along a straight line in joint-velocity space, each
        joint by at most ``a_max ×`` the time since the previous step (one period before
        the first step).
        """
        while self._sent and self._sent[0][0] <= t + 1e-9:
            self._target = self._sent.popleft()[1]
        elapsed = self.dt if self._stepped_at is None else t - self._stepped_at
        self._stepped_at = t
        if elapsed <= 0.0:
            return self.dq
        return self._approach(self._target, self.a_max * elapsed)


class WallClockArm:
    """The arm in a real-time run: between two ticks, however far apart, it keeps executing
    the last command for the real time that passed, not for one control period.

    With an arm model it steps on the held command once a period through a gap
    (:meth:`ArmResponse.step`: the reaction time is wall time, the acceleration limits allow
    ``a_j ×`` the real time between steps), each step's velocity saturated at the joint
    limits as a tick's is; without one the velocity holds. On ticks at most a period apart
    the arm moves by ``dq · (t[k+1] − t[k])``; the path clock advances by the held
    ``time_scale ×`` the same real time, so the reference keeps up with an arm that kept
    moving (with the nominal period it would fall behind by every late tick's lateness,
    and the path-error term would pull the arm back).

    Parameters
    ----------
    arm
        The arm model (used through :meth:`ArmResponse.send` and :meth:`ArmResponse.step`
        only), or None for an arm that follows its command exactly and at once.
    dt
        Control period, s.
    robot
        The arm (its joint limits and kinematics).
    record
        Keep the arm's steps between ticks in :attr:`steps` (for :meth:`least_clearance`).

    Attributes
    ----------
    vel_violations, pos_violations
        The steps between ticks whose velocity needed saturating, and those whose joint
        angles were out of their limits.
    steps
        ``(time, q, moving)`` of each step between ticks (with ``record``).
    """

    def __init__(
        self,
        arm: ArmResponse | None,
        dt: float,
        robot: Robot,
        record: bool = False,
    ):
        self.arm, self.dt, self.robot, self.record = arm, dt, robot, record
        self.dq_max, self.q_min, self.q_max = robot.dq_max, robot.q_min, robot.q_max
        self.vel_violations = self.pos_violations = 0
        self.steps: list[tuple[float, np.ndarray, bool]] = []
        self._t: float | None = None  # no tick yet
        self._dq, self._scale = np.zeros(robot.nv), 0.0

    def command(self, command: np.ndarray, t: float) -> np.ndarray:
        """The arm's joint velocity from tick time ``t`` (s), given this tick's command."""
        return command if self.arm is None else self.arm.send(command, t)

    def hold(self, t: float, dq: np.ndarray, time_scale: float) -> None:
        """The tick at ``t`` (s) is done: the arm leaves it at ``dq`` (saturated, rad/s), the
        path clock at rate ``time_scale``."""
        self._t, self._dq, self._scale = t, dq, time_scale

    def advance(self, q: np.ndarray, t: float) -> tuple[np.ndarray, float]:
        """The joint angles at tick time ``t`` (s), from ``q`` at the last tick's, and how far
        the path clock advanced in between, s (``q`` and 0 at the first tick)."""
        if self._t is None:
            return q, 0.0
        t0 = self._t
        dq, s, m = self._dq, t0, 1
        while t0 + m * self.dt < t - 1e-9:  # a step of the arm inside the gap
            s_next = t0 + m * self.dt
            q = q + dq * (s_next - s)
            if self.arm is not None:
                dq = self.arm.step(s_next)
                if np.any(np.abs(dq) > self.dq_max * (1 + 1e-9)):
                    self.vel_violations += 1
                    dq = np.clip(dq, -self.dq_max, self.dq_max)
            if np.any(q > self.q_max + 1e-12) or np.any(q < self.q_min - 1e-12):
                self.pos_violations += 1
            if self.record:
                self.steps.append((s_next, q, bool(np.any(dq != 0.0))))
            s, m = s_next, m + 1
        return q + dq * (t - s), self._scale * (t - t0)

    def least_clearance(
        self, clearance: Callable[[Kinematics, float], np.ndarray] | None
    ) -> float | None:
        """The smallest ``clearance(kinematics, time)`` (m) over the recorded steps between
        ticks while the arm moved: what the ticks' own clearances miss in a gap (None if
        there were no such steps, or no ``clearance``: the truth is not measured)."""
        if clearance is None:
            return None
        kin = self.robot.kinematics
        values = [
            float(np.min(clearance(kin(q, jacobians=False), s))) for s, q, m in self.steps if m
        ]
        return min(values) if values else None
