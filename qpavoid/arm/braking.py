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

Where the description gives a joint's jerk limit j_j (``[arm] max_jerk_radps3``; the Franka
arms'), the acceleration along that line changes no faster than the jerk allows: a change is
the time-optimal jerk-limited ramp of the fraction x ∈ [0, 1] of the change, whose rate is at
most α = min_j a_j / |Δq̇_j| and whose rate changes at most at ι = min_j j_j / |Δq̇_j|
(:func:`stop_time`). A stop from rest acceleration then lasts

    T_s = 1/α + α/ι   if α² ≤ ι,  else  2/√ι                      (with 1/α = max_j |q̇_j| / a_j)

and its deceleration profile is symmetric in time, so the velocity falls as
``q̇(T_s − t) = q̇₀ − q̇(t)`` and a point moving at v still travels exactly ``v T_s / 2``.
Such a stop never lasts longer, nor travels farther, than the arm waiting
:func:`jerk_lag_s` and then braking at constant deceleration: speed and separation monitoring
counts the lag in its reaction time and keeps its constant-deceleration terms.

The values are the robot description's (``[arm]`` of its control-point file) unless a
:class:`BrakingConfig` says otherwise; the bundled iiwa 14's, with their sources, are in
docs/safety.md ("Robot"), each arm's in docs/robot.md.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from qpavoid.arm.dynamics import ArmDynamics
from qpavoid.arm.model import Kinematics, Robot
from qpavoid.core.errors import InputError


@dataclass(frozen=True)
class BrakingConfig:
    """The arm's response to a velocity command.

    Each value left at None is the robot description's (``[arm]`` of its control-point
    file, :class:`~qpavoid.arm.dynamics.ArmDynamics`: for the bundled iiwa 14 the FRI
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
    max_jerk_radps3
        ``(joint name, limit)`` pairs: the joints' jerk limits, rad/s³; a joint without one
        (and every joint, given ``()``: the iiwa's description has none) changes its
        acceleration at once.
    """

    reaction_time_s: float | None = None
    max_acceleration_radps2: tuple[tuple[str, float], ...] | None = None
    max_jerk_radps3: tuple[tuple[str, float], ...] | None = None

    def resolve(self, arm: ArmDynamics) -> BrakingConfig:
        """This config with every value left at None taken from the description's ``arm``."""
        return BrakingConfig(
            arm.reaction_time_s if self.reaction_time_s is None else self.reaction_time_s,
            (
                arm.max_acceleration_radps2
                if self.max_acceleration_radps2 is None
                else self.max_acceleration_radps2
            ),
            (
                getattr(arm, "max_jerk_radps3", ())  # none in a description read before them
                if self.max_jerk_radps3 is None
                else self.max_jerk_radps3
            ),
        )


def reaction_ticks(reaction_time_s: float, dt: float) -> int:
    """The arm's reaction in control periods: a command sent at tick k becomes its target
    at tick ``k + reaction_ticks`` (the reaction time rounded up to whole periods of
    ``dt`` s; 0 for an arm that follows at once)."""
    return int(np.ceil(reaction_time_s / dt - 1e-9))


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


def stop_time(
    dq: ArrayLike, max_acceleration: ArrayLike, max_jerk: ArrayLike | None = None
) -> float:
    """The time a path-keeping stop from ``dq`` (at rest acceleration) takes, s.

    Without jerk limits ``T_s = max_j |q̇_j| / a_j``. With them (``inf`` for a joint without
    one), every joint follows ``q̇_j(t) = q̇_j σ(t)``, σ falling from 1 to 0 with
    ``|σ'| ≤ α = min_j a_j / |q̇_j|`` and ``|σ''| ≤ ι = min_j j_j / |q̇_j|``; the fastest
    such σ ramps its rate up at ι, holds α, ramps down at ι:

        T_s = 1/α + α/ι  if α² ≤ ι  (α is reached),  else  2/√ι.
    """
    speed = np.abs(np.asarray(dq, dtype=float))
    if max_jerk is None:
        return float(np.max(speed / np.asarray(max_acceleration)))
    rate = float(np.max(speed / np.asarray(max_acceleration)))  # 1/α
    inv_iota = float(np.max(speed / np.asarray(max_jerk, dtype=float)))  # 1/ι
    if rate == 0.0:
        return 0.0
    if inv_iota <= rate * rate:  # α² ≤ ι
        return rate + inv_iota / rate
    return 2.0 * math.sqrt(inv_iota)


def jerk_lag_s(
    max_acceleration_radps2: tuple[tuple[str, float], ...],
    max_jerk_radps3: tuple[tuple[str, float], ...],
) -> float:
    """τ = 2 max_j a_j / j_j over the joints with a jerk limit (0 without any), s.

    A jerk-limited stop is never slower, in time nor in distance, than waiting τ and then
    braking at constant deceleration a_j. From rest acceleration: the stop lasts at most
    ``v/a + a/j`` (:func:`stop_time`; ``2√(v/j) ≤ v/a + a/j``) and travels ``v T_s / 2 ≤
    v a/(2j) + v²/(2a)``. Found accelerating at up to a (towards a target it will not
    overshoot, so its speed stays below the last commanded one), the arm first needs a/j
    more to bring its acceleration to zero. Both fit in τ = 2 a / j.
    """
    accel = dict(max_acceleration_radps2)
    return 2.0 * max((accel[n] / j for n, j in max_jerk_radps3 if n in accel), default=0.0)


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
        #: Each joint's jerk limit (inf: none), or None if no joint has one (the iiwa's).
        self.j_max: np.ndarray | None = None
        if cfg.max_jerk_radps3:
            jerk = dict(cfg.max_jerk_radps3)
            self.j_max = np.array([jerk.get(n, np.inf) for n in joint_names], dtype=float)
        #: The joints' acceleration, rad/s² (followed only with jerk limits).
        self.ddq = np.zeros(len(joint_names))
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
        delay = reaction_ticks(cfg.reaction_time_s, dt)
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
        return self._approach(self._pending.popleft(), self.a_dt, self.dt)

    def _approach(self, target: np.ndarray, max_change: np.ndarray, h: float) -> np.ndarray:
        """Move the velocity towards ``target`` along a straight line in joint-velocity
        space, each joint by at most ``max_change`` (= ``a_max · h``), rad/s, or along the
        jerk-limited ramp over ``h`` s (:meth:`_approach_jerk`); the new velocity."""
        if self.j_max is not None:
            return self._approach_jerk(target, h, self.j_max)
        change = target - self.dq
        worst = float((np.abs(change) / max_change).max(initial=0.0))
        self.dq = target.copy() if worst <= 1.0 else self.dq + change / worst
        return self.dq

    def _approach_jerk(self, target: np.ndarray, h: float, j_max: np.ndarray) -> np.ndarray:
        """One step of ``h`` s along the jerk-limited ramp to ``target``; the new velocity.

        The velocity moves along ``q̇ + x Δ`` (Δ = target − q̇) with x from 0 to 1 on the
        time-optimal ramp of :func:`_ramp`: rate ẋ ≤ α = min_j a_j / |Δ_j|, its change
        |ẍ| ≤ ι = min_j j_j / |Δ_j|, ending at rest acceleration. The ramp starts from the
        arm's acceleration along Δ (its projection, within [0, α]): a command that turns
        the line drops the acceleration across it at once, the only place where this model
        is kinder than the jerk limit (the lag of :func:`jerk_lag_s` covers it).
        """
        change = target - self.dq
        size = np.abs(change)
        if not size.any():
            self.ddq[:] = 0.0
            return self.dq
        moving = size > 0.0
        alpha = float(np.min(self.a_max[moving] / size[moving]))
        iota = float(np.min(j_max[moving] / size[moving]))
        if math.isinf(iota):  # no moving joint has a jerk limit: a constant-rate ramp
            x, rate = min(1.0, alpha * h), alpha
        else:
            rate = float(np.clip(self.ddq @ change / (change @ change), 0.0, alpha))
            x, rate = _ramp(1.0, rate, alpha, iota, h)
        if x >= 1.0:
            self.dq, self.ddq = target.copy(), np.zeros_like(self.ddq)
        else:
            self.dq, self.ddq = self.dq + x * change, rate * change
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
        return self._approach(self._target, self.a_max * elapsed, elapsed)


def _ramp(
    remaining: float, rate: float, alpha: float, iota: float, h: float
) -> tuple[float, float]:
    """Advance the time-optimal jerk-limited ramp of x towards ``remaining`` for ``h`` s.

    The ramp moves x at rate r ≥ 0 with r ≤ α and |ṙ| ≤ ι, arriving with r = 0: it raises
    r at ι until the distance left equals the distance needed to bring r back to 0,
    ``r² / (2ι)``, or r reaches α; holds α until then; lowers r at ι. While rising from
    r₀ the switch comes after ``t = (√(r₀²/2 + ι d) − r₀) / ι`` (d: the distance left at
    r₀), where ``d − r₀ t − ι t²/2 = (r₀ + ι t)² / (2ι)``.

    Returns
    -------
    advance, rate
        How far x moved (at most ``remaining``) and its rate at the end of the step.
    """
    x, t = 0.0, h
    for _ in range(8):  # at most rise, hold, fall (and rounding's extra pass)
        left = remaining - x
        if t <= 0.0 or left <= 0.0:
            break
        brake = rate * rate / (2.0 * iota)
        if brake >= left * (1.0 - 1e-12):  # fall: bring the rate to 0 (arriving)
            tau = min(t, rate / iota)
            x += rate * tau - iota * tau * tau / 2.0
            rate -= iota * tau
            t -= tau
            if rate <= 1e-12 * alpha:  # arrived (or, found too fast, stopped at the target)
                return remaining, 0.0
        elif rate < alpha:  # rise, until the switch or α
            switch = (math.sqrt(rate * rate / 2.0 + iota * left) - rate) / iota
            tau = min(t, switch, (alpha - rate) / iota)
            x += rate * tau + iota * tau * tau / 2.0
            rate += iota * tau
            t -= tau
        else:  # hold α until the fall must start
            tau = min(t, (left - brake) / rate)
            x += rate * tau
            t -= tau
    return min(x, remaining), rate


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

    def path_advance(self, t: float, max_gap_s: float = math.inf) -> float:
        """How far the path clock advanced from the last tick to tick time ``t`` (s) at the
        held rate (0 at the first tick): for an arm that moves on its own, and holds a
        command at most ``max_gap_s`` s (then brakes to rest by itself)."""
        return 0.0 if self._t is None else self._scale * min(t - self._t, max_gap_s)

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
