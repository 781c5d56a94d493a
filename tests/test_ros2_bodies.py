"""The drivers' messages as per-sensor frames, and every bad message counted, not raised."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("rosbags")

from ros2_standin import (
    make,
    marker,
    marker_array,
    objects_stamped,
    to_ros_axes,
    zed_object,
)

from qpavoid.core.errors import InputError
from qpavoid.sensing.ros2_bodies import BodyTopic, driver_of
from qpavoid.sensing.ros2_types import from_cdr, to_cdr

T = 1_700_000_000.25


def _k4a_body(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (32, 3)) + np.array([0.0, 0.0, 2.0])


def test_a_marker_array_is_one_body_in_the_depth_camera_frame():
    joints = _k4a_body()
    joints[5] = np.nan  # no marker for joint 5
    topic = BodyTopic("femto", "k4abt")
    # through the wire and back: the bytes the driver sends
    msg = from_cdr(
        "humble",
        to_cdr("humble", marker_array(T, {7: joints}), "visualization_msgs/msg/MarkerArray"),
        "visualization_msgs/msg/MarkerArray",
    )
    frame = topic.read(msg)
    assert frame is not None and frame.t == pytest.approx(T, abs=1e-9)
    (body,) = frame.bodies
    assert (body.sensor, body.body, body.format) == ("femto", 0, "k4abt")  # id 7 -> slot 0
    np.testing.assert_array_equal(body.joints[np.arange(32) != 5], joints[np.arange(32) != 5])
    assert np.isnan(body.joints[5]).all() and body.state[5] == 0
    assert (body.state[np.arange(32) != 5] == 2).all()


def test_two_bodies_keep_their_numbers_and_an_empty_array_is_nobody():
    topic = BodyTopic("femto", "k4abt")
    a = topic.read(marker_array(T, {12: _k4a_body(1), 3: _k4a_body(2)}))
    b = topic.read(marker_array(T + 0.033, {3: _k4a_body(2), 12: _k4a_body(1)}))
    ids_a = {round(f.joints[0, 0], 9): f.body for f in a.bodies}
    ids_b = {round(f.joints[0, 0], 9): f.body for f in b.bodies}
    assert ids_a == ids_b and sorted(ids_a.values()) == [0, 1]
    empty = topic.read(make("visualization_msgs/msg/MarkerArray", markers=[]))
    assert empty is not None and empty.t is None and empty.bodies == ()
    assert topic.taken == 3 and not topic.drops


def test_zed_keypoints_turn_from_ros_axes_into_the_format_frame():
    """ROS (x forward, y left, z up) to the ZED format's (x right, y down, z forward):
    a keypoint 2 m ahead, 0.5 m left and 0.3 m up is at (-0.5, -0.3, 2.0)."""
    n = 34
    ros = np.tile([2.0, 0.5, 0.3], (n, 1)).astype(np.float32)
    ros[3] = np.nan  # not detected
    topic = BodyTopic("zed", "zed_body_34")
    frame = topic.read(objects_stamped(T, [zed_object(41, ros, body_format=1, tracking=2)]))
    (body,) = frame.bodies
    np.testing.assert_allclose(body.joints[0], [-0.5, -0.3, 2.0], atol=1e-7)
    assert body.state[3] == 0 and np.isnan(body.joints[3]).all()
    assert (np.delete(body.state, 3) == 1).all()  # SEARCHING: inferred
    assert to_ros_axes("zed_body_34", body.joints[:1]) == pytest.approx(ros[:1])
    nobody = topic.read(objects_stamped(T + 0.1, []))
    assert nobody.t == pytest.approx(T + 0.1) and nobody.bodies == ()


def _count(topic, message):
    before = dict(topic.drops)
    assert topic.read(message) is None
    return {k: v - before.get(k, 0) for k, v in topic.drops.items() if v != before.get(k, 0)}


def test_every_bad_marker_array_is_dropped_by_its_reason():
    topic = BodyTopic("femto", "k4abt")
    body = _k4a_body()

    def arr(*markers):
        return make("visualization_msgs/msg/MarkerArray", markers=list(markers))

    nan = body.copy()
    nan[2, 1] = np.nan
    inf = body.copy()
    inf[2, 1] = np.inf
    cases = {
        "non_finite": [arr(marker(T, 0, [np.nan, 0, 1])), arr(marker(T, 0, [np.inf, 0, 1]))],
        "bad_marker": [arr(marker(T, -1, [0, 0, 1]))],
        "joint_beyond_format": [arr(marker(T, 40, [0, 0, 1]))],
        "duplicate_joint": [arr(marker(T, 3, [0, 0, 1]), marker(T, 3, [0, 0, 1]))],
        "mixed_headers": [arr(marker(T, 0, [0, 0, 1]), marker(T + 1, 1, [0, 0, 1]))],
        "outside_range": [arr(marker(T, 0, [0, 0, 1000.0]))],
        "too_many_bodies": [arr(*[marker(T, b * 100, [0, 0, 1]) for b in range(11)])],
        "unreadable": [
            make(
                "sensor_msgs/msg/JointState",
                header=None,
                name=[],
                position=[],
                velocity=[],
                effort=[],
            )
        ],
    }
    for reason, messages in cases.items():
        for m in messages:
            assert _count(topic, m) == {reason: 1}, reason
    bad_stamp = arr(marker(T, 0, [0, 0, 1]))
    bad_stamp.markers[0].header.stamp.nanosec = 2_000_000_000
    assert _count(topic, bad_stamp) == {"bad_stamp": 1}
    assert topic.read(arr(marker(T, 0, [0, 0, 1]))) is not None
    assert _count(topic, arr(marker(T, 0, [0, 0, 1]))) == {"out_of_order_or_duplicate": 1}
    assert topic.taken == 1


class _Untouchable(list):
    """A sequence whose elements must not be looked at (only its length)."""

    def __getitem__(self, i):
        raise AssertionError("an element was read")

    def __iter__(self):
        raise AssertionError("the markers were iterated")


def test_ten_thousand_markers_are_refused_from_their_count_alone():
    topic = BodyTopic("femto", "k4abt")
    flood = make("visualization_msgs/msg/MarkerArray", markers=[])
    flood.markers = _Untouchable([None] * 10_000)
    start = time.perf_counter()
    assert topic.read(flood) is None
    assert time.perf_counter() - start < 0.01
    assert topic.drops == {"too_many_markers": 1}
    objects = objects_stamped(T, [])
    objects.objects = _Untouchable([None] * 11)
    zed = BodyTopic("zed", "zed_body_38")
    assert zed.read(objects) is None and zed.drops == {"too_many_bodies": 1}


def test_bad_zed_objects_are_dropped_by_their_reason():
    topic = BodyTopic("zed", "zed_body_34")
    good = np.zeros((34, 3), np.float32) + np.float32([2.0, 0.0, 0.0])
    inf = good.copy()
    inf[4, 0] = np.inf
    assert _count(topic, objects_stamped(T, [zed_object(1, good, body_format=2)])) == {
        "wrong_format": 1
    }
    assert _count(topic, objects_stamped(T, [zed_object(1, inf, 1)])) == {"non_finite": 1}
    two = objects_stamped(T, [zed_object(1, good, 1), zed_object(1, good, 1)])
    assert _count(topic, two) == {"duplicate_body": 1}
    off = topic.read(objects_stamped(T, [zed_object(1, good, 1, tracking=0)]))
    assert off is not None and off.bodies == ()  # OFF: not a valid object


def test_a_format_no_driver_publishes_is_refused():
    assert driver_of("zed_body_38").message == "zed_msgs/msg/ObjectsStamped"
    with pytest.raises(InputError, match="no ROS 2 driver publishes"):
        BodyTopic("kinect", "kinect_v2")
