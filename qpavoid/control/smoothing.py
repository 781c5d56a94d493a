"""Commands a real arm accepts: each tick's command within reach of the last one, stops as ramps.

A real arm faults on a command it cannot follow (libfranka's ``joint_motion_generator_*``
reflexes, a UR protective stop). :class:`CommandRamp` keeps the controller's commands
``u_k`` (one per control period dt, from rest: ``u_{-1} = u_{-2} = 0``) within the arm's
limits, per joint j:

    |u_k|                      ≤ v_j                  velocity (the arm's; eq. 3's below)
    |u_k − u_{k−1}|            ≤ a_j dt               acceleration
    |u_k − 2u_{k−1} + u_{k−2}| ≤ j_j dt²              jerk, where the arm publishes one
    |u_k| H ≤ the room from q + dt Σ_{i=1..r} u_{k−i} to q_min, q_max     room to brake

(a_j the acceleration limit, b_j ≤ a_j the braking deceleration of speed and separation
monitoring, j_j the jerk limit, H the time over which a stop begun after u_k may carry a
joint at its speed, :meth:`CommandRamp.braking_horizon`: the description's ``[arm]``, or
tighter ones an arm's interface imposes, :meth:`CommandRamp.tighten`; the sum is the travel
still in flight: an arm reacting r = ⌈T_r / dt⌉ periods after a command,
:func:`~qpavoid.arm.braking.reaction_ticks`, is still carried by the last r when ``u_k``
begins). These rows form the *reachable box* ``lo ≤ u_k ≤ hi`` of :meth:`CommandRamp.box`: the
QP takes it as bounds (:class:`~qpavoid.control.qp.limits.acceleration.AccelerationLimit`);
where a limit (a velocity limit eq. 3 just lowered, a joint limit) lies outside the box, the
box's nearest end holds: the arm slows as fast as it may, never faster. The analytic
controller's command is moved towards along a straight line from ``u_{k−1}``, as far as the
box allows (:meth:`CommandRamp.limit`), which keeps its direction.

A stop is a ramp, commanded here (IEC 60204-1 category 2: the arm brakes under control and
stays powered): from the last command, every joint along the same line in joint-velocity
space to rest, at the braking deceleration b_j of the slowest joint and the jerk limits
(:class:`~qpavoid.arm.braking.ArmResponse` with no reaction time), which is the stop speed
and separation monitoring counts on (its T_s and S_s; the arm's reaction time is added there).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from qpavoid.arm.braking import ArmResponse, BrakingConfig, per_joint, reaction_ticks
from qpavoid.arm.model import Robot
from qpavoid.core.compiling import ctrl_c_deferred, kernel_input

__all__ = ["TESTED_JERK_RATE_HZ", "CommandRamp", "smooth_rate_limit_hz"]

#: What a commit changes: the last two commands, the stop's start speed, the commands in flight.
_Sent = tuple[np.ndarray, np.ndarray, float | None, tuple[np.ndarray, ...]]


#: The highest control rate at which the stop ramps and the room to brake are shown to keep
#: a jerk-limited arm's limits, Hz: libfranka's own 1 kHz (``tests/test_smoothing.py``: the
#: room sweeps and the stops at 1 ms, where ``j dt² < a dt`` and the gain is counted).
TESTED_JERK_RATE_HZ = 1000.0


def smooth_rate_limit_hz(robot: Robot) -> float:
    """The highest control rate at which the arm's commands are shown to keep its limits,
    Hz: :data:`TESTED_JERK_RATE_HZ` for an arm with jerk limits (where ``j dt² < a dt``,
    above 500 Hz on the FR3 and the Panda, a stop begun while joints speed up keeps
    speeding up for a few ticks: the room to brake counts that gain, :meth:`CommandRamp.box`;
    until 2026-12-02 it did not, and ``--arm`` was refused above 500 Hz there), inf
    without any."""
    jerk_limited = any(n in robot.joint_names for n, _ in robot.arm.max_jerk_radps3)
    return TESTED_JERK_RATE_HZ if jerk_limited else float("inf")


class CommandRamp:
    """The commands so far, and what the next may be (one per controller).

    Parameters
    ----------
    robot
        The arm: its acceleration and jerk limits (``[arm]``) and joint limits.
    dt
        The control period, s.
    braking_radps2
        ``(joint, b_j)`` pairs: the braking deceleration of a stop, rad/s² (speed and
        separation monitoring's, :meth:`~qpavoid.laws.ssm.SSMConfig.resolve`).
    reaction_time_s
        From a command to the arm following it, s (the description's ``[arm]
        reaction_time_s``, as :class:`~qpavoid.arm.braking.ArmResponse` counts it): the
        commands sent within it still move the joints when the next one begins, and the
        room to brake leaves their travel out. No default: an arm that follows at once (0)
        is a choice to make, not to fall into.
    """

    def __init__(
        self,
        robot: Robot,
        dt: float,
        braking_radps2: tuple[tuple[str, float], ...],
        *,
        reaction_time_s: float,
    ) -> None:
        names = robot.joint_names
        self.dt = dt
        self.a_dt = per_joint(robot.arm.max_acceleration_radps2, names) * dt
        self.brake_radps2 = per_joint(braking_radps2, names)
        jerk = dict(robot.arm.max_jerk_radps3)
        self.j_dt2 = np.array([jerk.get(n, np.inf) for n in names]) * dt * dt
        self.q_min, self.q_max = np.array(robot.q_min, float), np.array(robot.q_max, float)
        self.v_max = np.array(robot.dq_max, dtype=float)
        self._no_sent = np.zeros(robot.nv)
        self.names = tuple(names)
        jerks = tuple((n, j) for n, j in robot.arm.max_jerk_radps3 if n in names)
        self._ramp = ArmResponse(BrakingConfig(0.0, braking_radps2, jerks), names, dt)
        self._constants()
        warm_up()
        self.u1 = np.zeros(robot.nv)  # the last command, rad/s
        self.u2 = np.zeros(robot.nv)  # the one before
        #: How many of the last commands the arm is still to follow when the next is sent.
        self.in_flight = reaction_ticks(reaction_time_s, dt)
        self._sent: tuple[np.ndarray, ...] = ()  # those commands (at most in_flight), rad/s
        self.at_stop: float | None = None  # the speed (∞-norm) the ramp started from
        self._before: _Sent | None = None  # u1, u2, at_stop and those before the last commit

    def tighten(
        self,
        velocity_radps: np.ndarray,
        acceleration_radps2: np.ndarray,
        jerk_radps3: np.ndarray,
        braking_radps2: tuple[tuple[str, float], ...],
    ) -> None:
        """Keep within an arm's tighter limits (nv,) each (what its interface accepts:
        franky-control's, :attr:`~qpavoid.drive.franka.FrankaArm.limits`), braking at
        ``braking_radps2``."""
        dt = self.dt
        self.v_max = np.minimum(self.v_max, velocity_radps)
        self.a_dt = np.minimum(self.a_dt, np.asarray(acceleration_radps2) * dt)
        self.j_dt2 = np.minimum(self.j_dt2, np.asarray(jerk_radps3) * dt * dt)
        self.brake_radps2 = per_joint(braking_radps2, self.names)
        jerks = tuple(
            (n, float(j))
            for n, j in zip(self.names, self.j_dt2 / dt / dt, strict=True)
            if j < np.inf
        )
        self._ramp = ArmResponse(BrakingConfig(0.0, braking_radps2, jerks), self.names, dt)
        self._constants()

    def _constants(self) -> None:
        """What every tick's box uses and only the limits change: 1/b_j and the jerk lag
        ``max_j (a_j + b_j)² / (2 j_j b_j)`` of :meth:`braking_horizon` (0 without jerk)."""
        a, b = self.a_dt / self.dt, self.brake_radps2
        j = self.j_dt2 / (self.dt * self.dt)
        self._inv_b = 1.0 / b
        self._lag = float(np.max((a + b) ** 2 / (2.0 * j * b), initial=0.0))
        # where the jerk allows less change per tick than the acceleration (j dt² < a dt: a
        # Franka above 500 Hz), a stop begun while joints speed up keeps speeding up: each
        # joint's acceleration turns at its own jerk over a few ticks, and the stop's line
        # follows the slowest to turn; a joint may gain up to a (max_i a_i / j_i + dt) more
        # speed, rad/s, which the horizon and the room count (0 where a tick turns it)
        jerk_bound = self.j_dt2 < self.a_dt * (1.0 - 1e-9)  # (j dt² = a dt: turns in a tick)
        turn_s = float(np.max(np.where(jerk_bound, a / j, 0.0), initial=0.0))
        self._jerk_bound = bool(jerk_bound.any())
        self._gain = a * (turn_s + self.dt) if self._jerk_bound else np.zeros_like(a)

    def undo(self) -> None:
        """Forget the last :meth:`commit`: its command was never sent (a tick that missed
        its deadline is replaced by a braking one)."""
        if self._before is not None:
            self.u1, self.u2, self.at_stop, self._sent = self._before
            self._before = None

    def reset(self) -> None:
        """Forget the commands: the arm is at rest (and an :meth:`undo` has nothing to undo)."""
        self.u1, self.u2 = np.zeros_like(self.u1), np.zeros_like(self.u2)
        self.at_stop, self._sent, self._before = None, (), None

    def box(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reachable box ``(lo, hi)`` of the next command (nv,), rad/s, at joint angles
        ``q``: acceleration, jerk and room to brake before the joint limits, in one
        compiled call (:func:`command_box`; :meth:`box_numpy` is the same, term by term)."""
        in_flight = len(self._sent) > 0
        sent = sum(self._sent, np.zeros_like(q)) if in_flight else self._no_sent
        return command_box(
            kernel_input(q, np.float64), self.u1, self.u2, sent, in_flight, self.dt,
            self.a_dt, self.j_dt2, self.q_min, self.q_max, self.v_max, self._inv_b,
            self._lag, self._gain, self._jerk_bound,
        )  # fmt: skip

    def box_numpy(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`box` in numpy, term by term (the tests' reference for the kernel)."""
        lo, hi = self._reach()
        # room to brake: where the commands in flight leave the joints when this one
        # begins; then a stop begun after it (every joint on one line, at the pace of the
        # slowest, the jerk's lag included) carries a joint at u at most u H
        ahead = q + self.dt * sum(self._sent, np.zeros_like(q)) if self._sent else q
        inv_h = 1.0 / self.braking_horizon()
        up = (self.q_max - ahead).clip(0.0) * inv_h
        down = (ahead - self.q_min).clip(0.0) * inv_h
        if self._jerk_bound:  # (|u| + the gain) H within the room
            up, down = (up - self._gain).clip(0.0), (down - self._gain).clip(0.0)
        up, down = np.minimum(up, self.v_max), np.minimum(down, self.v_max)
        return (-down).clip(lo, hi), up.clip(lo, hi)

    def braking_horizon(self) -> float:
        """H, s: a joint at speed |u| after the next command travels at most |u| H until
        the arm is at rest, if a stop begins then:

            H = dt + T / 2 + max_j (a_j + b_j)² / (2 j_j b_j),   T = max_j (|u₁,j| + a_j dt) / b_j

        (this tick at u; then a line-keeping ramp, whose constant-deceleration part lasts
        at most T, the next command being within ``a_j dt`` of the last, and travels u T/2;
        with jerk limits the ramp first holds its speed while the joint's acceleration
        turns from +a_j to −b_j, at most ``(a_j + b_j) / j_j``, which costs at most the last
        term more; 0 without jerk limits)."""
        speed = np.abs(self.u1) + self.a_dt + self._gain
        return self.dt + 0.5 * float((speed * self._inv_b).max()) + self._lag

    def _reach(self) -> tuple[np.ndarray, np.ndarray]:
        """The acceleration and jerk rows of the box alone (nv,) each, rad/s."""
        u1, step = self.u1, self.u1 - self.u2
        lo = np.maximum(u1 - self.a_dt, u1 + step - self.j_dt2)
        hi = np.minimum(u1 + self.a_dt, u1 + step + self.j_dt2)
        return lo, hi

    def limit(self, dq: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """``dq`` moved towards from the last command along a straight line, as far as the
        box ``[lo, hi]`` allows (all of the way if it lies inside), rad/s (nv,)."""
        if (dq >= lo).all() and (dq <= hi).all():  # within reach: all of the way
            return np.array(dq, dtype=float)
        change = dq - self.u1
        room = np.where(change > 0, hi, lo) - self.u1
        fraction = np.divide(room, change, out=np.full_like(change, np.inf), where=change != 0)
        s = min(max(float(fraction.min(initial=1.0)), 0.0), 1.0)
        return np.clip(self.u1 + s * change, lo, hi)

    def brake(self) -> np.ndarray:
        """The next command of a stop ramp from the last command (rad/s, nv)."""
        if not self.u1.any() and not self.u2.any():  # at rest: it stays there
            self.at_stop = 0.0 if self.at_stop is None else self.at_stop
            return np.zeros_like(self.u1)
        ramp = self._ramp
        ramp.dq, ramp.ddq = self.u1.copy(), (self.u1 - self.u2) / self.dt
        if self.at_stop is None:
            self.at_stop = float(np.max(np.abs(self.u1), initial=0.0))
        u = ramp(np.zeros_like(self.u1))
        # The ramp's fraction s of u₁ (u = s u₁), kept within this tick's reach: the ramp
        # drops an acceleration away from rest at once, which a sampled jerk limit forbids
        moving = self.u1 != 0.0
        if not moving.any():
            return np.zeros_like(self.u1)
        lo, hi = self._reach()
        a, b = lo[moving] / self.u1[moving], hi[moving] / self.u1[moving]
        s_lo, s_hi = float(np.max(np.minimum(a, b))), float(np.min(np.maximum(a, b)))
        j = int(np.argmax(np.abs(self.u1)))
        s = float(u[j] / self.u1[j])
        if s_lo <= s_hi:
            taper = self._taper_floor(np.abs(self.u1[moving]), self.j_dt2[moving])
            s = min(max(s, s_lo, taper), s_hi)
        # where no point of the line is within reach (joints accelerating unevenly, jerk
        # tighter than a tick's acceleration: 1 kHz on a Franka), the nearest reachable
        # command, off the line for a tick: the limits come first
        return np.clip(max(s, 0.0) * self.u1, lo, hi)

    @staticmethod
    def _taper_floor(speed: np.ndarray, j_dt2: np.ndarray) -> float:
        """The smallest fraction s of the last command from which a stop on its line can
        still reach rest with every step within the jerk limit (0 without one).

        In units of each joint's speed |u₁,j|, the line drops by d = 1 − s this tick, and
        each later drop may shrink by at most r = min_j j_j dt² / |u₁,j| per tick until the
        last step to rest (a step to zero from speed s is itself a drop s ≤ r). Shrinking as
        fast as that loses at least T(d) = max_n (n d − r n(n + 1) / 2) more speed, so s must
        be at least T(1 − s):

            s ≥ max_n ( n / (n + 1) − r n / 2 ),   n = 0, 1, …

        whose largest term is at the integers around n = √(2/r) − 1. A stop that begins while
        its joints already decelerate hard (1 kHz on a Franka, where j dt² < a dt) would
        otherwise reach zero with its deceleration still on: a step of jerk up to 1.4 times
        the limit, measured.
        """
        r = float(np.min(j_dt2 / speed))
        if not math.isfinite(r):
            return 0.0
        n0 = math.sqrt(2.0 / r) - 1.0
        candidates = (max(math.floor(n0), 0), max(math.ceil(n0), 0))
        return max(0.0, *(n / (n + 1) - 0.5 * r * n for n in candidates))

    def commit(self, u: np.ndarray, stopping: bool) -> float:
        """``u`` is the command sent; the fraction of the stop's start speed it keeps
        (1 while not ``stopping``, falling to 0 along a stop ramp)."""
        self._before = (self.u1, self.u2, self.at_stop, self._sent)
        self.u2, self.u1 = self.u1, np.array(u, dtype=float)
        if self.in_flight:
            self._sent = (*self._sent, self.u1)[-self.in_flight :]
        if not stopping:
            self.at_stop = None
            return 1.0
        start = self.at_stop or 0.0
        return float(np.max(np.abs(u), initial=0.0)) / start if start > 0.0 else 0.0


@njit(cache=True)
def command_box(
    q: np.ndarray,
    u1: np.ndarray,
    u2: np.ndarray,
    sent: np.ndarray,
    in_flight: bool,
    dt: float,
    a_dt: np.ndarray,
    j_dt2: np.ndarray,
    q_min: np.ndarray,
    q_max: np.ndarray,
    v_max: np.ndarray,
    inv_b: np.ndarray,
    lag: float,
    gain: np.ndarray,
    jerk_bound: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`CommandRamp.box` in one pass over the joints (nv,) each, rad/s.

    The reach of the next command from the last two, ``u₁`` and ``u₂``:
    ``max(u₁ − a dt, 2u₁ − u₂ − j dt²) ≤ u ≤ min(u₁ + a dt, 2u₁ − u₂ + j dt²)``
    (:meth:`CommandRamp._reach`); the room to brake from where the commands in flight
    (their sum ``sent``, if ``in_flight``) leave the joints, ``q̂ = q + dt Σ sent``: a
    joint at u may travel u H before rest, H = dt + max_j (|u₁,j| + a_j dt + g_j) / (2 b_j)
    + lag (:meth:`CommandRamp.braking_horizon`), so
    ``u ≤ max(q_max − q̂, 0) / H`` (less the gain g where the jerk binds), and as much
    down; both within the velocity limit, then clipped to the reach as ``np.clip`` does.
    """
    n = q.shape[0]
    worst = -np.inf
    for k in range(n):
        worst = max(worst, (abs(u1[k]) + a_dt[k] + gain[k]) * inv_b[k])
    inv_h = 1.0 / (dt + 0.5 * worst + lag)
    lo_out, hi_out = np.empty(n), np.empty(n)
    for k in range(n):
        step = u1[k] - u2[k]
        lo = max(u1[k] - a_dt[k], u1[k] + step - j_dt2[k])
        hi = min(u1[k] + a_dt[k], u1[k] + step + j_dt2[k])
        ahead = q[k] + dt * sent[k] if in_flight else q[k]
        up = max(q_max[k] - ahead, 0.0) * inv_h
        down = max(ahead - q_min[k], 0.0) * inv_h
        if jerk_bound:
            up, down = max(up - gain[k], 0.0), max(down - gain[k], 0.0)
        up, down = min(up, v_max[k]), min(down, v_max[k])
        lo_out[k] = min(max(-down, lo), hi)  # np.clip's order: the lower bound first
        hi_out[k] = min(max(up, lo), hi)
    return lo_out, hi_out


@functools.cache
def warm_up() -> None:
    """Compile (or load from the disk cache) :func:`command_box`, once per process."""
    with ctrl_c_deferred():
        z = np.zeros(2)
        command_box(z, z, z, z, False, 0.01, z, z, z, z, z, z, 0.0, z, False)
