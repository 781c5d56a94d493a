"""The planned path and the start configuration."""

from __future__ import annotations

import numpy as np
import pytest

from qpavoid.control.task import A_FIN, A_IN, ArcPath, inverse_kinematics, quintic
from qpavoid.core.errors import InputError


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
