"""What the controller may trust: lost, inferred and frozen joints, velocities, fingers, camera."""

from __future__ import annotations

import numpy as np
import pytest

from qpavoid.arm.braking import ArmResponse, BrakingConfig, stop_time
from qpavoid.human.body import KinectHuman
from qpavoid.human.frames import HumanFrame
from qpavoid.human.kinect_v2 import KINECT_V2, JointType, TrackingState
from qpavoid.human.posture import Operator
from qpavoid.loop.camera import Camera, CameraConfig, CameraFault
from qpavoid.perception.tracker import PerceptionConfig, Tracker, part_velocities

J = JointType
MAX_BONE_M = KINECT_V2.max_bone_m
HAND = int(J.HandRight)
WRIST = int(J.WristRight)


def frame(joints, state=None) -> HumanFrame:
    return HumanFrame.check(np.array(joints, dtype=float), state)


def test_a_lost_joint_stays_with_an_uncertainty_growing_at_human_speed():
    rest = Operator().rest()
    tracker = Tracker(PerceptionConfig())
    tracker.update(frame(rest), 0.0)
    lost = rest.copy()
    lost[[HAND, WRIST, int(J.ElbowRight), int(J.HandTipRight), int(J.ThumbRight)]] = np.nan
    p = tracker.update(frame(lost), 0.1)
    # kept where it was last seen, flagged Inferred, radius 2.0 m/s x 0.1 s = 0.2 m ...
    np.testing.assert_array_equal(p.frame.joints[HAND], rest[HAND])
    assert p.frame.state[HAND] == TrackingState.Inferred
    assert p.joint_radius[HAND] == pytest.approx(0.2)
    # ... until the reach of the tracked shoulder is smaller: then it sits at the shoulder
    p = tracker.update(frame(lost), 1.0)
    shoulder = rest[int(J.ShoulderRight)]

    def bone(j, parent):  # the longest seen, or the anthropometric bound
        return max(np.linalg.norm(rest[j] - rest[parent]), MAX_BONE_M[j])

    arm = (
        bone(int(J.ElbowRight), int(J.ShoulderRight))
        + bone(WRIST, int(J.ElbowRight))
        + bone(HAND, WRIST)
    )
    assert arm == pytest.approx(0.40 + 0.33 + 0.12)  # the operator's arm is within bounds
    np.testing.assert_array_equal(p.frame.joints[HAND], shoulder)
    assert p.joint_radius[HAND] == pytest.approx(arm)
    # the hand part never vanishes from the geometry: its margin is its farthest joint's
    # radius, the fingertip's (one bone beyond the hand)
    geo = KinectHuman().geometry(p.frame, joint_radius=p.joint_radius)
    k = KinectHuman().part_names.index("right_hand")
    tip = arm + bone(int(J.HandTipRight), HAND)
    assert geo.segment_valid[k] and geo.part_margin[k] == pytest.approx(tip)


def test_a_foreshortened_frame_before_a_loss_does_not_shrink_the_reach():
    rest = Operator().rest()
    tracker = Tracker(PerceptionConfig())
    tracker.update(frame(rest), 0.0)
    folded = rest.copy()  # the Kinect collapses the forearm and hand onto the elbow
    for j in (WRIST, HAND, int(J.HandTipRight), int(J.ThumbRight)):
        folded[j] = rest[int(J.ElbowRight)]
    tracker.update(frame(folded), 1 / 30)
    lost = rest.copy()
    lost[[WRIST, HAND, int(J.HandTipRight), int(J.ThumbRight)]] = np.nan
    p = tracker.update(frame(lost), 1.0)
    np.testing.assert_array_equal(p.frame.joints[HAND], rest[int(J.ElbowRight)])
    assert p.joint_radius[HAND] == pytest.approx(0.33 + 0.12)


def test_a_limb_never_seen_is_within_reach_of_its_tracked_ancestor():
    rest = Operator().rest()
    hidden = rest.copy()
    arm = [int(J.ElbowRight), WRIST, HAND, int(J.HandTipRight), int(J.ThumbRight)]
    hidden[arm] = np.nan
    state = np.full(25, 2)
    state[arm] = TrackingState.NotTracked
    p = Tracker(PerceptionConfig()).update(frame(hidden, state), 0.0)
    shoulder = rest[int(J.ShoulderRight)]
    for j, reach in ((HAND, 0.85), (int(J.HandTipRight), 1.0), (int(J.ElbowRight), 0.40)):
        np.testing.assert_array_equal(p.frame.joints[j], shoulder)
        assert p.joint_radius[j] == pytest.approx(reach)
        assert p.frame.state[j] == TrackingState.Inferred
    # the hand part is in the geometry with the fingertip's reach: a real hand anywhere
    # within reach of the shoulder is inside it
    geo = KinectHuman().geometry(p.frame, joint_radius=p.joint_radius)
    k = KinectHuman().part_names.index("right_hand")
    assert geo.segment_valid[k] and geo.part_margin[k] == pytest.approx(1.0)


def test_inferred_joints_carry_more_uncertainty_the_longer_they_are_not_tracked():
    rest = Operator().rest()
    tracker = Tracker(PerceptionConfig(inferred_uncertainty_m=0.1))
    tracker.update(frame(rest), 0.0)
    state = np.full(25, 2)
    state[HAND] = TrackingState.Inferred
    p = tracker.update(frame(rest, state), 0.005)
    assert p.joint_radius[HAND] == pytest.approx(0.1 + 2.0 * 0.005)
    np.testing.assert_array_equal(p.frame.joints[HAND], rest[HAND])
    assert p.joint_radius[WRIST] == 0.0
    # once that is more than the reach of the tracked wrist, the hand is bounded by it
    # (an Inferred hand can never stop the robot for good)
    for t in (0.5, 5.0, 50.0):
        p = tracker.update(frame(rest, state), t)
        np.testing.assert_array_equal(p.frame.joints[HAND], rest[WRIST])
        assert p.joint_radius[HAND] == pytest.approx(0.12)


def test_frozen_frames_are_counted_and_out_of_order_frames_ignored():
    rest = Operator().rest()
    tracker = Tracker()
    counts = [tracker.update(frame(rest), k / 30).identical for k in range(5)]
    assert counts == [0, 1, 2, 3, 4]
    moved = rest + 1e-6
    assert tracker.update(frame(moved), 5 / 30).identical == 0
    old = tracker.update(frame(rest + 1.0), 1 / 30)  # captured before the last one
    np.testing.assert_array_equal(old.frame.joints, moved)


def test_a_person_unseen_is_not_a_frozen_sensor():
    """Frames with no usable joint (a person the fusion keeps unseen: all alike) are not a
    sensor repeating itself: counted, they stopped the robot as "frozen" until the person
    was seen again (issue 40's network adversary); their joints' growing uncertainty
    bounds them instead."""
    rest = Operator().rest()
    tracker = Tracker()
    tracker.update(frame(rest), 0.0)
    nobody = np.full_like(rest, np.nan)
    lost = np.zeros(len(rest), dtype=np.int8)
    seen = [tracker.update(frame(nobody, lost), k / 30) for k in range(1, 30)]
    assert [p.identical for p in seen] == [0] * 29
    radius = [float(p.joint_radius[HAND]) for p in seen]
    assert radius == sorted(radius) and radius[-1] > radius[0] + 1.0  # 2 m/s for ~1 s


def test_velocity_filter_lag_and_noise_on_a_known_motion():
    """A hand moving at 1 m/s, seen at 30 Hz with 2 mm noise: the α-β estimate converges
    within 0.3 s and its noise stays below 0.1 m/s (docs/safety.md has the full numbers)."""
    rng = np.random.default_rng(0)
    tracker = Tracker()
    v = np.array([1.0, 0.0, 0.0])
    est = []
    for k in range(90):
        t = k / 30
        joints = Operator().rest()
        joints[HAND] += v * max(t - 1.0, 0.0)  # starts moving at t = 1 s
        joints += rng.normal(0.0, 0.002, joints.shape)
        est.append(tracker.update(frame(joints), t).joint_velocity[HAND])
    est = np.array(est)
    t = np.arange(90) / 30
    assert np.abs(est[t < 1.0]).max() < 0.3  # still: noise only
    settled = t > 1.3
    np.testing.assert_allclose(est[settled].mean(axis=0), v, atol=0.05)
    assert est[settled, 0].std() < 0.1
    # the part takes its fastest joint's velocity
    joint_v = np.zeros((25, 3))
    joint_v[HAND] = v
    joint_v[WRIST] = 0.5 * v
    parts = KinectHuman().part_joints()
    k = KinectHuman().part_names.index("right_hand")
    np.testing.assert_array_equal(part_velocities([joint_v], parts)[k], v)


def test_fingers_widen_the_hand_capsule_by_how_far_they_stick_out():
    joints = Operator().rest()
    wrist, hand = joints[WRIST], joints[HAND]
    axis = (hand - wrist) / np.linalg.norm(hand - wrist)
    joints[int(J.HandTipRight)] = hand + 0.12 * axis  # beyond the hand along its axis
    joints[int(J.ThumbRight)] = hand  # inside
    human = KinectHuman()
    geo = human.geometry(joints)
    k = human.part_names.index("right_hand")
    assert geo.reach_margin[k] == pytest.approx(0.12 - 0.05)  # capsule radius 0.05 m
    joints[int(J.HandTipRight)] = np.nan  # a lost finger widens nothing
    assert human.geometry(joints).reach_margin[k] == pytest.approx(0.0)


class Still:
    def frame_at(self, t):
        return Operator().rest(), np.full(25, 2)


def test_camera_latency_noise_and_faults():
    cfg = CameraConfig(latency_s=0.06, noise_m=0.002, seed=1)
    camera = Camera(Still(), cfg)
    for t in (0.0, 0.1, 0.5, 1.234):
        f, captured = camera.frame_at(t)
        assert captured == pytest.approx(np.floor((t - 0.06) * 30 + 1e-9) / 30)
    noise = np.array(
        [camera.frame_at(k / 30 + 0.07)[0].joints - Operator().rest() for k in range(300)]
    )
    assert noise.std() == pytest.approx(0.002, rel=0.05)
    faults = (
        CameraFault("freeze", 1.0, 1.5),
        CameraFault("lost", 2.0, 2.5, (HAND,)),
        CameraFault("gap", 3.0, 3.5),
    )
    camera = Camera(Still(), CameraConfig(latency_s=0.0, faults=faults))
    frozen = [camera.frame_at(1.0 + k / 30) for k in range(10)]
    assert all(np.array_equal(f.joints, frozen[0][0].joints) for f, _ in frozen)
    assert frozen[-1][1] > frozen[0][1]  # time stamps advance
    f, _ = camera.frame_at(2.2)
    assert np.isnan(f.joints[HAND]).all() and f.state[HAND] == TrackingState.NotTracked
    _, captured = camera.frame_at(3.4)
    assert captured < 3.0  # nothing delivered in the gap


def test_a_stop_is_a_ramp_after_the_reaction_time():
    dt = 0.002
    limits = (("A1", 8.0), ("A2", 8.0))
    arm = ArmResponse(BrakingConfig(0.004, limits), ("A1", "A2"), dt)
    dq = np.array([0.4, -0.2])
    for _ in range(200):
        arm(dq)
    np.testing.assert_allclose(arm.dq, dq)
    out = np.array([arm(np.zeros(2)).copy() for _ in range(40)])
    np.testing.assert_allclose(out[:2], [dq, dq])  # 2 ticks of reaction
    # then both joints fall together (the path is kept), A1 at 8 rad/s²: zero after 0.05 s
    np.testing.assert_allclose(out[2], dq * (1 - 8 * dt / 0.4))
    assert stop_time(dq, [8.0, 8.0]) == pytest.approx(0.05)
    first_zero = int(np.flatnonzero(~out.any(axis=1))[0])
    assert first_zero == 2 + 24  # 0.05 s / 2 ms = 25 steps, the 25th lands on zero


def test_tracked_geometry_is_geometry_and_part_velocities_in_one_call():
    """The perceiver's one compiled call (capsules, margins, part velocities) against the
    separate calls it replaced, on random frames with lost, inferred and NaN joints."""
    rng = np.random.default_rng(7)
    human = KinectHuman()
    parts = human.part_joints()
    for _ in range(200):
        joints = Operator().rest() + rng.normal(0.0, 0.05, (25, 3))
        state = rng.choice([0, 1, 2], size=25, p=[0.15, 0.15, 0.7]).astype(np.int8)
        joints[rng.random(25) < 0.1] = np.nan
        frame = HumanFrame.check(joints, state)
        radius, velocity = rng.random(25) * 0.2, rng.normal(0.0, 1.0, (25, 3))
        geo, part_v = human.tracked_geometry(frame, radius, velocity)
        ref = human.geometry(frame, joint_radius=radius)
        for name in ("points", "point_valid", "segments", "segment_valid", "part_margin",
                     "reach_margin"):  # fmt: skip
            np.testing.assert_array_equal(getattr(geo, name), getattr(ref, name), err_msg=name)
        np.testing.assert_array_equal(part_v, part_velocities([velocity], parts))
        # and against brute force: each part's largest radius and fastest joint
        np.testing.assert_array_equal(geo.part_margin, [radius[row].max() for row in parts])
        fastest = [np.flatnonzero(row)[np.argmax(np.linalg.norm(velocity[row], axis=1))]
                   for row in parts]  # fmt: skip
        np.testing.assert_array_equal(part_v, velocity[fastest])
