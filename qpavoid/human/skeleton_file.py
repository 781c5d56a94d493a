"""A skeleton format file's shape: the TOML read, bounded, and its keys and tables checked.

A format file (``formats/kinect_v2.toml`` shows the keys, each with its meaning and source)
holds the joints in the sensor's order, the mirror pairs, the torso, the groups, the
camera's ``[sensor]`` table, the units and axes, ``[confidence]`` and the tables of rules
``[landmarks]`` and ``[simulate]``. This module checks what needs no other key: the file's
size and syntax, the keys known and each of its kind; :func:`format_fields` gives the
fields of a :class:`~qpavoid.human.skeleton.SkeletonFormat`, which checks that they agree
with one another when built. A body file (:mod:`qpavoid.human.body_file`) is read within
the same bound (:func:`read_toml`).

Every refusal is a :class:`~qpavoid.core.errors.SkeletonFormatError` naming the key and
the offending value (:meth:`~qpavoid.human.skeleton.SkeletonFormat.load` adds the file).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING
from pathlib import Path
from typing import Any, NoReturn

from qpavoid.core.checks import one_line
from qpavoid.core.errors import SkeletonFormatError
from qpavoid.core.file_bounds import NotTOMLError
from qpavoid.core.file_bounds import read_toml as read_toml_file
from qpavoid.human.camera_spec import CameraSpec, Evidence
from qpavoid.human.conversion import Confidence, only_keys, parse_rule

__all__ = [
    "FORMATS_DIR",
    "MAX_FORMAT_FILE_BYTES",
    "UNITS_M",
    "format_fields",
    "read_toml",
]

#: Where the library's own format and body files are.
FORMATS_DIR = Path(__file__).with_name("formats")
#: Largest format or body file read, bytes: the Kinect v2's is 6 kB; 1 MB is junk.
MAX_FORMAT_FILE_BYTES = 2**20

_TOP_KEYS = (
    "name",
    "title",
    "tracking_states",
    "sensor",
    "joints",
    "mirror_pairs",
    "torso",
    "groups",
    "units",
    "axes",
    "confidence",
    "body",
    "landmarks",
    "simulate",
)
#: A format's length units: metres per unit.
UNITS_M = {"m": 1.0, "mm": 0.001}
_JOINT_KEYS = ("id", "name", "parent", "max_bone_m")


def read_toml(path: str | Path) -> dict:
    """The parsed TOML file at ``path`` (bounded to :data:`MAX_FORMAT_FILE_BYTES`), or a
    :class:`SkeletonFormatError` naming the file."""
    try:
        return read_toml_file(path, MAX_FORMAT_FILE_BYTES)
    except NotTOMLError as exc:
        raise SkeletonFormatError(f"{path}: not TOML: {one_line(exc)}", path=path) from None
    except (OSError, ValueError) as exc:
        raise SkeletonFormatError(
            f"{path}: cannot read the file: {one_line(exc)}", path=path
        ) from None


def format_fields(data: Mapping[str, object]) -> dict[str, Any]:
    """The fields of a :class:`~qpavoid.human.skeleton.SkeletonFormat` from a parsed format
    file, its shape checked: the keys known, each of its kind, the joints' ids in order,
    ``[sensor]`` (:class:`~qpavoid.human.camera_spec.CameraSpec`, with its evidence),
    ``[confidence]`` and the tables of rules parsed. Whether they agree with one another
    (joint names, the tree, the mirror pairs) is the format's to check when built.

    Raises
    ------
    SkeletonFormatError
        Naming the key and the offending value.
    """
    only_keys(data, _TOP_KEYS, "")
    rows = _require(data, "joints", list, "an array of tables")
    names, parents, bounds = [], [], []
    for k, row in enumerate(rows):
        if not isinstance(row, dict):
            _fail(f"joints[{k}] must be a table, got {row!r}", f"joints[{k}]", row)
        only_keys(row, _JOINT_KEYS, f"joints[{k}].")
        if row.get("id") != k or isinstance(row.get("id"), bool):
            _fail(
                f"joints[{k}].id must be {k} (ids run 0, 1, 2, ... in file order), "
                f"got {row.get('id')!r}",
                f"joints[{k}].id",
                row.get("id"),
            )
        names.append(_require(row, "name", str, "a string", f"joints[{k}]."))
        parent = row.get("parent")
        if parent is not None and not isinstance(parent, str):
            _fail(f"joints[{k}].parent must be a joint name, got {parent!r}", "parent", parent)
        parents.append(parent)
        bounds.append(row.get("max_bone_m", 0.0))
    pairs = _require(data, "mirror_pairs", list, "an array of [left, right] pairs")
    groups = data.get("groups", {})  # optional: code that needs a role says so
    if not isinstance(groups, dict):
        _fail(f"groups must be a table of tables, got {groups!r}", "groups", groups)
    for group, roles in groups.items():
        if not isinstance(roles, dict):
            _fail(f"groups.{group} must be a table, got {roles!r}", f"groups.{group}", roles)
    sensor = dict(_require(data, "sensor", dict, "a table"))
    only_keys(sensor, tuple(CameraSpec.__dataclass_fields__), "sensor.")
    evidence = sensor.pop("evidence", {})
    if not isinstance(evidence, dict):
        _fail(f"sensor.evidence must be a table, got {evidence!r}", "sensor.evidence", evidence)
    sensor["evidence"] = tuple((k, Evidence.read(k, v)) for k, v in evidence.items())
    missing = [
        k
        for k, f in CameraSpec.__dataclass_fields__.items()
        if k not in sensor and f.default is MISSING
    ]
    if missing:
        _fail(f"sensor has no key {missing[0]!r}", f"sensor.{missing[0]}", None)
    states = data.get("tracking_states", {})  # absent: the library's (the default)
    if not isinstance(states, dict):
        _fail(f"tracking_states must be a table, got {states!r}", "tracking_states", states)
    units = data.get("units", "m")
    if units not in UNITS_M:
        _fail(f"units must be one of {list(UNITS_M)}, got {units!r}", "units", units)
    axes = data.get("axes", ["left", "up", "forward"])
    if not isinstance(axes, list):
        _fail(f"axes must be three directions, got {axes!r}", "axes", axes)
    tables = {}
    for key in ("landmarks", "simulate"):
        table = data.get(key, {})
        if not isinstance(table, dict):
            _fail(f"{key} must be a table, got {table!r}", key, table)
        tables[key] = tuple((k, parse_rule(v, f"{key}.{k}")) for k, v in table.items())
    body = data.get("body", "")
    if not isinstance(body, str):
        _fail(f"body must be a format's name, got {body!r}", "body", body)
    fields: dict[str, Any] = {
        "name": _require(data, "name", str, "a string"),
        "title": _require(data, "title", str, "a string"),
        "joints": tuple(names),
        "parents": tuple(parents),
        "bone_bounds_m": tuple(bounds),
        "mirror_pairs": tuple(tuple(p) if isinstance(p, list) else p for p in pairs),
        "torso": tuple(_require(data, "torso", list, "an array of joint names")),
        "groups": tuple((g, tuple(roles.items())) for g, roles in groups.items()),
        "sensor": CameraSpec(
            **{k: tuple(v) if isinstance(v, list) else v for k, v in sensor.items()}  # type: ignore[arg-type]
        ),
        "unit_m": UNITS_M[units],
        "axes": tuple(axes),
        "confidence": Confidence.from_mapping(data.get("confidence", {})),
        "body": body,
        "landmarks": tables["landmarks"],
        "simulate": tables["simulate"],
    }
    if "tracking_states" in data:
        fields["tracking_states"] = tuple(states.items())
    return fields


def _fail(message: str, name: str, value: object) -> NoReturn:
    raise SkeletonFormatError(message, name=name, value=value)


def _require(data: Mapping[str, object], key: str, kind: type, what: str, prefix: str = "") -> Any:
    """``data[key]``, which must be a ``kind`` (``what`` in the message)."""
    if key not in data:
        _fail(f"{prefix}{key} is missing (expected {what})", f"{prefix}{key}", None)
    value = data[key]
    if not isinstance(value, kind):
        _fail(f"{prefix}{key} must be {what}, got {value!r}", f"{prefix}{key}", value)
    return value
