"""The planned path and the start configuration."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import qpavoid
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.control.path import A_FIN, A_IN, ArcPath, WaypointPath, quintic
from qpavoid.control.task import BodyTarget, Task, default_task, load_task
from qpavoid.core.errors import InputError, RobotDescriptionError
from qpavoid.core.geometry import orthonormalize
from qpavoid.human.posture import Operator


def test_path_ends_and_orientation():
    path = ArcPath()
    T0, v0 = path.reference(0.0)
    T1, v1 = path.reference(15.0)
    np.testing.assert_allclose(T0[:3, 3], A_IN[:3, 3], atol=1e-12)
    np.testing.assert_allclose(T1[:3, 3], A_FIN[:3, 3], atol=1e-12)
    np.testing.assert_allclose(v0, 0, atol=1e-12)
    np.testing.assert_allclose(v1, 0, atol=1e-12)
    np.testing.assert_allclose(T0[:3, :3], A_IN[:3, :3], atol=1e-3)
    np.testing.assert_allclose(T0[:3, :3] @ T0[:3, :3].T, np.eye(3), atol=1e-12)
    # Before and after: waits at the ends.
    np.testing.assert_allclose(path.reference(-1.0)[0], T0)
    np.testing.assert_allclose(path.reference(99.0)[0], T1)


def test_arc_geometry():
    path = ArcPath()
    pts = np.array([path.reference(t)[0][:3, 3] for t in np.linspace(0, 15, 301)])
    np.testing.assert_allclose(pts[:, 1], 0.6105, atol=1e-12)  # in the plane y = 0.6105
    # Constant distance from one centre (a circle), and the sagitta above the chord.
    chord_mid = 0.5 * (A_IN[:3, 3] + A_FIN[:3, 3])
    mid = path.position(0.5)[0]
    assert np.linalg.norm(mid - chord_mid) == pytest.approx(0.08, abs=1e-12)
    assert mid[2] > chord_mid[2]
    L = np.linalg.norm(A_FIN[:3, 3] - A_IN[:3, 3])
    assert path.length_m() > L
    straight = ArcPath(sagitta_m=0.0)
    assert straight.length_m() == pytest.approx(L)


def test_twist_is_the_derivative_of_the_pose():
    path = ArcPath()
    for t in (0.5, 3.0, 7.5, 12.0, 14.9):
        h = 1e-6
        dp = (path.reference(t + h)[0][:3, 3] - path.reference(t - h)[0][:3, 3]) / (2 * h)
        np.testing.assert_allclose(path.reference(t)[1][:3], dp, atol=1e-8)
        np.testing.assert_allclose(path.reference(t)[1][3:], 0)


def test_quintic_time_law():
    assert quintic(0.0) == (0.0, 0.0)
    assert quintic(1.0) == (1.0, 0.0)
    assert quintic(0.5) == (0.5, pytest.approx(1.875))


def test_start_configuration_is_the_reading_notes_branch(robot):
    q = inverse_kinematics(robot, A_IN)
    np.testing.assert_allclose(np.degrees(q), [60.0, 35.3, -82.7, 0.0, -58.0, 0.0], atol=0.1)
    T = robot.end_effector(q)
    np.testing.assert_allclose(T[:3, 3], A_IN[:3, 3], atol=1e-9)
    # Both ends and the whole path are reachable with A3 locked.
    q1 = inverse_kinematics(robot, A_FIN, q0=q)
    np.testing.assert_allclose(robot.end_effector(q1)[:3, 3], A_FIN[:3, 3], atol=1e-9)


def test_unreachable_target_is_an_error(robot):
    far = A_IN.copy()
    far[:3, 3] = [1.5, 0.0, 0.5]
    with pytest.raises(InputError, match="unreachable"):
        inverse_kinematics(robot, far)
    with pytest.raises(InputError, match="duration_s must be positive"):
        ArcPath(duration_s=0.0)


# --- task files (qpavoid.control.task: WaypointPath, load_task, default_task) ---

POSE = """
[[waypoints]]
position_m = [0.3524, 0.6105, 0.5779]
rotation = [[0.25, -0.866, 0.433], [0.433, 0.5, 0.75], [-0.866, 0.0, 0.5]]
"""


#: A second waypoint, 1 s after POSE.
SECOND = "[[waypoints]]\nposition_m = [0, 0.6, 0.6]\nrpy_rad = [0, 0, 0]\nduration_s = 1\n"


def write_task(tmp_path, text: str):
    path = tmp_path / "task.toml"
    path.write_text(text)
    return path


def rotation_rate(path, t: float, h: float = 1e-6) -> np.ndarray:
    """Angular velocity (base frame) by central differences: log3(R(t+h) R(t-h)ᵀ) / 2h."""
    R1, R0 = path.reference(t + h)[0][:3, :3], path.reference(t - h)[0][:3, :3]
    return pin.log3(R1 @ R0.T) / (2 * h)


def test_a_turning_segment_reaches_the_goal_orientation_at_the_twist_it_reports():
    rng = np.random.default_rng(5)
    for _ in range(20):
        start, goal = np.eye(4), np.eye(4)
        start[:3, :3] = pin.exp3(rng.normal(size=3))
        goal[:3, :3] = pin.exp3(rng.normal(size=3))
        start[:3, 3], goal[:3, 3] = rng.normal(size=3), rng.normal(size=3)
        seg = ArcPath(start, goal, 4.0, 0.05, turn=True)
        np.testing.assert_allclose(seg.reference(4.0)[0][:3, :3], goal[:3, :3], atol=1e-12)
        np.testing.assert_allclose(seg.reference(0.0)[0][:3, :3], start[:3, :3], atol=1e-12)
        for t in (0.3, 1.7, 2.0, 3.9):
            twist = seg.reference(t)[1]
            np.testing.assert_allclose(twist[3:], rotation_rate(seg, t), atol=1e-7)
            h = 1e-6
            v = (seg.reference(t + h)[0][:3, 3] - seg.reference(t - h)[0][:3, 3]) / (2 * h)
            np.testing.assert_allclose(twist[:3], v, atol=1e-7)
        # one fixed axis: every intermediate orientation is R0 exp(σ w), w along one line
        w = pin.log3(start[:3, :3].T @ goal[:3, :3])
        for t in (1.0, 2.5):
            step = pin.log3(start[:3, :3].T @ seg.reference(t)[0][:3, :3])
            assert np.linalg.norm(np.cross(step, w)) < 1e-9 * max(1.0, np.linalg.norm(w))


def test_a_waypoint_path_runs_its_segments_one_after_the_other():
    poses = [np.eye(4) for _ in range(3)]
    poses[0][:3, 3], poses[1][:3, 3], poses[2][:3, 3] = [0, 0, 0], [1, 0, 0], [1, 2, 0]
    poses[2][:3, :3] = pin.exp3(np.array([0.0, 0.0, 0.5]))
    path = WaypointPath(
        (ArcPath(poses[0], poses[1], 2.0, 0.0), ArcPath(poses[1], poses[2], 3.0, 0.0, turn=True))
    )
    assert path.duration_s == 5.0
    for t, pose in ((-1.0, poses[0]), (0.0, poses[0]), (2.0, poses[1]), (5.0, poses[2])):
        np.testing.assert_allclose(path.reference(t)[0], pose, atol=1e-12)
        np.testing.assert_allclose(path.reference(t)[1], 0.0, atol=1e-12)  # at rest
    np.testing.assert_allclose(path.reference(9.0)[0], poses[2], atol=1e-12)
    # the second segment at its own clock
    np.testing.assert_array_equal(path.reference(3.2)[0], path.segments[1].reference(3.2 - 2.0)[0])
    assert path.length_m() == pytest.approx(3.0)
    with pytest.raises(InputError, match="at least one"):
        WaypointPath(())


def test_a_task_file_of_rpy_and_joint_waypoints(tmp_path, robot):
    q = np.array([0.5, 0.6, -1.4, 0.1, -1.0, 0.2])
    T = robot.end_effector(q)
    joints = ", ".join(f"{n} = {v!r}" for n, v in zip(robot.joint_names, q.tolist(), strict=True))
    rpy = pin.rpy.matrixToRpy(T[:3, :3])
    text = (
        POSE
        + f"""
[[waypoints]]
joints_rad = {{ {joints}, A3 = 0.0 }}
duration_s = 5.0

[[waypoints]]
position_m = {(T[:3, 3] + [0.0, 0.0, 0.1]).tolist()}
rpy_rad = {rpy.tolist()}
duration_s = 2.0
sagitta_m = 0.02

[operator]
x_m = 0.1
distance_m = 0.9

[strikes]
wrist = {{ frame = "A6", xyz = [0.0, 0.0, 0.05] }}
"""
    )
    task = load_task(write_task(tmp_path, text), robot)
    assert task.path.duration_s == 7.0
    np.testing.assert_allclose(task.path.reference(5.0)[0], T, atol=1e-12)  # FK of q
    end = task.path.reference(7.0)[0]
    np.testing.assert_allclose(end[:3, 3], T[:3, 3] + [0, 0, 0.1], atol=1e-12)
    np.testing.assert_allclose(end[:3, :3], T[:3, :3], atol=1e-12)  # rpy round trip
    assert not task.path.segments[1].turn  # the same orientation: held
    assert task.path.segments[0].turn
    assert task.operator == Operator(x_m=0.1, distance_m=0.9)
    assert task.test2_operator == Operator(x_m=-0.25, distance_m=0.9)
    assert task.body_targets == (BodyTarget("wrist", "A6", (0.0, 0.0, 0.05)),)
    assert task.scaling is None


def test_a_robot_without_a_task_file_gets_the_papers(tmp_path, robot):
    task = default_task(robot, tmp_path)
    assert task.file is None and task.body_targets == () and task.scaling is None
    assert task.operator == Operator() and task.test2_operator == Operator(x_m=-0.25)
    assert isinstance(task.path, ArcPath) and isinstance(Task().path, ArcPath)
    np.testing.assert_array_equal(task.path.reference(3.0)[0], ArcPath().reference(3.0)[0])


@pytest.mark.parametrize(
    "text, key, words",
    [
        ("", "waypoints", "at least two"),
        (POSE + "[[waypoints]]\nposition_m = [0, 0, 1]\n", "waypoints[1]", "one of rotation"),
        (
            POSE + "[[waypoints]]\nposition_m = [0, 0, 1]\nrpy_rad = [0, 0, 0]\n",
            "waypoints[1].duration_s",
            "missing",
        ),
        (
            POSE.replace("0.5779]", "0.5779]\nduration_s = 1.0")
            + "[[waypoints]]\nposition_m = [0, 0, 1]\nrpy_rad = [0, 0, 0]\nduration_s = 1.0\n",
            "waypoints[0].duration_s",
            "the first waypoint is the start",
        ),
        (
            POSE + "[[waypoints]]\nposition_m = [0, 0, 1]\nrpy_rad = [0, 0, 0]\nduration_s = 0\n",
            "waypoints[1].duration_s",
            "above 0",
        ),
        (
            POSE
            + "[[waypoints]]\nposition_m = [0, 0, 1]\nrpy_rad = [0, 0, 0]\nduration_s = 1\n"
            + "sagitta_m = -0.1\n",
            "waypoints[1].sagitta_m",
            "at least 0",
        ),
        (
            POSE.replace("[0.25, -0.866", "[0.25, 0.866") + SECOND,
            "waypoints[0].rotation",
            "not a rotation matrix",
        ),
        (
            POSE.replace("0.5779]", "nan]") + SECOND,
            "waypoints[0].position_m[2]",
            "must be a number at least -10 and at most 10, m, got nan",
        ),
        (
            POSE.replace(", 0.5779]", "]") + SECOND,
            "waypoints[0].position_m",
            "must be 3 finite numbers (x, y, z), m",
        ),
        (POSE + "speed = 1\n" + SECOND, "waypoints[0].speed", "unknown key(s) ['speed']"),
        ("colour = 1\n" + POSE, "colour", "unknown key(s) ['colour']"),
        (
            POSE + "[[waypoints]]\njoints_rad = { A1 = 0.1 }\nduration_s = 1\n",
            "waypoints[1].joints_rad",
            "every joint",
        ),
        (
            POSE + "[[waypoints]]\njoints_rad = { B1 = 0.1 }\nduration_s = 1\n",
            "waypoints[1].joints_rad.B1",
            "no joint",
        ),
        (
            POSE
            + "[[waypoints]]\njoints_rad = { A1 = 0, A2 = 0, A3 = 0.3, A4 = 0, A5 = 0, "
            + "A6 = 0, A7 = 0 }\nduration_s = 1\n",
            "waypoints[1].joints_rad.A3",
            "locked at 0",
        ),
        (
            POSE
            + "[[waypoints]]\njoints_rad = { A1 = 0, A2 = 9, A4 = 0, A5 = 0, A6 = 0, A7 = 0 }\n"
            + "duration_s = 1\n",
            "waypoints[1].joints_rad.A2",
            "outside the joint's limits",
        ),
        (POSE + POSE + 'duration_s = 1\n[strikes]\nL1 = "A2"\n', "strikes.L1", "a set's name"),
        (POSE + POSE + 'duration_s = 1\n[strikes]\nhip = "B2"\n', "strikes.hip", "no frame"),
        (POSE + POSE + "duration_s = 1\n[operator]\ndistance_m = -1\n", "operator.distance_m", ""),
        (POSE + POSE + "duration_s = 1\n[scaling]\nshoulder = 'A2'\n", "scaling.reference", ""),
        ("waypoints = [", "", "Invalid"),
    ],
)
def test_a_bad_task_file_is_one_line_naming_the_file_and_the_key(tmp_path, robot, text, key, words):
    path = write_task(tmp_path, text)
    with pytest.raises(RobotDescriptionError) as caught:
        load_task(path, robot)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{path}: ")
    table, _, leaf = key.rpartition(".")  # the key's path, or its table's and its name
    assert key in message or (f": {table} " in message and f"{leaf}" in message)
    assert words in message
    assert caught.value.path == path and (caught.value.name == key or not key)


def test_rpy_is_roll_pitch_yaw_about_the_fixed_axes(tmp_path, robot):
    """``rpy_rad = [r, p, y]`` is R_z(y) R_y(p) R_x(r), written out by hand."""
    # the paper's orientation as roll, pitch, yaw (a pose the arm reaches), to 4 digits
    r, p, y = (round(float(v), 4) for v in pin.rpy.matrixToRpy(orthonormalize(A_IN[:3, :3])))
    c, s = np.cos, np.sin
    Rx = np.array([[1, 0, 0], [0, c(r), -s(r)], [0, s(r), c(r)]])
    Ry = np.array([[c(p), 0, s(p)], [0, 1, 0], [-s(p), 0, c(p)]])
    Rz = np.array([[c(y), -s(y), 0], [s(y), c(y), 0], [0, 0, 1]])
    second = SECOND.replace("position_m = [0, 0.6, 0.6]", "position_m = [-0.0476, 0.6105, 0.6779]")
    text = POSE + second.replace("rpy_rad = [0, 0, 0]", f"rpy_rad = [{r}, {p}, {y}]")
    task = load_task(write_task(tmp_path, text), robot)
    np.testing.assert_allclose(task.path.reference(1.0)[0][:3, :3], Rz @ Ry @ Rx, atol=1e-12)


def test_a_description_loaded_from_a_folder_takes_that_folders_task(tmp_path):
    """The task of a robot is the task.toml beside the control-point file it was read
    from, wherever that folder is."""
    source = Path(__file__).resolve().parents[1] / "robots" / "iiwa14"
    folder = tmp_path / "myarm"
    shutil.copytree(source, folder)
    text = (folder / "task.toml").read_text().replace("x_m = 0.15", "x_m = 0.05")
    (folder / "task.toml").write_text(text)
    task = default_task(qpavoid.load_robot(folder))
    assert task.file == folder / "task.toml" and task.operator.x_m == 0.05
    (folder / "task.toml").unlink()
    assert default_task(qpavoid.load_robot(folder)).file is None  # the paper's


def test_a_waypoint_out_of_reach_is_refused_naming_it(tmp_path, robot):
    """A goal 2.5 m away (or written in mm) is refused when the file is read, not found
    out by a run that cannot track it."""
    far = SECOND.replace("position_m = [0, 0.6, 0.6]", "position_m = [0, 2.5, 0.6]")
    with pytest.raises(RobotDescriptionError) as err:
        load_task(write_task(tmp_path, POSE + far), robot)
    assert err.value.name == "waypoints[1]" and "cannot reach this pose" in str(err.value)
    assert "\n" not in str(err.value)
