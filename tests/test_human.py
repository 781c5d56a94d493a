"""The upper-body model: 21 points in 8 parts, usability of joints."""

from __future__ import annotations

import numpy as np

from qpavoid.human.kinect_v2 import JointType as J
from qpavoid.human.posture import Operator


def test_points_and_parts(human):
    joints = Operator().rest()
    P = human.points(joints)
    assert P.shape == (21, 3)
    assert human.part_names[:2] == ("head", "trunk")
    # 13 joints, then the 8 mid-points in part order.
    order = [
        J.SpineBase,
        J.SpineMid,
        J.SpineShoulder,
        J.Neck,
        J.Head,
        J.ShoulderLeft,
        J.ElbowLeft,
        J.WristLeft,
        J.HandLeft,
        J.ShoulderRight,
        J.ElbowRight,
        J.WristRight,
        J.HandRight,
    ]
    np.testing.assert_allclose(P[:13], joints[order])
    np.testing.assert_allclose(P[13], (joints[J.Neck] + joints[J.Head]) / 2)
    np.testing.assert_allclose(P[14], (joints[J.SpineShoulder] + joints[J.SpineMid]) / 2)
    np.testing.assert_allclose(P[20], (joints[J.WristRight] + joints[J.HandRight]) / 2)
    assert human.point_part.sum(axis=0).tolist() == [3, 4, 3, 3, 3, 3, 3, 3]
    assert human.point_part.any(axis=1).all()  # every point belongs to a part


def test_head_larger_than_hand(human):
    r = dict(zip(human.part_names, human.sphere_radii))
    assert r["trunk"] > r["head"] > r["right_upper_arm"] > r["right_hand"]


def test_unusable_points(human):
    joints = Operator().rest()
    state = np.full(25, 2)
    state[J.ElbowLeft] = 0
    joints[J.Head] = np.nan
    geo = human.geometry(joints, state)
    # Head (4), ElbowLeft (6), and the mid-points that use them: head (13), left upper arm
    # (15), left forearm (16).
    assert set(np.flatnonzero(~geo.point_valid)) == {4, 6, 13, 15, 16}
    assert np.isnan(geo.points[~geo.point_valid]).all()
    # Capsules: the head shrinks to the neck, the left upper arm to the shoulder.
    np.testing.assert_allclose(geo.segments[0], [joints[J.Neck], joints[J.Neck]])
    np.testing.assert_allclose(geo.segments[2], [joints[J.ShoulderLeft]] * 2)
    assert geo.segment_valid.all()
