"""The iiwa 14 model: published lengths, hand-worked poses, Jacobians by finite differences."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_q

import qpavoid
from qpavoid.core.errors import InputError, RobotDescriptionError

D = np.radians


def test_reduced_model_locks_a3(robot, robot7):
    assert robot.model.nv == 6 and robot.nq == 6
    assert robot.joint_names == ("A1", "A2", "A4", "A5", "A6", "A7")
    assert robot7.model.nv == 7 and "A3" in robot7.joint_names
    assert robot.locked == {"A3": 0.0} and robot7.locked == {}
    # Same points as the 7-joint model with A3 = 0, for random angles of the others.
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = random_q(rng, robot)
        q7 = np.insert(q, 2, 0.0)
        np.testing.assert_allclose(robot.control_points(q), robot7.control_points(q7), atol=1e-12)


def test_limits_are_the_published_ones(robot7):
    np.testing.assert_allclose(np.degrees(robot7.q_max), [170, 120, 170, 120, 170, 120, 175])
    np.testing.assert_allclose(np.degrees(robot7.q_min), [-170, -120, -170, -120, -170, -120, -175])
    np.testing.assert_allclose(np.degrees(robot7.dq_max), [85, 85, 100, 75, 130, 135, 135])


def test_lock_a3_at_other_angle_moves_the_forearm():
    r = qpavoid.load_robot("iiwa14", locked={"A3": np.pi / 2})
    # A3 = 90 deg turns the A4 axis from -y to +x: bending A4 by 90 deg swings z onto -y.
    q = np.array([0, 0, D(90), 0, 0, 0])
    P = r.control_points(q)
    np.testing.assert_allclose(P[7], [0, -0.40, 0.78], atol=1e-12)  # wrist centre A6


def test_zero_configuration_heights(robot):
    kin = robot.kinematics(np.zeros(6))
    assert kin.points.shape == (9, 3)
    np.testing.assert_allclose(kin.segments[0, 0], [0, 0, 0.36], atol=1e-12)  # shoulder A2
    np.testing.assert_allclose(kin.points[3], [0, 0, 0.78], atol=1e-12)  # elbow A4
    np.testing.assert_allclose(kin.points[7], [0, 0, 1.18], atol=1e-12)  # wrist A6
    np.testing.assert_allclose(kin.points[8], [0, 0, 1.306], atol=1e-12)  # flange
    # Mid-points: half-way between the joint centres of the paper's Sect. 4.
    z = [
        (0.36 + 0.5645) / 2,
        0.5645,
        (0.5645 + 0.78) / 2,
        0.78,
        (0.78 + 0.9645) / 2,
        0.9645,
        (0.9645 + 1.18) / 2,
        1.18,
        1.306,
    ]
    np.testing.assert_allclose(kin.points[:, 2], z, atol=1e-12)
    T = np.eye(4)
    T[2, 3] = 1.306
    np.testing.assert_allclose(kin.ee_placement, T, atol=1e-12)


@pytest.mark.parametrize(
    "q, elbow, wrist, flange",
    [
        (
            [0, 90, 0, 0, 0, 0],
            [0.42, 0, 0.36],
            [0.82, 0, 0.36],
            [0.946, 0, 0.36],
        ),  # A2 lays the arm along +x
        (
            [90, 90, 0, 0, 0, 0],
            [0, 0.42, 0.36],
            [0, 0.82, 0.36],
            [0, 0.946, 0.36],
        ),  # A1 turns it to +y
        (
            [0, 0, 90, 0, 0, 0],
            [0, 0, 0.78],
            [-0.40, 0, 0.78],
            [-0.526, 0, 0.78],
        ),  # A4 bends about -y
        ([0, 0, 0, 0, 90, 0], [0, 0, 0.78], [0, 0, 1.18], [0.126, 0, 1.18]),  # A6 bends the flange
        ([0, 0, 0, 90, 90, 0], [0, 0, 0.78], [0, 0, 1.18], [0, 0.126, 1.18]),  # A5 turns that bend
    ],
)
def test_hand_worked_configurations(robot, q, elbow, wrist, flange):
    P = robot.control_points(D(q))
    np.testing.assert_allclose(P[3], elbow, atol=1e-12)
    np.testing.assert_allclose(P[7], wrist, atol=1e-12)
    np.testing.assert_allclose(P[8], flange, atol=1e-12)


def test_paper_initial_pose(robot):
    """The reading notes' closed-form IK solution reaches the paper's initial pose."""
    A_in = np.array(
        [
            [0.25, -0.866, 0.433, 0.3524],
            [0.433, 0.5, 0.75, 0.6105],
            [-0.866, 0, 0.5, 0.5779],
            [0, 0, 0, 1],
        ]
    )
    T = robot.end_effector(D([60, 35.3, -82.7, 0, -58.0, 0]))
    np.testing.assert_allclose(T, A_in, atol=6e-4)  # the paper prints 4 digits, angles 0.1 deg


def _fd(f, q, eps=1e-6):
    cols = []
    for k in range(len(q)):
        dq = np.zeros(len(q))
        dq[k] = eps
        cols.append((f(q + dq) - f(q - dq)) / (2 * eps))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("which", ["robot", "robot7"])
def test_jacobians_match_finite_differences(which, request):
    r = request.getfixturevalue(which)
    rng = np.random.default_rng(7)
    for _ in range(10):
        q = random_q(rng, r)
        kin = r.kinematics(q)
        np.testing.assert_allclose(kin.point_jacobians, _fd(r.control_points, q), atol=1e-7)
        np.testing.assert_allclose(kin.segment_jacobians, _fd(r.capsules, q), atol=1e-7)
        for s in (0.0, 0.3, 1.0):
            for i in range(3):

                def seg_point(qq, i=i, s=s):
                    a, b = r.capsules(qq)[i]
                    return (1 - s) * a + s * b

                np.testing.assert_allclose(
                    kin.segment_point_jacobian(i, s), _fd(seg_point, q)[...], atol=1e-7
                )
        # End effector twist: linear part by differences of positions, angular by log3.
        R0 = kin.ee_placement[:3, :3]
        jv = _fd(lambda qq: r.end_effector(qq)[:3, 3], q)
        jw = _fd(lambda qq, R0=R0: pin.log3(r.end_effector(qq)[:3, :3] @ R0.T), q)
        np.testing.assert_allclose(kin.ee_jacobian[:3], jv, atol=1e-7)
        np.testing.assert_allclose(kin.ee_jacobian[3:], jw, atol=1e-6)


def _fresh_reads(r, q):
    """Positions and EE pose at ``q`` read from a new Pinocchio data, frame by frame."""
    data = r.model.createData()
    pin.forwardKinematics(r.model, data, q)
    pin.updateFramePlacements(r.model, data)
    points = np.array([data.oMf[f].translation for f in r.point_frames])
    return points, data.oMf[r.ee_frame].homogeneous


def test_kinematics_reads_the_current_placements_of_its_own_data(robot):
    """The placements are held references into ``robot.data``: they must follow every new
    q, a reassigned data, copies and pickles (which would otherwise read another data)."""
    import copy
    import pickle

    rng = np.random.default_rng(3)
    twins = {
        "itself": robot,
        "copy": copy.copy(robot),
        "deepcopy": copy.deepcopy(robot),
        "pickle": pickle.loads(pickle.dumps(robot)),
    }
    reassigned = copy.copy(robot)
    reassigned.data = robot.model.createData()
    twins["reassigned"] = reassigned
    for name, r in twins.items():
        kins = []
        for _ in range(3):
            q = random_q(rng, robot)
            kin = r.kinematics(q)
            points, ee = _fresh_reads(robot, q)
            np.testing.assert_allclose(kin.points, points, atol=1e-12, err_msg=name)
            np.testing.assert_allclose(kin.ee_placement, ee, atol=1e-12, err_msg=name)
            kins.append((kin, points))
        for kin, points in kins:  # an earlier tick's arrays are its own, never rewritten
            np.testing.assert_array_equal(kin.points, points)
    if robot.data is not reassigned.data:  # the twin computes in its own data
        q = random_q(rng, robot)
        robot.kinematics(q)
        reassigned.kinematics(q + 0.1)
        np.testing.assert_allclose(robot.kinematics(q).points, _fresh_reads(robot, q)[0])


def test_point_sets(robot):
    assert robot.set_names == ("L1", "L2", "EE")
    assert [len(s.points) for s in robot.sets] == [4, 4, 1]
    assert robot.point_set.tolist() == [0, 0, 0, 0, 1, 1, 1, 1, 2]


def test_bad_inputs(robot):
    with pytest.raises(RobotDescriptionError, match="unknown robot 'ur5'"):
        qpavoid.load_robot("ur5")
    with pytest.raises(InputError, match=r"shape \(6,\), got \(7,\)"):
        robot.control_points(np.zeros(7))
    with pytest.raises(InputError, match="non-finite entry at index \\(2,\\)"):
        robot.control_points([0, 0, np.nan, 0, 0, 0])
    with pytest.raises(InputError, match="cannot lock 'A9'"):
        qpavoid.load_robot("iiwa14", locked=("A9",))
    with pytest.raises(InputError, match="numeric"):
        robot.control_points("zero")


def test_description_from_a_folder(tmp_path, robot):
    """Any URDF with a control-point file beside it loads by path."""
    import shutil
    from importlib import resources

    src = resources.files("qpavoid.robots") / "iiwa14"
    robot_dir = tmp_path / "myarm"
    robot_dir.mkdir()
    for name in ("iiwa14.urdf", "control_points.toml"):
        shutil.copy(str(src / name), robot_dir / name)
    r = qpavoid.load_robot(robot_dir)
    assert r.name == "myarm"
    np.testing.assert_allclose(r.control_points(np.zeros(6)), robot.control_points(np.zeros(6)))
    (robot_dir / "control_points.toml").write_text('urdf = "iiwa14.urdf"\n')
    with pytest.raises(RobotDescriptionError, match="missing key 'sets'"):
        qpavoid.load_robot(robot_dir)
