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


@pytest.mark.parametrize("arm", ["iiwa14", "panda", "fr3", "ur5"])
def test_the_frames_positions_read_through_one_view_are_pinocchios(arm):
    """Positions gathered through the view over ``data.oMf`` equal each frame's own
    placement computed in other data, bit for bit; a copy for a thread and a pickled copy
    read their own data (no memory shared), and without the view (read one by one) the
    kinematics are the same."""
    import pickle

    robot = qpavoid.load_robot(arm)
    view = robot._held[3]
    assert view is not None  # Pinocchio's vector at one stride
    model, data = robot.model, robot.model.createData()
    others = [robot.for_thread(), pickle.loads(pickle.dumps(robot))]
    for other in others:
        assert not np.shares_memory(other._held[3], view)
    one_by_one = robot.for_thread()
    one_by_one._held = (*one_by_one._held[:3], None)
    rng = np.random.default_rng(5)
    for _ in range(30):
        q = random_q(rng, robot)
        kin = robot.kinematics(q)
        pin.framesForwardKinematics(model, data, q)
        points = np.array([data.oMf[f].translation for f in robot.point_frames])
        assert np.array_equal(kin.points, points)
        for i, s in enumerate(robot.sets):
            for end, f in enumerate(s.capsule_frames):
                assert np.array_equal(kin.segments[i, end], data.oMf[f].translation)
        assert np.array_equal(kin.ee_placement, data.oMf[robot.ee_frame].homogeneous)
        ref = one_by_one.kinematics(q)
        assert np.array_equal(kin.points, ref.points)
        assert np.array_equal(kin.point_jacobians, ref.point_jacobians)
        q2 = random_q(rng, robot)
        for other in others:  # another data moved elsewhere leaves this one's as it was
            other.kinematics(q2)
        assert np.array_equal(robot.kinematics(q).points, kin.points)
