"""The control-point file's shape: ``control_points.toml`` read, and its structure checked.

A robot description's own file (``docs/robot.md``) names the URDF, the end-effector frame
and the control sets (``[[sets]]``: each set's points, spheres and capsule), and holds the
tables the sibling modules read against the URDF's model: ``[roles]``
(:mod:`qpavoid.arm.roles`), ``[arm]`` (:mod:`qpavoid.arm.dynamics`), ``locked``, ``held``,
``home`` and ``[ik_seed]`` (:mod:`qpavoid.arm.joints`). This module checks what needs no
model: the file's size and syntax, its top-level keys, each set's keys, name, points and
radii, the ``[coverage]`` table, and that no ``TO DO`` of ``qpavoid robot fit`` is left.
Whether the frames a set names exist is the URDF's to say (:mod:`qpavoid.arm.frames`).

Every refusal is a one-line :class:`~qpavoid.core.errors.RobotDescriptionError` naming
the file, the key as the file says it and the offending value.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from qpavoid.arm.fields import number as _number
from qpavoid.arm.fields import table as _table
from qpavoid.arm.fields import unknown_keys as _unknown_keys
from qpavoid.arm.urdf import urdf_path
from qpavoid.core.checks import one_line
from qpavoid.core.errors import RobotDescriptionError
from qpavoid.core.file_bounds import NotTOMLError, read_toml

__all__ = [
    "CONFIG_NAME",
    "SET_NAME",
    "ControlSet",
    "is_spot",
    "read_config",
    "read_coverage",
]

#: The control-point file's name in a description's folder.
CONFIG_NAME = "control_points.toml"
#: Keys of a ``[[sets]]`` entry of the control-point file and of its ``capsule`` table.
SET_KEYS = ("name", "sphere_radius_m", "points", "capsule")
CAPSULE_KEYS = ("from", "to", "capsule_radius_m")
#: The control-point file's top-level keys (a misspelt one would otherwise be ignored).
TOP_KEYS = (
    "urdf",
    "end_effector",
    "locked",
    "held",
    "sets",
    "roles",
    "arm",
    "ik_seed",
    "coverage",
    "home",
)
#: Most bytes a control-point file may have (the iiwa's has about 4 kB): checked before it
#: is read.
MAX_CONFIG_BYTES = 2**20
#: What a set's name may hold: it becomes part of frame names, log keys and file names
#: (``fig10_distance_<name>.png``).
SET_NAME = re.compile(r"[A-Za-z0-9_.-]+")
#: The shape of a set's ``points``, for messages.
POINTS_SHAPE = (
    'points = [["<frame>"], ["<frame>", "<frame>"], { frame = "<frame>", xyz = [x, y, z] }]'
)
#: Keys of a point or capsule end given as an offset from a frame (``{ frame, xyz }``).
OFFSET_KEYS = ("frame", "xyz")


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


def _set_error(path: Path, k: int, key: str, message: str, value: object) -> RobotDescriptionError:
    """A :class:`RobotDescriptionError` about key ``key`` of ``[[sets]]`` entry ``k``."""
    return RobotDescriptionError(
        f"{path}: [[sets]] entry {k}: {message}",
        path=path,
        name=f"sets[{k}].{key}",
        value=value,
    )


def is_spot(spot: object, frame_name: bool = False) -> bool:
    """Whether ``spot`` names a point: a non-empty list of frame names, an offset
    ``{ frame = "<frame>", xyz = [x, y, z] }`` (finite, m), or with ``frame_name`` a
    frame name alone (a capsule end)."""
    if isinstance(spot, str):
        return frame_name
    if isinstance(spot, list):
        return bool(spot) and all(isinstance(n, str) for n in spot)
    if not isinstance(spot, dict) or set(spot) != set(OFFSET_KEYS):
        return False
    xyz = spot["xyz"]
    return (
        isinstance(spot["frame"], str)
        and isinstance(xyz, list)
        and len(xyz) == 3
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xyz)
        and bool(np.isfinite(xyz).all())
    )


def _check_points(points: object, path: Path, k: int) -> None:
    """Refuse a set's ``points`` unless it is a non-empty list of non-empty lists of frame
    names (:data:`POINTS_SHAPE`)."""
    if isinstance(points, list) and points and all(is_spot(p) for p in points):
        return
    raise _set_error(
        path,
        k,
        "points",
        "points must be a non-empty list of control points, each the list of the frames "
        f"it is the centroid of, e.g. {POINTS_SHAPE}; got {points!r}",
        points,
    )


def _check_sets(set_cfgs: list, path: Path) -> None:
    """Raise :class:`RobotDescriptionError` unless every ``[[sets]]`` entry has its keys,
    no other, a name of its own made of letters, digits, ``_``, ``.`` and ``-``, points
    of the shape :data:`POINTS_SHAPE`, capsule ends named by frame names and radii above
    0 m."""
    names: list[object] = []
    for k, sc in enumerate(set_cfgs):
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
        _unknown_keys(sc, SET_KEYS, f"[[sets]] entry {k}", path, f"sets[{k}]")
        name = sc["name"]
        if not isinstance(name, str) or not SET_NAME.fullmatch(name):
            raise _set_error(
                path,
                k,
                "name",
                "name must be letters, digits, '_', '.' and '-' only (it becomes part of "
                f"frame names, log keys and figure file names), got {name!r}",
                name,
            )
        if name in names:
            raise _set_error(
                path,
                k,
                "name",
                f"the name {name!r} is already entry {names.index(name)}'s; give each "
                "set a name of its own",
                name,
            )
        names.append(name)
        _check_points(sc["points"], path, k)
        if not isinstance(cap, dict):
            raise RobotDescriptionError(
                f"{path}: [[sets]] entry {k}: capsule must be a table "
                '{ from = "<frame>", to = "<frame>", capsule_radius_m = <m> }',
                path=path,
                name=f"sets[{k}].capsule",
                value=cap,
            )
        _unknown_keys(cap, CAPSULE_KEYS, f"[[sets]] entry {k}: capsule", path, f"sets[{k}].capsule")
        for end in ("from", "to"):
            if not is_spot(cap[end], frame_name=True):
                raise _set_error(
                    path,
                    k,
                    f"capsule.{end}",
                    f"capsule.{end} must be a frame name or an offset from one, "
                    f'{{ frame = "<frame>", xyz = [x, y, z] }} (m), got {cap[end]!r}',
                    cap[end],
                )
        _number(sc["sphere_radius_m"], f"sets[{k}].sphere_radius_m", path, 0.0, strict=True)
        _number(cap["capsule_radius_m"], f"sets[{k}].capsule.capsule_radius_m", path, 0.0, True)


def read_config(folder: Path) -> tuple[dict, Path, list, str]:
    """The parsed control-point file of ``folder``, its URDF path, sets and end effector."""
    path = folder / CONFIG_NAME
    try:
        cfg = read_toml(path, MAX_CONFIG_BYTES)
    except NotTOMLError as exc:
        raise RobotDescriptionError(f"{path}: {one_line(exc)}", path=path) from None
    except (OSError, ValueError) as exc:  # too large, not a regular file, not UTF-8
        raise RobotDescriptionError(
            f"{path}: cannot read the file: {one_line(exc)}", path=path
        ) from None
    try:
        urdf_name, set_cfgs, ee_name = cfg["urdf"], cfg["sets"], cfg["end_effector"]
    except KeyError as exc:
        raise RobotDescriptionError(
            f"{path}: missing key {exc}", path=path, name=exc.args[0]
        ) from None
    _unknown_keys(cfg, TOP_KEYS, "the top level", path, "")
    _check_finished(cfg, path)
    for key, value in (("urdf", urdf_name), ("end_effector", ee_name)):
        if key == "urdf" and isinstance(value, dict):
            continue
        if not isinstance(value, str) or not value:
            raise RobotDescriptionError(
                f"{path}: {key} must be a name (text), got {value!r}",
                path=path,
                name=key,
                value=value,
            )
    if not isinstance(set_cfgs, list):
        raise RobotDescriptionError(
            f"{path}: sets must be an array of tables, one [[sets]] per set (docs/robot.md)",
            path=path,
            name="sets",
            value=set_cfgs,
        )
    _check_sets(set_cfgs, path)
    return cfg, urdf_path(urdf_name, folder, path), set_cfgs, ee_name


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


def read_coverage(cfg: Mapping[str, Any], path: Path) -> dict[str, str]:
    """The ``[coverage]`` table's exclusions: collision object name -> the reason it may
    lie outside the capsules and spheres (each reason required); ``{}`` without one."""
    if "coverage" not in cfg:
        return {}
    table = _table(cfg, "coverage", path, 'exclude = { "<collision object>" = "<why>" }')
    _unknown_keys(table, ("exclude",), "[coverage]", path, "coverage")
    exclude = table.get("exclude", {})
    if not isinstance(exclude, dict) or not all(
        isinstance(v, str) and v.strip() for v in exclude.values()
    ):
        raise RobotDescriptionError(
            f"{path}: [coverage] exclude must map each collision object it leaves out to "
            'the reason, e.g. exclude = { "link_0_0" = "fixed to the base: never moves" }; '
            f"got {exclude!r}",
            path=path,
            name="coverage.exclude",
            value=exclude,
        )
    return {str(k): str(v) for k, v in exclude.items()}
