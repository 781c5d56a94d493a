"""The frames' Jacobians of a tick (one compiled call from the joints' Jacobian) against
Pinocchio's own ``getFrameJacobian``, frame by frame, on every shipped arm."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_q

import qpavoid

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@pytest.mark.parametrize("arm", ["iiwa14", "panda", "fr3", "ur5"])
def test_every_frames_jacobian_is_pinocchios(arm):
    robot = qpavoid.load_robot(arm)
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(23)
    for _ in range(50):
        q = random_q(rng, robot)
        kin = robot.kinematics(q)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        points = np.array(
            [pin.getFrameJacobian(model, data, f, LWA)[:3] for f in robot.point_frames]
        )
        np.testing.assert_allclose(kin.point_jacobians, points, atol=1e-12)
        ee = pin.getFrameJacobian(model, data, robot.ee_frame, LWA)
        np.testing.assert_allclose(kin.ee_jacobian, ee, atol=1e-12)
        for i, s in enumerate(robot.sets):  # the capsules' ends
            for end, f in enumerate(s.capsule_frames):
                ref = pin.getFrameJacobian(model, data, f, LWA)[:3]
                np.testing.assert_allclose(kin.segment_jacobians[i, end], ref, atol=1e-12)
        assert kin.point_jacobians.flags.c_contiguous  # as the kernels after it take them
