"""Distance tables against independent references.

* spheres: a plain double loop over every robot point and human point;
* capsules (the compiled pass and coal's alike): an analytic segment-segment distance
  written here (critical point of the squared distance plus the four endpoint-to-segment
  distances), to 1e-6 m.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_q

import qpavoid
from qpavoid.arm.model import Kinematics
from qpavoid.distance.methods import (
    CapsuleDistance,
    CoalCapsuleDistance,
    SphereDistance,
    axis_rotations,
)
from qpavoid.human.body import HumanGeometry
from qpavoid.human.kinect_v2 import JointType, TrackingState
from qpavoid.human.posture import random_posture

# ----------------------------------------------------------------------------- references


def point_segment(p, a, b):
    ab = b - a
    L2 = ab @ ab
    t = 0.0 if L2 == 0 else np.clip((p - a) @ ab / L2, 0.0, 1.0)
    return np.linalg.norm(p - (a + t * ab))


def segment_segment(a, b, c, d):
    """Exact distance between segments [a, b] and [c, d] (any may have zero length)."""
    cands = [
        point_segment(a, c, d),
        point_segment(b, c, d),
        point_segment(c, a, b),
        point_segment(d, a, b),
    ]
    u, v, w = b - a, d - c, a - c
    A, B, C = u @ u, u @ v, v @ v
    den = A * C - B * B
    if A > 0 and C > 0 and den > 1e-14 * A * C:
        s = (B * (v @ w) - C * (u @ w)) / den
        t = (A * (v @ w) - B * (u @ w)) / den
        if 0 <= s <= 1 and 0 <= t <= 1:
            cands.append(np.linalg.norm(w + s * u - t * v))
    return min(cands)


def sphere_reference(robot, kin, human, geo):
    """Double loop: (distance, robot point index, human point index) per set x part."""
    S, K = len(robot.sets), len(human.parts)
    dist = np.full((S, K), np.inf)
    rp = np.full((S, K), -1)
    hp = np.full((S, K), -1)
    for i, rset in enumerate(robot.sets):
        for j, part in enumerate(human.parts):
            for p in rset.points:
                for m in np.flatnonzero(human.point_part[:, j]):
                    if not geo.point_valid[m]:
                        continue
                    d = (
                        np.linalg.norm(kin.points[p] - geo.points[m])
                        - rset.sphere_radius_m
                        - part.sphere_radius_m
                    )
                    if d < dist[i, j]:
                        dist[i, j], rp[i, j], hp[i, j] = d, p, m
    return dist, rp, hp


# ----------------------------------------------------------------------------- spheres


def test_spheres_match_double_loop(robot, human):
    rng = np.random.default_rng(0)
    spheres = SphereDistance(robot, human)
    for _ in range(300):
        q = random_q(rng, robot)
        kin = robot.kinematics(q, jacobians=False)
        joints = random_posture(rng, kin.points, spread_m=0.15)
        state = np.where(rng.random(25) < 0.1, 0, 2)  # a few joints lost
        geo = human.geometry(joints, state)
        t = spheres(kin, geo)
        dist, rp, hp = sphere_reference(robot, kin, human, geo)
        np.testing.assert_allclose(t.distance, dist, atol=1e-12)
        seen = np.isfinite(dist)
        assert np.array_equal(t.robot_index[seen], rp[seen])
        assert np.array_equal(t.human_index[seen], hp[seen])
        # Witness points and direction are consistent with the distance.
        diff = kin.points[rp[seen]] - geo.points[hp[seen]]
        np.testing.assert_allclose(
            t.vector[seen], diff / np.linalg.norm(diff, axis=1)[:, None], atol=1e-12
        )
        np.testing.assert_allclose(
            np.einsum("nk,nk->n", t.robot_point[seen] - t.human_point[seen], t.vector[seen]),
            t.distance[seen],
            atol=1e-12,
        )
        assert not np.any(np.isnan(t.distance))


def test_sphere_hand_computed(robot, human):
    """One hand point straight above the flange: d = gap - r_R - r_hand."""
    q = np.zeros(6)
    joints = np.full((25, 3), np.nan)
    joints[JointType.WristRight] = [0, 0, 1.306 + 0.40]
    joints[JointType.HandRight] = [0, 0, 1.306 + 0.30]
    t = qpavoid.sphere_distances(robot, q, human, joints)
    j = human.part_names.index("right_hand")
    r_ee, r_hand = robot.sets[2].sphere_radius_m, human.parts[j].sphere_radius_m
    assert t.distance[2, j] == pytest.approx(0.30 - r_ee - r_hand, abs=1e-12)
    np.testing.assert_allclose(t.vector[2, j], [0, 0, -1], atol=1e-12)  # human above: push down
    assert t.robot_index[2, j] == 8
    # Only the right hand and the forearm (through its wrist) are seen; the rest is +inf.
    seen = np.isfinite(t.distance)
    assert seen[:, j].all() and seen[:, j - 1].all() and seen.sum() == 6
    assert np.all(t.vector[~seen] == 0)


# ----------------------------------------------------------------------------- capsules


def _geometry(human, segments):
    segments = np.asarray(segments, dtype=float)
    return HumanGeometry(
        np.zeros((human.n_points, 3)),
        np.ones(human.n_points, dtype=bool),
        segments,
        np.ones(len(segments), dtype=bool),
    )


def _kinematics(segments):
    segments = np.asarray(segments, dtype=float)
    return Kinematics(np.zeros(6), np.zeros((9, 3)), None, segments, None, np.eye(4), None)


def _check_capsules(robot, human, table, rseg, hseg, widen=None):
    # widen: (K,) what the geometry adds to each human capsule (uncertainty, fingers), m.
    r_human = human.capsule_radii + (0.0 if widen is None else widen)
    for i in range(len(rseg)):
        for j in range(len(hseg)):
            ref = segment_segment(*rseg[i], *hseg[j]) - robot.capsule_radii[i] - r_human[j]
            assert table.distance[i, j] == pytest.approx(ref, abs=1e-6), (i, j)
            if ref > 1e-6:
                # Witness points on the surfaces, the vector along their difference.
                rp, hp = table.robot_point[i, j], table.human_point[i, j]
                assert point_segment(rp, *rseg[i]) == pytest.approx(
                    robot.capsule_radii[i], abs=1e-6
                )
                assert point_segment(hp, *hseg[j]) == pytest.approx(r_human[j], abs=1e-6)
                # robot_s: where on the axis the robot witness point's Jacobian is taken
                s = table.robot_s[i, j]
                on_axis = (1 - s) * rseg[i][0] + s * rseg[i][1]
                assert np.linalg.norm(rp - on_axis) == pytest.approx(
                    robot.capsule_radii[i], abs=1e-6
                )
                np.testing.assert_allclose(rp - hp, ref * table.vector[i, j], atol=1e-6)
            assert np.linalg.norm(table.vector[i, j]) == pytest.approx(1.0)


@pytest.mark.parametrize("method", [CapsuleDistance, CoalCapsuleDistance])
def test_capsules_random_against_analytic(robot, human, method):
    rng = np.random.default_rng(3)
    caps = method(robot, human)
    for _ in range(200):
        q = random_q(rng, robot)
        kin = robot.kinematics(q, jacobians=False)
        geo = human.geometry(random_posture(rng, kin.points, spread_m=0.15))
        t = caps(kin, geo)
        widen = geo.part_margin + geo.reach_margin
        _check_capsules(robot, human, t, kin.segments, geo.segments, widen)
        s = t.robot_s
        assert np.all((s >= 0) & (s <= 1))


@pytest.mark.parametrize(
    "name, hseg",
    [
        ("parallel", [[0.3, 0.0, 0.0], [0.3, 0.0, 0.5]]),
        ("parallel_offset", [[0.4, 0.1, 0.6], [0.4, 0.1, 1.5]]),
        ("antiparallel", [[0.0, 0.25, 0.8], [0.0, 0.25, 0.2]]),
        ("crossing", [[-0.5, 0.0, 0.4], [0.5, 0.0, 0.4]]),  # through the robot axis
        ("skew", [[-0.5, 0.3, 0.4], [0.5, 0.2, 0.9]]),
        ("touching", [[0.0, 0.17, -0.5], [0.0, 0.17, 0.5]]),  # gap 0.17 = 0.07 (L1) + 0.10 (head)
        ("degenerate_human", [[0.2, 0.2, 0.3], [0.2, 0.2, 0.3]]),
        ("beyond_end", [[0.0, 0.0, 1.2], [0.0, 0.0, 1.6]]),  # collinear, past the end
        ("along_minus_z", [[0.3, 0.0, 1.0], [0.3, 0.0, 0.2]]),
    ],
)
@pytest.mark.parametrize("method", [CapsuleDistance, CoalCapsuleDistance])
def test_capsules_special_cases(robot, human, name, hseg, method):
    caps = method(robot, human)
    rseg = np.array(
        [
            [[0, 0, 0.0], [0, 0, 1.0]],  # vertical
            [[0, 0, 0.0], [0, 0, 0.0]],  # degenerate robot capsule (a sphere)
            [[0.1, -0.2, 0.5], [0.4, 0.3, 0.5]],
        ]
    )
    hsegs = np.repeat(np.asarray(hseg, dtype=float)[None], len(human.parts), axis=0)
    hsegs[1:] += np.linspace(0, 0.3, len(human.parts) - 1)[:, None, None] * [1, -1, 0.5]
    t = caps(_kinematics(rseg), _geometry(human, hsegs))
    _check_capsules(robot, human, t, rseg, hsegs)
    if name == "touching":
        assert t.distance[0, 0] == pytest.approx(0.0, abs=1e-9)


def test_capsule_one_usable_joint_is_a_sphere(robot, human):
    """A forearm whose wrist is lost shrinks to a sphere at the elbow."""
    q = np.zeros(6)
    joints = np.full((25, 3), np.nan)
    joints[JointType.ElbowRight] = [0.3, 0.0, 0.9]
    joints[JointType.WristRight] = [0.1, 0.0, 0.9]
    state = np.full(25, TrackingState.Tracked)
    state[JointType.WristRight] = TrackingState.NotTracked
    t = qpavoid.capsule_distances(robot, q, human, joints, state)
    j = human.part_names.index("right_forearm")
    r_l2 = robot.capsule_radii[1]
    assert t.distance[1, j] == pytest.approx(0.3 - r_l2 - human.parts[j].capsule_radius_m, abs=1e-9)
    np.testing.assert_allclose(t.vector[1, j], [-1, 0, 0], atol=1e-9)
    # The upper arm has its elbow only, the hand nothing at all.
    assert np.isfinite(t.distance[:, human.part_names.index("right_upper_arm")]).all()
    assert np.isinf(t.distance[:, human.part_names.index("right_hand")]).all()
    assert not np.any(np.isnan(t.distance))


# ----------------------------------------------------------------------------- both


@pytest.mark.parametrize("method", [qpavoid.sphere_distances, qpavoid.capsule_distances])
def test_untracked_and_nan_joints_are_left_out(robot, human, method):
    rng = np.random.default_rng(5)
    q = random_q(rng, robot)
    joints = random_posture(rng, robot.control_points(q))
    full = method(robot, q, human, joints)
    assert np.isfinite(full.distance).all()
    # Right hand lost two ways: NaN coordinates, or state NotTracked.
    lost = [JointType.WristRight, JointType.HandRight]
    j_nan = joints.copy()
    j_nan[lost] = np.nan
    state = np.full(25, 2)
    state[lost] = 0
    hand = human.part_names.index("right_hand")
    for t in (method(robot, q, human, j_nan), method(robot, q, human, joints, state)):
        assert np.isinf(t.distance[:, hand]).all()
        assert not np.any(np.isnan(t.distance))
        keep = [k for k, n in enumerate(human.part_names) if not n.startswith("right_")]
        np.testing.assert_allclose(t.distance[:, keep], full.distance[:, keep])
    # Everything lost: all +inf, never NaN.
    t = method(robot, q, human, np.full((25, 3), np.nan))
    assert np.isinf(t.distance).all() and not np.any(np.isnan(t.vector))


@pytest.mark.parametrize("method", [qpavoid.sphere_distances, qpavoid.capsule_distances])
def test_table_shapes_and_labels(robot, human, method):
    from qpavoid.human.posture import Operator

    t = method(robot, np.zeros(6), human, Operator().rest())
    assert t.distance.shape == (3, 8) and t.vector.shape == (3, 8, 3)
    assert t.robot_point.shape == (3, 8, 3) and t.human_point.shape == (3, 8, 3)
    assert t.set_names == ("L1", "L2", "EE")
    assert t.part_names == (
        "head",
        "trunk",
        "left_upper_arm",
        "left_forearm",
        "left_hand",
        "right_upper_arm",
        "right_forearm",
        "right_hand",
    )
    np.testing.assert_allclose(t.min_per_set(), t.distance.min(axis=1))


def test_bad_human_input(robot, human):
    q = np.zeros(6)
    with pytest.raises(qpavoid.InputError, match=r"joints .* shape \(25, 3\), got \(21, 3\)"):
        qpavoid.sphere_distances(robot, q, human, np.zeros((21, 3)))
    with pytest.raises(qpavoid.InputError, match=r"state .* shape \(25,\)"):
        qpavoid.sphere_distances(robot, q, human, np.zeros((25, 3)), state=np.zeros(24))
    bad = np.full(25, 2)
    bad[11] = 5
    with pytest.raises(qpavoid.InputError, match=r"state\[11\] \(HandRight\) is 5"):
        qpavoid.capsule_distances(robot, q, human, np.zeros((25, 3)), state=bad)
    j = np.zeros((25, 3))
    j[3, 1] = np.inf
    with pytest.raises(qpavoid.InputError, match="infinite coordinate at joint Head"):
        qpavoid.capsule_distances(robot, q, human, j)
    with pytest.raises(qpavoid.InputError, match="unknown distance method 'boxes'"):
        qpavoid.distance_method("boxes", robot, human)


def test_axis_rotations_take_z_onto_each_axis():
    """Random directions, the antiparallel one and a zero-length axis (a sphere)."""
    rng = np.random.default_rng(0)
    u = rng.normal(size=(50, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u = np.vstack([u, [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]])
    R = axis_rotations(u)
    np.testing.assert_allclose(R @ np.array([0.0, 0.0, 1.0]), u, atol=1e-12)
    np.testing.assert_allclose(
        R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(R), 1.0)
    np.testing.assert_array_equal(axis_rotations(np.zeros((1, 3)))[0], np.eye(3))


@pytest.mark.parametrize("method", [CapsuleDistance, CoalCapsuleDistance, SphereDistance])
def test_closest_of_several_people_is_each_pair_s_closest_person(robot, human, method):
    """``closest`` (coal's capsules: people tried in order of a bounding-sphere bound, coal
    skipped for the rest; the compiled ones: every person in one pass) equals the minimum
    over every person's own table, entry by entry."""
    rng = np.random.default_rng(7)
    table_of, many = method(robot, human), method(robot, human)
    for _ in range(40):
        kin = robot.kinematics(random_q(rng, robot), jacobians=False)
        geos = [
            human.geometry(random_posture(rng, kin.points, spread_m=float(rng.uniform(0.1, 1.5))))
            for _ in range(int(rng.integers(1, 7)))
        ]
        own = [table_of(kin, g) for g in geos]
        table, who = many.closest(kin, geos)
        D = np.stack([t.distance for t in own])
        np.testing.assert_allclose(table.distance, D.min(axis=0), atol=1e-9)
        picked = np.take_along_axis(D, who[None], axis=0)[0]
        np.testing.assert_allclose(picked, table.distance, atol=1e-9)  # who is a closest one
        for i, j in zip(*np.nonzero(np.isfinite(table.distance)), strict=True):
            np.testing.assert_allclose(table.vector[i, j], own[who[i, j]].vector[i, j], atol=1e-6)
            np.testing.assert_allclose(
                table.robot_point[i, j], own[who[i, j]].robot_point[i, j], atol=1e-6
            )


@pytest.mark.parametrize("method", [CapsuleDistance, SphereDistance])
def test_closest_of_nobody_is_a_clear_error(robot, human, method):
    kin = robot.kinematics(robot.neutral(), jacobians=False)
    with pytest.raises(qpavoid.InputError, match="no person"):
        method(robot, human).closest(kin, [])
