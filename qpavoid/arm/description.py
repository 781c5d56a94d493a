"""Reading a robot description: the control-point file, the URDF and the reduced model.

A robot description is a folder with a URDF and a control-point file (TOML, see
``docs/robot.md``). Every control point and capsule end becomes an operational frame of
the Pinocchio model, so positions and Jacobians come from Pinocchio; locking joints (the
paper locks A3) is Pinocchio's ``buildReducedModel``, which carries the frames over.

:func:`read_description` returns the pieces a :class:`~qpavoid.arm.model.Robot` is made of;
:func:`qpavoid.arm.model.load_robot` makes the robot from them.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from qpavoid.core.checks import one_line
from qpavoid.core.errors import InputError, RobotDescriptionError

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10: the same parser, as a package
    import tomli as tomllib

CONFIG_NAME = "control_points.toml"
#: Keys of a ``[[sets]]`` entry of the control-point file and of its ``capsule`` table.
SET_KEYS = ("name", "sphere_radius_m", "points", "capsule")
CAPSULE_KEYS = ("from", "to", "capsule_radius_m")


@dataclass(frozen=True)
class ControlSet:
    """One set of control points (L1, L2 or EE in the paper) and its capsule.

    Attributes
    ----------
    name
        Set name, e.g. ``"L2"``.
    sphere_radius_m
        Radius r_R of the spheres centred on the set's points (paper eq. 1), m.
    points
        Indices of the set's points in :attr:`~qpavoid.arm.model.Robot.point_frames` order.
    capsule_frames
        Frame ids of the capsule's two ends (from, to).
    capsule_radius_m
        Capsule radius for the exact distance method, m.
    """

    name: str
    sphere_radius_m: float
    points: tuple[int, ...]
    capsule_frames: tuple[int, int]
    capsule_radius_m: float


class Description(NamedTuple):
    """A read robot description: the arguments of :class:`~qpavoid.arm.model.Robot`, in order."""

    model: pin.Model
    sets: list[ControlSet]
    point_frames: list[int]
    ee_frame: int
    name: str
    locked: dict[str, float]


def _bundled_root() -> Path:
    """Folder of the bundled descriptions: the installed ``qpavoid.robots`` package, or
    ``robots/`` beside the package in a source checkout."""
    try:
        return Path(str(resources.files("qpavoid.robots")))
    except ModuleNotFoundError:
        return Path(__file__).resolve().parent.parent / "robots"


def _description_dir(name: str | Path) -> Path:
    """Folder of a robot description: a path, or the name of a bundled description."""
    path = Path(name)
    if path.suffix == ".toml" and path.is_file():
        return path.parent
    if path.is_dir() and (path / CONFIG_NAME).is_file():
        return path
    root = _bundled_root()
    if (root / str(name) / CONFIG_NAME).is_file():
        return root / str(name)
    available = sorted(p.name for p in root.iterdir() if (p / CONFIG_NAME).is_file())
    raise RobotDescriptionError(
        f"unknown robot {str(name)!r}: not a folder with {CONFIG_NAME} and not one of the "
        f"bundled descriptions {available}",
        path=path,
        name="robot",
        value=str(name),
    )


def _carriers(model: pin.Model, frame_id: int) -> set[int]:
    """Joints whose body carries the origin of a frame.

    The origin of a revolute joint's frame lies on its axis, so it is fixed on both the
    parent body and the joint's own body.
    """
    frame = model.frames[frame_id]
    carriers = {frame.parentJoint}
    if frame.type == pin.FrameType.JOINT:
        carriers.add(model.parents[frame.parentJoint])
    return carriers


def _add_point_frame(model: pin.Model, data: pin.Data, label: str, names: Sequence[str]) -> int:
    """Add an operational frame at the centroid of the named frames; return its id."""
    ids = []
    for n in names:
        if not model.existFrame(n):
            raise RobotDescriptionError(
                f"{label}: no frame named {n!r} in the URDF", name=label, value=n
            )
        ids.append(model.getFrameId(n))
    common = set.intersection(*(_carriers(model, i) for i in ids))
    if not common:
        raise RobotDescriptionError(
            f"{label}: frames {list(names)} are not on one rigid body",
            name=label,
            value=list(names),
        )
    parent = max(common)  # the deepest body carrying all of them
    centre = np.mean([data.oMf[i].translation for i in ids], axis=0)
    placement = data.oMi[parent].actInv(pin.SE3(np.eye(3), centre))
    return model.addFrame(pin.Frame(label, parent, placement, pin.FrameType.OP_FRAME))


def _check_sets(set_cfgs: Any, path: Path) -> None:
    """Raise :class:`RobotDescriptionError` unless every ``[[sets]]`` entry has its keys."""
    for k, sc in enumerate(set_cfgs if isinstance(set_cfgs, list) else [set_cfgs]):
        sc = sc if isinstance(sc, dict) else {}
        missing = [key for key in SET_KEYS if key not in sc]
        cap = sc.get("capsule")
        if isinstance(cap, dict):
            missing += [f"capsule.{key}" for key in CAPSULE_KEYS if key not in cap]
        if missing:
            raise RobotDescriptionError(
                f"{path}: [[sets]] entry {k} is missing key(s) {', '.join(missing)}",
                path=path,
                name=f"sets[{k}]",
                value=missing,
            )


def _read_config(folder: Path) -> tuple[dict, Path, list, str]:
    """The parsed control-point file of ``folder``, its URDF path, sets and end effector."""
    path = folder / CONFIG_NAME
    with open(path, "rb") as fh:
        try:
            cfg = tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise RobotDescriptionError(f"{path}: {one_line(exc)}", path=path) from exc
    try:
        urdf, set_cfgs, ee_name = folder / cfg["urdf"], cfg["sets"], cfg["end_effector"]
    except KeyError as exc:
        raise RobotDescriptionError(
            f"{path}: missing key {exc}", path=path, name=exc.args[0]
        ) from None
    _check_sets(set_cfgs, path)
    return cfg, urdf, set_cfgs, ee_name


def _build_model(urdf: Path) -> pin.Model:
    """The Pinocchio model of a URDF, or :class:`RobotDescriptionError`."""
    try:
        return pin.buildModelFromUrdf(str(urdf))
    except (ValueError, RuntimeError, OSError) as exc:  # missing or malformed URDF
        raise RobotDescriptionError(
            f"{urdf}: cannot build a model from this URDF: {one_line(exc)}", path=urdf
        ) from exc


def _locked_angles(
    locked: Mapping[str, float] | Sequence[str] | None, default: Mapping[str, float]
) -> dict[str, float]:
    """The joints to lock and their angles (rad); see :func:`read_description`."""
    default_locked = {k: float(v) for k, v in default.items()}
    if locked is None:
        locked = default_locked
    elif not isinstance(locked, Mapping):
        locked = {n: default_locked.get(n, 0.0) for n in locked}
    try:
        return {str(k): float(v) for k, v in locked.items()}
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"locked angles must be numbers (rad), got {dict(locked)!r}",
            name="locked",
            value=dict(locked),
        ) from exc


def _add_frames(model: pin.Model, set_cfgs: list) -> None:
    """Operational frames for points and capsule ends, placed at the neutral configuration."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    labels: list[tuple[str, list[str]]] = []
    for sc in set_cfgs:
        for k, names in enumerate(sc["points"]):
            labels.append((f"{sc['name']}_p{k}", list(names)))
        cap = sc["capsule"]
        labels.append((f"{sc['name']}_capsule_from", [cap["from"]]))
        labels.append((f"{sc['name']}_capsule_to", [cap["to"]]))
    for label, names in labels:
        _add_point_frame(model, data, label, names)


def _lock(model: pin.Model, locked: Mapping[str, float]) -> pin.Model:
    """The model with the ``locked`` joints removed at their angles (``buildReducedModel``)."""
    if not locked:
        return model
    for jn in locked:
        if not model.existJointName(jn):
            raise InputError(
                f"cannot lock {jn!r}: joints are {list(model.names)[1:]}", name="locked", value=jn
            )
    q_ref = pin.neutral(model)
    for jn, angle in locked.items():
        q_ref[model.joints[model.getJointId(jn)].idx_q] = angle
    return pin.buildReducedModel(model, [model.getJointId(jn) for jn in locked], q_ref)


def _control_sets(model: pin.Model, set_cfgs: list) -> tuple[list[ControlSet], list[int]]:
    """The control sets and the frame id of every control point, set after set."""
    sets: list[ControlSet] = []
    point_frames: list[int] = []
    for sc in set_cfgs:
        idx = []
        for k in range(len(sc["points"])):
            idx.append(len(point_frames))
            point_frames.append(model.getFrameId(f"{sc['name']}_p{k}"))
        sets.append(
            ControlSet(
                name=sc["name"],
                sphere_radius_m=float(sc["sphere_radius_m"]),
                points=tuple(idx),
                capsule_frames=(
                    model.getFrameId(f"{sc['name']}_capsule_from"),
                    model.getFrameId(f"{sc['name']}_capsule_to"),
                ),
                capsule_radius_m=float(sc["capsule"]["capsule_radius_m"]),
            )
        )
    return sets, point_frames


def read_description(
    name: str | Path = "iiwa14", locked: Mapping[str, float] | Sequence[str] | None = None
) -> Description:
    """Read a robot description and build its (reduced) Pinocchio model.

    Arguments and errors as :func:`qpavoid.arm.model.load_robot`, which makes the
    :class:`~qpavoid.arm.model.Robot` from the returned :class:`Description`.
    """
    folder = _description_dir(name)
    cfg, urdf, set_cfgs, ee_name = _read_config(folder)
    model = _build_model(urdf)
    locked = _locked_angles(locked, cfg.get("locked", {}))
    _add_frames(model, set_cfgs)
    if not model.existFrame(ee_name):
        raise RobotDescriptionError(
            f"end_effector {ee_name!r} is not a frame of {urdf.name}",
            path=urdf,
            name="end_effector",
            value=ee_name,
        )
    model = _lock(model, locked)
    sets, point_frames = _control_sets(model, set_cfgs)
    return Description(model, sets, point_frames, model.getFrameId(ee_name), folder.name, locked)
