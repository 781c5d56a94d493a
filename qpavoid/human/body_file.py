"""A body file's shape: ``<format>_body.toml`` read, its keys and tables checked.

A body file (``formats/kinect_v2_body.toml`` shows the keys, each with its meaning) names
its skeleton format, the joints that are model points in order, the centres and the
``[[parts]]``. :func:`read_body_file` checks what needs no format: the file's size and
syntax (:func:`~qpavoid.human.skeleton_file.read_toml`) and its shape, the schema of
:mod:`qpavoid.human.body_schema` (the keys known and required, each of its kind and range);
whether the joints it names are its format's is the model's to check
(:class:`~qpavoid.human.body.BodyModel`, :mod:`qpavoid.human.body_parts`).
"""

from __future__ import annotations

from pathlib import Path

from qpavoid.core.errors import SkeletonFormatError
from qpavoid.core.schema import convert
from qpavoid.human.body_parts import BodyPart, Joint
from qpavoid.human.body_schema import BodyFile
from qpavoid.human.skeleton_file import read_toml

__all__ = ["read_body_file"]


def read_body_file(
    path: str | Path,
) -> tuple[tuple[str, ...], tuple[BodyPart, ...], str, tuple[tuple[str, tuple[Joint, ...]], ...]]:
    """The point order, the parts, the format's name and the centres of the body file at
    ``path``.

    Raises
    ------
    SkeletonFormatError
        For a file that cannot be read, is not TOML, or is not of its schema's shape
        (:mod:`qpavoid.human.body_schema`: a key missing or unknown, a value of the wrong
        type or out of its range); joint names are checked against the format by
        :class:`BodyModel`.
    """

    def fail(key: str, message: str, value: object) -> SkeletonFormatError:
        return SkeletonFormatError(f"{path}: {message}", path=path, name=key, value=value)

    body = convert(read_toml(path), BodyFile, fail)
    if len(set(body.points)) != len(body.points):
        raise fail("points", f"points names a joint twice: {body.points!r}", body.points)
    parts = tuple(
        BodyPart(
            row.name,
            tuple(row.chain),
            row.mid,
            row.sphere_radius_m,
            row.capsule_radius_m,
            tuple(row.reach),
            row.moves_with_body,
            row.region,
        )
        for row in body.parts
    )
    centres = tuple((name, tuple(joints)) for name, joints in body.centres.items())
    return tuple(body.points), parts, body.format, centres
