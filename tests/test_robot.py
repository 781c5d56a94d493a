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
    with pytest.raises(RobotDescriptionError, match="unknown robot 'ur10'"):
        qpavoid.load_robot("ur10")
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
    with pytest.raises(RobotDescriptionError, match=r"missing key\(s\) sets"):
        qpavoid.load_robot(robot_dir)


def test_a_joint_without_limits_is_refused_naming_it(tmp_path):
    """A revolute joint with no <limit> (the URDF parser only says so on the console)."""
    import shutil
    from importlib import resources

    folder = tmp_path / "arm"
    shutil.copytree(str(resources.files("qpavoid.robots") / "iiwa14"), folder)
    urdf = folder / "iiwa14.urdf"
    text = urdf.read_text()
    start = text.index("<limit", text.index('name="A4"'))
    urdf.write_text(text[:start] + text[text.index("/>", start) + 2 :])
    with pytest.raises(RobotDescriptionError) as info:
        qpavoid.load_robot(folder)
    assert info.value.path == urdf and info.value.name == "A4"
    assert "\n" not in str(info.value)
    assert "joint 'A4' (revolute) has no <limit>: give it <limit lower=" in str(info.value)


#: The arms shipped beside the iiwa: the package their URDF comes from, the joints the
#: paper's roles name, the end-effector frame.
ARMS = {
    "panda": ("example-robot-data", "panda_", "panda_hand"),
    "fr3": ("franky-sim", "fr3_", "fr3_hand"),
    "ur5": ("example-robot-data", None, "tool0"),
}


def _arm(name: str) -> qpavoid.Robot:
    from importlib import metadata

    try:
        metadata.distribution(ARMS[name][0])
    except metadata.PackageNotFoundError:
        pytest.skip(f"{ARMS[name][0]} is not installed (the extra 'robots')")
    return qpavoid.load_robot(name)


@pytest.mark.parametrize("name", sorted(ARMS))
def test_the_shipped_arms_load_with_the_paper_roles(name):
    r = _arm(name)
    _, prefix, ee = ARMS[name]
    assert r.nv == 6 and r.model.frames[r.ee_frame].name == ee
    if prefix is None:  # the UR5: six joints, nothing locked
        assert r.role_names == ("upper_arm", "forearm", "wrist_3") and r.locked == {}
        assert r.roles.repelled_joints == (
            "shoulder_pan_joint",
            "shoulder_lift_joint",
            "elbow_joint",
        )
    else:  # the Franka arms: joint3 locked as the iiwa's A3, the fingers held open
        assert r.role_names == ("link3", "link5", "hand")
        assert r.roles.scaled_joints == (f"{prefix}joint1", f"{prefix}joint2")
        assert r.roles.repelled_joints == tuple(f"{prefix}joint{k}" for k in (1, 2, 4))
        fingers = {f"{prefix}finger_joint{k}": 0.04 for k in (1, 2)}
        assert r.locked == {f"{prefix}joint3": 0.0} | fingers
        free = qpavoid.load_robot(name, locked=())  # the redundant mode
        assert free.nv == 7 and f"{prefix}joint3" in free.joint_names
        assert free.locked == fingers  # held in every mode
    assert r.arm.sources and all(text for _, text in r.arm.sources)


@pytest.mark.parametrize("name", sorted(ARMS))
def test_the_end_effector_frame_lies_in_its_capsule_and_the_elbow_at_the_elbow(name):
    r = _arm(name)
    cs = r.sets[r.roles.end_effector]
    rng = np.random.default_rng(2)
    for _ in range(5):
        q = random_q(rng, r)
        kin = r.kinematics(q, jacobians=False)
        a, b = kin.segments[r.roles.end_effector]
        p = kin.ee_placement[:3, 3]
        s = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
        assert np.linalg.norm(p - a - s * (b - a)) <= cs.capsule_radius_m
        # the elbow point lies within 5 cm of the elbow joint's origin (on its housing)
        elbow_joint = r.roles.repelled_joints[-1]
        origin = r.data.oMi[r.model.getJointId(elbow_joint)].translation
        assert np.linalg.norm(kin.points[r.roles.elbow] - origin) < 0.05


@pytest.mark.parametrize("name", sorted(ARMS))
def test_offset_points_have_pinocchios_jacobians(name):
    """Points and capsule ends given as offsets from a link frame: finite differences."""
    r = _arm(name)
    rng = np.random.default_rng(4)
    for _ in range(3):
        q = random_q(rng, r)
        kin = r.kinematics(q)
        np.testing.assert_allclose(kin.point_jacobians, _fd(r.control_points, q), atol=1e-7)
        np.testing.assert_allclose(kin.segment_jacobians, _fd(r.capsules, q), atol=1e-7)


@pytest.mark.parametrize(
    "name, targets",
    [
        ("panda", [(0.4, 0.2, 0.4), (0.5, 0.0, 0.3), (0.3, -0.3, 0.5)]),
        ("fr3", [(0.4, 0.2, 0.4), (0.5, 0.0, 0.3)]),
        ("ur5", [(0.4, 0.2, 0.3), (0.5, -0.1, 0.2), (0.3, 0.4, 0.4)]),
    ],
)
def test_the_seed_reaches_targets_in_front_elbow_up_with_eq6_well_conditioned(name, targets):
    """The hand pointing down at targets in front: the seed's branch has the elbow above
    the shoulder, and eq. (6)'s 3x3 Jacobian (the repelled joints' columns) at the
    forearm's points is well conditioned, but at a point on the elbow's own axis (the
    UR5's forearm capsule runs into the elbow joint, as the iiwa's L2 capsule starts at
    A4: the damped inverse of eq. (6) takes that one)."""
    from qpavoid.arm.ik import inverse_kinematics
    from qpavoid.arm.model import joint_columns

    r = _arm(name)
    columns = joint_columns(r, None, "repelled_joints")
    shoulder = r.model.getJointId(r.roles.scaled_joints[-1])
    for p in targets:
        target = np.eye(4)
        target[:3, :3] = np.diag([1.0, -1.0, -1.0])
        target[:3, 3] = p
        q = inverse_kinematics(r, target)
        kin = r.kinematics(q)
        np.testing.assert_allclose(kin.ee_placement[:3, 3], p, atol=1e-9)
        assert kin.points[r.roles.elbow][2] > r.data.oMi[shoulder].translation[2] + 0.1
        for i in r.sets[r.roles.repelled].points:
            J = kin.point_jacobians[i][:, columns]
            # the elbow's column is |axis x (p − o)|: the point's distance from its axis
            if np.linalg.norm(J[:, -1]) > 0.05:
                assert np.linalg.cond(J) < 12.0, (p, i, np.linalg.cond(J))


def test_a_held_joint_is_locked_in_every_mode_and_not_also_locked(tmp_path):
    """``held`` (a gripper's fingers) stays locked when ``locked=`` frees the rest."""
    import shutil
    from importlib import resources

    folder = tmp_path / "arm"
    shutil.copytree(str(resources.files("qpavoid.robots") / "iiwa14"), folder)
    path = folder / "control_points.toml"
    text = path.read_text()
    path.write_text(
        text.replace("locked = { A3 = 0.0 }", "locked = { A3 = 0.0 }\nheld = { A7 = 0.5 }")
    )
    paper, free = qpavoid.load_robot(folder), qpavoid.load_robot(folder, locked=())
    assert paper.joint_names == ("A1", "A2", "A4", "A5", "A6") and paper.locked == {
        "A3": 0.0,
        "A7": 0.5,
    }
    assert free.joint_names == ("A1", "A2", "A3", "A4", "A5", "A6") and free.locked == {"A7": 0.5}
    # the flange turned 0.5 rad about A7's axis (z at q = 0)
    R = free.end_effector(np.zeros(6))[:3, :3]
    np.testing.assert_allclose(R, pin.rpy.rpyToMatrix(0.0, 0.0, 0.5), atol=1e-12)
    path.write_text(
        text.replace("locked = { A3 = 0.0 }", "locked = { A3 = 0.0 }\nheld = { A3 = 0.0 }")
    )
    with pytest.raises(RobotDescriptionError, match=r"\['A3'\] are both held and locked") as info:
        qpavoid.load_robot(folder)
    assert info.value.name == "held" and info.value.path == path


def test_a_copy_for_another_thread_computes_in_data_of_its_own():
    """The ROS 2 outputs' thread computed capsules in the loop's Pinocchio data: a live run's
    commands then differed from the same inputs given again by up to 0.014 rad/s on 40 of
    7030 ticks (found by the run's journal, 2026-12-07). Two threads, each on its own copy,
    each get the kinematics of their own q every time."""
    import threading

    robot = qpavoid.load_robot("iiwa14")
    other = robot.for_thread()
    assert other.data is not robot.data and other.model is robot.model
    rng = np.random.default_rng(3)
    qs = [rng.uniform(robot.q_min, robot.q_max) for _ in range(2)]
    want = [robot.kinematics(q).segments.copy() for q in qs]
    wrong = [0, 0]

    def spin(r, k):
        for _ in range(3000):
            if not np.array_equal(r.kinematics(qs[k]).segments, want[k]):
                wrong[k] += 1

    threads = [threading.Thread(target=spin, args=(r, k)) for k, r in enumerate((robot, other))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert wrong == [0, 0]
