"""The frames' Jacobians of a tick from the joints' Jacobian, compiled (numba).

:meth:`~qpavoid.arm.model.Robot.kinematics` asks Pinocchio for the joints' Jacobian once
(``computeJointJacobians``: ``J``, 6 × nv, the world frame) and for the frames'
placements, then forms every frame's Jacobian here in one call instead of one
``getFrameJacobian`` call per frame from Python. A point p fixed on the body of joint i
moves at ``v_p = v_o + ω × p`` for the body's twist (v_o, ω) at the world origin, so its
Jacobian in the local world-aligned frame (LWA) is, column by column,

    J_p[:, k] = J[:3, k] + J[3:, k] × p     for the joints k that carry joint i,

and 0 for the others (the ``support`` mask, from ``model.supports``). The angular rows
are ``J[3:, k]`` on the same columns. tests/test_robot.py holds them to Pinocchio's own
``getFrameJacobian`` on every arm.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.core.compiling import ctrl_c_deferred

__all__ = ["frame_jacobians", "warm_up"]


@njit(cache=True)
def frame_jacobians(
    joint_jacobian_t: np.ndarray,
    positions: np.ndarray,
    support: np.ndarray,
    ee_position: np.ndarray,
    ee_support: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The LWA Jacobians of the points ``positions`` (F, 3), m, each carried by the joints
    ``support[f]`` (F, nv) marks, and of the end effector at ``ee_position`` (3,) carried
    by ``ee_support`` (nv,), from the world-frame joint Jacobian, given transposed
    (``joint_jacobian_t`` (nv, 6): Pinocchio's ``data.J.T``, a C-ordered view).

    Returns
    -------
    linear
        (F, 3, nv) the points' linear rows ``J[:3] + J[3:] × p``.
    end_effector
        (6, nv) the end effector's linear and angular rows.
    """
    n_frames, nv = positions.shape[0], joint_jacobian_t.shape[0]
    linear = np.zeros((n_frames, 3, nv))
    end_effector = np.zeros((6, nv))
    for k in range(nv):
        vx, vy, vz = joint_jacobian_t[k, 0], joint_jacobian_t[k, 1], joint_jacobian_t[k, 2]
        wx, wy, wz = joint_jacobian_t[k, 3], joint_jacobian_t[k, 4], joint_jacobian_t[k, 5]
        for f in range(n_frames):
            if support[f, k]:
                px, py, pz = positions[f, 0], positions[f, 1], positions[f, 2]
                linear[f, 0, k] = vx + wy * pz - wz * py
                linear[f, 1, k] = vy + wz * px - wx * pz
                linear[f, 2, k] = vz + wx * py - wy * px
        if ee_support[k]:
            px, py, pz = ee_position[0], ee_position[1], ee_position[2]
            end_effector[0, k] = vx + wy * pz - wz * py
            end_effector[1, k] = vy + wz * px - wx * pz
            end_effector[2, k] = vz + wx * py - wy * px
            end_effector[3, k], end_effector[4, k], end_effector[5, k] = wx, wy, wz
    return linear, end_effector


@functools.cache
def warm_up() -> None:
    """Compile (or load from the disk cache) the kernel, once per process."""
    with ctrl_c_deferred():
        frame_jacobians(
            np.zeros((2, 6)),
            np.zeros((3, 3)),
            np.ones((3, 2), dtype=np.bool_),
            np.zeros(3),
            np.ones(2, dtype=np.bool_),
        )
