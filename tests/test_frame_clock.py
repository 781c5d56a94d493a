"""A frame's freshness by its own time: a 1 kHz loop holding a 30 Hz frame (issue 27 item 2)."""

from __future__ import annotations

import runpy
from pathlib import Path

import numpy as np
import pytest

from qpavoid import ControllerConfig
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.control.analytic import AnalyticController
from qpavoid.control.qp import QPController
from qpavoid.core.errors import InputError
from qpavoid.human.people import People, as_people
from qpavoid.human.posture import Operator
from qpavoid.perception.freshness import FrameClock

DT = 0.001  # a 1 kHz loop
EXAMPLE = Path(__file__).parents[1] / "examples" / "control_loop.py"


def far_person(k: int) -> np.ndarray:
    """The operator at rest, 1 m further away, moving 1 mm per 30 Hz frame ``k``."""
    joints = Operator().rest() + np.array([1.0, 0.0, 0.0])
    return joints + np.array([0.0, 0.001 * k, 0.0])


def loop(ctrl, ticks: int, **keys) -> list[str]:
    """``ticks`` calls at 1 kHz with the frame of a 30 Hz camera (a new array every call);
    ``keys(k, frame)`` gives the step's frame keywords. The stop reasons, one per tick."""
    q = inverse_kinematics(ctrl.robot, ctrl.path.reference(0.0)[0])
    reasons = []
    for k in range(ticks):
        frame = int(k * DT * 30.0)
        extra = keys["keys"](k, frame) if keys else {}
        cmd = ctrl.step(q, far_person(frame).copy(), None, t=0.0, **extra)
        reasons.append(cmd.reason)
    return reasons


@pytest.mark.parametrize(
    "kind", [AnalyticController, pytest.param(QPController, marks=pytest.mark.slow)]
)
@pytest.mark.parametrize(
    "keys",
    [
        None,  # the README's call: nothing but the joints
        lambda k, f: {"frame_time_s": f / 30.0},  # the camera's capture time
        pytest.param(lambda k, f: {"frame_id": f}, marks=pytest.mark.slow),  # a counter
        pytest.param(
            lambda k, f: {"frame_time_s": f / 30.0, "frame_age_s": k * DT - f / 30.0},
            marks=pytest.mark.slow,
        ),
    ],
    ids=["joints-only", "frame-time", "frame-id", "time-and-age"],
)
def test_a_held_frame_is_not_a_frozen_sensor(robot, kind, keys):
    ctrl = kind(robot, config=ControllerConfig(control_period_s=DT))
    reasons = loop(ctrl, 200, **({"keys": keys} if keys else {}))  # 6 frames, 200 ticks
    assert not any(reasons), sorted(set(reasons))


def test_the_same_skeleton_under_new_times_is_a_frozen_sensor(robot):
    """A sensor repeating its last skeleton with new timestamps: 4 identical frames stop."""
    ctrl = AnalyticController(robot, config=ControllerConfig(control_period_s=DT))
    q = inverse_kinematics(robot, ctrl.path.reference(0.0)[0])
    joints = far_person(0)
    reasons = [
        ctrl.step(q, joints.copy(), None, 0.0, frame_time_s=int(k * DT * 30) / 30.0).reason
        for k in range(200)
    ]
    first = next(k for k, r in enumerate(reasons) if r)
    assert "frozen (5 identical skeletons" in reasons[first]
    assert int(first * DT * 30) == 4  # the fifth frame, not the fifth call
    # the same with frame ids
    ctrl = AnalyticController(robot, config=ControllerConfig(control_period_s=DT))
    reasons = [ctrl.step(q, joints, None, 0.0, frame_id=k // 33).reason for k in range(200)]
    assert "frozen" in next(r for r in reasons if r)


def test_a_frame_held_too_long_is_stale_on_the_controllers_clock(robot):
    """Nothing new for longer than max_frame_age_s: stale at exactly that age."""
    cfg = ControllerConfig(control_period_s=DT, max_frame_age_s=0.1)
    ctrl = AnalyticController(robot, config=cfg)
    q = inverse_kinematics(robot, ctrl.path.reference(0.0)[0])
    joints = far_person(0)
    reasons = [ctrl.step(q, joints.copy(), None, 0.0).reason for _ in range(150)]
    first = next(k for k, r in enumerate(reasons) if r)
    assert first == 101  # ages 0, 1 ms, ..., 100 ms pass; 101 ms is stale
    assert reasons[first].startswith("human frame is stale (101.0 ms old, max 100.0 ms)")
    # a new frame brings it back
    assert not ctrl.step(q, far_person(1), None, 0.0).reason


def test_frame_clock_keys_and_ages():
    clock = FrameClock()
    a, b = far_person(0), far_person(1)
    pa, pa2, pb = as_people(a, None), as_people(a.copy(), None), as_people(b, None)
    assert clock.observe(pa, 0.0, None, None, None) == (True, 0.0)
    assert clock.observe(pa2, 0.5, None, None, None) == (False, 0.5)  # same content
    assert clock.observe(pb, 0.6, None, None, None) == (True, 0.0)  # new content
    assert clock.observe(pb, 0.7, 0.25, None, None) == (False, 0.25)  # the caller's age wins
    assert clock.observe(pb, 0.8, None, 3.0, None)[0]  # a time: new
    assert not clock.observe(pa, 0.9, None, 3.0, None)[0]  # same time, other content: held
    assert not clock.observe(pa, 1.0, None, 3.0, 7)[0]  # a new id at the same time: held
    assert clock.observe(pa, 1.05, None, 3.5, 7)[0]  # a new id, later: new
    assert not clock.observe(pb, 1.1, None, 4.0, 7)[0]  # same id: held, whatever the time
    assert clock.observe(pb, 1.2, None, 2.0, 8) == (False, pytest.approx(0.15))  # earlier
    assert clock.observe(pb, 1.3, 0.01, 2.0, 9) == (False, pytest.approx(0.25))  # held: aging


@pytest.mark.parametrize(
    "times",
    [
        lambda f: (f if f < 15 else f - 15) / 30.0,  # the sensor's clock restarts at 0.5 s
        pytest.param(lambda f: 100.0 - f / 30.0, marks=pytest.mark.slow),  # counting down
        pytest.param(  # one frame stamped far ahead
            lambda f: 1e9 if f == 15 else f / 30.0, marks=pytest.mark.slow
        ),
        pytest.param(lambda f: 1.0, marks=pytest.mark.slow),  # a counter over a frozen clock
    ],
    ids=["restart", "backwards", "glitch-ahead", "frozen-clock"],
)
def test_a_frame_not_later_than_the_newest_is_held_and_goes_stale(robot, times):
    """Frames whose capture time does not advance never refresh the frame in hand: the robot
    stops on it once it is older than max_frame_age_s, however the ids or contents run."""
    ctrl = AnalyticController(robot, config=ControllerConfig(control_period_s=DT))
    q = inverse_kinematics(robot, ctrl.path.reference(0.0)[0])
    reasons = []
    for k in range(800):  # 0.8 s at 1 kHz, 24 frames
        f = int(k * DT * 30.0)
        joints = far_person(f)
        reasons.append(ctrl.step(q, joints, None, 0.0, frame_time_s=times(f), frame_id=f).reason)
    stale = [r for r in reasons[650:] if "stale" in r]  # a frame in hand since 0.5 s at most
    assert len(stale) == 150, sorted(set(reasons[650:]))  # stopped, and stays stopped


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("frame_time_s", float("nan")),
        ("frame_time_s", "1.0"),
        ("frame_time_s", np.array([1.0])),
        ("frame_time_s", 1j),
        ("frame_age_s", -0.01),
        ("frame_age_s", "0.01"),
    ],
)
def test_bad_frame_times_are_refused(robot, key, value):
    ctrl = AnalyticController(robot)
    q = inverse_kinematics(robot, ctrl.path.reference(0.0)[0])
    with pytest.raises(InputError, match=key):
        ctrl.step(q, far_person(0), None, 0.0, **{key: value})


@pytest.mark.slow
def test_the_example_loop_runs_the_whole_of_test1():
    """examples/control_loop.py: the README's step loop at 1 kHz with a held 30 Hz Kinect
    frame runs Test 1 to its goal without a frozen-frame (or any) stop."""
    stops, reached = runpy.run_path(str(EXAMPLE))["run"]()
    assert reached
    assert not [s for s in stops if "frozen" in s or "stale" in s], stops


def test_one_frozen_person_beside_a_moving_one_stops_the_robot(robot):
    """Two people, one of them bit-identical frame after frame (a frozen track) while the
    other moves: any frozen person is a frozen sensor for the robot."""
    ctrl = AnalyticController(robot, config=ControllerConfig(control_period_s=DT))
    q = inverse_kinematics(robot, ctrl.path.reference(0.0)[0])
    still = far_person(0)
    reasons = []
    for k in range(300):
        f = int(k * DT * 30.0)
        people = People.check((1, 2), (still, far_person(f) + np.array([0.0, 0.5, 0.0])))
        reasons.append(ctrl.step(q, people, None, 0.0, frame_time_s=f / 30.0).reason)
    assert any("frozen" in r for r in reasons), sorted(set(reasons))
