"""A fifth arm, added as a user would: a URDF and a description in a temporary folder, no
code change (docs/robot.md, "Adding an arm"). The UR10 of example-robot-data: its geometry
from ``fit_description``, its roles, dynamics, IK seed and task written here."""

from __future__ import annotations

import importlib.metadata
import json
import re
from pathlib import Path

import numpy as np
import pytest

from qpavoid.arm.fit import fit_description
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import load_robot
from qpavoid.arm.reach import arm_reach, shoulder_centre
from qpavoid.arm.urdf import mesh_dirs
from qpavoid.control.task import default_task
from qpavoid.experiments.campaign import campaign_spec
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.runs import simulate_one
from qpavoid.experiments.sweep import run_case

UR10 = "cmeel.prefix/share/example-robot-data/robots/ur_description/urdf/ur10_robot.urdf"
ROBOTS = Path(__file__).resolve().parents[1] / "robots"

try:
    ERD = Path(str(importlib.metadata.distribution("example-robot-data").locate_file(UR10)))
except importlib.metadata.PackageNotFoundError:
    ERD = None
pytestmark = pytest.mark.skipif(
    ERD is None, reason="the extra 'robots' (example-robot-data) is missing"
)

#: What the user writes in place of the fitted file's TO DO lines (the UR5's choices: the
#: UR10 is the same kinematic design, longer).
ROLES = """[roles]
scaled = { set = "upper_arm", joints = ["shoulder_pan_joint", "shoulder_lift_joint"] }
repelled = { set = "forearm", joints = ["shoulder_pan_joint", "shoulder_lift_joint", \
"elbow_joint"] }
end_effector = { set = "wrist_3" }
"""
ARM = """[arm]
reaction_time_s = 0.008
max_acceleration_radps2 = { shoulder_pan_joint = 5.0, shoulder_lift_joint = 5.0, \
elbow_joint = 5.0, wrist_1_joint = 5.0, wrist_2_joint = 5.0, wrist_3_joint = 5.0 }
max_point_speed_mps = 10.0

[arm.sources]
reaction_time_s = "one CB3 control period (125 Hz), as the UR5's"
max_acceleration_radps2 = "a slow-side value for the test (UR publishes none)"
max_point_speed_mps = "the loader's ceiling"

[ik_seed]
aim = "shoulder_pan_joint"
# the branch of the UR5's start configuration (the seed a user finds by solving the pose
# on the UR5)
angles = { shoulder_lift_joint = -1.08, elbow_joint = 1.385, wrist_1_joint = -0.834, \
wrist_2_joint = 1.42, wrist_3_joint = -1.483 }
wrist_to_tool_m = 0.0922
"""


def _replace_section(text: str, header: str, new: str) -> str:
    """``text`` with the TOML table ``header`` (up to the next comment block or table that
    is not its own sub-table) replaced by ``new``."""
    lines = text.splitlines()
    start = lines.index(header)
    end = start + 1
    while end < len(lines) and not (
        lines[end].startswith("[") and not lines[end].startswith(header[:-1] + ".")
    ):
        end += 1
    while lines[end - 1].startswith("#"):  # the next table's comments
        end -= 1
    return "\n".join([*lines[:start], new, *lines[end:]]) + "\n"


@pytest.fixture(scope="module")
def ur10(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("arms") / "ur10"
    folder.mkdir()
    text = fit_description(
        ERD,
        urdf_entry={"package": "example-robot-data", "path": UR10},
        package_dirs=mesh_dirs(ERD),
        merge=["ee_fixed_joint"],
    )
    text = re.sub(r'^end_effector = "TO DO[^"]*"', 'end_effector = "tool0"', text, flags=re.M)
    text = _replace_section(text, "[roles]", ROLES)
    text = _replace_section(text, "[arm]", ARM)
    (folder / "control_points.toml").write_text(text)
    # the UR5's task scaled by the reach, about the shoulder centre (docs/robot.md, Tasks);
    # the seat moved back as far again as the UR5's (its tool reaches further)
    ur5, ur10 = load_robot("ur5"), load_robot(folder)
    frame = "shoulder_lift_joint"
    s = arm_reach(ur10, frame, samples=200)[0] / arm_reach(ur5, frame, samples=200)[0]
    c5, c10 = shoulder_centre(ur5, frame), shoulder_centre(ur10, frame)
    task = (ROBOTS / "ur5" / "task.toml").read_text()
    for line in [ln for ln in task.splitlines() if ln.startswith("position_m = ")]:
        p = np.array(json.loads(line.split("=", 1)[1].split("#")[0]))
        task = task.replace(line, f"position_m = {list(map(float, c10 + s * (p - c5)))}")
    ur5_task = default_task(ur5)
    shift = s * (ur5_task.path.start[1, 3] - c5[1]) + c10[1] - ur5_task.path.start[1, 3]
    seat = ur5_task.operator.distance_m + shift  # as far from the path as the UR5's
    task = re.sub(r"^distance_m = .*$", f"distance_m = {seat:.4f}", task, flags=re.M)
    (folder / "task.toml").write_text(re.sub(r"^\[scaling\][^[]*", "", task, flags=re.M))
    return folder


def test_the_fifth_arm_loads_with_its_own_geometry(ur10):
    robot = load_robot(ur10)
    assert robot.nv == 6 and 'TO DO"' not in (ur10 / "control_points.toml").read_text()
    assert robot.role_names == ("upper_arm", "forearm", "wrist_3")
    # the UR10's upper arm is 0.612 m long: longer than any UR5 link
    upper = robot.sets[robot.set_index("upper_arm")]
    a, b = (robot.model.frames[f].placement.translation for f in upper.capsule_frames)
    assert np.linalg.norm(b - a) > 0.55
    task = default_task(robot)
    q0 = inverse_kinematics(robot, task.path.reference(0.0)[0])
    assert np.all((q0 >= robot.q_min) & (q0 <= robot.q_max))


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["analytic", "qp"])
def test_the_fifth_arm_runs_free_to_its_goal(ur10, controller):
    spec = RunSpec(
        scenario="free", controller=controller, robot=str(ur10), rate_hz=100.0, max_time_s=16.0
    )
    run = simulate_one(spec)
    log = run.sim.log
    ee_error = np.linalg.norm(log["ee_pos"][-1] - task_goal(ur10))
    assert ee_error < 1e-3
    assert not log["stopped"][-10:].any()


def task_goal(folder: Path) -> np.ndarray:
    robot = load_robot(folder)
    path = default_task(robot).path
    return path.reference(path.duration_s)[0][:3, 3]


@pytest.mark.slow
def test_a_strike_at_the_fifth_arm_never_finds_it_moving_in_contact(ur10):
    spec = campaign_spec("qp", robot=str(ur10))
    check = run_case(spec, 0)
    assert check.target in (*load_robot(ur10).set_names, "shoulder", "base")
    assert check.ticks_moving_in_true_contact == 0
    assert check.moving_s > 0.5  # it worked, not only stood still
