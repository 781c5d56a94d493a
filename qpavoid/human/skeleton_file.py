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
from pathlib import Path
from typing import Any

from qpavoid.core.checks import one_line
from qpavoid.core.errors import SkeletonFormatError
from qpavoid.core.file_bounds import NotTOMLError
from qpavoid.core.file_bounds import read_toml as read_toml_file
from qpavoid.core.schema import convert
from qpavoid.human.camera_spec import CameraSpec, Evidence
from qpavoid.human.conversion import Confidence, refused, rule_of
from qpavoid.human.format_schema import FormatFile

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
#: A format's length units: metres per unit.
UNITS_M = {"m": 1.0, "mm": 0.001}


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
    file, its shape checked by its schema (:mod:`qpavoid.human.format_schema`: the keys
    known and required, each of its kind and range), the joints' ids in order,
    ``[sensor]`` (:class:`~qpavoid.human.camera_spec.CameraSpec`, with its evidence),
    ``[confidence]`` and the tables of rules made. Whether they agree with one another
    (joint names, the tree, the mirror pairs) is the format's to check when built.

    Raises
    ------
    SkeletonFormatError
        Naming the key's path and the offending value.
    """
    file = convert(data, FormatFile, refused)
    for k, row in enumerate(file.joints):
        if row.id != k:
            raise SkeletonFormatError(
                f"joints[{k}].id must be {k} (ids run 0, 1, 2, ... in file order), got {row.id!r}",
                name=f"joints[{k}].id",
                value=row.id,
            )
    sensor = file.sensor
    numbers = {k: getattr(sensor, k) for k in CameraSpec.__dataclass_fields__ if k != "evidence"}
    evidence = tuple(
        (k, Evidence.of(f"sensor.evidence.{k}", v)) for k, v in sensor.evidence.items()
    )
    fields: dict[str, Any] = {
        "name": file.name,
        "title": file.title,
        "joints": tuple(row.name for row in file.joints),
        "parents": tuple(row.parent for row in file.joints),
        "bone_bounds_m": tuple(row.max_bone_m for row in file.joints),
        "mirror_pairs": tuple(tuple(p) for p in file.mirror_pairs),
        "torso": tuple(file.torso),
        "groups": tuple((g, tuple(roles.items())) for g, roles in file.groups.items()),
        "sensor": CameraSpec(**numbers, evidence=evidence),
        "unit_m": UNITS_M[file.units],
        "axes": tuple(file.axes),
        "confidence": Confidence.from_table(file.confidence),
        "body": file.body,
        "landmarks": tuple((k, rule_of(v, f"landmarks.{k}")) for k, v in file.landmarks.items()),
        "simulate": tuple((k, rule_of(v, f"simulate.{k}")) for k, v in file.simulate.items()),
    }
    if file.tracking_states is not None:
        fields["tracking_states"] = tuple(file.tracking_states.items())
    return fields
