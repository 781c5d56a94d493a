"""The control-point file's tables of joints: ``locked``, ``held``, ``home`` and ``[ik_seed]``.

Each names joints of the URDF, and each angle (rad) must lie within its joint's URDF
limits. ``locked`` joints are removed from the model at their angles unless the
``locked=`` argument of :func:`~qpavoid.arm.model.load_robot` says otherwise; ``held``
joints are removed in every mode. :func:`lock_joints` removes them with Pinocchio's
``buildReducedModel``, which carries the operational frames over (the paper locks its third
joint). ``home`` is the arm's home configuration, ``[ik_seed]`` where its inverse kinematics
starts (:class:`IKSeed`).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from qpavoid.arm.description_schema import IKSeedTable
from qpavoid.core.errors import InputError, RobotDescriptionError

__all__ = [
    "IKSeed",
    "angle_fault",
    "check_free",
    "check_lock_angle",
    "file_locked",
    "joint_list",
    "lock_joints",
    "locked_angles",
    "read_home",
    "read_ik_seed",
]


@dataclass(frozen=True)
class IKSeed:
    """Where the inverse kinematics of a pose starts (``[ik_seed]``, optional).

    The seed picks the solution's branch: every joint at 0 except ``angles``, and the
    ``aim`` joint (a base joint turning about the vertical) turned to face the wrist
    centre, which lies ``wrist_to_tool_m`` behind the end-effector frame along its z axis.

    Attributes
    ----------
    aim
        The base joint turned to face the wrist centre (``atan2(y, x)``), or None.
    angles
        ``(joint name, angle)`` pairs, rad.
    wrist_to_tool_m
        From the wrist centre to the end-effector frame along the frame's z axis, m (the
        seed only needs it roughly).
    """

    aim: str | None = None
    angles: tuple[tuple[str, float], ...] = ()
    wrist_to_tool_m: float = 0.0


def joint_list(
    value: Sequence[str], where: str, path: Path, joints: Sequence[str]
) -> tuple[str, ...]:
    """``value`` (names, as the file's schema read them) as a tuple of joint names of the
    URDF, or a :class:`RobotDescriptionError`."""
    missing = [n for n in value if n not in joints]
    if missing:
        raise RobotDescriptionError(
            f"{path}: {where}: {missing} are not joints of the URDF; its joints are {list(joints)}",
            path=path,
            name=where,
            value=missing,
        )
    return tuple(value)


def check_lock_angle(model: pin.Model, joint: str, angle: float) -> None:
    """Raise :class:`InputError` if ``joint`` cannot be locked at ``angle`` (rad)."""
    fault = angle_fault(model, joint, angle)
    if fault:
        raise InputError(
            f"cannot lock {joint} at {angle!r} rad: {fault}", name="locked", value={joint: angle}
        )


def angle_fault(model: pin.Model, joint: str, angle: float) -> str:
    """What is wrong with locking the model's joint ``joint`` at ``angle`` (rad), or ``""``."""
    idx = model.joints[model.getJointId(joint)].idx_q
    low, high = model.lowerPositionLimit[idx], model.upperPositionLimit[idx]
    if not (np.isfinite(angle) and low <= angle <= high):
        return f"not within the joint's limits [{low:g}, {high:g}] rad"
    return ""


def file_locked(
    value: Mapping[str, float] | Sequence[str] | None,
    path: Path,
    model: pin.Model,
    key: str = "locked",
) -> dict[str, float]:
    """The file's ``locked`` (or ``held``, as ``key`` says; its shape checked by the file's
    schema): a table of joint angles (rad), or a list of joint names (locked at 0), each a
    joint of the URDF locked within its limits."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        twice = sorted({n for n in value if value.count(n) > 1})
        if twice:
            raise RobotDescriptionError(
                f"{path}: {key} lists {twice} more than once",
                path=path,
                name=key,
                value=twice,
            )
        value = dict.fromkeys(value, 0.0)
    for joint, angle, fault in _angle_faults(value, path, model, key):
        raise RobotDescriptionError(
            f"{path}: {key}: {joint} = {angle!r} is {fault}; lock it at an angle (rad) "
            "within its limits",
            path=path,
            name=f"{key}.{joint}",
            value=angle,
        )
    return {joint: float(angle) for joint, angle in value.items()}


def _angle_faults(
    table: Mapping[str, float], path: Path, model: pin.Model, key: str
) -> Iterator[tuple[str, float, str]]:
    """``(joint, angle, fault)`` of each angle of ``table`` (the file's ``key``) that is not
    within its joint's limits; a name that is not a joint of the URDF raised."""
    for joint, angle in table.items():
        if not model.existJointName(joint):
            raise RobotDescriptionError(
                f"{path}: {key}: {joint!r} is not a joint of the URDF; its joints are "
                f"{list(model.names)[1:]}",
                path=path,
                name=key,
                value=joint,
            )
        if fault := angle_fault(model, joint, angle):
            yield joint, angle, fault


def locked_angles(
    locked: Mapping[str, float] | Sequence[str] | None,
    default: Mapping[str, float],
    model: pin.Model,
) -> dict[str, float]:
    """The joints to lock and their angles (rad), as the ``locked=`` argument of
    :func:`~qpavoid.arm.description.read_description` says, or the file's without it.

    ``default`` is the file's ``locked`` (already checked); a fault of the argument
    ``locked`` alone is an :class:`InputError`.
    """
    if locked is None:
        return dict(default)
    if isinstance(locked, (str, bytes)):
        raise InputError(
            f"locked must be joint names or a mapping of joint names to angles (rad), "
            f"not the text {locked!r}",
            name="locked",
            value=locked,
        )
    if not isinstance(locked, Mapping):
        locked = {n: default.get(n, 0.0) for n in locked}
    try:
        angles = {str(k): float(v) for k, v in locked.items()}
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"locked angles must be numbers (rad), got {dict(locked)!r}",
            name="locked",
            value=dict(locked),
        ) from exc
    for joint, angle in angles.items():
        if not model.existJointName(joint):
            raise InputError(
                f"cannot lock {joint!r}: joints are {list(model.names)[1:]}",
                name="locked",
                value=joint,
            )
        check_lock_angle(model, joint, angle)
    return angles


def check_free(joints: Sequence[str], locked: Mapping[str, float], path: Path, by: str) -> None:
    """Refuse locking every joint (a model with nothing to move)."""
    if set(joints) <= set(locked):
        raise RobotDescriptionError(
            f"{path}: {by} locks every joint, {list(joints)}: nothing is left to move; "
            "leave at least the joints of [roles] free",
            path=path,
            name="locked",
            value=sorted(locked),
        )


def lock_joints(model: pin.Model, locked: Mapping[str, float]) -> pin.Model:
    """The model with the ``locked`` joints (checked) removed at their angles
    (``buildReducedModel``)."""
    if not locked:
        return model
    q_ref = pin.neutral(model)
    for jn, angle in locked.items():
        q_ref[model.joints[model.getJointId(jn)].idx_q] = angle
    return pin.buildReducedModel(model, [model.getJointId(jn) for jn in locked], q_ref)


def read_ik_seed(table: IKSeedTable | None, path: Path, joints: Sequence[str]) -> IKSeed:
    """The ``[ik_seed]`` table (its shape checked by the file's schema), its joints the
    URDF's, or the zero configuration's seed without one."""
    if table is None:
        return IKSeed()
    aim = table.aim
    if aim is not None:
        (aim,) = joint_list([aim], "ik_seed.aim", path, joints)
    joint_list(list(table.angles), "ik_seed.angles", path, joints)
    return IKSeed(
        aim=aim, angles=tuple(table.angles.items()), wrist_to_tool_m=table.wrist_to_tool_m
    )


def read_home(value: Mapping[str, float] | None, path: Path, model: pin.Model) -> dict[str, float]:
    """The file's ``home`` (its shape checked by the file's schema): a table of joint
    angles (rad), each a joint of the URDF at a finite angle within its limits; ``{}``
    without one (:meth:`Robot.neutral <qpavoid.arm.model.Robot.neutral>` then puts every
    joint at 0, or mid-range where 0 is outside its limits)."""
    if value is None:
        return {}
    for joint, angle, fault in _angle_faults(value, path, model, "home"):
        raise RobotDescriptionError(
            f"{path}: home: {joint} = {angle!r}: {fault}",
            path=path,
            name="home",
            value={joint: angle},
        )
    return {str(joint): float(angle) for joint, angle in value.items()}
