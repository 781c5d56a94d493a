"""Checks of a robot description that need its model: what the controllers assume of the
capsules, the roles, the end effector and the point speed bound.

Each refuses a description the controllers would misread, with a one-line
:class:`~qpavoid.core.errors.RobotDescriptionError` saying how to fix the file: a capsule
must move with one rigid body (:func:`check_capsules`), no control point may outrun
``[arm] max_point_speed_mps`` (:func:`check_point_speed`), each role joint must move its set
(:func:`check_role_joints`) and stay free after locking (:func:`check_roles_free`), and the
end-effector frame must lie in its set's capsule (:func:`check_end_effector`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from qpavoid.arm.control_points import ControlSet
from qpavoid.arm.description_schema import ControlSetTable
from qpavoid.arm.frames import LWA
from qpavoid.arm.roles import Roles
from qpavoid.core.errors import RobotDescriptionError

__all__ = [
    "CHECK_TOLERANCE",
    "check_capsules",
    "check_end_effector",
    "check_point_speed",
    "check_role_joints",
    "check_roles_free",
]

#: Where along a capsule's axis, and at how many configurations, the check of
#: :func:`check_capsules` compares Jacobians (beyond the zero configuration); its
#: tolerance, m/s per rad/s (far above rounding, far below any joint's lever arm).
CHECK_PARAMETERS = (0.2, 0.5, 0.8)
CHECK_CONFIGURATIONS = 3
CHECK_TOLERANCE = 1e-9


def check_capsules(model: pin.Model, sets: Sequence[ControlSet], path: Path) -> None:
    """Refuse a capsule whose axis does not move with one rigid body.

    The controllers take the Jacobian of a capsule's witness point as the interpolation
    ``(1 − s) J_a + s J_b`` of its ends' Jacobians
    (:meth:`~qpavoid.arm.model.Kinematics.segment_point_jacobian`). That is the Jacobian of
    the point on the body that carries it exactly when some body carries the whole axis:
    both ends on one link, or ends on the axis of every joint between them (the iiwa's
    roll joints turn about their capsules' axes). Checked here with Pinocchio: some body's
    Jacobian, taken at points along the axis, must equal the interpolation at the zero
    configuration and at a few others.

    Raises
    ------
    RobotDescriptionError
        For the first capsule carried by no single body, naming the joints that bend it
        and how to fix the file.
    """
    data = model.createData()
    rng = np.random.default_rng(0)  # the same configurations every time
    configurations = [pin.neutral(model)] + [
        pin.integrate(model, pin.neutral(model), rng.uniform(-1.0, 1.0, model.nv))
        for _ in range(CHECK_CONFIGURATIONS)
    ]
    carried = {k: set(range(model.njoints)) for k in range(len(sets))}  # bodies left
    for q in configurations:
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for k, cs in enumerate(sets):
            a_id, b_id = cs.capsule_frames
            a, b = data.oMf[a_id].translation, data.oMf[b_id].translation
            Ja = pin.getFrameJacobian(model, data, a_id, LWA)[:3]
            Jb = pin.getFrameJacobian(model, data, b_id, LWA)[:3]
            for s in CHECK_PARAMETERS:
                point = pin.SE3(np.eye(3), (1.0 - s) * a + s * b)
                interpolated = (1.0 - s) * Ja + s * Jb
                carried[k] = {
                    j
                    for j in carried[k]
                    if np.allclose(
                        pin.getFrameJacobian(model, data, j, data.oMi[j].actInv(point), LWA)[:3],
                        interpolated,
                        rtol=0.0,
                        atol=CHECK_TOLERANCE,
                    )
                }
    for k, cs in enumerate(sets):
        if carried[k]:
            continue
        # the joints bending it: where the velocity of its mid-point on the body carrying
        # its first end differs from the interpolation (at the last configuration)
        a_id, b_id = cs.capsule_frames
        a, b = data.oMf[a_id].translation, data.oMf[b_id].translation
        interpolated = 0.5 * (
            pin.getFrameJacobian(model, data, a_id, LWA)[:3]
            + pin.getFrameJacobian(model, data, b_id, LWA)[:3]
        )
        body = model.frames[a_id].parentJoint
        mid = data.oMi[body].actInv(pin.SE3(np.eye(3), 0.5 * (a + b)))
        J = pin.getFrameJacobian(model, data, body, mid, LWA)[:3]
        columns = [
            str(model.names[j]) for j in range(1, model.njoints) for _ in range(model.joints[j].nv)
        ]
        bent = np.abs(J - interpolated).max(axis=0) > CHECK_TOLERANCE
        between = [columns[v] for v in np.flatnonzero(bent)]
        raise RobotDescriptionError(
            f"{path}: the capsule of set {cs.name!r} is carried by no single body: joint(s) "
            f"{between} between its ends turn one end about an axis that is not the "
            "capsule's, so a point on it does not move as the interpolation of its ends. "
            "Fix the file: give the set a capsule whose two ends lie on one link (split it "
            "at the joint into two sets), or whose ends lie on the axis of every joint "
            "between them",
            path=path,
            name=f"sets.{cs.name}.capsule",
            value=between,
        )


def check_point_speed(
    model: pin.Model, point_frames: Sequence[int], bound_mps: float, path: Path
) -> None:
    """Refuse an ``[arm] max_point_speed_mps`` that some control point exceeds: with one
    joint alone at its URDF velocity limit, a point moves at ``‖J_p[:, j]‖ q̇_max,j``, a
    lower bound of its fastest speed, checked at the zero configuration and at
    :data:`CHECK_CONFIGURATIONS` others (speed and separation leaves out the rows whose
    bound exceeds ``max_point_speed_mps``: too low a value would drop rows that bind)."""
    data = model.createData()
    rng = np.random.default_rng(0)
    configurations = [pin.neutral(model)] + [
        pin.integrate(model, pin.neutral(model), rng.uniform(-1.0, 1.0, model.nv))
        for _ in range(CHECK_CONFIGURATIONS)
    ]
    fastest, where = 0.0, ""
    for q in configurations:
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for f in point_frames:
            J = pin.getFrameJacobian(model, data, f, LWA)[:3]
            speeds = np.linalg.norm(J, axis=0) * model.velocityLimit
            if speeds.max() > fastest:
                fastest, where = float(speeds.max()), str(model.frames[f].name)
    if fastest > bound_mps:
        raise RobotDescriptionError(
            f"{path}: [arm] max_point_speed_mps = {bound_mps:g} m/s, but the control point "
            f"{where} moves at {fastest:.2f} m/s with a single joint at its URDF speed limit: "
            "give a bound no point of the arm reaches (docs/robot.md, Arm)",
            path=path,
            name="arm.max_point_speed_mps",
            value=bound_mps,
        )


def check_role_joints(
    model: pin.Model, roles: Roles, sets: Sequence[ControlSetTable], path: Path
) -> None:
    """Refuse a role joint that moves none of its set's points: in Pinocchio's tree
    (``model.supports``) it must be an ancestor of at least one point's body."""
    for role, row, role_joints in (
        ("scaled", roles.scaled, roles.scaled_joints),
        ("repelled", roles.repelled, roles.repelled_joints),
    ):
        name = sets[row].name
        bodies = {
            model.frames[model.getFrameId(f"{name}_p{k}")].parentJoint
            for k in range(len(sets[row].points))
        }
        moving = sorted({j for b in bodies for j in model.supports[b] if j > 0})
        moving_names = [str(model.names[j]) for j in moving]
        idle = [j for j in role_joints if j not in moving_names]
        if idle:
            raise RobotDescriptionError(
                f"{path}: [roles] {role}.joints: {idle} move no point of the set {name!r} "
                f"(they come after its points in the URDF's chain); the joints that move it "
                f"are {moving_names}: name those",
                path=path,
                name=f"roles.{role}.joints",
                value=idle,
            )


def check_roles_free(model: pin.Model, roles: Roles, path: Path, by: str) -> None:
    """Refuse a role joint that is not in the reduced model (locked)."""
    for role, role_joints in (
        ("scaled", roles.scaled_joints),
        ("repelled", roles.repelled_joints),
    ):
        locked = [j for j in role_joints if not model.existJointName(j)]
        if locked:
            raise RobotDescriptionError(
                f"{path}: [roles] {role}.joints: {locked} locked (by {by}); a role's joints "
                f"must be free: unlock them, or name free joints in [roles] {role}.joints",
                path=path,
                name=f"roles.{role}.joints",
                value=locked,
            )


#: How far the end-effector frame may lie outside the end-effector set's capsule, m
#: (rounding of the capsule's written ends and radius: 1 µm).
EE_INSIDE_TOLERANCE_M = 1e-6


def check_end_effector(
    model: pin.Model, sets: Sequence[ControlSetTable], roles: Roles, ee_name: str, path: Path
) -> None:
    """Refuse an end-effector set whose capsule does not hold the end-effector frame.

    The laws push the end effector (eq. 7) and servo its frame (eq. 8) with the set's
    distance, so the frame must lie on the set's body and inside its capsule: the
    capsule ends at the frame (by name, or at the same place of the same body, the
    paper's), or the frame lies within the capsule's radius of its axis (a capsule
    fitted to a hand's meshes) on a body that carries both ends.
    """
    sc = sets[roles.end_effector]
    ends = [model.frames[model.getFrameId(f"{sc.name}_capsule_{e}")] for e in ("from", "to")]
    ee = model.frames[model.getFrameId(ee_name)]
    same = ends[1].parentJoint == ee.parentJoint and np.allclose(
        ends[1].placement.translation, ee.placement.translation, rtol=0.0, atol=1e-12
    )
    if sc.capsule.to == ee_name or same:
        return
    # within the capsule, on the body of both ends (so at every configuration)
    radius = sc.capsule.capsule_radius_m
    excess = np.inf
    if ends[0].parentJoint == ends[1].parentJoint == ee.parentJoint:
        a, b = ends[0].placement.translation, ends[1].placement.translation
        ab, rel = b - a, ee.placement.translation - a
        s = float(np.clip(rel @ ab / (ab @ ab), 0.0, 1.0)) if ab @ ab > 0.0 else 0.0
        excess = float(np.linalg.norm(rel - s * ab)) - radius
        if excess <= EE_INSIDE_TOLERANCE_M:
            return
    where = (
        f"{excess:.4f} m outside it" if np.isfinite(excess) else "on another body than the capsule"
    )
    raise RobotDescriptionError(
        f"{path}: [roles] end_effector: the end_effector frame {ee_name!r} must lie in the "
        f"end-effector set's capsule; it is {where} (set {sc.name!r}): name the set "
        f'whose capsule holds it, give this set capsule.to = "{ee_name}", or name a frame '
        "inside the capsule as end_effector",
        path=path,
        name="roles.end_effector.set",
        value=sc.name,
    )
