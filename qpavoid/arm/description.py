"""Reading a robot description: the control-point file, the URDF and the reduced model.

A robot description is a folder with a URDF and a control-point file (TOML, see
``docs/robot.md``). Every control point and capsule end becomes an operational frame of
the Pinocchio model, so positions and Jacobians come from Pinocchio; locking joints (the
paper locks its third joint) is Pinocchio's ``buildReducedModel``, which carries the
frames over.

Besides the geometry the file says everything about the arm that the controllers need and
that differs from arm to arm: which set plays which part in the paper's laws and on which
joints (:class:`~qpavoid.arm.roles.Roles`), how fast the arm reacts and brakes
(:class:`~qpavoid.arm.dynamics.ArmDynamics`) and where its inverse kinematics starts
(:class:`~qpavoid.arm.joints.IKSeed`) and its home configuration (``home``,
:meth:`~qpavoid.arm.model.Robot.neutral`). No code holds a joint name, length or limit of a
particular arm.

This module finds a description (a bundled one by name, or a folder) and reads it, in this
order: the file's shape (:mod:`qpavoid.arm.control_points`), the URDF's model
(:mod:`qpavoid.arm.urdf`), the tables of joints (:mod:`qpavoid.arm.joints`), the roles
(:mod:`qpavoid.arm.roles`) and the dynamics (:mod:`qpavoid.arm.dynamics`), then the frames
(:mod:`qpavoid.arm.frames`) and the checks that need the model
(:mod:`qpavoid.arm.model_checks`). :func:`read_description` returns the pieces a
:class:`~qpavoid.arm.model.Robot` is made of; :func:`qpavoid.arm.model.load_robot` makes
the robot from them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import NamedTuple

import pinocchio as pin

from qpavoid.arm.control_points import CONFIG_NAME, SET_NAME, ControlSet, read_config
from qpavoid.arm.dynamics import ArmDynamics, arm_dynamics
from qpavoid.arm.frames import add_frames, control_sets
from qpavoid.arm.joints import (
    IKSeed,
    check_free,
    file_locked,
    lock_joints,
    locked_angles,
    read_home,
    read_ik_seed,
)
from qpavoid.arm.model_checks import (
    check_capsules,
    check_end_effector,
    check_point_speed,
    check_role_joints,
    check_roles_free,
)
from qpavoid.arm.roles import Roles, read_roles
from qpavoid.arm.urdf import build_urdf_model, check_urdf_joints, mesh_dirs
from qpavoid.core.errors import RobotDescriptionError

__all__ = ["Description", "bundled_robots", "description_reference", "read_description"]


class Description(NamedTuple):
    """A read robot description: the arguments of :class:`~qpavoid.arm.model.Robot`, in order."""

    model: pin.Model
    sets: list[ControlSet]
    point_frames: list[int]
    ee_frame: int
    name: str
    locked: dict[str, float]
    roles: Roles
    arm: ArmDynamics
    ik_seed: IKSeed
    urdf: Path
    mesh_dirs: tuple[Path, ...]
    coverage_exclude: dict[str, str]
    path: Path
    home: dict[str, float]


def _bundled_root() -> Path:
    """Folder of the bundled descriptions: the installed ``qpavoid.robots`` package, or
    ``robots/`` beside the package in a source checkout."""
    try:
        return Path(str(resources.files("qpavoid.robots")))
    except ModuleNotFoundError:
        return Path(__file__).resolve().parents[2] / "robots"  # qpavoid/arm/ -> the checkout


def bundled_robots() -> tuple[str, ...]:
    """Names of the bundled descriptions (``--robot NAME``), sorted: those whose URDF comes
    from an extra load only once it is installed."""
    root = _bundled_root()
    return tuple(sorted(p.name for p in root.iterdir() if (p / CONFIG_NAME).is_file()))


def _description_dir(name: str | Path) -> Path:
    """Folder of a robot description: the name of a bundled description (a bare name, as
    text: it wins over a folder of that name in the working directory, which ``./name``
    reaches), or a path."""
    root = _bundled_root()
    if isinstance(name, str) and SET_NAME.fullmatch(name) and (root / name / CONFIG_NAME).is_file():
        return root / name
    path = Path(name)
    if path.suffix == ".toml" and path.is_file():
        return path.parent
    if path.is_dir() and (path / CONFIG_NAME).is_file():
        return path
    available = list(bundled_robots())
    raise RobotDescriptionError(
        f"unknown robot {str(name)!r}: not a folder with {CONFIG_NAME} and not one of the "
        f"bundled descriptions {available}",
        path=path,
        name="robot",
        value=str(name),
    )


def description_reference(name: str | Path) -> str:
    """How a run records the robot it ran: a bundled description's name, or the absolute
    folder of any other (so that ``qpavoid view`` finds the same arm from anywhere)."""
    folder = _description_dir(name)
    if isinstance(name, str) and folder == _bundled_root() / name:
        return name
    return str(folder.resolve())


def read_description(
    name: str | Path = "iiwa14", locked: Mapping[str, float] | Sequence[str] | None = None
) -> Description:
    """Read a robot description and build its (reduced) Pinocchio model.

    Arguments and errors as :func:`qpavoid.arm.model.load_robot`, which makes the
    :class:`~qpavoid.arm.model.Robot` from the returned :class:`Description`.
    """
    folder = _description_dir(name)
    file, urdf = read_config(folder)
    ee_name, set_cfgs = file.end_effector, file.sets
    path = folder / CONFIG_NAME
    model = build_urdf_model(urdf)
    check_urdf_joints(model, urdf)
    joints = tuple(str(n) for n in model.names)[1:]
    held = file_locked(file.held, path, model, "held")
    default = file_locked(file.locked, path, model)
    both = sorted(set(held) & set(default))
    if both:
        raise RobotDescriptionError(
            f"{path}: {both} are both held and locked; a joint is held (locked in every "
            "mode) or locked (by default), not both: remove it from one",
            path=path,
            name="held",
            value=both,
        )
    also = " and `held`" if held else ""
    check_free(joints, {**default, **held}, path, f"the file's `locked`{also}")
    by = f"the file's `locked`{also}" if locked is None else "the locked= argument"
    by += " and the file's `held`" if held and locked is not None else ""
    locked = {**locked_angles(locked, default, model), **held}
    check_free(joints, locked, path, by)
    roles = read_roles(file.roles, path, set_cfgs, joints)
    arm = arm_dynamics(file.arm, path, joints)
    ik_seed = read_ik_seed(file.ik_seed, path, joints)
    home = read_home(file.home, path, model)
    coverage_exclude = dict(file.coverage.exclude)
    add_frames(model, set_cfgs, path, urdf)
    if not model.existFrame(ee_name):
        raise RobotDescriptionError(
            f"{path}: end_effector {ee_name!r} is not a frame of {urdf.name}",
            path=path,
            name="end_effector",
            value=ee_name,
        )
    check_end_effector(model, set_cfgs, roles, ee_name, path)
    check_role_joints(model, roles, set_cfgs, path)
    model = lock_joints(model, locked)
    check_roles_free(model, roles, path, by)
    sets, point_frames = control_sets(model, set_cfgs)
    check_capsules(model, sets, path)
    check_point_speed(model, point_frames, arm.max_point_speed_mps, path)
    return Description(
        model,
        sets,
        point_frames,
        model.getFrameId(ee_name),
        folder.name,
        locked,
        roles,
        arm,
        ik_seed,
        urdf,
        mesh_dirs(urdf),
        coverage_exclude,
        path,
        home,
    )
