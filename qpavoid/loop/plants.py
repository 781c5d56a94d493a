"""The arms a run drives: what :func:`~qpavoid.loop.simulation.simulate`'s one loop asks of
the arm each tick, and the three arms that answer.

A tick is, whatever the arm: wait for it (:meth:`Plant.wait`), read the joint angles
(:meth:`Plant.read`), take the frame in hand and catch up with the time that took
(:meth:`Plant.catch_up`), let the controller compute, have the arm execute the command
(:meth:`Plant.execute`: what it really did), log, and let the arm move on until the next
tick (:meth:`Plant.move`). The arms differ only in those answers:

* :class:`KinematicArm`: offline, on the simulated clock (``t = k dt``); the arm follows its
  command exactly, or through the description's reaction and acceleration limits
  (:class:`~qpavoid.arm.braking.ArmResponse`); ``q[k+1] = q[k] + dq[k] dt``.
* :class:`WallClockArm`: a real-time run of the simulated arm: ticks on the wall clock, and
  between two ticks, however late, the arm keeps executing the last command
  (:class:`~qpavoid.arm.braking.WallClockArm`); Ctrl-C ends the run.
* :class:`DrivenArm`: any :class:`~qpavoid.drive.interface.Arm` (a Franka through libfranka,
  franky-sim's, :class:`~qpavoid.drive.simulated.SimulatedArm`): each tick reads its state,
  checks the command against its limits and sends it, never within a period of the last;
  a missed deadline brakes for a tick, a stalled state or an arm error ends the run, a loop
  that stops sending has the arm stopped by a watchdog (each time it stops sending). A run
  that ends on its goal, its time cap, Ctrl-C, SIGTERM or bad input from the arm (NaN
  joint angles) brings the arm to rest on the controller's braking ramp before
  :meth:`~qpavoid.drive.interface.Arm.stop`; one that ends on an arm error, or on a command
  the check refused, has the arm stopped by :meth:`~qpavoid.drive.interface.Arm.stop` alone
  (its own stop: franky's brakes the arm within its limits).

May import: the stages above the loop (core to control), the drive interface.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from qpavoid.arm import braking
from qpavoid.arm.braking import ArmResponse
from qpavoid.arm.model import Kinematics, Robot
from qpavoid.control.controller import Controller
from qpavoid.control.tick import Command
from qpavoid.core.errors import ArmError, InputError
from qpavoid.core.signals import Interruption
from qpavoid.drive.interface import Arm
from qpavoid.drive.limits import CommandCheck, CommandLimits
from qpavoid.drive.watchdog import Watchdog
from qpavoid.loop.timing import LoopTiming, StallCheck

__all__ = ["DrivenArm", "KinematicArm", "Plant", "WallClockArm"]


class Plant:
    """The arm of a run, tick by tick (the base: nothing between the loop and the arm).

    Attributes
    ----------
    realtime
        The run ticks on the wall clock.
    ended_by
        Why the arm ended the run ("" while it runs; "at rest" after a clean ramp down).
    checked
        Every command against the arm's limits (:class:`~qpavoid.drive.limits.CommandCheck`).
    measured_online
        The truth is measured at each tick (False: after the run, where the arm was).
    """

    realtime = False
    measured_online = True

    def __init__(self, robot: Robot, dt: float, checked: CommandCheck):
        self.robot, self.dt, self.checked = robot, dt, checked
        self.ended_by = ""

    def begin(self) -> None:
        """The loop starts: the run's clock starts now."""

    def wait(self, k: int, t: float) -> float | None:
        """Tick ``k``'s time, its nominal one ``t`` on the run's clock, s (None: no tick
        ``k``, the run ends)."""
        return t

    def read(self, q: np.ndarray) -> np.ndarray | None:
        """The joint angles at the tick, from the loop's ``q`` (None: the arm ended the run,
        :attr:`ended_by` says why)."""
        return q

    def catch_up(self, t: float, q: np.ndarray) -> tuple[float, np.ndarray, float]:
        """After the frame was taken: the tick's time, the joint angles then and how far the
        path clock advanced since the last tick, s."""
        return t, q, 0.0

    def input_error(self, exc: InputError) -> bool:
        """The controller refused the tick's input: True if the run ends on it (else raise)."""
        return False

    def execute(
        self, controller: Controller, cmd: Command, t: float, captured_s: float
    ) -> tuple[Command, np.ndarray] | None:
        """The command the tick ends with and the joint velocities the arm moves at (rad/s);
        None: it never reached the arm, the run ends unlogged."""
        return cmd, cmd.dq

    def move(
        self, q: np.ndarray, dq: np.ndarray, t: float, cmd: Command
    ) -> tuple[np.ndarray, float]:
        """The joint angles at the next tick and how far the path clock advances, s."""
        return q + dq * self.dt, cmd.time_scale * self.dt

    def finish(self, controller: Controller) -> None:
        """The loop is over (not raised): leave the arm at rest."""

    def close(self) -> None:
        """However the run ended: release the arm."""

    def violations(self) -> tuple[int, int]:
        """Steps between ticks whose velocity needed saturating, and out of joint limits."""
        return 0, 0

    def report(self, truth: Callable[[Kinematics, float], np.ndarray] | None) -> dict[str, Any]:
        """The arm's own metrics of the run."""
        return {}


class KinematicArm(Plant):
    """The simulated arm offline: exactly and at once, or through ``response``."""

    def __init__(
        self, robot: Robot, dt: float, checked: CommandCheck, response: ArmResponse | None
    ):
        super().__init__(robot, dt, checked)
        self.response = response

    def execute(
        self, controller: Controller, cmd: Command, t: float, captured_s: float
    ) -> tuple[Command, np.ndarray]:
        return cmd, cmd.dq if self.response is None else self.response(cmd.dq)


class _RealTime(Plant):
    """Ticks on the wall clock, a period apart, late ones as late as they are."""

    realtime = True

    def __init__(
        self,
        robot: Robot,
        dt: float,
        checked: CommandCheck,
        wall: braking.WallClockArm,
        interrupt: Interruption,
        timing: LoopTiming,
    ):
        super().__init__(robot, dt, checked)
        self.wall, self.interrupt, self.timing = wall, interrupt, timing
        self.overruns = 0
        self.wall0 = time.perf_counter()

    def begin(self) -> None:
        self.wall0 = time.perf_counter()

    def due(self, t: float) -> float | None:
        """When tick time ``t`` is due (perf_counter, s), or None: the run ends."""
        return self.wall0 + t

    def wait(self, k: int, t: float) -> float | None:
        if self.interrupt.requested and k > 0:
            return None
        due = self.due(t)
        if due is None:
            return None
        wait = due - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        else:
            self.overruns += wait < -self.dt
        # the run clock is the wall clock: a late tick sees the time it really is, so the
        # frames it holds are as old as they really are
        return max(t, self.now())

    def now(self) -> float:
        """The run's clock, s."""
        return time.perf_counter() - self.wall0

    def move(
        self, q: np.ndarray, dq: np.ndarray, t: float, cmd: Command
    ) -> tuple[np.ndarray, float]:
        self.wall.hold(t, dq, cmd.time_scale)  # the arm moves on when the next tick comes
        return q, 0.0

    def violations(self) -> tuple[int, int]:
        return self.wall.vel_violations, self.wall.pos_violations

    def report(self, truth: Callable[[Kinematics, float], np.ndarray] | None) -> dict[str, Any]:
        return {
            "realtime_overruns": int(self.overruns),
            "min_true_clearance_in_gaps_m": self.wall.least_clearance(truth),
            "loop": self.timing.report(),
        }


class WallClockArm(_RealTime):
    """The simulated arm in real time: between ticks it executes the last command for the
    real time that passed (:class:`~qpavoid.arm.braking.WallClockArm`)."""

    measured_online = False  # the truth: after the run (each tick's q is exact), off its time

    def catch_up(self, t: float, q: np.ndarray) -> tuple[float, np.ndarray, float]:
        t = max(t, self.now())  # getting the frame took time too: the age is judged now
        q, moved = self.wall.advance(q, t)  # the arm kept moving until now
        return t, q, moved

    def execute(
        self, controller: Controller, cmd: Command, t: float, captured_s: float
    ) -> tuple[Command, np.ndarray]:
        now = self.now()  # the command is applied now: its deadline and latency counted
        self.timing.late(t, now)
        self.timing.sent(now, captured_s)
        return cmd, self.wall.command(cmd.dq, t)


class DrivenArm(_RealTime):
    """An :class:`~qpavoid.drive.interface.Arm`, driven: its state read, each command checked
    against its limits and sent, a watchdog beside the loop.

    Parameters
    ----------
    arm
        The arm.
    max_time_s, stall_timeout_s, watchdog_s
        As :class:`~qpavoid.loop.simulation.SimConfig`'s.
    """

    measured_online = False  # the truth: after the run, off the loop's time

    def __init__(
        self,
        robot: Robot,
        dt: float,
        controller: Controller,
        wall: braking.WallClockArm,
        interrupt: Interruption,
        timing: LoopTiming,
        arm: Arm,
        max_time_s: float,
        stall_timeout_s: float,
        watchdog_s: float,
    ):
        lim = arm.limits  # what the arm's interface accepts, if tighter
        controller.accept_limits(lim.velocity_radps, lim.acceleration_radps2, lim.jerk_radps3)
        checked = CommandCheck(replace(arm.limits, dt_s=dt))
        super().__init__(robot, dt, checked, wall, interrupt, timing)
        self.arm, self.max_time_s, self.watchdog_s = arm, max_time_s, watchdog_s
        self.stall = StallCheck(stall_timeout_s)
        # the watchdog stops the arm between two sends, never during one (the loop checks
        # whether it did, then sends, under the same lock: a send never continues a stream
        # the watchdog has ended)
        self.sending = threading.Lock()
        self.dog = Watchdog(watchdog_s, self._silence)
        self.stops = 0  # the watchdog's stops of the arm
        # the arm's own hold of a command (franky's, a SimulatedArm's), else none: a
        # ros2_control velocity controller holds the last command until the next, and only
        # the watchdog's stop ends it
        hold = getattr(arm, "holds_command_s", watchdog_s)
        self.held = _Held(hold, controller, checked, lambda: self.stops)
        self.watching = False  # the watchdog starts with the first command (not the warm-up)
        self.measured = np.zeros(robot.nv)  # the arm's reported velocity
        self.arm_failed = False  # the arm failed, or refused a command: no ramp to rest
        # when the last command's deadline began (its state read), and its tick was due
        self.began = self._due = self._sending = -math.inf  # (and the last send began)

    def start(self) -> np.ndarray:
        """The arm is where it is: its joint angles, rad."""
        return self.arm.read().q.copy()

    def due(self, t: float) -> float | None:
        # a late loop skips ticks rather than bursting them: the next tick a period after
        # the last was due, or now if that is more than a period ago (the sends are a
        # period apart whatever the ticks do: execute)
        now = time.perf_counter()
        due = max(self.wall0 + t, self._due + self.dt)
        if now - due > self.dt:  # more than a period late: an overrun, counted
            self.overruns += 1
            due = now
        self._due = due
        return None if due - self.wall0 > self.max_time_s else due

    def read(self, q: np.ndarray) -> np.ndarray | None:
        self.began = time.perf_counter()
        try:
            state = self.stall(self.arm.read(), self.began)
            self.began = time.perf_counter()  # the command's deadline runs from its state
            if (gap := self.held.ran_out(self.began)) is not None:  # the loop itself
                self.timing.stalled(gap)  # stalled: the arm stopped on its own, from rest
        except ArmError as exc:
            self.ended_by = f"arm {exc.reason or 'error'}: {exc}"
            self.arm_failed = True
            return None
        self.measured = state.dq
        return state.q

    def catch_up(self, t: float, q: np.ndarray) -> tuple[float, np.ndarray, float]:
        t = max(t, self.now())
        return t, q, self.wall.path_advance(t, self.watchdog_s)  # held at most watchdog_s

    def input_error(self, exc: InputError) -> bool:
        self.ended_by = f"input error: {exc}"  # (a real arm reporting NaN): stop, say why
        return True

    def execute(
        self, controller: Controller, cmd: Command, t: float, captured_s: float
    ) -> tuple[Command, np.ndarray] | None:
        # never two commands within a period (each is checked, and followed, as a period
        # after the last): a command ready sooner after the last send began waits for it;
        # the deadline is judged at that send, the wait included, and everything is decided
        # before waiting, so that the send follows the wait at once
        send_at = max(time.perf_counter(), self._sending + self.dt)
        late = self.timing.late(self.began, send_at)
        why = f"missed deadline ({late * 1e3:.1f} ms late)" if late else ""
        with self.sending:
            if (gap := self.held.ran_out(send_at)) is not None:  # the arm stopped on its
                self.timing.stalled(gap)  # own, or the watchdog stopped it: from rest
                cmd = controller.brake(why or "the arm came to rest meanwhile")
            elif late:  # the arm still follows the last command: this is a step from it
                cmd = controller.brake(why, instead=True)
            failed = self._send(cmd.dq, send_at, moves_schedule=True)
        if failed:
            self.ended_by, self.arm_failed = failed, True
            refused = failed.startswith("command")  # never sent (the arm would fault): logged
            return (cmd, self.measured) if refused else None
        self.timing.sent(self.held.last - self.wall0, captured_s)
        if not self.watching:
            self.dog.__enter__()
            self.watching = True
        self.dog.kick()
        return cmd, self.measured  # what the arm reports

    def _send(self, dq: np.ndarray, send_at: float, moves_schedule: bool = False) -> str:
        """Check ``dq`` against the arm's limits, wait for ``send_at`` and send it: "", or
        why it was not sent (refused by the check, or the arm's error). With
        ``moves_schedule``, a wait of over half a period moves the schedule on by the rest:
        after a slow tick the next states are read that much later (else every later
        command would wait, and go a whole period after its state)."""
        if self.checked(dq):
            return f"command beyond the arm's limits: {self.checked.last}"
        waited = _until(send_at)
        if moves_schedule:
            self._due += max(waited - 0.5 * self.dt, 0.0)
        self._sending = time.perf_counter()  # (a send takes its time: the next's from here)
        try:
            self.arm.send(dq)
        except ArmError as exc:
            return f"arm {exc.reason or 'error'}: {exc}"
        self.held.sent(time.perf_counter())
        return ""

    def finish(self, controller: Controller) -> None:
        # the goal, the time cap, Ctrl-C, SIGTERM, bad input from the arm: a ramp to rest,
        # on time; an arm that failed, or a command the check refused, gets arm.stop only
        if not self.arm_failed:
            ramp = self._ramp_down(controller)
            self.ended_by = self.ended_by or ramp

    def _ramp_down(self, controller: Controller) -> str:
        """The controller's braking ramp sent once a period (each a period after the last
        send began, the loop's included) until it commands rest (at most 10 s); "at rest",
        or why it could not finish. Where the arm's hold of the last command ran out
        meanwhile, it stopped on its own: the ramp starts from rest."""
        for _ in range(int(10.0 / self.dt)):
            send_at = max(time.perf_counter(), self._sending + self.dt)
            with self.sending:
                self.held.ran_out(send_at)
                cmd = controller.brake("end of run")
                failed = self._send(cmd.dq, send_at)
            if failed:
                return failed
            if self.watching:
                self.dog.kick()
            if not np.any(cmd.dq):
                return "at rest"
        return "at rest"

    def _silence(self) -> None:
        """The watchdog's call: the loop has sent nothing for ``watchdog_s``; stop the arm
        unless a send came meanwhile (checked under the sending lock)."""
        with self.sending:
            if self.dog.silent_s() > self.watchdog_s:
                self.arm.stop()
                self.stops += 1

    def close(self) -> None:
        if self.watching:
            self.dog.__exit__(None, None, None)
        try:
            self.arm.stop()
        except ArmError as exc:
            self.ended_by = self.ended_by or f"arm {exc.reason or 'error'}: {exc}"

    def report(self, truth: Callable[[Kinematics, float], np.ndarray] | None) -> dict[str, Any]:
        return super().report(truth) | ({"watchdog_fired": True} if self.dog.fired else {})


#: How close to a send's time :func:`_until` stops sleeping and spins, s: ``time.sleep``
#: overshoots by 0.05-0.2 ms here, which a wait each period would add to every period.
SPIN_S = 3e-4


def _until(deadline: float) -> float:
    """Return at ``deadline`` (``time.perf_counter``, s), not later by a sleep's overshoot:
    sleep until :data:`SPIN_S` before it, then spin. How long it waited, s (0 if past)."""
    start = time.perf_counter()
    while (left := deadline - time.perf_counter()) > 0:
        if left > SPIN_S:
            time.sleep(left - SPIN_S)
    return max(deadline - start, 0.0)


def offline_limits(robot: Robot, dt: float) -> CommandCheck:
    """The check of a simulated arm's commands: the description's limits."""
    return CommandCheck(CommandLimits.of(robot, dt))


class _Held:
    """When the last command went to the arm, and whether the arm still follows it.

    An arm holds a command for ``hold_s`` (franky's hold, the watchdog's timeout,
    :class:`~qpavoid.drive.simulated.SimulatedArm`'s ``hold_s``; None: until the next, as a
    ros2_control velocity controller does), then brakes to rest on its own; or the
    watchdog stops it (``stops`` counts it). A command sent after that is the first of a
    new stream, from rest: the
    controller's ramp and the command check start again from rest, together. Judged from
    the time of the last *send*, as the arm judges it, not from when a tick began: a late
    tick sends long after it began, and the arm still follows that command after it.
    """

    def __init__(
        self,
        hold_s: float | None,
        controller: Controller,
        checked: CommandCheck,
        stops: Callable[[], int],
    ):
        self.hold_s, self.controller, self.checked = hold_s, controller, checked
        self.stops = stops  # how many times the watchdog has stopped the arm
        self.at: float | None = None  # when the command the arm holds was sent, if one
        self.last = -math.inf  # when the last command was sent (the next: a period later)
        self._stops_at_send = 0

    def sent(self, now: float) -> None:
        """A command went to the arm at ``now`` (wall clock, s)."""
        self.at = self.last = now
        self._stops_at_send = self.stops()

    def ran_out(self, now: float) -> float | None:
        """If the arm's hold of the last command ran out by ``now`` (its own hold, or the
        watchdog stopped it): the controller and the check then start from rest; the time
        since that command, s (else None)."""
        if self.at is None:
            return None
        stopped = self.stops() != self._stops_at_send
        if not stopped and (self.hold_s is None or now - self.at <= self.hold_s):
            return None
        gap, self.at = now - self.at, None
        self.controller.at_rest()
        self.checked.restart()
        return gap
