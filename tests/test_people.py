"""Several people: the controllers use the closest, the truth the nearest, files carry ids."""

from __future__ import annotations

import numpy as np
import pytest

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.control.path import ArcPath
from qpavoid.control.qp import QPController
from qpavoid.control.tick import ControllerConfig
from qpavoid.experiments.runs import RunSpec, simulate_one
from qpavoid.fusion.fuser import Fuser
from qpavoid.fusion.offline import fuse_recordings, load_people, save_fused_npz
from qpavoid.human.frames import HumanFrame
from qpavoid.human.people import People
from qpavoid.human.posture import Operator
from qpavoid.loop.crowd import Crowd
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario
from qpavoid.scenarios.strikes import strike_case, strike_motion
from qpavoid.sensing.recording import Recording
from qpavoid.sensing.synthetic_pair import TwoSensorConfig, two_sensor_data


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


class FusedLive:
    """Two simulated Kinects fused frame by frame as a live loop would (60 ms latency),
    with the frames ``hidden(frame, capture_time)`` says never reach the fusion."""

    def __init__(self, data, hidden=lambda frame, t: False, latency_s=0.06):
        cal = data.calibration
        self.rows = sorted(
            (
                (f.t + cal[f.sensor].time_offset_s, f)
                for r in data.recordings.values()
                for f in r.frames()
            ),
            key=lambda row: row[0],
        )
        self.rows = [(t, f) for t, f in self.rows if not hidden(f, t)]
        self.fuser, self.k, self.latency_s = Fuser(cal), 0, latency_s
        self.seen: list[tuple[float, tuple[int, ...], tuple[bool, ...]]] = []

    def frame_at(self, t):
        while self.k < len(self.rows) and self.rows[self.k][0] + self.latency_s <= t:
            self.fuser.add(self.rows[self.k][1])
            self.k += 1
        fused = self.fuser.fuse(t - self.latency_s)
        people = People(tuple(p.id for p in fused.people), tuple(p.frame for p in fused.people))
        visible = tuple(bool(np.isfinite(p.frame.joints).any()) for p in fused.people)
        self.seen.append((t, people.ids, visible))
        return people, fused.captured_s


def run_live(robot, crowd, source, seconds):
    """The QP controller (SSM, 100 Hz) on ``source``, judged against ``crowd``."""
    ctrl = QPController(robot, config=ControllerConfig(safety="ssm", control_period_s=0.01))
    config = SimConfig(control_rate_hz=100.0, max_time_s=seconds, measure_truth=True)
    return simulate(ctrl, crowd, config, source=source)


def test_a_colleague_who_vanishes_from_view_mid_strike_is_not_forgotten(robot):
    """Both sensors lose the colleague 0.4 s before their hand arrives (stepped behind
    the operator); the hand goes on. The operator stays in view: judged against both."""
    case = strike_case(5, 1.5)
    case = type(case)(case.seed, "EE", 1.5, "right", False, 2.2, "none")
    free, strike = make_scenario("free", robot), strike_motion(case, robot)
    data = two_sensor_data([free, strike], 4.0, TwoSensorConfig(seed=6))
    source = FusedLive(data, hidden=lambda f, t: f.body == 1 and t >= case.arrival_s - 0.4)
    sim = run_live(robot, Crowd({0: free, 1: strike}), source, 4.0)
    assert sim.metrics["ticks_moving_in_true_contact"] == 0
    assert np.nanmin(sim.log["true_distance"]) < 0.05  # the hidden hand did reach the robot
    moving = np.any(sim.log["dq_command"] != 0.0, axis=1)
    assert moving[sim.log["t"] < case.arrival_s - 0.8].any()  # it worked before
    gone = [(ids, vis) for t, ids, vis in source.seen if t > case.arrival_s]
    assert gone and all(ids == (0, 1) and vis == (True, False) for ids, vis in gone[:100])


class Walk:
    """A motion carried from ``start`` to ``end`` (m, added to it) between ``t0`` and ``t1``."""

    def __init__(self, motion, start, end, t0, t1):
        self.motion, self.t0, self.t1 = motion, t0, t1
        self.start, self.end = np.asarray(start, float), np.asarray(end, float)

    def offset(self, t):
        s = min(max((t - self.t0) / (self.t1 - self.t0), 0.0), 1.0)
        return self.start + s * (self.end - self.start)

    def frame_at(self, t):
        frame = self.motion.frame_at(t)
        frame = frame if isinstance(frame, HumanFrame) else HumanFrame.check(*frame)
        return HumanFrame(frame.joints + self.offset(t), frame.state)


def test_two_people_who_swap_places_keep_their_ids(robot):
    """Two people pass each other (0.35 m apart sideways) and end in each other's place:
    each fused id follows the same person throughout, and the robot is judged safe
    against both."""
    rest = make_scenario("free", robot)
    a = Walk(rest, [-0.3, -0.3, 0.0], [0.9, -0.3, 0.0], 0.5, 2.5)
    b = Walk(rest, [0.9, -0.65, 0.0], [-0.3, -0.65, 0.0], 0.5, 2.5)
    data = two_sensor_data([a, b], 3.5, TwoSensorConfig(seed=8))
    source = FusedLive(data)
    sim = run_live(robot, Crowd({0: a, 1: b}), source, 3.5)
    assert sim.metrics["ticks_moving_in_true_contact"] == 0
    fuser = source.fuser
    assert sorted(tr.id for tr in fuser.tracks) == [0, 1]  # nobody new, nobody lost
    for track, motion in zip(sorted(fuser.tracks, key=lambda tr: tr.id), (a, b), strict=True):
        # each id ends where its own person ended (they swapped sides: 1.2 m apart in x)
        centre = track.centre()
        truth = motion.frame_at(3.4 - 0.06).joints[[0, 1, 20]].mean(axis=0)
        assert np.linalg.norm(centre[:2] - truth[:2]) < 0.15, (track.id, centre, truth)


def test_a_person_whose_recording_ends_unseen_has_left():
    """A fused recording's person dropped by the fusion ends with frames that see nothing:
    absent after them (as live), not held unseen for ever (a lost person's growing
    uncertainty stopped the robot for the rest of an offline run: adversarial tester)."""
    rest = Operator().rest()
    t = np.arange(0.0, 3.0, 0.1)
    joints = np.repeat(rest[None], len(t), axis=0)
    state = np.full((len(t), 25), 2, dtype=np.int8)
    stays = Recording(t, joints, state)
    joints_left, state_left = joints.copy(), state.copy()
    joints_left[20:], state_left[20:] = np.nan, 0  # unseen from 2.0 s, the file ends at 2.9
    aside = np.array([1.0, 0.0, 0.0])
    leaves = Recording(t, joints_left + aside, state_left)
    crowd = Crowd({0: stays, 1: leaves})
    assert crowd.frame_at(2.5).ids == (0, 1)  # unseen but not yet dropped: still there
    assert crowd.frame_at(5.0).ids == (0,)  # after the end: gone
    held = Crowd({0: stays, 1: Recording(t, joints + aside, state)})
    assert held.frame_at(5.0).ids == (0, 1)  # a person seen at the end is held
