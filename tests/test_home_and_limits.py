"""The arm's home configuration and the joint limits a given configuration must keep
(issue 46, item 6.1: ``robot.neutral()`` put the Panda's joint 4 at 0, outside its range,
and ``check_q`` let it through).

Every shipped arm's ``neutral()`` is within its limits: the Franka arms' is Franka's
ready pose (their description's ``home``), the iiwa's and the UR5's every joint at 0 (0 is
inside their ranges). ``check_q`` refuses an angle past a limit by more than
``Q_LIMIT_TOLERANCE_RAD``, naming the joint, the angle and the limits, on the paths where
a configuration is given (a simulation's start, a simulated arm's); the kinematics still
take any finite configuration.
"""

from __future__ import annotations

import math
import re
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest

import qpavoid
from qpavoid.arm.description import bundled_robots
from qpavoid.arm.model import Q_LIMIT_TOLERANCE_RAD
from qpavoid.core.errors import InputError, RobotDescriptionError
from qpavoid.drive.simulated import SimulatedArm
from qpavoid.scenarios.generated import make_scenario

#: The package each shipped arm's URDF comes from (None: in the repository).
PACKAGES = {
    "iiwa14": None,
    "panda": "example-robot-data",
    "fr3": "franky-sim",
    "ur5": "example-robot-data",
}
#: Franka's ready pose, joints 1-7 (rad): libfranka's examples' start.
READY = (0.0, -math.pi / 4, 0.0, -3 * math.pi / 4, 0.0, math.pi / 2, math.pi / 4)


def _arm(name: str, **kw) -> qpavoid.Robot:
    if PACKAGES[name] is not None:
        try:
            metadata.distribution(PACKAGES[name])
        except metadata.PackageNotFoundError:
            pytest.skip(f"{PACKAGES[name]} is not installed (the extra 'robots')")
    return qpavoid.load_robot(name, **kw)


def test_every_shipped_arm_is_checked_here():
    assert set(bundled_robots()) == set(PACKAGES)


@pytest.mark.parametrize("name", sorted(PACKAGES))
def test_neutral_is_within_the_limits(name):
    robot = _arm(name)
    q = robot.neutral()
    assert q.shape == (robot.nq,)
    assert np.all(robot.q_min <= q) and np.all(q <= robot.q_max)
    assert np.array_equal(robot.check_q(q), q)
    q[0] += 1.0  # a copy: the robot's home is its own
    assert robot.neutral()[0] != q[0]


@pytest.mark.parametrize("name", ["panda", "fr3"])
def test_a_franka_arms_home_is_the_ready_pose(name):
    """Joint 3 locked at 0 (the description's): the six others of the ready pose; with
    joint 3 freed, all seven. Every joint at 0 is outside joint 4's range [-3.07, -0.07]."""
    robot = _arm(name)
    assert robot.joint_names == tuple(f"{name}_joint{k}" for k in (1, 2, 4, 5, 6, 7))
    assert np.allclose(robot.neutral(), [READY[k - 1] for k in (1, 2, 4, 5, 6, 7)], atol=1e-15)
    free = _arm(name, locked=())
    assert free.nq == 7 and np.allclose(free.neutral(), READY, atol=1e-15)
    assert not robot.q_min[2] <= 0.0 <= robot.q_max[2]  # the old neutral was out


@pytest.mark.parametrize("name", ["iiwa14", "ur5"])
def test_an_arm_whose_zero_is_inside_its_limits_stays_at_zero(name):
    robot = _arm(name)
    assert np.array_equal(robot.neutral(), np.zeros(robot.nq))


def _copy_without_home(tmp_path: Path, name: str) -> Path:
    """The shipped description ``name`` in a temporary folder, its ``home`` line removed."""
    source = Path(str(_arm(name).path))
    text = source.read_text()
    home = re.search(r"^home = .*\n", text, re.M)
    assert home is not None
    folder = tmp_path / f"{name}_nohome"
    folder.mkdir()
    (folder / "control_points.toml").write_text(text[: home.start()] + text[home.end() :])
    return folder


def test_without_a_home_a_joint_whose_range_misses_zero_sits_mid_range(tmp_path):
    """The Panda without its ``home``: joint 4's range [-3.0718, -0.0698] misses 0, so it
    sits at its middle, -1.5708 rad; joint 6's [-0.0175, 3.7525] holds 0."""
    robot = qpavoid.load_robot(_copy_without_home(tmp_path, "panda"))
    q = robot.neutral()
    assert q[2] == pytest.approx((-3.0718 - 0.0698) / 2, abs=1e-12)
    assert np.array_equal(np.delete(q, 2), np.zeros(5))
    robot.check_q(q)


@pytest.mark.parametrize(
    "line, word",
    [
        ("home = { panda_joint4 = 0.0 }", "panda_joint4 = 0.0: not within the joint's limits"),
        ("home = { panda_joint9 = 0.0 }", "'panda_joint9' is not a joint of the URDF"),
        ('home = { panda_joint4 = "up" }', "home.panda_joint4 must be an angle (rad), got 'up'"),
        ("home = [0.0, 0.0]", "home must be a table of joint angles"),
    ],
)
def test_a_home_outside_the_limits_is_refused(tmp_path, line, word):
    folder = _copy_without_home(tmp_path, "panda")
    file = folder / "control_points.toml"
    text = file.read_text()
    anchor = text.index("\n[[sets]]")
    file.write_text(text[:anchor] + "\n" + line + text[anchor:])
    with pytest.raises(RobotDescriptionError) as info:
        qpavoid.load_robot(folder)
    assert info.value.name.startswith("home") and word in str(info.value)


@pytest.mark.parametrize("name", sorted(PACKAGES))
def test_check_q_refuses_just_outside_and_accepts_just_inside(name):
    """Each joint in turn, from the home configuration: at its limits and a µrad inside
    them accepted, a tolerance's fraction past them too (round-off), twice the tolerance
    and 0.01 rad past them refused, naming the joint, the angle and the limits."""
    robot = _arm(name)
    home = robot.neutral()
    tol = Q_LIMIT_TOLERANCE_RAD
    for i, joint in enumerate(robot.joint_names):
        lo, hi = robot.q_min[i], robot.q_max[i]
        for inside in (lo, hi, lo + 1e-6, hi - 1e-6, lo - 0.5 * tol, hi + 0.5 * tol):
            q = home.copy()
            q[i] = inside
            assert robot.check_q(q)[i] == inside
        for outside in (lo - 2 * tol, hi + 2 * tol, lo - 0.01, hi + 0.01):
            q = home.copy()
            q[i] = outside
            with pytest.raises(InputError) as info:
                robot.check_q(q)
            message = str(info.value)
            assert f"{joint} = {outside:.6g} rad is outside its limits" in message
            assert f"[{lo:.6g}, {hi:.6g}] rad" in message
            assert info.value.name == "q" and "\n" not in message


def test_check_q_names_the_first_joint_out_and_counts_the_others():
    """The Panda at every joint 0: joint 4 (the third active joint) alone is out."""
    panda = _arm("panda")
    with pytest.raises(InputError, match=r"panda_joint4 = 0 rad is outside its limits "):
        panda.check_q(np.zeros(6))
    q = panda.neutral()
    q[[0, 2]] = 10.0  # two joints out
    with pytest.raises(InputError, match=r"panda_joint1 = 10 rad .* \(and 1 more joints\)"):
        panda.check_q(q)


def test_check_q_still_refuses_a_wrong_shape_or_a_nan(robot):
    with pytest.raises(InputError, match="q"):
        robot.check_q(np.zeros(robot.nq + 1))
    q = robot.neutral()
    q[0] = np.nan
    with pytest.raises(InputError):
        robot.check_q(q)


def test_a_start_outside_the_limits_is_refused_where_it_is_given(robot):
    """A simulation's start and a simulated arm's: refused before the first tick."""
    q0 = robot.neutral()
    q0[1] = robot.q_max[1] + 0.01
    controller = qpavoid.AnalyticController(robot)
    with pytest.raises(InputError, match=f"{robot.joint_names[1]} = "):
        qpavoid.simulate(controller, make_scenario("free", robot), q0=q0)
    with pytest.raises(InputError, match="outside its limits"):
        SimulatedArm(robot, q0)


def test_the_kinematics_take_any_finite_configuration(robot):
    """Finite differences step past a limit, an arm may read a hair past one: the
    kinematics are not a gate (only check_q is)."""
    q = robot.q_max + 0.01
    kin = robot.kinematics(q)
    ahead = robot.kinematics(q + 1e-7 * np.eye(robot.nq)[0], jacobians=False)
    velocity = (ahead.points - kin.points) / 1e-7  # joint 1 at 1 rad/s
    assert np.allclose(velocity, kin.point_jacobians[:, :, 0], atol=1e-5)
