"""The control-point file read: ``control_points.toml``, its shape checked by its schema.

A robot description's own file (``docs/robot.md``) names the URDF, the end-effector frame
and the control sets (``[[sets]]``: each set's points, spheres and capsule), and holds the
tables the sibling modules read against the URDF's model: ``[roles]``
(:mod:`qpavoid.arm.roles`), ``[arm]`` (:mod:`qpavoid.arm.dynamics`), ``locked``, ``held``,
``home`` and ``[ik_seed]`` (:mod:`qpavoid.arm.joints`). This module reads what needs no
model: the file's size and syntax, its shape (every table's types, ranges, keys known and
required: the schema, :mod:`qpavoid.arm.description_schema`), each set's name its own, the
``[coverage]`` table, and that no ``TO DO`` of ``qpavoid robot fit`` is left. Whether the
frames a set names exist is the URDF's to say (:mod:`qpavoid.arm.frames`).

Every refusal is a one-line :class:`~qpavoid.core.errors.RobotDescriptionError` naming
the file, the key's path in it (``sets[1].capsule.capsule_radius_m``) and the offending
value.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from qpavoid.arm.description_schema import (
    POINTS_SHAPE,
    SET_NAME,
    ControlPointFile,
    ControlSetTable,
    Spot,
)
from qpavoid.arm.fields import refused
from qpavoid.arm.urdf import urdf_path
from qpavoid.core.checks import one_line
from qpavoid.core.errors import RobotDescriptionError
from qpavoid.core.file_bounds import NotTOMLError, read_toml
from qpavoid.core.schema import convert

__all__ = [
    "CONFIG_NAME",
    "POINTS_SHAPE",
    "SET_NAME",
    "ControlSet",
    "Spot",
    "read_config",
]

#: The control-point file's name in a description's folder.
CONFIG_NAME = "control_points.toml"
#: Most bytes a control-point file may have (the iiwa's has about 4 kB): checked before it
#: is read.
MAX_CONFIG_BYTES = 2**20


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


def read_config(folder: Path) -> tuple[ControlPointFile, Path]:
    """The control-point file of ``folder`` as its schema reads it, and its URDF's path."""
    path = folder / CONFIG_NAME
    try:
        cfg = read_toml(path, MAX_CONFIG_BYTES)
    except NotTOMLError as exc:
        raise RobotDescriptionError(f"{path}: {one_line(exc)}", path=path) from None
    except (OSError, ValueError) as exc:  # too large, not a regular file, not UTF-8
        raise RobotDescriptionError(
            f"{path}: cannot read the file: {one_line(exc)}", path=path
        ) from None
    _check_finished(cfg, path)
    file = convert(cfg, ControlPointFile, refused(path))
    _check_names(file.sets, path)
    return file, urdf_path(file.urdf, folder, path)


def _check_names(sets: list[ControlSetTable], path: Path) -> None:
    """Refuse two sets of one name (roles would resolve to the first)."""
    names = [sc.name for sc in sets]
    for k, name in enumerate(names):
        if name in names[:k]:
            raise RobotDescriptionError(
                f"{path}: [[sets]] entry {k}: the name {name!r} is already entry "
                f"{names.index(name)}'s; give each set a name of its own",
                path=path,
                name=f"sets[{k}].name",
                value=name,
            )


#: What ``qpavoid robot fit`` writes where the user has to fill something in.
TO_DO = "TO DO"


def _check_finished(value: object, path: Path, key: str = "") -> None:
    """Refuse a file that still holds a :data:`TO_DO` of ``qpavoid robot fit`` (a role, a
    frame or a source left as written), naming the first such key."""
    if isinstance(value, dict):
        for k, v in value.items():
            _check_finished(v, path, f"{key}.{k}" if key else str(k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _check_finished(v, path, f"{key}[{i}]")
    elif isinstance(value, str) and TO_DO in value:
        raise RobotDescriptionError(
            f"{path}: {key} is still {value!r}, as `qpavoid robot fit` wrote it: fill it in "
            "(docs/robot.md, Adding an arm)",
            path=path,
            name=key,
            value=value,
        )
