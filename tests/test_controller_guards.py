"""What a controller refuses or stops on whatever robot and camera it is given: a frame of
another skeleton format, a robot set that plays no part in the laws touching the person."""

from __future__ import annotations

import shutil
from importlib import resources

import numpy as np
import pytest

import qpavoid
from qpavoid.core.errors import InputError
from qpavoid.human.frames import HumanFrame
from qpavoid.human.people import People
from qpavoid.human.posture import Operator

IIWA = resources.files("qpavoid.robots") / "iiwa14"


@pytest.mark.parametrize("controller", [qpavoid.AnalyticController, qpavoid.QPController])
@pytest.mark.parametrize("n_joints", [17, 33])
def test_a_frame_of_another_skeleton_is_refused_not_read(robot, controller, n_joints):
    """A checked frame of another format (17 COCO keypoints, 33 MediaPipe landmarks) read
    with the Kinect v2's joint order would be another body: refused by its size."""
    rng = np.random.default_rng(n_joints)
    frame = HumanFrame(rng.uniform(0.3, 0.8, (n_joints, 3)), np.full(n_joints, 2, np.int8))
    ctrl = controller(robot)
    for given in (frame, People((0,), (frame,))):
        with pytest.raises(InputError, match=f"a frame of {n_joints} joints"):
            ctrl.step(robot.neutral(), given, None, t=0.0)


def test_a_set_with_no_part_in_the_laws_stops_the_robot_when_it_touches(tmp_path):
    """An extra set (a column around the base, no role) touched by the hand while every set
    that plays a part is far: the paper's controller has no law for it, and stops."""
    folder = tmp_path / "arm"
    folder.mkdir()
    for name in ("iiwa14.urdf", "control_points.toml"):
        shutil.copy(str(IIWA / name), folder / name)
    toml = folder / "control_points.toml"
    toml.write_text(
        toml.read_text().replace(
            "[roles]",
            '[[sets]]\nname = "column"\nsphere_radius_m = 0.12\npoints = [["A1"]]\n'
            'capsule = { from = "link_0", to = "A2", capsule_radius_m = 0.11 }\n\n[roles]',
            1,
        )
    )
    robot = qpavoid.load_robot(folder)
    column = robot.set_names.index("column")
    q = np.array([0.0, 1.2, -0.5, 0.0, 0.0, 0.0])  # leaning forward: L1, L2, EE far from it
    ctrl = qpavoid.AnalyticController(robot)
    segment = robot.kinematics(q).segments[column]
    rest = Operator().rest()
    rng = np.random.default_rng(1)
    touched = 0
    for _ in range(400):
        p = segment[0] + rng.uniform() * (segment[1] - segment[0])
        joints = rest + (p - rest[11]) + rng.normal(0.0, 0.05, 3)  # the right hand at p
        d = qpavoid.capsule_distances(robot, q, ctrl.human, joints).distance.min(axis=1)
        others = np.delete(d, column)
        if d[column] > 0.0 or others.min() < 0.15:  # no stop rule of the paper's holds
            continue
        touched += 1
        cmd = ctrl.step(q, joints, None, t=0.0)
        assert cmd.stopped and cmd.reason.startswith("column touches the person"), cmd.reason
        assert not np.any(cmd.dq)
    assert touched >= 5
