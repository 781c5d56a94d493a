"""Several people: the controllers use the closest, the truth the nearest, files carry ids."""

from __future__ import annotations

import numpy as np
import pytest

from qpavoid.controller import ControllerConfig
from qpavoid.frames import HumanFrame
from qpavoid.fused import fuse_recordings, load_people, save_fused_npz
from qpavoid.people import Crowd, People
from qpavoid.posture import Operator
from qpavoid.qp import QPController
from qpavoid.runs import RunSpec, simulate_one
from qpavoid.scenarios import make_scenario
from qpavoid.simulation import SimConfig, simulate
from qpavoid.strikes import strike_case, strike_motion
from qpavoid.task import ArcPath, inverse_kinematics
from qpavoid.two_sensors import TwoSensorConfig, two_sensor_data


class Shifted:
    """A motion moved by a constant offset, m (another person beside the first)."""

    def __init__(self, motion, offset):
        self.motion, self.offset = motion, np.asarray(offset, dtype=float)

    def frame_at(self, t):
        frame = self.motion.frame_at(t)
        frame = frame if isinstance(frame, HumanFrame) else HumanFrame.check(*frame)
        return HumanFrame(frame.joints + self.offset, frame.state)


@pytest.mark.parametrize("safety", ["paper", "ssm"])
def test_every_pair_uses_the_closest_person(robot, safety):
    q = inverse_kinematics(robot, ArcPath().reference(7.0)[0])
    rng = np.random.default_rng(3)
    config = ControllerConfig(safety=safety, control_period_s=0.01)
    for _ in range(5):
        a = Operator().rest() + rng.uniform(-0.2, 0.2, 3)
        b = Operator().rest() + rng.uniform(-0.6, 0.6, 3)
        alone = [
            QPController(robot, config=config).measure(q, f, None, 7.0).table.distance
            for f in (a, b)
        ]
        for ids, frames in (((0, 1), (a, b)), ((7, 2), (b, a))):
            people = People.check(ids, frames)
            tick = QPController(robot, config=config).measure(q, people, None, 7.0)
            np.testing.assert_array_equal(tick.table.distance, np.minimum(*alone))
            closest = int(np.argmin(tick.table.distance.ravel()))
            assert tick.table.distance.ravel()[closest] == min(d.min() for d in alone)


def test_people_need_unique_ids():
    rest = Operator().rest()
    with pytest.raises(Exception, match="unique id"):
        People.check((1, 1), (rest, rest))
    with pytest.raises(Exception, match="unique id"):
        People.check((1,), (rest, rest))


def test_nobody_in_view_stops_the_robot(robot):
    q = inverse_kinematics(robot, ArcPath().reference(0.0)[0])
    cmd = QPController(robot).step(q, People((), ()), None, 0.0)
    assert cmd.stopped and "no body part" in cmd.reason


def test_a_second_person_striking_finds_the_robot_stationary_before_contact(robot):
    """The operator works; a colleague strikes L2 at 2 m/s: judged against both, true."""
    case = strike_case(2, 2.0)
    case = type(case)(case.seed, "L2", 2.0, "right", False, 2.0, "none")
    crowd = Crowd({0: make_scenario("free", robot), 1: strike_motion(case, robot)})
    ctrl = QPController(robot, config=ControllerConfig(safety="ssm", control_period_s=0.01))
    sim = simulate(
        ctrl, crowd, SimConfig(control_rate_hz=100.0, max_time_s=4.5, measure_truth=True)
    )
    m = sim.metrics
    assert m["ticks_moving_in_true_contact"] == 0
    assert np.nanmin(sim.log["true_distance"]) < 0.05  # the strike did reach the robot
    assert m["stop_events"], "the robot should have stopped for the colleague"


def test_fused_people_go_through_a_file_and_a_run(tmp_path, robot):
    one = make_scenario("free", robot)
    two = Shifted(one, [1.1, 0.3, 0.0])
    data = two_sensor_data([one, two], 1.0, TwoSensorConfig(seed=2))
    fused = fuse_recordings(list(data.recordings.values()), data.calibration)
    assert fused.ids == (0, 1)
    for pid, motion in ((0, one), (1, two)):  # ids follow who is who
        rows = fused.body == pid
        truth = np.array([motion.frame_at(t).joints for t in fused.t[rows]]) if pid else None
        if truth is not None:
            err = np.linalg.norm(fused.joints[rows] - truth, axis=2)
            assert np.nanmean(err) < 0.06
    path = tmp_path / "fused.npz"
    save_fused_npz(path, fused)
    people = load_people(path)
    assert sorted(people) == [0, 1]
    run = simulate_one(RunSpec(human_file=str(path), rate_hz=100.0, max_time_s=1.0))
    assert run.metrics["min_true_clearance_moving_m"] is None or np.isfinite(
        run.metrics["min_true_clearance_moving_m"]
    )
    assert np.isfinite(run.sim.log["true_distance"]).all()
