"""The loop on an arm (issue 27 item 3): the same ``simulate`` driving an Arm in real time,
its deadlines, a stalled or failing arm, the watchdog, Ctrl-C, and the ramp to rest."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import load_robot
from qpavoid.control.analytic import AnalyticController
from qpavoid.control.qp import QPController
from qpavoid.core.errors import ArmError
from qpavoid.drive.interface import Arm, ArmState
from qpavoid.drive.limits import CommandCheck, CommandLimits
from qpavoid.drive.simulated import SimulatedArm
from qpavoid.drive.stop_ramp import ramp_to_rest
from qpavoid.drive.watchdog import Watchdog
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.loop.timing import LoopTiming, StallCheck
from qpavoid.scenarios.generated import make_scenario


class RecordingArm(SimulatedArm):
    """A simulated arm that keeps every command it was sent, and may fail on cue."""

    def __init__(self, robot, q0, *, stall_after_s=None, fail_after=None):
        super().__init__(robot, q0)
        self.sent: list[np.ndarray] = []
        self.stopped = 0
        self.stall_after_s, self.fail_after = stall_after_s, fail_after
        self._start = time.perf_counter()
        self._frozen: ArmState | None = None

    def read(self) -> ArmState:
        state = super().read()
        if (
            self.stall_after_s is not None
            and time.perf_counter() - self._start > self.stall_after_s
        ):
            self._frozen = self._frozen or state
            return self._frozen  # the same state again: its clock stands still
        return state

    def send(self, dq: np.ndarray) -> None:
        if self.fail_after is not None and len(self.sent) >= self.fail_after:
            raise ArmError("reflex: cartesian_reflex", arm=self.name, reason="fault")
        self.sent.append(np.array(dq))
        super().send(dq)

    def stop(self) -> None:
        self.stopped += 1
        super().stop()


def start(robot, controller_kind=AnalyticController):
    ctrl = controller_kind(robot)
    return ctrl, inverse_kinematics(robot, ctrl.path.reference(0.0)[0])


def within_limits(robot, commands) -> CommandCheck:
    check = CommandCheck(CommandLimits.of(robot, 0.002))
    for u in commands:
        check(u)
    return check


@pytest.mark.slow  # real time: seconds of wall clock (the default suite: the stall, the fault)
@pytest.mark.parametrize("kind", [AnalyticController, QPController])
def test_the_loop_drives_an_arm_and_leaves_it_at_rest(robot, kind):
    ctrl, q0 = start(robot, kind)
    arm = RecordingArm(robot, q0)
    assert isinstance(arm, Arm)
    cfg = SimConfig(max_time_s=2.0, measure_truth=True)
    m = simulate(ctrl, make_scenario("test1", robot), cfg, arm=arm).metrics
    assert m["end_reason"] == "time cap"
    assert m["loop"]["commands_sent"] > 100
    assert set(m["loop"]) >= {"deadline_misses", "longest_gap_s", "frame_to_command_s"}
    # the run ended mid-motion: the controller's ramp brought the arm to rest, then stop()
    moving = [u for u in arm.sent if np.any(u)]
    assert moving and not np.any(arm.sent[-1])
    assert arm.stopped == 1
    check = within_limits(robot, arm.sent)
    assert check.total() == 0, check.counts
    assert m["command_limit_violations"] == {"velocity": 0, "acceleration": 0, "jerk": 0}
    # the truth is that of the arm's own states (measured after the run)
    assert np.isfinite(m["min_true_clearance_moving_m"])


def test_a_stalled_arm_ends_the_run(robot):
    ctrl, q0 = start(robot)
    arm = RecordingArm(robot, q0, stall_after_s=0.3)
    m = simulate(ctrl, make_scenario("free", robot), SimConfig(max_time_s=4.0), arm=arm).metrics
    assert m["end_reason"].startswith("arm stalled: the arm's state has not changed for")
    assert m["duration_s"] < 1.5  # ended on the stall, not the time cap
    assert arm.stopped == 1


def test_an_arm_fault_ends_the_run_in_one_line(robot):
    ctrl, q0 = start(robot)
    arm = RecordingArm(robot, q0, fail_after=50)
    m = simulate(ctrl, make_scenario("free", robot), SimConfig(max_time_s=4.0), arm=arm).metrics
    assert m["end_reason"] == "arm fault: reflex: cartesian_reflex"
    assert len(arm.sent) == 50 and arm.stopped == 1


@pytest.mark.slow  # real time: seconds of wall clock
def test_a_missed_deadline_brakes_for_that_tick(robot):
    ctrl, q0 = start(robot)
    step, calls = ctrl.step, []

    def slow_step(*args, **kwargs):
        calls.append(1)
        if len(calls) == 50:
            time.sleep(0.02)  # one tick takes ten periods
        return step(*args, **kwargs)

    ctrl.step = slow_step
    arm = RecordingArm(robot, q0)
    res = simulate(ctrl, make_scenario("free", robot), SimConfig(max_time_s=2.0), arm=arm)
    assert res.metrics["loop"]["deadline_misses"] >= 1
    reasons = res.log["stop_reason"]
    assert reasons[49].startswith("missed deadline (")
    k = 49
    assert np.all(np.abs(arm.sent[k]) <= np.abs(arm.sent[k - 1]) + 1e-12)  # it braked
    assert within_limits(robot, arm.sent).total() == 0


@pytest.mark.slow  # real time: seconds of wall clock
def test_ctrl_c_mid_motion_ramps_the_arm_to_rest(robot):
    ctrl, q0 = start(robot)
    arm = RecordingArm(robot, q0)
    timer = threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        m = simulate(
            ctrl, make_scenario("test1", robot), SimConfig(max_time_s=5.0), arm=arm
        ).metrics
    finally:
        timer.cancel()
    assert m["end_reason"] == "interrupted"
    assert m["duration_s"] < 2.0
    assert np.abs(np.array(arm.sent)).sum(axis=1).max() > 5e-3  # it was moving
    assert not np.any(arm.sent[-1]) and arm.stopped == 1
    assert within_limits(robot, arm.sent).total() == 0


def test_the_watchdog_fires_only_when_not_kicked():
    fired = threading.Event()
    with Watchdog(0.05, fired.set) as dog:
        for _ in range(20):
            dog.kick()
            time.sleep(0.005)
        assert not dog.fired
        assert fired.wait(5.0)
    assert dog.fired and dog.error is None
    with Watchdog(0.01, lambda: 1 / 0) as dog:
        deadline = time.monotonic() + 5.0
        while not dog.fired and time.monotonic() < deadline:
            time.sleep(0.01)
    assert isinstance(dog.error, ZeroDivisionError)  # kept, not a thread's traceback


def test_loop_timing_by_hand():
    timing = LoopTiming(0.002, 0.002)
    assert timing.late(1.000, 1.0015) is None
    assert timing.late(1.000, 1.0030) == pytest.approx(0.003)
    for now, captured in [(0.010, 0.0), (0.012, 0.0), (0.020, 0.0), (0.022, 0.015)]:
        timing.sent(now, captured)
    r = timing.report()
    assert r["deadline_misses"] == 1 and r["commands_sent"] == 4
    assert r["longest_gap_s"] == pytest.approx(0.008)
    # each frame's first command: 10 ms after the first capture, 7 ms after the second
    assert r["frame_to_command_s"]["max"] == pytest.approx(0.010)
    assert r["frame_to_command_s"]["median"] == pytest.approx(0.0085)


def test_stall_check_by_hand():
    check = StallCheck(0.05)
    state = ArmState(10.0, np.zeros(2), np.zeros(2))
    check(state, 0.0)
    check(state, 0.04)  # the same state within the timeout: fine
    check(ArmState(10.001, np.zeros(2), np.zeros(2)), 0.06)  # a new one resets it
    check(ArmState(10.001, np.zeros(2), np.zeros(2)), 0.10)
    with pytest.raises(ArmError, match=r"has not changed for 0\.05") as err:
        check(ArmState(10.001, np.zeros(2), np.zeros(2)), 0.111)
    assert err.value.reason == "stalled"
    with pytest.raises(ArmError, match="ran backwards"):
        check(ArmState(9.0, np.zeros(2), np.zeros(2)), 0.112)


@pytest.mark.slow  # real time: seconds of wall clock
def test_a_loop_that_stalls_restarts_the_arm_from_rest(robot):
    """The loop stands still for 0.5 s (paused, starved): the watchdog stops the arm, the
    path clock does not run ahead by the stall, and the next commands start from rest."""
    ctrl, q0 = start(robot)
    step, calls = ctrl.step, []

    def stalling_step(*args, **kwargs):
        calls.append(1)
        if len(calls) == 300:
            time.sleep(0.5)
        return step(*args, **kwargs)

    ctrl.step = stalling_step
    arm = RecordingArm(robot, q0)
    res = simulate(ctrl, make_scenario("free", robot), SimConfig(max_time_s=3.0), arm=arm)
    m, log = res.metrics, res.log
    assert m["watchdog_fired"] and m["loop"]["loop_stalls"] == 1
    assert m["loop"]["longest_stall_s"] >= 0.5
    k = 300  # the first tick after the stall
    assert abs(log["tau"][k] - log["tau"][k - 1]) <= 0.1 + 1e-9  # at most the arm's hold
    a_dt = np.array([dict(robot.arm.max_acceleration_radps2)[n] for n in robot.joint_names])
    assert np.all(np.abs(arm.sent[k]) <= a_dt * 0.002 * (1 + 1e-9))  # from rest
    assert within_limits(robot, arm.sent).total() == 0


@pytest.mark.slow  # real time: 4 s of wall clock
def test_an_arm_that_holds_its_last_command_is_ramped_to_rest_by_the_watchdog():
    """A ros2_control velocity controller holds the last command until the next: when the
    loop stands still for 0.5 s, the watchdog's stop is the braking ramp (from the last two
    commands, within the limits), and the loop starts again from rest after it. Every
    command the arm got, the loop's and the watchdog's, keeps the limits (a helper's run
    through the ROS 2 stand-ins saw a step to zero of 2.4 times an acceleration limit)."""
    robot = load_robot("panda")  # jerk-limited: a step to rest breaks its jerk limit
    ctrl, q0 = start(robot)
    step, calls, stalled = ctrl.step, [], []

    def stalling_step(*args, **kwargs):
        calls.append(time.perf_counter())
        if calls[-1] - calls[0] > 3.2 and not stalled:  # moving fast (by the wall clock: a
            stalled.append(len(calls))  # loaded machine skips ticks, fewer calls)
            time.sleep(0.5)
        return step(*args, **kwargs)

    class HoldingArm(RecordingArm):
        holds_command_s = None  # until the next command: only a stop ends it

        def __init__(self, robot, q0):
            super().__init__(robot, q0)
            self.hold_s = 1e9

        def stop(self) -> None:
            self.stopped += 1
            last = self.sent[-1] if self.sent else np.zeros(robot.nv)
            before = self.sent[-2] if len(self.sent) > 1 else np.zeros(robot.nv)
            ramp_to_rest(robot, CommandLimits.of(robot, 0.002), (last, before), self.send)

    ctrl.step = stalling_step
    arm = HoldingArm(robot, q0)
    res = simulate(ctrl, make_scenario("free", robot), SimConfig(max_time_s=4.2), arm=arm)
    m = res.metrics
    assert m["watchdog_fired"] and m["loop"]["loop_stalls"] >= 1  # (a loaded machine: more)
    assert arm.stopped >= 2  # the watchdog's, and the end of the run's
    moving = np.abs(np.array(arm.sent)).max(axis=1)
    j_dt2 = min(dict(robot.arm.max_jerk_radps3).values()) * 0.002**2
    assert moving[: stalled[0]].max() > j_dt2  # fast enough that a step to rest breaks the limit
    assert within_limits(robot, arm.sent).total() == 0, within_limits(robot, arm.sent).worst


@pytest.mark.slow  # real time: seconds of wall clock
def test_an_arm_reporting_nan_is_ramped_to_rest_and_named(robot):
    ctrl, q0 = start(robot)

    class NaNArm(RecordingArm):
        def read(self) -> ArmState:
            state = super().read()
            if len(self.sent) >= 400:
                return ArmState(state.time_s, np.full_like(state.q, np.nan), state.dq)
            return state

    arm = NaNArm(robot, q0)
    m = simulate(ctrl, make_scenario("test1", robot), SimConfig(max_time_s=4.0), arm=arm).metrics
    assert m["end_reason"].startswith("input error: ")
    assert np.abs(arm.sent[399]).max() > 1e-3  # it was moving
    assert not np.any(arm.sent[-1]) and len(arm.sent) >= 401  # then a ramp to rest
    assert within_limits(robot, arm.sent).total() == 0


def test_a_stream_is_checked_as_its_commands_one_by_one(robot):
    """CommandCheck.stream (an offline run's, vectorised) counts as the per-command check."""
    rng = np.random.default_rng(0)
    for _ in range(50):
        commands = np.cumsum(rng.normal(0, 0.01, (40, robot.nv)), axis=0) * rng.uniform(0.5, 3)
        one, whole = (CommandCheck(CommandLimits.of(robot, 0.002)) for _ in range(2))
        for u in commands:
            one(u)
        whole.stream(commands)
        assert one.counts == whole.counts
        assert one.worst == pytest.approx(whole.worst, abs=1e-12)


class FakeTime:
    """The loop's clock, run by hand: ``sleep`` moves it on, every reading takes 10 µs, and
    ``stall(s)`` makes the work in hand take ``s`` s more (a loaded machine, on cue)."""

    def __init__(self) -> None:
        self.now = 1000.0

    def perf_counter(self) -> float:
        self.now += 1e-5
        return self.now

    def perf_counter_ns(self) -> int:
        return int(self.perf_counter() * 1e9)

    def monotonic(self) -> float:
        return self.perf_counter()

    def sleep(self, seconds: float) -> None:
        self.now += max(seconds, 0.0)

    def stall(self, seconds: float) -> None:
        self.now += seconds


class QuietWatchdog:
    """The watchdog of a run on a hand-run clock: the arm's own hold stands for it."""

    fired = False

    def __init__(self, timeout_s, on_timeout) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass

    def kick(self) -> None:
        pass


class TimedArm(RecordingArm):
    """A recording arm on the hand-run clock that also keeps when each command came, and
    whose reads may take long on cue (``slow_reads``: read number → s)."""

    def __init__(self, robot, q0, clock: FakeTime, slow_reads=None):
        SimulatedArm.__init__(self, robot, q0, clock=clock.perf_counter)
        self.sent, self.stopped, self.stall_after_s, self.fail_after = [], 0, None, None
        self.times: list[float] = []
        self.fake, self.slow_reads, self.reads = clock, dict(slow_reads or {}), 0

    def read(self) -> ArmState:
        self.reads += 1
        self.fake.stall(self.slow_reads.get(self.reads, 0.0))
        return SimulatedArm.read(self)

    def send(self, dq: np.ndarray) -> None:
        super().send(dq)
        self.times.append(self.fake.now)


def held_segments_within_limits(robot, arm: TimedArm, hold_s: float) -> int:
    """Commands beyond the limits in what the arm was sent, each run of commands between
    two gaps longer than the arm's hold (after which it had braked to rest on its own)
    checked from rest."""
    broken, check = 0, None
    for k, u in enumerate(arm.sent):
        if check is None or arm.times[k] - arm.times[k - 1] > hold_s:
            check = CommandCheck(CommandLimits.of(robot, 0.002))
        broken += bool(check(u))
    return broken


# (step → s of extra compute, read → s of extra reading, the step SIGTERM comes on; from the
# 1900th step the iiwa moves at more than 2.5 ticks' acceleration: a restart from rest
# that the check does not know of breaks its limits)
LATENESS = {
    "one late tick": ({1900: 0.005}, {}, None),
    "two late ticks in a row": ({1900: 0.005, 1901: 0.004}, {}, None),
    "a late tick, then SIGTERM": ({1900: 0.005}, {}, 1900),
    "a late tick, SIGTERM on the next": ({1900: 0.005}, {}, 1901),
    "a tick past the arm's hold": ({1900: 0.105}, {}, None),
    "a tick past the hold, then SIGTERM": ({1900: 0.105}, {}, 1901),
    "a slow read past the hold": ({}, {1900: 0.12}, None),
    "late, then a slow read: 0.1 s between reads, not sends": ({1900: 0.06}, {1902: 0.045}, None),
}


#: The cases the default suite runs (its time budget: 1.4 s each); the slow one runs all.
QUICK = (
    "a tick past the hold, then SIGTERM",
    "late, then a slow read: 0.1 s between reads, not sends",
)


@pytest.mark.parametrize(
    "case", [c if c in QUICK else pytest.param(c, marks=pytest.mark.slow) for c in LATENESS]
)
def test_every_command_sent_is_within_limits_however_late_the_ticks(robot, monkeypatch, case):
    """On a hand-run clock (no dependence on the machine's speed): ticks late by a few ms,
    two in a row, a late tick then SIGTERM, a tick or a read past the arm's 0.1 s hold of a
    command, a late tick at the end of the run: every command the loop sends keeps the
    arm's limits from the one before (or from rest, where the arm held none for 0.1 s and
    stopped on its own), and the run ends with the arm ramped to rest."""
    from qpavoid.loop import plants, simulation

    compute, reads, term_at = LATENESS[case]
    clock = FakeTime()
    monkeypatch.setattr(simulation, "time", clock)
    monkeypatch.setattr(plants, "time", clock)
    monkeypatch.setattr(plants, "Watchdog", QuietWatchdog)
    ctrl, q0 = start(robot)
    step, calls = ctrl.step, []

    def loaded_step(*args, **kwargs):
        calls.append(1)
        if len(calls) == term_at:
            os.kill(os.getpid(), signal.SIGTERM)
        out = step(*args, **kwargs)
        clock.stall(compute.get(len(calls), 0.0))
        return out

    ctrl.step = loaded_step
    arm = TimedArm(robot, q0, clock, reads)
    m = simulate(ctrl, make_scenario("test1", robot), SimConfig(max_time_s=4.0), arm=arm).metrics
    a_dt = arm.limits.acceleration_radps2 * 0.002
    moving = np.max(np.abs(arm.sent[1890]) / a_dt)
    assert moving > 2.5, moving  # fast enough that a jump from rest breaks the limits
    assert m["command_limit_violations"] == {"velocity": 0, "acceleration": 0, "jerk": 0}
    assert held_segments_within_limits(robot, arm, 0.1) == 0
    assert not np.any(arm.sent[-1]) and arm.stopped == 1
    assert m["end_reason"] == ("interrupted" if term_at else "time cap")
    if term_at:
        assert len(calls) == term_at
    past_hold = any(s > 0.1 for s in (*compute.values(), *reads.values()))
    assert m["loop"]["loop_stalls"] == past_hold  # (then the arm stopped by itself)
    assert np.diff(arm.times[:-1]).min() > 0.0019  # never two within a period (then stop)


def test_the_loop_keeps_its_rate_and_its_sends_a_period_apart(robot, monkeypatch):
    """On the hand-run clock, ticks whose work varies from 0.1 to 1.4 ms of a 2 ms period
    (and a send that takes 0.3 ms): the commands go out a period apart, never sooner (the
    tick after a slow one waits to send), and the loop keeps its rate: 0.5 s of run sends
    its 251 commands but for the hand-run clock's own cost (10 µs a reading, some 20 of a
    send's wait: at most 2 %); until 2026-12-02, 190 (a tick that sent late in its period
    put the next one a whole period after that send, and a send's own time added up)."""
    from qpavoid.loop import plants, simulation

    clock = FakeTime()
    monkeypatch.setattr(simulation, "time", clock)
    monkeypatch.setattr(plants, "time", clock)
    monkeypatch.setattr(plants, "Watchdog", QuietWatchdog)
    ctrl, q0 = start(robot)
    step, work = ctrl.step, iter(np.random.default_rng(5).uniform(1e-4, 1.4e-3, 10_000))

    def varying_step(*args, **kwargs):
        out = step(*args, **kwargs)
        clock.stall(next(work))
        return out

    class SlowSend(TimedArm):
        def send(self, dq: np.ndarray) -> None:
            super().send(dq)
            clock.stall(3e-4)

    ctrl.step = varying_step
    arm = SlowSend(robot, q0, clock)
    m = simulate(ctrl, make_scenario("free", robot), SimConfig(max_time_s=0.5), arm=arm).metrics
    loop_sends = np.array(arm.times[: m["loop"]["commands_sent"]])
    gaps = np.diff(loop_sends)
    assert gaps.min() >= 0.002 - 1e-9  # never sooner than a period after the last began
    assert len(loop_sends) >= 0.98 * 251  # t = 0, 0.002, ..., 0.5: the schedule's ticks
    assert np.median(gaps) == pytest.approx(0.002, rel=0.02)  # the run's period
    assert m["loop"]["deadline_misses"] == 0


def test_the_watchdog_fires_once_per_silence_and_again_after_a_kick():
    """A stall fires it once however long it lasts; a kick arms it again, and a second
    stall fires it again (until 2026-12-02 its thread ended after the first)."""
    with Watchdog(0.02, lambda: None) as dog:
        deadline = time.monotonic() + 5.0
        while not dog.fires and time.monotonic() < deadline:
            time.sleep(0.005)
        time.sleep(0.1)  # still silent: not again
        assert dog.fires == 1
        dog.kick()
        while dog.fires < 2 and time.monotonic() < deadline + 5.0:
            time.sleep(0.005)
    assert dog.fires == 2


def hand_clock(monkeypatch) -> FakeTime:
    """The loop on the hand-run clock, its watchdog quiet (the arm's own hold stands)."""
    from qpavoid.loop import plants, simulation

    clock = FakeTime()
    monkeypatch.setattr(simulation, "time", clock)
    monkeypatch.setattr(plants, "time", clock)
    monkeypatch.setattr(plants, "Watchdog", QuietWatchdog)
    return clock


def test_a_slow_step_of_the_end_ramp_sends_no_two_commands_within_a_period(robot, monkeypatch):
    """The ramp to rest after the time cap, one of its steps 7 ms late: its commands still
    go a period after the last began (until 2026-12-02 they were due on a grid, and the two
    due meanwhile went 20 µs apart), and the arm is stopped once, at rest."""
    clock = hand_clock(monkeypatch)
    ctrl, q0 = start(robot)
    brake, ramp_steps = ctrl.brake, []

    def slow_brake(reason, instead=False):
        out = brake(reason, instead)
        if reason == "end of run":
            ramp_steps.append(out.dq)
            if len(ramp_steps) == 2:
                clock.stall(0.007)
        return out

    ctrl.brake = slow_brake
    arm = TimedArm(robot, q0, clock)
    m = simulate(ctrl, make_scenario("free", robot), SimConfig(max_time_s=4.0), arm=arm).metrics
    assert len(ramp_steps) >= 3 and np.any(ramp_steps[0])  # it was moving: a real ramp
    assert np.diff(arm.times[:-1]).min() >= 0.002 - 1e-9  # (the last: the stop, at rest)
    assert held_segments_within_limits(robot, arm, 0.1) == 0
    assert not np.any(arm.sent[-1]) and arm.stopped == 1 and m["end_reason"] == "time cap"


@pytest.mark.parametrize("fails", ["first read", "first send"])
def test_an_arm_that_fails_at_once_is_one_error_stopped_with_the_handlers_back(
    robot, monkeypatch, fails
):
    """An arm failing on its first read (before any tick) or its first send: simulate
    raises ArmError naming why, the arm is stopped, and Ctrl-C's and SIGTERM's handlers are
    the ones before the run (until 2026-12-02 a failed first read left the run's own, which
    swallowed every later Ctrl-C; a failed first send crashed on an empty log)."""
    clock = hand_clock(monkeypatch)
    ctrl, q0 = start(robot)

    class Failing(TimedArm):
        def read(self):
            if fails == "first read":
                raise ArmError("no connection", arm="test", reason="unreachable")
            return super().read()

        def send(self, dq):
            raise ArmError("reflex", arm="test", reason="fault")

    arm = Failing(robot, q0, clock)
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    with pytest.raises(ArmError, match=r"before its first tick|no connection"):
        simulate(ctrl, make_scenario("free", robot), SimConfig(max_time_s=1.0), arm=arm)
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before
    assert arm.stopped == 1 and arm.sent == []
