"""The body model as data: the Kinect v2 body file is the paper's model, a wrong body file
is refused with its path and key, and another skeleton format works through the body
model, the tracker, the fusion, the run log, the receiver's slots, the file bounds and the
views with nothing but its two files."""

from __future__ import annotations

import multiprocessing
from pathlib import Path

import numpy as np
import pytest

from qpavoid.core.errors import InputError, SkeletonFormatError
from qpavoid.core.file_bounds import row_values
from qpavoid.fusion.fuser import Fuser
from qpavoid.human.body import (
    KINECT_V2_BODY_FILE,
    KINECT_V2_BODY_PARTS,
    UPPER_BODY,
    BodyModel,
    KinectHuman,
)
from qpavoid.human.body_parts import BodyPart
from qpavoid.human.frames import HumanFrame
from qpavoid.human.kinect_v2 import KINECT_V2, KINECT_V2_FILE, JointType
from qpavoid.human.posture import Operator
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.laws.ssm import SSMConfig
from qpavoid.loop.run_log import new_log
from qpavoid.output.live_view import _one_tick
from qpavoid.output.view_data import checked_log, replay_data
from qpavoid.perception.tracker import Tracker
from qpavoid.sensing.calibration import Calibration, SensorCalibration
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.receiver import SlotTable

J = JointType
BODY_TEXT = KINECT_V2_BODY_FILE.read_text()


def test_kinect_human_is_the_body_file_on_the_kinect_v2_format():
    human, loaded = KinectHuman(), BodyModel.load(KINECT_V2_BODY_FILE)
    assert loaded.skeleton == KINECT_V2 and loaded.parts == human.parts
    assert loaded.point_order == human.point_order
    np.testing.assert_array_equal(loaded.joint_ids, human.joint_ids)
    np.testing.assert_array_equal(loaded.point_part, human.point_part)
    rng = np.random.default_rng(0)
    for _ in range(20):
        joints = Operator().rest() + rng.normal(0.0, 0.05, (25, 3))
        state = rng.integers(0, 3, 25).astype(np.int8)
        a, b = human.geometry(joints, state), loaded.geometry(joints, state)
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.reach_margin, b.reach_margin)


def test_the_paper_model_by_hand():
    human = KinectHuman()
    assert human.part_names == (
        "head",
        "trunk",
        "left_upper_arm",
        "left_forearm",
        "left_hand",
        "right_upper_arm",
        "right_forearm",
        "right_hand",
    )
    assert human.n_points == 21 and len(human.joint_ids) == 13
    np.testing.assert_allclose(human.sphere_radii, [0.11, 0.17, 0.09, 0.08, 0.06, 0.09, 0.08, 0.06])
    np.testing.assert_allclose(
        human.capsule_radii, [0.10, 0.15, 0.055, 0.045, 0.05, 0.055, 0.045, 0.05]
    )
    members = human.part_joints()
    assert set(np.flatnonzero(members[7])) == {
        J.WristRight,
        J.HandRight,
        J.HandTipRight,
        J.ThumbRight,
    }
    assert set(np.flatnonzero(members[1])) == {J.SpineShoulder, J.SpineMid, J.SpineBase}
    # the head and the trunk move with the body: speed and separation's default
    assert KINECT_V2_BODY_PARTS == human.body_parts == ("head", "trunk")
    assert SSMConfig().body_parts == ("head", "trunk")
    assert SSMConfig().sensing_uncertainty_m == KINECT_V2.sensor.tracked_uncertainty_m == 0.03


def test_parts_may_name_their_joints_by_sdk_index_as_before():
    by_index = tuple(
        BodyPart(
            p.name,
            tuple(J[j] for j in p.chain),
            (J[p.mid[0]], J[p.mid[1]]),
            p.sphere_radius_m,
            p.capsule_radius_m,
            tuple(J[j] for j in p.reach),
        )
        for p in UPPER_BODY
    )
    a, b = KinectHuman(by_index), KinectHuman()
    np.testing.assert_array_equal(a.joint_ids, b.joint_ids)
    joints = Operator().rest()
    np.testing.assert_array_equal(a.geometry(joints).segments, b.geometry(joints).segments)


def body_refused(tmp_path: Path, text: str, match: str) -> SkeletonFormatError:
    path = tmp_path / "kinect_v2_body.toml"
    path.write_text(text)
    (tmp_path / "kinect_v2.toml").write_text(KINECT_V2_FILE.read_text())
    with pytest.raises(SkeletonFormatError, match=match) as err:
        BodyModel.load(path)
    assert isinstance(err.value, InputError) and err.value.path == path
    assert str(err.value).startswith(str(path))
    return err.value


def test_a_wrong_body_file_is_refused_with_the_key(tmp_path):
    err = body_refused(
        tmp_path,
        BODY_TEXT.replace('"WristRight", "HandRight"]\nmid', '"WristRight", "Hand"]\nmid'),
        "right_hand.chain: 'Hand' is not a joint",
    )
    assert err.value == "Hand"
    err = body_refused(
        tmp_path,
        BODY_TEXT.replace('name = "trunk"', 'name = "head"'),
        "two parts are called 'head'",
    )
    err = body_refused(
        tmp_path,
        BODY_TEXT.replace("capsule_radius_m = 0.15", "capsule_radius_m = -0.15"),
        r"part 'trunk': parts\[1\].capsule_radius_m must be a number at least 0.01 and at most "
        r"1, m, got -0.15",
    )
    assert (err.name, err.value) == ("parts[1].capsule_radius_m", -0.15)
    err = body_refused(
        tmp_path,
        BODY_TEXT.replace("sphere_radius_m = 0.11\n", ""),
        r"parts\[0\] is missing key\(s\) sphere_radius_m",
    )
    err = body_refused(
        tmp_path,
        BODY_TEXT.replace("moves_with_body = true", "moves_with_body = 1", 1),
        "true or false",
    )
    err = body_refused(
        tmp_path,
        BODY_TEXT.replace("reach = [", "fingers = [", 1),
        r"parts\[4\] has unknown key\(s\) \['fingers'\]",
    )
    err = body_refused(
        tmp_path,
        BODY_TEXT.replace('format = "kinect_v2"', 'format = "kinect_v3"'),
        "its format 'kinect_v3': .*kinect_v3.toml: cannot read the file",
    )
    assert err.value == "kinect_v3"


def test_a_body_on_another_format_than_the_one_given_is_refused(tmp_path):
    path = tmp_path / "body.toml"
    path.write_text(BODY_TEXT.replace('format = "kinect_v2"', 'format = "stick"'))
    with pytest.raises(SkeletonFormatError, match="on the 'stick' format, not 'kinect_v2'"):
        BodyModel.load(path, KINECT_V2)


# A three-joint "stick" sensor: one arm, nothing else. Its two files are all it takes.
STICK = """
name = "stick"
title = "Stick"
joints = [
    { id = 0, name = "Shoulder" },
    { id = 1, name = "Elbow", parent = "Shoulder", max_bone_m = 0.4 },
    { id = 2, name = "Hand", parent = "Elbow", max_bone_m = 0.35 },
]
mirror_pairs = []
torso = ["Shoulder"]

[tracking_states]
not_tracked = 0
inferred = 1
tracked = 2

[sensor]
frame_rate_hz = 60.0
latency_s = 0.02
noise_m = 0.001
tracked_uncertainty_m = 0.01
field_of_view_deg = [90.0, 60.0]
range_m = [0.2, 3.0]
max_bodies = 2

[sensor.evidence]
latency_s = { basis = "estimate", note = "a test's camera" }
noise_m = { basis = "estimate", note = "a test's camera" }
tracked_uncertainty_m = { basis = "estimate", note = "a test's camera" }
"""
STICK_BODY = """
format = "stick"
points = ["Shoulder", "Elbow", "Hand"]

[[parts]]
name = "upper_arm"
chain = ["Shoulder", "Elbow"]
mid = ["Shoulder", "Elbow"]
sphere_radius_m = 0.09
capsule_radius_m = 0.05

[[parts]]
name = "forearm"
chain = ["Elbow", "Hand"]
mid = ["Elbow", "Hand"]
sphere_radius_m = 0.08
capsule_radius_m = 0.04
"""


@pytest.fixture
def stick(tmp_path):
    (tmp_path / "stick.toml").write_text(STICK)
    (tmp_path / "stick_body.toml").write_text(STICK_BODY)
    return BodyModel.load(tmp_path / "stick_body.toml")


def test_another_format_runs_through_the_body_model(stick):
    assert stick.skeleton.n_joints == 3 and stick.n_points == 5
    joints = np.array([[0.0, 0.0, 1.0], [0.3, 0.0, 1.0], [0.3, 0.3, 1.0]])
    geo = stick.geometry(joints)
    np.testing.assert_allclose(geo.points[3], [0.15, 0.0, 1.0])  # upper arm's mid-point
    np.testing.assert_allclose(geo.segments[1], joints[[1, 2]])
    with pytest.raises(InputError, match=r"joints \(Stick, m\) must have shape \(3, 3\)"):
        stick.geometry(np.zeros((25, 3)))


def test_another_format_runs_through_the_tracker_with_its_own_bones(stick):
    tracker = Tracker(skeleton=stick.skeleton)
    joints = np.array([[0.0, 0.0, 1.0], [0.3, 0.0, 1.0], [0.3, 0.3, 1.0]])
    tracker.update(HumanFrame.check(joints, skeleton=stick.skeleton), 0.0)
    lost = HumanFrame(joints.copy(), np.array([2, 2, 0], dtype=np.int8))
    p = tracker.update(lost, 1.0)
    # the hand, lost a second ago (2 m/s × 1 s), is within its bound of the tracked elbow,
    # 0.35 m (the file's, longer than the 0.3 m seen): placed there with that radius
    assert p.joint_radius[2] == pytest.approx(0.35)
    np.testing.assert_array_equal(p.frame.joints[2], joints[1])
    geometry, velocity = stick.tracked_geometry(p.frame, p.joint_radius, p.joint_velocity)
    np.testing.assert_allclose(geometry.part_margin, [0.0, 0.35])
    assert velocity.shape == (2, 3)


def test_another_format_runs_through_the_fusion(stick):
    sk = stick.skeleton
    cal = Calibration({"a": SensorCalibration("a", np.eye(4))})
    fuser = Fuser(cal, skeleton=sk)
    joints = np.array([[0.0, 1.0, 0.3], [0.3, 1.0, 0.3], [0.3, 0.7, 0.3]])
    for k in range(3):
        fuser.add(BodyFrame("a", 0, k / 60, joints + 0.01 * k, np.full(3, 2, dtype=np.int8)))
        fused = fuser.fuse(k / 60)
    (person,) = fused.people
    assert person.frame.joints.shape == (3, 3) and person.confidence.shape == (3,)
    # the torso centre is the format's one torso joint, α-β filtered (α 0.3, β 0.05) by
    # hand: at rest at z; then r = 0.01, p + 0.003, v = 0.05 r / Δt = 0.03 m/s; then
    # p̂ = p + 0.0035, r = 0.0165, p = p̂ + 0.3 r: 0.00845 from the first frame
    np.testing.assert_allclose(fuser.tracks[0].centre(), joints[0] + 0.00845, atol=1e-12)
    # the bones, first measured as they are, then averaged: all equal lengths here
    np.testing.assert_allclose(fuser.tracks[0].bone, [0.0, 0.3, 0.3])


def test_another_format_sizes_the_log_the_slots_the_file_bounds_and_the_view(stick, robot):
    sk = stick.skeleton
    log = new_log(4, robot, sk)
    assert log["joints"].shape == (4, 3, 3) and log["state"].shape == (4, 3)
    table = SlotTable.create(multiprocessing.get_context("spawn"), ["a", "b"], sk)
    assert (table.n_joints, table.max_bodies) == (3, 2)
    assert len(table.values) == 2 * 2 * (3 + 4 * 3)  # sensors × bodies × (head + frame)
    assert table.take() == []
    assert dict(row_values(sk.n_joints)) == {
        "t": 1,
        "sensor": 1,
        "body": 1,
        "joints": 9,
        "state": 3,
        "confidence": 3,
    }
    start = _one_tick(robot, sk)
    assert checked_log(start, robot, sk)["joints"].shape == (1, 3, 3)
    with pytest.raises(InputError, match=r"joints must be numbers of shape \(1, 25, 3\)"):
        checked_log(start, robot, KINECT_V2)
    data = replay_data(start, {"distance_method": "capsules"}, robot, human=stick)
    assert data["part_names"] == ["upper_arm", "forearm"] and data["human"].shape == (1, 2, 2, 3)


def test_a_format_file_in_the_formats_folder_loads_as_any_other():
    assert SkeletonFormat.load(KINECT_V2_FILE).group("arm_left")["hand"] == J.HandLeft
