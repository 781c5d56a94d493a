"""The arm's reach: how far its end effector gets from its shoulder, and the shoulder's
centre (what a task is scaled about, :class:`qpavoid.control.task.TaskScaling`)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.optimize import minimize

from qpavoid.arm.model import Robot


def shoulder_centre(robot: Robot, frame: str) -> np.ndarray:
    """(3,) the point of the first joint's axis nearest the origin of ``frame`` at the zero
    configuration, base frame, m: where a task is scaled about (:class:`TaskScaling`).

    The iiwa's A2 lies on that axis: (0, 0, 0.36); the UR5's shoulder lift joint is 0.136
    m beside it, and its centre is (0, 0, 0.089). The axis is the angular part of the
    first joint's column of Pinocchio's Jacobian; for a prismatic first joint (no axis)
    the frame's origin itself.
    """
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))  # every joint at 0
    pin.updateFramePlacements(model, data)
    p = data.oMf[model.getFrameId(frame)].translation.copy()
    axis = pin.getJointJacobian(model, data, 1, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[3:, 0]
    if np.linalg.norm(axis) < 0.5:
        return p
    origin = data.oMi[1].translation
    return origin + ((p - origin) @ axis) * axis


def arm_reach(
    robot: Robot, frame: str, samples: int = 2000, seed: int = 0
) -> tuple[float, np.ndarray]:
    """The arm's reach from ``frame`` (the shoulder), m, and the configuration (nq,) at it.

    The reach is the largest distance from the origin of ``frame`` to the end-effector
    frame over the joint limits, ``max_q d(q) = ‖p_ee(q) − p_frame(q)‖`` subject to
    ``q_min ≤ q ≤ q_max``: SciPy's bounded L-BFGS-B on ``−d`` with the gradient ``∇d =
    rᵀ (J_ee − J_frame) / d``, ``r = p_ee − p_frame``, from the frames' translation
    Jacobians (Pinocchio), started from the 10 farthest of ``samples`` uniform
    configurations (seeded: the same every time). For an arm that stretches straight (the
    iiwa) it is the sum of the link lengths from the shoulder (0.946 m); an elbow that
    cannot straighten (the Panda's joint 4 stops at −0.07 rad) or offset links make it the
    longest reachable stretch.
    """
    model = robot.model
    data = model.createData()
    fs, fe = model.getFrameId(frame), robot.ee_frame
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

    def negative_distance(q: np.ndarray) -> tuple[float, np.ndarray]:
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        r = data.oMf[fe].translation - data.oMf[fs].translation
        d = float(np.linalg.norm(r))
        J = pin.getFrameJacobian(model, data, fe, lwa) - pin.getFrameJacobian(model, data, fs, lwa)
        return -d, -(r @ J[:3]) / max(d, 1e-12)

    rng = np.random.default_rng(seed)
    starts = rng.uniform(robot.q_min, robot.q_max, (samples, robot.nq))
    far = np.argsort([negative_distance(q)[0] for q in starts])[:10]
    bounds = list(zip(robot.q_min, robot.q_max, strict=True))
    best = min(
        (
            minimize(negative_distance, q, jac=True, method="L-BFGS-B", bounds=bounds)
            for q in starts[far]
        ),
        key=lambda result: float(result.fun),
    )
    return -float(best.fun), np.clip(best.x, robot.q_min, robot.q_max)
