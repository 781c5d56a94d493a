"""A body file's shape: ``<format>_body.toml`` read, its keys and tables checked.

A body file (``formats/kinect_v2_body.toml`` shows the keys, each with its meaning) names
its skeleton format, the joints that are model points in order, the centres and the
``[[parts]]``. :func:`read_body_file` checks what needs no format: the file's size and
syntax (:func:`~qpavoid.human.skeleton_file.read_toml`), the keys known, each of its kind;
whether the joints it names are its format's is the model's to check
(:class:`~qpavoid.human.body.BodyModel`, :mod:`qpavoid.human.body_parts`).
"""

from __future__ import annotations

from pathlib import Path

from qpavoid.core.errors import SkeletonFormatError
from qpavoid.human.body_parts import BodyPart, Joint
from qpavoid.human.skeleton_file import read_toml

__all__ = ["read_body_file"]

_BODY_KEYS = ("format", "points", "centres", "parts")
_PART_KEYS = (
    "name",
    "chain",
    "mid",
    "sphere_radius_m",
    "capsule_radius_m",
    "reach",
    "moves_with_body",
    "region",
)


def read_body_file(
    path: str | Path,
) -> tuple[tuple[str, ...], tuple[BodyPart, ...], str, tuple[tuple[str, tuple[Joint, ...]], ...]]:
    """The point order, the parts, the format's name and the centres of the body file at
    ``path``.

    Raises
    ------
    SkeletonFormatError
        For a file that cannot be read, is not TOML, or lacks a key or has an unknown one
        (joint names are checked against the format by :class:`BodyModel`).
    """
    data = read_toml(path)

    def fail(message: str, key: str, value: object) -> SkeletonFormatError:
        return SkeletonFormatError(f"{path}: {message}", path=path, name=key, value=value)

    unknown = [k for k in data if k not in _BODY_KEYS]
    if unknown:
        raise fail(
            f"unknown key {unknown[0]}; the keys are {', '.join(_BODY_KEYS)}",
            unknown[0],
            data[unknown[0]],
        )
    format_name, points, rows = data.get("format"), data.get("points", []), data.get("parts")
    if not isinstance(format_name, str):
        raise fail(
            f"format must name a skeleton format, got {format_name!r}", "format", format_name
        )
    if not isinstance(points, list) or not all(isinstance(p, str) for p in points):
        raise fail(f"points must be an array of joint names, got {points!r}", "points", points)
    if len(set(points)) != len(points):
        raise fail(f"points names a joint twice: {points!r}", "points", points)
    if not format_name.replace("_", "").replace("-", "").isalnum():
        raise fail(
            f"format must be a format's name (letters, digits, _ and -), got {format_name!r}",
            "format",
            format_name,
        )
    if not isinstance(rows, list) or not rows:
        raise fail(f"parts must be an array of tables ([[parts]]), got {rows!r}", "parts", rows)
    table = data.get("centres", {})
    if not isinstance(table, dict) or not all(
        isinstance(v, list) and all(isinstance(j, str) for j in v) for v in table.values()
    ):
        raise fail(
            f"centres must be a table of names to arrays of joint names, got {table!r}",
            "centres",
            table,
        )
    centres = tuple((name, tuple(joints)) for name, joints in table.items())
    parts = []
    for k, row in enumerate(rows):
        if not isinstance(row, dict):
            raise fail(f"parts[{k}] must be a table, got {row!r}", f"parts[{k}]", row)
        unknown = [key for key in row if key not in _PART_KEYS]
        missing = [key for key in _PART_KEYS[:5] if key not in row]
        if unknown or missing:
            key = (unknown or missing)[0]
            what = "unknown key" if unknown else "missing key"
            raise fail(
                f"parts[{k}]: {what} {key}; the keys are {', '.join(_PART_KEYS)}",
                f"parts[{k}].{key}",
                row.get(key),
            )
        for key in ("chain", "mid", "reach"):
            joints = row.get(key, [])
            if not isinstance(joints, list) or not all(isinstance(j, str) for j in joints):
                raise fail(
                    f"parts[{k}].{key} must be an array of joint names, got {joints!r}",
                    f"parts[{k}].{key}",
                    joints,
                )
        moves = row.get("moves_with_body", False)
        if not isinstance(moves, bool):
            raise fail(
                f"parts[{k}].moves_with_body must be true or false, got {moves!r}",
                f"parts[{k}].moves_with_body",
                moves,
            )
        region = row.get("region")
        if region is not None and (not isinstance(region, str) or not region.strip()):
            raise fail(
                f"parts[{k}].region must name a body region (text), got {region!r}",
                f"parts[{k}].region",
                region,
            )
        parts.append(
            BodyPart(
                row["name"],
                tuple(row["chain"]),
                tuple(row["mid"]),
                row["sphere_radius_m"],
                row["capsule_radius_m"],
                tuple(row.get("reach", ())),
                moves,
                region,
            )
        )
    return tuple(points), tuple(parts), format_name, centres
