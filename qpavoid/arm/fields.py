"""A robot description's refusals: one rule for every file of it.

A schema's refusal (:func:`refused`): a :class:`~qpavoid.core.errors.RobotDescriptionError`
naming the file, the key's path in it and the offending value.
"""

from __future__ import annotations

from pathlib import Path

from qpavoid.core.errors import RobotDescriptionError
from qpavoid.core.schema import Fail

__all__ = ["refused"]


def refused(path: Path) -> Fail:
    """How a schema's refusal (:func:`qpavoid.core.schema.convert`) becomes a
    :class:`RobotDescriptionError`: the file, then the field's path and the message."""

    def fail(name: str, message: str, value: object) -> RobotDescriptionError:
        return RobotDescriptionError(f"{path}: {message}", path=path, name=name, value=value)

    return fail
