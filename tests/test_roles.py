"""The arm as data: the controllers address the robot's sets by role, never by name.

A copy of the iiwa's description with every joint and set renamed gives the same commands;
the package's code holds no iiwa joint name and no iiwa fact; the description loader
refuses what the controllers could not use, saying how to fix the file.
"""

from __future__ import annotations

import ast
import re
import shutil
from dataclasses import replace
from importlib import resources
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import ideal_sim, paper_config, random_q

import qpavoid
from qpavoid.arm.frames import LWA
from qpavoid.arm.model_checks import CHECK_TOLERANCE
from qpavoid.control.analytic import AnalyticController
from qpavoid.control.qp import QPController
from qpavoid.control.tick import ControllerConfig
from qpavoid.core.errors import InputError, RobotDescriptionError
from qpavoid.loop.run_log import repulsion_keys
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario

PACKAGE = Path(qpavoid.__file__).parent
#: The renames of the copy: every joint of the URDF, and the three sets.
SETS = {"L1": "upper_arm", "L2": "forearm", "EE": "tool"}


def iiwa_copy(folder: Path, edit=None) -> Path:
    """The bundled iiwa description copied into ``folder`` (its control-point file passed
    through ``edit``, a function of its text, if given)."""
    src = resources.files("qpavoid.robots") / "iiwa14"
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("iiwa14.urdf", "control_points.toml"):
        shutil.copy(str(src / name), folder / name)
    if edit is not None:
        path = folder / "control_points.toml"
        path.write_text(edit(path.read_text()))
    return folder


def renamed(text: str) -> str:
    """Every iiwa joint A1..A7 renamed J1..J7 and the sets L1, L2, EE renamed."""
    text = re.sub(r"\bA([1-7])\b", r"J\1", text)
    for old, new in SETS.items():
        text = text.replace(f'"{old}"', f'"{new}"')
    return text


@pytest.fixture(scope="module")
def other(tmp_path_factory) -> qpavoid.Robot:
    """The iiwa under other names: joints J1..J7, sets upper_arm, forearm, tool."""
    folder = iiwa_copy(tmp_path_factory.mktemp("renamed") / "other_arm")
    for name in ("iiwa14.urdf", "control_points.toml"):
        path = folder / name
        path.write_text(renamed(path.read_text()))
    return qpavoid.load_robot(folder)


def test_the_renamed_copy_has_no_iiwa_name_left(other, robot):
    assert other.joint_names == ("J1", "J2", "J4", "J5", "J6", "J7")  # J3 locked, as A3
    assert other.set_names == ("upper_arm", "forearm", "tool")
    assert other.role_names == ("upper_arm", "forearm", "tool")
    assert other.roles == robot.roles.__class__(
        scaled=0,
        scaled_joints=("J1", "J2"),
        repelled=1,
        repelled_joints=("J1", "J2", "J4"),
        end_effector=2,
        elbow=3,
    )
    assert dict(other.arm.max_acceleration_radps2)["J4"] == 11.36
    assert other.ik_seed.aim == "J1" and dict(other.ik_seed.angles) == {
        "J2": 0.5,
        "J4": -1.5,
        "J6": -1.0,
    }
    assert repulsion_keys(other) == ("v_rep_forearm", "v_rep_tool")
    assert repulsion_keys(robot) == ("v_rep_L2", "v_rep_EE")  # the iiwa's log keys, as ever


@pytest.mark.parametrize(
    "controller, safety",
    [  # one in the default suite (its time), the other three with the slow ones
        ("analytic", "ssm"),
        pytest.param("qp", "paper", marks=pytest.mark.slow),  # the default suite's time
        pytest.param("qp", "ssm", marks=pytest.mark.slow),
        pytest.param("analytic", "paper", marks=pytest.mark.slow),
    ],
)
def test_renamed_joints_and_sets_give_the_same_commands(other, robot, controller, safety):
    """Test 1 until the hand is at its closest (12 s at 100 Hz): the repulsion of the
    repelled set and of the end effector acts (the paper's rules) or the separation bounds
    stop the robot (ssm), and every command of the renamed robot equals the iiwa's."""
    logs = []
    for arm in (robot, other):
        cls = AnalyticController if controller == "analytic" else QPController
        if safety == "paper":
            cfg, sim = paper_config(control_period_s=0.01), ideal_sim(control_rate_hz=100.0)
        else:  # the description's reaction time, accelerations and fastest point speed
            cfg = ControllerConfig(control_period_s=0.01, safety="ssm")
            sim = SimConfig(control_rate_hz=100.0)
        sim = replace(sim, max_time_s=12.0)
        logs.append(simulate(cls(arm, config=cfg), make_scenario("test1", arm), sim).log)
    iiwa, renamed_log = logs
    if safety == "paper":  # the repulsion of both sets acts
        assert np.linalg.norm(iiwa["v_rep_L2"], axis=1).max() > 1e-3
        assert np.linalg.norm(iiwa["v_rep_EE"], axis=1).max() > 1e-3
    else:  # the separation bounds (the arm's reaction and braking) stop the robot
        assert any(str(r).startswith("speed and separation") for r in iiwa["stop_reason"])
    np.testing.assert_allclose(renamed_log["dq_command"], iiwa["dq_command"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(renamed_log["q"], iiwa["q"], rtol=0, atol=1e-9)
    for role in (0, 1):
        np.testing.assert_allclose(
            renamed_log[repulsion_keys(other)[role]],
            iiwa[repulsion_keys(robot)[role]],
            rtol=0,
            atol=1e-9,
        )
    reasons = {str(r) for r in iiwa["stop_reason"]}
    names = dict(zip(robot.role_names, other.role_names, strict=True))
    expected = {re.sub(r"\b(L1|L2|EE)\b", lambda m: names[m.group(1)], r) for r in reasons}
    assert {str(r) for r in renamed_log["stop_reason"]} == expected


# --------------------------------------------------------------------------- no iiwa in code

#: An iiwa joint name, or a string naming the iiwa (its maker, its product line).
IIWA = re.compile(r"\bA[1-7]\b|iiwa|kuka|\blbr\b", re.IGNORECASE)


def _docstrings(tree: ast.AST) -> set[int]:
    """Ids of the string constants that are docstrings: a module's, class's or function's
    first statement, and any other bare string statement (an attribute's docstring)."""
    return {
        id(node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Expr)
        and isinstance(node.value, ast.Constant)
        and isinstance(node.value.value, str)
    }


def iiwa_strings(root: Path) -> list[str]:
    """Every string constant of the Python code under ``root`` (docstrings and comments
    aside) that names an iiwa joint or the iiwa, other than the default robot's name."""
    found = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        docs = _docstrings(tree)
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and id(node) not in docs
                and node.value != "iiwa14"
                and IIWA.search(node.value)
            ):
                found.append(f"{path.relative_to(root)}:{node.lineno}: {node.value!r}")
    return found


def test_the_scan_sees_a_joint_name_and_the_iiwa_in_code_not_in_docstrings(tmp_path):
    (tmp_path / "a.py").write_text(
        '"""Module docstring: A1 of the iiwa."""\n'
        "def f():\n"
        '    """A2."""\n'
        "    #: a comment on A3\n"
        '    return ("A4", f"{1} KUKA", "iiwa14", "A10")\n'
    )
    assert iiwa_strings(tmp_path) == ["a.py:5: 'A4'", "a.py:5: ' KUKA'"]


def test_the_package_code_holds_no_iiwa_joint_name_and_no_iiwa_fact():
    """Docstrings and comments may cite the paper's iiwa; code takes it from the robot
    description (robots/iiwa14/), except the default robot's name "iiwa14"."""
    assert iiwa_strings(PACKAGE) == []


# --------------------------------------------------------------------------- refusals


def test_a_capsule_bent_by_a_joint_is_refused_with_the_fix(tmp_path):
    """The forearm's capsule from A3 to A5 spans the elbow A4, which does not turn about
    it: its points do not move as the interpolation of its ends (with A3 locked or free)."""
    folder = iiwa_copy(
        tmp_path / "bent",
        lambda t: t.replace('{ from = "A4", to = "A6"', '{ from = "A3", to = "A5"'),
    )
    for locked in (None, ()):
        with pytest.raises(RobotDescriptionError) as info:
            qpavoid.load_robot(folder, locked=locked)
        err = info.value
        assert err.path == folder / "control_points.toml"
        assert (err.name, err.value) == ("sets.L2.capsule", ["A4"])
        message = str(err)
        assert "capsule of set 'L2' is carried by no single body" in message
        assert "joint(s) ['A4']" in message
        assert "Fix the file: give the set a capsule whose two ends lie on one link" in message


@pytest.mark.parametrize("locked", [None, ()])
def test_the_interpolated_capsule_jacobian_is_pinocchios_at_the_witness_point(locked):
    """What the load-time check guarantees, at random configurations: a point on each
    capsule axis moves as the body that carries it (Pinocchio's Jacobian of the point on
    body carrying the capsule's first end), i.e. as the interpolation."""
    robot = qpavoid.load_robot("iiwa14", locked=locked)
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(7)
    for _ in range(20):
        q = random_q(rng, robot)
        kin = robot.kinematics(q)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for i, cs in enumerate(robot.sets):
            body = model.frames[cs.capsule_frames[0]].parentJoint  # its first end's body
            s = rng.uniform()
            a, b = kin.segments[i]
            point = pin.SE3(np.eye(3), (1 - s) * a + s * b)
            J = pin.getFrameJacobian(model, data, body, data.oMi[body].actInv(point), LWA)[:3]
            np.testing.assert_allclose(
                kin.segment_point_jacobian(i, s), J, rtol=0, atol=CHECK_TOLERANCE
            )


ROLES = '[roles]\nscaled = { set = "L1", joints = ["A1", "A2"] }'


@pytest.mark.parametrize(
    "edit, name, fix",
    [
        (
            lambda t: t[: t.index("[roles]")],
            "roles",
            "no [roles] table; add one, e.g. scaled = {",
        ),
        (
            lambda t: t.replace('repelled = { set = "L2"', 'repelled = { set = "L3"'),
            "roles.repelled.set",
            "[roles] repelled: no set named 'L3'; the sets are ['L1', 'L2', 'EE']",
        ),
        (
            lambda t: t.replace('joints = ["A1", "A2"] }', 'joints = ["A1", "A9"] }'),
            "roles.scaled.joints",
            "roles.scaled.joints: ['A9'] are not joints of the URDF",
        ),
        (
            lambda t: t.replace('end_effector = { set = "EE" }', ""),
            "roles.end_effector",
            "roles needs end_effector = { set = ... } (docs/robot.md: Roles)",
        ),
        (
            lambda t: t.replace('elbow = ["A4"]', 'elbow = ["A9"]'),
            "roles.elbow",
            "[roles] elbow must be one control point as its set's points give it",
        ),
        (
            lambda t: t.replace("A7 = 15.72 }", "}").replace("A6 = 15.72, ", "A6 = 15.72 "),
            "arm.max_acceleration_radps2",
            "must give one limit (rad/s²) for each joint of the URDF",
        ),
        (
            lambda t: t.replace("max_point_speed_mps = 3.0\n", ""),
            "arm.max_point_speed_mps",
            "arm is missing key(s) max_point_speed_mps (docs/robot.md: Arm)",
        ),
        (
            lambda t: t.replace("reaction_time_s = 0.005\n", "reaction_time_s = -1.0\n"),
            "arm.reaction_time_s",
            "arm.reaction_time_s must be a number at least 0 and at most 0.1, got -1.0",
        ),
        (
            lambda t: t.replace('aim = "A1"', 'aim = "flange"'),
            "ik_seed.aim",
            "ik_seed.aim: ['flange'] are not joints of the URDF",
        ),
        (
            lambda t: t.replace("[roles]\n", "[roles]\nscaled_joints = []\n"),
            "roles.scaled_joints",
            "roles has unknown key(s) ['scaled_joints']",
        ),
        (  # a unit error: a reaction time in ms
            lambda t: t.replace("reaction_time_s = 0.005", "reaction_time_s = 5.0"),
            "arm.reaction_time_s",
            "arm.reaction_time_s must be a number at least 0 and at most 0.1, got 5.0",
        ),
        (
            lambda t: t.replace("A1 = 8.57", "A1 = 1e-300"),
            "arm.max_acceleration_radps2.A1",
            "max_acceleration_radps2.A1 must be a number at least 0.1 and at most 100,",
        ),
        (
            lambda t: t.replace("max_point_speed_mps = 3.0", "max_point_speed_mps = 3000.0"),
            "arm.max_point_speed_mps",
            "arm.max_point_speed_mps must be a number above 0 and at most 10, got 3000.0",
        ),
        (  # a misspelt top-level key would silently keep the default
            lambda t: t.replace("locked =", "lockd =", 1),
            "lockd",
            "the top level has unknown key(s) ['lockd']",
        ),
        (
            lambda t: t.replace(
                "sphere_radius_m = 0.09", "sphere_radus_m = 0.09\nsphere_radius_m = 0.09", 1
            ),
            "sets[0].sphere_radus_m",
            "sets[0] has unknown key(s) ['sphere_radus_m']",
        ),
        (
            lambda t: t.replace("capsule_radius_m = 0.07", "capsule_radius_m = -0.07", 1),
            "sets[0].capsule.capsule_radius_m",
            "sets[0].capsule.capsule_radius_m must be a number above 0 and at most 1, got -0.07",
        ),
        (
            lambda t: t.replace("sphere_radius_m = 0.09", "sphere_radius_m = 0", 1),
            "sets[0].sphere_radius_m",
            "sets[0].sphere_radius_m must be a number above 0 and at most 1, got 0",
        ),
        (  # roles would resolve to the first of two sets of one name
            lambda t: t.replace('name = "L2"', 'name = "L1"'),
            "sets[1].name",
            "[[sets]] entry 1: the name 'L1' is already entry 0's; give each set a name of",
        ),
        (  # set names become file names (fig10_distance_<name>.png)
            lambda t: t.replace('name = "L2"', 'name = "L/2"'),
            "sets[1].name",
            "name must be letters, digits, '_', '.' and '-' only",
        ),
        (  # A7 comes after every point of L2 in the chain
            lambda t: t.replace('joints = ["A1", "A2", "A4"]', 'joints = ["A5", "A6", "A7"]'),
            "roles.repelled.joints",
            "[roles] repelled.joints: ['A7'] move no point of the set 'L2' (they come after "
            "its points in the URDF's chain); the joints that move it are ['A1', 'A2', 'A3', "
            "'A4', 'A5', 'A6']: name those",
        ),
        (
            lambda t: t.replace('joints = ["A1", "A2", "A4"]', 'joints = ["A1", "A1", "A4"]'),
            "roles.repelled.joints",
            "[roles] repelled.joints lists ['A1'] more than once",
        ),
        (
            lambda t: t.replace('joints = ["A1", "A2"]', "joints = []"),
            "roles.scaled.joints",
            "[roles] scaled.joints is empty; name each joint that moves the set 'L1' once",
        ),
        (
            lambda t: t.replace('joints = ["A1", "A2", "A4"]', "joints = []"),
            "roles.repelled.joints",
            "[roles] repelled.joints is empty",
        ),
        (  # a role's joint locked by the file
            lambda t: t.replace("locked = { A3 = 0.0 }", "locked = { A4 = 0.0 }"),
            "roles.repelled.joints",
            "[roles] repelled.joints: ['A4'] locked (by the file's `locked`); a role's joints "
            "must be free",
        ),
        (  # nothing left to move (Pinocchio crashed on the empty model)
            lambda t: t.replace(
                "locked = { A3 = 0.0 }", 'locked = ["A1", "A2", "A3", "A4", "A5", "A6", "A7"]'
            ),
            "locked",
            "the file's `locked` locks every joint",
        ),
        (
            lambda t: t.replace("locked = { A3 = 0.0 }", "locked = { A3 = 10.0 }"),
            "locked.A3",
            "locked: A3 = 10.0 is not within the joint's limits [-2.96706, 2.96706] rad",
        ),
        (
            lambda t: t.replace("locked = { A3 = 0.0 }", "locked = { A3 = nan }"),
            "locked.A3",
            "locked: A3 = nan is not within the joint's limits",
        ),
        (
            lambda t: t.replace("locked = { A3 = 0.0 }", "locked = { A9 = 0 }"),
            "locked",
            "locked: 'A9' is not a joint of the URDF; its joints are ['A1', 'A2',",
        ),
        (
            lambda t: t.replace("locked = { A3 = 0.0 }", "locked = 3"),
            "locked",
            "locked must be a table of angles (rad), e.g. locked = { <joint> = 0.0 }, or a list",
        ),
        *(
            (
                lambda t, bad=bad: t.replace('points = [["flange"]]', f"points = {bad}"),
                "sets[2].points",
                "sets[2].points must be a non-empty list of control points, each the "
                'list of the frames it is the centroid of, e.g. points = [["<frame>"], '
                '["<frame>", "<frame>"], { frame = "<frame>", xyz = [x, y, z] }]',
            )
            for bad in ("[]", "[[]]", '["flange"]')  # '["flange"]' was read letter by letter
        ),
        (
            lambda t: t.replace('["A5"]', '["X"]'),
            "sets[1].points[1]",
            "[[sets]] entry 1 (L2) points[1]: no frame named 'X' in iiwa14.urdf; its frames "
            "are [link_0, A1, link_1,",
        ),
        (
            lambda t: t.replace('from = "A6"', 'from = "X"'),
            "sets[2].capsule.from",
            "[[sets]] entry 2 (EE) capsule.from: no frame named 'X' in iiwa14.urdf",
        ),
        (
            lambda t: t.replace('end_effector = { set = "EE" }', 'end_effector = { set = "L1" }'),
            "roles.end_effector.set",
            "the end_effector frame 'flange' must lie in the end-effector set's capsule; it is "
            "on another body than the capsule (set 'L1'): name the set whose capsule holds it",
        ),
        (
            lambda t: t.replace('end_effector = "flange"', 'end_effector = "tool"'),
            "end_effector",
            "end_effector 'tool' is not a frame of iiwa14.urdf",
        ),
    ],
)
def test_description_refusals_say_how_to_fix_the_file(tmp_path, edit, name, fix):
    folder = iiwa_copy(tmp_path / "arm", edit)
    with pytest.raises(RobotDescriptionError) as info:
        qpavoid.load_robot(folder)
    assert info.value.path == folder / "control_points.toml"
    assert info.value.name == name
    assert fix in str(info.value)


def test_the_file_may_lock_a_list_of_joints_at_zero(tmp_path, robot):
    """``locked = ["A3"]`` is ``locked = { A3 = 0.0 }``."""
    folder = iiwa_copy(tmp_path / "arm", lambda t: t.replace("{ A3 = 0.0 }", '["A3"]'))
    listed = qpavoid.load_robot(folder)
    assert listed.locked == {"A3": 0.0} and listed.joint_names == robot.joint_names
    q = np.linspace(-0.5, 0.5, 6)
    np.testing.assert_array_equal(listed.control_points(q), robot.control_points(q))


@pytest.mark.parametrize(
    "locked, name, fix",
    [
        (
            ["A1", "A2", "A3", "A4", "A5", "A6", "A7"],
            "locked",
            "the locked= argument locks every joint, ['A1', 'A2', 'A3', 'A4', 'A5', 'A6', "
            "'A7']: nothing is left to move",
        ),
        (
            ["A2"],
            "roles.scaled.joints",
            "[roles] scaled.joints: ['A2'] locked (by the locked= argument); a role's joints "
            "must be free: unlock them, or name free joints in [roles] scaled.joints",
        ),
    ],
)
def test_locking_what_the_description_needs_is_refused(locked, name, fix):
    """The argument ``locked`` may not take the description's role joints or every joint:
    refused at load time (the controllers, or Pinocchio, failed later)."""
    with pytest.raises(RobotDescriptionError) as info:
        qpavoid.load_robot("iiwa14", locked=locked)
    assert info.value.path == resources.files("qpavoid.robots") / "iiwa14" / "control_points.toml"
    assert info.value.name == name
    assert fix in str(info.value)


@pytest.mark.parametrize(
    "locked, fix",
    [
        ({"A3": float("nan")}, "cannot lock A3 at nan rad: not within the joint's limits"),
        ({"A3": 10.0}, "cannot lock A3 at 10.0 rad: not within the joint's limits"),
        ("A3", "locked must be joint names or a mapping of joint names to angles (rad)"),
    ],
)
def test_a_locked_argument_out_of_the_joint_limits_is_an_input_error(locked, fix):
    with pytest.raises(InputError) as info:
        qpavoid.load_robot("iiwa14", locked=locked)
    assert info.value.name == "locked"
    assert fix in str(info.value)


@pytest.mark.parametrize(
    "edit, fault",
    [
        (
            lambda u: u.replace('name="A7" type="revolute"', 'name="A7" type="continuous"'),
            "it is a JointModelRUBZ (nq = 2, nv = 1)",
        ),
        (
            lambda u: u.replace('name="A7" type="revolute"', 'name="A7" type="floating"'),
            "it is a JointModelFreeFlyer (nq = 7, nv = 6)",
        ),
        (
            lambda u: re.sub(
                r'(<joint name="A7".*?<limit) lower="[^"]*" upper="[^"]*"', r"\1", u, flags=re.S
            ),
            "its position limits are [0, 0]",
        ),
        (
            lambda u: re.sub(r'(<joint name="A7".*?velocity=")[^"]*"', r'\g<1>0"', u, flags=re.S),
            "its velocity limit is 0",
        ),
    ],
)
def test_joints_without_one_limited_degree_of_freedom_are_refused(tmp_path, edit, fault):
    folder = iiwa_copy(tmp_path / "arm")
    urdf = folder / "iiwa14.urdf"
    urdf.write_text(edit(urdf.read_text()))
    with pytest.raises(RobotDescriptionError) as info:
        qpavoid.load_robot(folder)
    assert (info.value.path, info.value.name) == (urdf, "A7")
    assert f"joint 'A7': {fault}; only revolute and prismatic joints with limits are " in str(
        info.value
    )


def test_an_oversized_control_point_file_is_refused_unread(tmp_path):
    folder = iiwa_copy(tmp_path / "arm", lambda t: t + "#" + "x" * 2**20 + "\n")
    with pytest.raises(RobotDescriptionError) as info:
        qpavoid.load_robot(folder)
    assert info.value.path == folder / "control_points.toml"
    assert "cannot read the file: 1" in str(info.value)
    assert f"more than the {2**20} allowed" in str(info.value)


def test_iiwa_defaults_come_from_the_description(robot):
    """What was code is the file's: the scaled and repelled joints, the elbow, the arm's
    reaction and accelerations (with their sources), its fastest point, the IK seed."""
    assert robot.role_names == ("L1", "L2", "EE")
    assert robot.roles.scaled_joints == ("A1", "A2")
    assert robot.roles.repelled_joints == ("A1", "A2", "A4")
    assert robot.point_frames[robot.roles.elbow] == robot.model.getFrameId("L1_p3")  # A4
    assert robot.arm.reaction_time_s == 0.005 and robot.arm.max_point_speed_mps == 3.0
    assert dict(robot.arm.max_acceleration_radps2) == {
        "A1": 8.57, "A2": 8.57, "A3": 8.74, "A4": 11.36, "A5": 12.23, "A6": 15.72, "A7": 15.72,
    }  # fmt: skip
    assert {k for k, _ in robot.arm.sources} == {
        "reaction_time_s",
        "max_acceleration_radps2",
        "max_point_speed_mps",
        "rated_payload_kg",
    }
    assert robot.arm.rated_payload_kg == 14.0  # the iiwa 14 R820's
    assert robot.ik_seed.wrist_to_tool_m == 0.126
    ctrl = AnalyticController(robot)  # the settings' None: the description's joints
    assert robot.joint_names[ctrl.limits.scaled_cols[0]] == "A1"
    assert [robot.joint_names[c] for c in ctrl.repelled_cols] == ["A1", "A2", "A4"]
    assert ctrl.ssm.max_acceleration_radps2 == robot.arm.max_acceleration_radps2
