"""In real time the arm moves for the real time between ticks, not for the nominal period.

A real arm keeps executing its last command however late the next one comes: when the
control loop stalls, the simulated arm must have moved for the whole stall (else the true
clearance is optimistic exactly when the loop overruns). Every expectation here is built
from the log's own measured times, never from fixed durations, so a slow machine only
makes the gaps longer.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np
import pytest

from qpavoid.arm.braking import ArmResponse, BrakingConfig, per_joint
from qpavoid.arm.model import Robot
from qpavoid.control.qp import QPController
from qpavoid.control.tick import Command, ControllerConfig
from qpavoid.human.body import KinectHuman
from qpavoid.human.frames import HumanFrame
from qpavoid.human.posture import Operator
from qpavoid.loop.simulation import SimConfig, SimResult, simulate
from qpavoid.loop.truth import TrueClearance

DT = 0.01  # 100 Hz
STALL_S = 0.3
#: The commanded joint velocities, rad/s (six joints: the iiwa with A3 locked).
V = np.array([0.2, -0.1, 0.15, 0.1, -0.2, 0.1])
#: A person 3 m in front of the robot, seated; 2 mm of noise so that no two are identical.
FRAMES = [
    HumanFrame.check(Operator(distance_m=3.0).rest() + noise)
    for noise in np.random.default_rng(0).normal(0.0, 0.002, (8, 25, 3))
]


#: ``Constant`` commands a step to ``V`` on purpose: the arm model's response to it is what
#: these tests measure (the controllers' own commands never step: tests/test_smoothing.py).
pytestmark = pytest.mark.paper_steps


class Constant(QPController):
    """The real controller's tick, its command replaced by ``V`` from tick ``start`` on
    (zero before), moving, with the path clock at full rate."""

    def __init__(self, robot: Robot, start: int = 0):
        super().__init__(robot, config=ControllerConfig(control_period_s=DT))
        self.start, self.ticks = start, 0

    def step(self, *args: Any, **kwargs: Any) -> Command:
        cmd = super().step(*args, **kwargs)
        dq = V.copy() if self.ticks >= self.start else np.zeros_like(V)
        self.ticks += 1
        return dataclasses.replace(cmd, dq=dq, stopped=False, reason="", time_scale=1.0)


class Stalling:
    """``FRAMES`` at 30 Hz of the tick's time; the loop stalls once for ``STALL_S`` (in the
    frame call) right after tick ``after`` has been computed."""

    def __init__(self, controller: Constant, after: int):
        self.controller, self.after, self.stalled = controller, after, False

    def frame_at(self, t: float) -> tuple[HumanFrame, float]:
        if self.controller.ticks == self.after + 1 and not self.stalled:
            self.stalled = True
            time.sleep(STALL_S)
        k = int(t * 30)
        return FRAMES[k % len(FRAMES)], k / 30


class StandingStill:
    """The truth: the person still, where the first frame shows them."""

    def frame_at(self, t: float) -> HumanFrame:
        return FRAMES[0]


def run(
    robot: Robot, start: int, after: int, realtime: bool, stall: bool = True, truth: bool = False
) -> SimResult:
    controller = Constant(robot, start)
    source = Stalling(controller, after if stall else -10)
    motion = StandingStill() if truth else None
    cfg = SimConfig(control_rate_hz=1 / DT, max_time_s=0.6, measure_truth=truth)
    return simulate(controller, motion, cfg, source=source, realtime=realtime)


def test_a_stall_moves_the_arm_by_its_velocity_times_the_real_gap(robot: Robot) -> None:
    after = 40  # the arm (iiwa reaction and acceleration) is long at V by then
    log = run(robot, start=0, after=after, realtime=True).log
    k = after
    gap = log["t"][k + 1] - log["t"][k]  # measured: the stall and whatever else it took
    assert gap >= STALL_S
    np.testing.assert_array_equal(log["dq_command"][k], V)
    np.testing.assert_array_equal(log["dq"][k], V)  # steady: the arm does what it is told
    moved = log["q"][k + 1] - log["q"][k]
    np.testing.assert_allclose(moved, V * gap, rtol=1e-9, atol=1e-12)
    assert (np.abs(moved) > 25 * np.abs(V) * DT).all()  # not V × one period
    # the path clock ran for the same real time (time_scale 1), not for one period
    assert np.isclose(log["tau"][k + 1] - log["tau"][k], gap, rtol=1e-9, atol=1e-12)
    # and at every other tick too: the arm moved for the time that really passed
    steady = np.arange(20, len(log["t"]) - 1)
    expected = log["dq"][steady] * np.diff(log["t"])[steady, None]
    np.testing.assert_allclose(np.diff(log["q"], axis=0)[steady], expected, atol=1e-12)
    np.testing.assert_allclose(np.diff(log["tau"])[steady], np.diff(log["t"])[steady], atol=1e-12)


def test_a_command_sent_just_before_a_stall_is_followed_through_it(robot: Robot) -> None:
    """From rest, V commanded at tick ``k`` and the loop stalls: the arm reacts, ramps up
    at its acceleration limits and runs at V for the rest of the real gap."""
    k = 30
    log = run(robot, start=k, after=k, realtime=True).log
    gap = log["t"][k + 1] - log["t"][k]
    assert gap >= STALL_S
    np.testing.assert_array_equal(log["dq"][k], 0.0)  # the reaction time: still at rest
    # the ramp happened during the gap (one period's worth would be a_max·dt, below V)
    np.testing.assert_array_equal(log["dq"][k + 1], V)
    cfg = BrakingConfig().resolve(robot.arm)  # the description's reaction and accelerations
    reaction = np.ceil(cfg.reaction_time_s / DT - 1e-9) * DT
    ramp = float(np.max(np.abs(V) / per_joint(cfg.max_acceleration_radps2, robot.joint_names)))
    moved = log["q"][k + 1] - log["q"][k]
    # continuous time: V (gap − reaction − ramp/2); the steps every period differ by < V dt
    assert (np.abs(moved - V * (gap - reaction - ramp / 2)) <= np.abs(V) * DT).all()


def test_without_realtime_a_stall_changes_nothing(robot: Robot) -> None:
    """Simulated time: ticks exactly one period apart and ``q[k+1] = q[k] + dq[k]·dt`` to
    the bit, however long the loop stalls."""
    after = 20
    stalled = run(robot, start=5, after=after, realtime=False).log
    smooth = run(robot, start=5, after=after, realtime=False, stall=False).log
    n = len(stalled["t"])
    assert n == round(0.6 / DT) + 1
    np.testing.assert_array_equal(stalled["t"], np.arange(n) * DT)
    np.testing.assert_array_equal(stalled["q"][1:], stalled["q"][:-1] + stalled["dq"][:-1] * DT)
    for key, values in stalled.items():
        if key != "tick_us":
            np.testing.assert_array_equal(values, smooth[key], err_msg=key)


def test_on_regular_ticks_the_wall_clock_arm_is_the_periodic_arm(robot: Robot) -> None:
    rng = np.random.default_rng(3)
    cfg = BrakingConfig().resolve(robot.arm)  # the description's reaction and accelerations
    periodic = ArmResponse(cfg, robot.joint_names, DT)
    wall = ArmResponse(cfg, robot.joint_names, DT)
    for k in range(300):
        command = rng.normal(0.0, 0.5, robot.nv) * (k % 50 < 40)  # moves and stops
        np.testing.assert_allclose(wall.send(command, k * DT), periodic(command), atol=1e-12)


def test_a_held_stop_brakes_at_the_acceleration_limits_over_the_real_time(robot: Robot) -> None:
    """A stop sent, then no command for 0.1 s: the arm steps on the held stop every period
    and is at rest after the reaction time and T_s = max |q̇_j| / a_j, whatever the gap."""
    cfg = BrakingConfig().resolve(robot.arm)  # the description's reaction and accelerations
    a_max = per_joint(cfg.max_acceleration_radps2, robot.joint_names)
    arm = ArmResponse(cfg, robot.joint_names, DT)
    for k in range(20):
        arm.send(V, k * DT)
    t0 = 20 * DT + 0.0037  # a late tick
    np.testing.assert_array_equal(arm.send(np.zeros_like(V), t0), V)  # still reacting
    stop_s = float(np.max(np.abs(V) / a_max))
    t, speeds = t0, []
    while t < t0 + 0.1:
        t += DT
        speeds.append(arm.step(t).copy())
    at_rest = t0 + DT * (1 + np.flatnonzero(~np.any(speeds, axis=1))[0])
    assert at_rest <= t0 + arm.delay_s + stop_s + DT + 1e-9
    changes = np.abs(np.diff([V, *speeds], axis=0))
    assert (changes <= a_max * DT * (1 + 1e-9)).all()  # never faster than a_max


def test_the_true_clearance_is_measured_where_the_arm_really_was_through_a_stall(
    robot: Robot,
) -> None:
    """At the tick after the stall the truth is measured at the arm's real position, and the
    arm's steps inside the gap are measured too (``min_true_clearance_in_gaps_m``)."""
    after = 40
    sim = run(robot, start=0, after=after, realtime=True, truth=True)
    log, k = sim.log, after
    truth = TrueClearance(robot, KinectHuman(), StandingStill())

    def at(q: np.ndarray, t: float) -> np.ndarray:
        return truth(robot.kinematics(q, jacobians=False), t)

    np.testing.assert_allclose(log["true_distance"][k + 1], at(log["q"][k + 1], log["t"][k + 1]))
    # the steps in the gap: every period from t[k], the arm at V all the way
    gap = log["t"][k + 1] - log["t"][k]
    inside = np.arange(1, int(np.ceil(gap / DT - 1e-9))) * DT
    expected = min(at(log["q"][k] + V * s, log["t"][k] + s).min() for s in inside)
    in_gaps = sim.metrics["min_true_clearance_in_gaps_m"]
    assert in_gaps is not None and in_gaps <= expected + 1e-9
