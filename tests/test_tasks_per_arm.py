"""Each shipped arm's task (its description folder's ``task.toml``): the paper's tests on it.

For every arm whose description loads (a folder not written yet, or an extra not
installed, is skipped with the reason): the start pose's inverse kinematics converges from
the description's seed; the path tracked with nobody near stays inside the joint limits
with a margin; the file's numbers are the iiwa's scaled by the measured reach; ``free``
reaches the goal in its time with both controllers; ``test1`` brings the hand beside the
path ahead of the robot and ``test2`` near the scaled set until f > 0.8 and the robot
stops; strikes and random approaches aim at the arm's own sets. Closed loops run on the
paper's bench (ideal sensor, exact arm) at 100 Hz.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import qpavoid
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import Robot
from qpavoid.arm.reach import arm_reach, shoulder_centre
from qpavoid.control.analytic import AnalyticController
from qpavoid.control.path import ArcPath
from qpavoid.control.qp import QPController
from qpavoid.control.task import Task, default_task
from qpavoid.control.tick import ControllerConfig
from qpavoid.core.errors import RobotDescriptionError
from qpavoid.distance.methods import distance_method
from qpavoid.human.body import KinectHuman
from qpavoid.human.posture import ARM, Operator
from qpavoid.loop.camera import CameraConfig
from qpavoid.loop.simulation import SimConfig, SimResult, simulate
from qpavoid.perception.tracker import PerceptionConfig
from qpavoid.scenarios.generated import make_scenario, nominal_configurations, random_approach
from qpavoid.scenarios.strikes import StrikeCase, strike_motion, strike_targets

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
ARMS = ("iiwa14", "panda", "ur5", "fr3")
#: Smallest distance from a joint limit along the nominal path, rad (measured: iiwa 0.54,
#: Panda 0.95, UR5 0.58, FR3 1.13).
MARGIN_RAD = 0.3
#: The file's numbers are printed to 4 decimals: rounding, and the reach's own.
PRINTED = 6e-5
RIGHT_HAND = ARM["right"][3]


@functools.cache
def _load(name: str) -> tuple[Robot, Task] | str:
    """The arm and its task, or why it cannot be tested (a skip reason)."""
    if not (ROBOTS / name / "control_points.toml").is_file():
        return f"robots/{name}/control_points.toml is not written yet"
    if not (ROBOTS / name / "task.toml").is_file():
        return f"robots/{name}/task.toml is not written yet"
    try:
        robot = qpavoid.load_robot(name)
    except RobotDescriptionError as exc:
        if "not installed" in str(exc):
            return str(exc)
        raise
    return robot, default_task(robot)


@pytest.fixture(params=ARMS)
def arm(request) -> tuple[Robot, Task]:
    loaded = _load(request.param)
    if isinstance(loaded, str):
        pytest.skip(loaded)
    return loaded


#: The closed loops: the Panda (a fitted arm, eight sets, a tool reaching past the
#: flange) with the default suite, the other arms with the slow one (the iiwa's own
#: closed loops are the regression's and test_analytic's).
@pytest.fixture(
    params=[pytest.param(n, marks=pytest.mark.slow) if n != "panda" else n for n in ARMS]
)
def arm_loop(request) -> tuple[Robot, Task]:
    loaded = _load(request.param)
    if isinstance(loaded, str):
        pytest.skip(loaded)
    return loaded


def closed_loop(
    robot: Robot, task: Task, scenario: str, controller: str, max_time_s: float = 25.0
) -> SimResult:
    """``scenario`` on the paper's bench at 100 Hz, against the arm's own path, the
    controller measuring capsules (``log["distance"]``: the arm's collision meshes lie
    inside them, docs/robot.md)."""
    config = ControllerConfig(
        control_period_s=0.01, perception=PerceptionConfig(max_identical_frames=None)
    )
    kind = AnalyticController if controller == "analytic" else QPController
    return simulate(
        kind(robot, path=task.path, config=config),
        make_scenario(scenario, robot, task=task),
        SimConfig(
            control_rate_hz=100.0,
            camera=CameraConfig.ideal(),
            braking=None,
            max_time_s=max_time_s,
            measure_truth=False,  # the collision meshes' clearance: 5x the run's time
        ),
    )


def hand_distances(robot, joints, configurations, method="spheres") -> np.ndarray:
    """(T, S) distance of the right hand of the skeleton ``joints`` to each set, the
    robot at each of ``configurations`` (T, nq)."""
    human = KinectHuman()
    table = distance_method(method, robot, human)
    geo = human.geometry(joints)
    hand = human.part_names.index("right_hand")
    return np.array(
        [table(robot.kinematics(q, jacobians=False), geo).distance[:, hand] for q in configurations]
    )


@pytest.mark.parametrize("name", ARMS)
def test_every_shipped_arm_loads_its_task(name):
    """``default_task(load_robot(name))`` for every shipped arm, never skipped: the test
    command installs the dev extra, which brings the packages of the arms' URDFs and
    meshes (example-robot-data, franky-sim), so an arm whose description or task does not
    load with the versions installed (the newest, or the oldest pyproject.toml allows:
    .ci/run runs this suite on both) fails here, whatever the tests below skip. Loading
    a task checks each waypoint reachable (inverse kinematics from the description's
    seed, within the joint limits)."""
    robot = qpavoid.load_robot(name)
    task = default_task(robot)
    assert robot.name == name
    assert task.file == robot.path.parent / "task.toml"  # the installed description's
    assert task.file.read_bytes() == (ROBOTS / name / "task.toml").read_bytes()
    assert task.path.duration_s > 0.0


def test_the_iiwas_task_file_is_the_papers_arc_bit_for_bit(robot):
    task = default_task(robot)
    paper = ArcPath()
    assert task.file == robot.path.parent / "task.toml"  # beside its description, wherever
    assert task.file.read_bytes() == (ROBOTS / "iiwa14" / "task.toml").read_bytes()
    assert task.path.duration_s == paper.duration_s
    assert np.array_equal(task.path.start, paper.start)
    for t in np.r_[np.linspace(-1.0, 16.0, 1701), np.pi, 7.123456789]:
        pose, twist = task.path.reference(float(t))
        pose0, twist0 = paper.reference(float(t))
        assert np.array_equal(pose, pose0) and np.array_equal(twist, twist0), t
    assert task.operator == Operator()
    assert task.test2_operator == Operator(x_m=-0.25)


def test_the_iiwas_strike_targets_are_todays(robot):
    """The shoulder (where L1's capsule starts) and the column 0.1 m under it, exactly."""
    task = default_task(robot)
    assert strike_targets(robot, task) == ("L1", "L2", "EE", "shoulder", "base")
    rng = np.random.default_rng(3)
    data = robot.model.createData()
    for _ in range(50):
        q = rng.uniform(robot.q_min, robot.q_max)
        pin.framesForwardKinematics(robot.model, data, q)
        at = {
            b.name: data.oMf[robot.model.getFrameId(b.frame)].act(np.array(b.xyz_m))
            for b in task.body_targets
        }
        shoulder = robot.capsules(q)[robot.roles.scaled, 0]
        np.testing.assert_array_equal(at["shoulder"], shoulder)
        np.testing.assert_allclose(at["base"], shoulder - [0.0, 0.0, 0.1], atol=1e-15)


def test_the_start_pose_inverse_kinematics_converges_from_the_seed(arm):
    robot, task = arm
    start = task.path.reference(0.0)[0]
    q = inverse_kinematics(robot, start)  # from the description's [ik_seed]
    reached = robot.end_effector(q)
    np.testing.assert_allclose(reached[:3, 3], start[:3, 3], atol=1e-9)
    np.testing.assert_allclose(reached[:3, :3], start[:3, :3], atol=1e-9)
    assert np.all(q >= robot.q_min) and np.all(q <= robot.q_max)


def test_the_nominal_path_stays_inside_the_joint_limits_with_a_margin(arm):
    """Tracked exactly (IK at 151 times, each from the last), every pose is reached, the
    joints move continuously (no branch jump) and stay MARGIN_RAD from their limits."""
    robot, task = arm
    times = np.linspace(0.0, task.path.duration_s, 151)
    Q = nominal_configurations(robot, task.path, times)
    for t, q in zip(times, Q, strict=True):
        np.testing.assert_allclose(
            robot.end_effector(q)[:3, 3], task.path.reference(float(t))[0][:3, 3], atol=1e-9
        )
    assert np.abs(np.diff(Q, axis=0)).max() < 0.05  # rad per 0.1 s of path
    assert np.minimum(Q - robot.q_min, robot.q_max - Q).min() > MARGIN_RAD


def test_the_reach_of_the_iiwa_is_its_link_lengths_and_no_sample_beats_any_arms(arm):
    """Hand-computed for the iiwa (straight up: 0.2045 + 0.2155 + 0.1845 + 0.2155 + 0.081
    + 0.045 m from A2 to the flange); for every arm no random configuration is farther, and
    the optimum is a stationary point (zero gradient on every joint off its limits)."""
    robot, task = arm
    if task.scaling is None:
        pytest.skip("the task gives no [scaling]")
    shoulder = task.scaling.shoulder
    reach, q = arm_reach(robot, shoulder)
    if robot.name == "iiwa14":
        assert reach == pytest.approx(0.946, abs=1e-9)
    model, data = robot.model, robot.model.createData()
    fs = model.getFrameId(shoulder)

    def distance(q):
        pin.framesForwardKinematics(model, data, q)
        return np.linalg.norm(data.oMf[robot.ee_frame].translation - data.oMf[fs].translation)

    samples = np.random.default_rng(7).uniform(robot.q_min, robot.q_max, (5000, robot.nq))
    assert max(distance(s) for s in samples) <= reach + 1e-9
    assert distance(q) == pytest.approx(reach, abs=1e-12)
    h = 1e-6
    for j in range(robot.nq):
        if robot.q_min[j] + 1e-4 < q[j] < robot.q_max[j] - 1e-4:
            dq = np.zeros(robot.nq)
            dq[j] = h
            assert abs(distance(q + dq) - distance(q - dq)) / (2 * h) < 1e-4


def test_the_task_file_is_the_iiwas_scaled_by_the_reach(arm):
    """Every number the file's comments derive: reach, scale, positions about the shoulder
    centres, sagitta, durations, the operator's seat; the tool heads the iiwa's way."""
    robot, task = arm
    if task.scaling is None:
        pytest.skip("the task gives no [scaling]")
    reference = _load(task.scaling.reference)
    assert not isinstance(reference, str), reference
    ref_robot, ref_task = reference
    assert ref_task.scaling is not None
    reach = arm_reach(robot, task.scaling.shoulder)[0]
    ref_reach = arm_reach(ref_robot, ref_task.scaling.shoulder)[0]
    s = reach / ref_reach
    assert task.scaling.reach_m == pytest.approx(reach, abs=PRINTED)
    assert task.scaling.scale == pytest.approx(s, abs=PRINTED)
    c = shoulder_centre(robot, task.scaling.shoulder)
    c_ref = shoulder_centre(ref_robot, ref_task.scaling.shoulder)
    segments, ref_segments = task.path.segments, ref_task.path.segments
    assert len(segments) == len(ref_segments)
    for seg, ref in zip(segments, ref_segments, strict=True):
        for pose, ref_pose in ((seg.start, ref.start), (seg.goal, ref.goal)):
            expected = c + s * (ref_pose[:3, 3] - c_ref)
            np.testing.assert_allclose(pose[:3, 3], expected, atol=PRINTED)
            # the tool heads the same way over the table (its elevation is the arm's)
            heading, ref_heading = pose[:2, 2], ref_pose[:2, 2]
            cos = heading @ ref_heading / np.linalg.norm(heading) / np.linalg.norm(ref_heading)
            assert cos == pytest.approx(1.0, abs=1e-6)
        assert seg.duration_s == ref.duration_s
        assert seg.sagitta_m == pytest.approx(s * ref.sagitta_m, abs=PRINTED)
    assert task.operator.x_m == pytest.approx(s * ref_task.operator.x_m, abs=PRINTED)
    # the seat is moved back from its scaled place until the person at rest is as far from
    # the arm along its path as on the iiwa (the person does not scale; a tool reaching
    # further would bring the arm within speed and separation's hold)
    assert task.operator.distance_m >= s * ref_task.operator.distance_m - PRINTED
    assert rest_gap(robot, task) == pytest.approx(rest_gap(ref_robot, ref_task), abs=0.01)
    assert task.test2_operator.x_m == pytest.approx(s * ref_task.test2_operator.x_m, abs=PRINTED)


def rest_gap(robot: Robot, task: Task) -> float:
    """The smallest capsule distance between the operator at rest (``free``) and the arm
    along its nominal path (31 instants over the path's duration), m."""
    human = KinectHuman()
    table = distance_method("capsules", robot, human)
    motion = make_scenario("free", robot)
    times = np.linspace(0.0, task.path.duration_s, 31)
    gaps = []
    for t, q in zip(times, nominal_configurations(robot, task.path, times), strict=True):
        joints, state = motion.frame_at(t)[:2]
        gaps.append(table(robot.kinematics(q), human.geometry(joints, state)).distance.min())
    return float(min(gaps))


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["analytic", "qp"])
def test_free_reaches_the_goal_in_its_time(arm_loop, controller):
    robot, task = arm_loop
    sim = closed_loop(robot, task, "free", controller)
    assert sim.metrics["reached_goal"]
    assert sim.log["t"][-1] <= task.path.duration_s + 0.02  # the goal at the path's end
    assert sim.metrics["stop_events"] == []
    goal = task.path.reference(task.path.duration_s)[0]
    np.testing.assert_allclose(robot.end_effector(sim.log["q"][-1])[:3, 3], goal[:3, 3], atol=1e-3)


@pytest.mark.slow
def test_test1_the_hand_waits_beside_the_path_ahead_of_the_robot(arm_loop):
    """Designed against the nominal motion: the hand, at its target from 5 s (before the
    robot's wrist gets there at 9 s), is 0.04 m from the path's closest approach (spheres;
    every set but the scaled one), and the robot comes within 0.1 m of it while it holds
    (5-11 s).
    In closed loop the robot goes by without touching it and reaches the goal."""
    robot, task = arm_loop
    motion = make_scenario("test1", robot, task=task)
    times = np.linspace(0.0, task.path.duration_s, 121)
    nominal = nominal_configurations(robot, task.path, times)
    d = hand_distances(robot, motion.frame_at(8.0)[0], nominal)
    others = [k for k, n in enumerate(robot.set_names) if n != robot.role_name("scaled")]
    closest = d[:, others].min(axis=1)
    assert closest.min() == pytest.approx(0.04, abs=1e-3)
    arrive, leave = np.searchsorted(times, [5.0, 11.0])
    holding = closest[arrive : leave + 1]
    assert holding.min() < min(closest[arrive] - 0.04, 0.1)  # it comes to the waiting hand
    assert d[:, robot.roles.scaled].min() > 0.1  # not at the scaled set: that is test 2
    sim = closed_loop(robot, task, "test1", "analytic")
    assert sim.log["distance"].min() > 0.0
    assert sim.log["distance"][:, others].min() < 0.15  # the hand did come close
    assert sim.metrics["reached_goal"]


def test_test2_the_hand_near_the_scaled_set_stops_the_robot(arm_loop):
    """Designed at the start configuration: the hand's target is within 0.02 m of the
    scaled set by both distance methods (f = 0.96 by the paper's eq. 2), or as near as the
    operator reaches (the iiwa's: 0.0213 m by capsules). In closed loop f exceeds 0.8, the
    robot stops for that set and stays still while the hand holds (4-9 s), and moves on
    once the hand is back (11 s)."""
    robot, task = arm_loop
    motion = make_scenario("test2", robot, task=task)
    q0 = inverse_kinematics(robot, task.path.reference(0.0)[0])
    scaled = robot.roles.scaled
    at = [
        hand_distances(robot, motion.frame_at(5.0)[0], [q0], method)[0, scaled]
        for method in ("spheres", "capsules")
    ]
    assert max(at) < 0.022
    sim = closed_loop(robot, task, "test2", "analytic", max_time_s=12.0)
    log = sim.log
    assert log["f"].max() > 0.8
    first = sim.metrics["stop_events"][0]["reason"]
    assert first.startswith("f = ") and f"({robot.role_name('scaled')})" in first
    hold = (log["t"] >= 4.0) & (log["t"] <= 9.0)
    assert log["stopped"][hold].all() and not np.any(log["dq"][hold])
    assert log["distance"].min() > 0.0
    back = log["t"] >= 11.5
    assert not log["stopped"][back].any() and np.all(np.abs(log["dq"][back]).max(axis=1) > 0)


def test_strikes_aim_at_the_arms_own_sets_and_places(arm):
    """Each set of the description is a target, then the task's [strikes] places: a
    strike at a set aims at a point of its capsule's axis (a robot that stays is hit), a
    strike at a place at that place (its frame's placement applied to its offset); the
    hand gets there, or as far as the operator's arm stretches towards it."""
    robot, task = arm
    targets = strike_targets(robot, task)
    assert targets == (*robot.set_names, *(b.name for b in task.body_targets))
    places = {b.name: b for b in task.body_targets}
    data = robot.model.createData()
    for k, target in enumerate(targets):
        case = StrikeCase(k, target, 2.0, "right", False, 3.0, "none")
        motion = strike_motion(case, robot, task=task)
        aim = motion.keyframes[1][1]
        (q,) = nominal_configurations(robot, task.path, np.array([case.arrival_s]))
        if target in robot.set_names:
            a, b = robot.capsules(q)[robot.set_index(target)]
            s = (aim - a) @ (b - a) / ((b - a) @ (b - a))
            assert 0.2 - 1e-9 <= s <= 1.0 + 1e-9, target
            np.testing.assert_allclose(aim, a + s * (b - a), atol=1e-12)
        else:
            pin.framesForwardKinematics(robot.model, data, q)
            frame = data.oMf[robot.model.getFrameId(places[target].frame)]
            np.testing.assert_array_equal(aim, frame.act(np.array(places[target].xyz_m)))
        op = motion.operator
        joints = motion.frame_at(case.arrival_s)[0]
        hand, shoulder = joints[RIGHT_HAND], joints[ARM["right"][0]]
        if np.linalg.norm(hand - aim) > 1e-9:  # out of reach: the arm is stretched to it
            arm_length = op.upper_arm_m + op.forearm_m + op.hand_m
            assert np.linalg.norm(hand - shoulder) == pytest.approx(arm_length, abs=1e-5)
        assert op.distance_m == task.operator.distance_m
        assert abs(op.x_m - task.operator.x_m) <= 0.15


def test_random_approaches_come_from_the_arms_operator_towards_its_points(arm):
    robot, task = arm
    times = np.linspace(0, task.path.duration_s, 31)
    nominal = nominal_configurations(robot, task.path, times)
    points = np.concatenate([robot.control_points(q) for q in nominal])
    for seed in range(20):
        reach = random_approach(np.random.default_rng(seed), robot, nominal=nominal, task=task)
        assert reach.operator.distance_m == task.operator.distance_m
        assert abs(reach.operator.x_m - task.operator.x_m) <= 0.2
        target = reach.keyframes[1][1]
        assert np.linalg.norm(points - target, axis=1).min() <= 0.1 + 1e-12
