"""Frames judged by their true age: gaps in a recording and a recording that has ended."""

from __future__ import annotations

import numpy as np
import pytest

from qpavoid.control.analytic import AnalyticController
from qpavoid.control.qp import QPController
from qpavoid.experiments.sweep_checks import braking_ticks
from qpavoid.loop.camera import CameraConfig
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario
from qpavoid.sensing.recording import Recording

RATE = 100.0
LATENCY = CameraConfig().latency_s


def recording_of(robot, times: np.ndarray) -> Recording:
    """The `free` scenario's person, captured only at ``times`` (s)."""
    motion = make_scenario("free", robot)
    frames = [motion.frame_at(float(t)) for t in times]
    return Recording(times, np.array([f[0] for f in frames]), np.array([f[1] for f in frames]))


# the paper's controller in the default suite, the QP with the slow ones
@pytest.mark.parametrize(
    "controller", [AnalyticController, pytest.param(QPController, marks=pytest.mark.slow)]
)
def test_a_gap_in_a_recording_stops_the_robot_until_frames_come_back(robot, controller):
    t = np.r_[np.arange(0.0, 3.0, 1 / 30), np.arange(4.0, 20.0, 1 / 30)]  # 1 s without frames
    ctrl = controller(robot)
    log = simulate(ctrl, recording_of(robot, t), SimConfig(control_rate_hz=RATE)).log
    age, moving = log["frame_age_s"], np.any(log["dq_command"] != 0, axis=1)
    stale = age > ctrl.config.max_frame_age_s
    # Within the gap the frame in hand is up to 1 s old: the robot holds still...
    gap = (log["t"] > 3.1) & (log["t"] < 4.0)
    assert stale[gap].all() and not moving[gap].any()
    # never moves on an old frame, but to brake (the stop's ramp, over by the gap's 0.1 s)
    braking = braking_ticks(log["dq_command"])
    assert not (moving & stale & ~braking).any()
    assert (moving & stale).any()  # the robot was moving when the frames stopped: a ramp
    assert age[gap].max() > 0.9
    # ...and moves again on fresh frames, reaching the goal later.
    assert moving[log["t"] > 4.1].any()
    # (a recording's first frame arrives one latency into the run: a short wait first)
    started = log["t"] > LATENCY + 0.01
    assert not log["stopped"][started & (log["t"] < 3.0)].any()
    assert 3.0 < log["t"][log["stopped"] & started].min() < 3.2


def test_a_recording_that_has_ended_is_stale(robot):
    """One frame, held: the robot stops once it is older than the limit, and stays stopped."""
    rec = recording_of(robot, np.array([0.0]))
    log = simulate(
        AnalyticController(robot), rec, SimConfig(control_rate_hz=RATE, max_time_s=10.0)
    ).log
    moving = np.any(log["dq_command"] != 0, axis=1)
    assert not moving[log["t"] > 0.1 + 1e-9].any()
    assert log["stopped"][-1] and log["t"][-1] >= 10.0 - 1e-9  # no goal on an old frame
    # Held as captured one latency before the run until it arrives, then its own time.
    arrived = log["t"] >= LATENCY - 1e-9
    np.testing.assert_allclose(log["frame_age_s"][arrived], log["t"][arrived])
    np.testing.assert_allclose(log["frame_age_s"][~arrived], log["t"][~arrived] + LATENCY)


def test_generated_motions_are_always_fresh(robot):
    log = simulate(
        AnalyticController(robot),
        make_scenario("free", robot),
        SimConfig(control_rate_hz=RATE, max_time_s=2.0),
    ).log
    age = log["frame_age_s"]
    assert age.min() > LATENCY - 1e-9 and age.max() < LATENCY + 1 / 30 + 1e-9


def test_a_person_holding_the_robot_off_its_goal_is_named(robot):
    """A hand resting near the goal: the run ends at the cap and says who held it."""
    from qpavoid.control.path import ArcPath
    from qpavoid.human.posture import Operator

    goal = ArcPath().reference(ArcPath().duration_s)[0][:3, 3]
    op = Operator()
    hand = op.reach(op.rest(), "right", goal + np.array([0.0, 0.11, 0.0]))
    t = np.arange(0.0, 25.0, 1 / 30)
    rec = Recording(t, np.repeat(hand[None], len(t), axis=0), np.full((len(t), 25), 2))
    # the path ends at 15 s: capped 3 s later, the hand still there
    run = simulate(AnalyticController(robot), rec, SimConfig(control_rate_hz=RATE, max_time_s=18.0))
    m = run.metrics
    assert not m["reached_goal"] and m["end_reason"] == "held by person"
    held = m["held_by_person"]
    assert held["part"] in ("right_hand", "right_forearm") and held["set"] in ("EE", "L2")
    assert 0.0 < held["distance_m"] < 0.2 and held["remaining_error_m"] > 1e-3
    free = simulate(
        AnalyticController(robot), make_scenario("free", robot), SimConfig(control_rate_hz=RATE)
    ).metrics
    assert free["end_reason"] == "goal reached" and free["held_by_person"] is None
