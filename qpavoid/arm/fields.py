"""A robot description's refusals: one rule for every file of it.

A schema's refusal (:func:`refused`) or an unknown key of a table read without a schema
(:func:`unknown_keys`): each a :class:`~qpavoid.core.errors.RobotDescriptionError` naming
the file, the key's path in it and the offending value.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from qpavoid.core.errors import RobotDescriptionError
from qpavoid.core.schema import Fail

__all__ = ["refused", "unknown_keys"]


def refused(path: Path) -> Fail:
    """How a schema's refusal (:func:`qpavoid.core.schema.convert`) becomes a
    :class:`RobotDescriptionError`: the file, then the field's path and the message."""

    def fail(name: str, message: str, value: object) -> RobotDescriptionError:
        return RobotDescriptionError(f"{path}: {message}", path=path, name=name, value=value)

    return fail


def unknown_keys(
    table: Mapping[str, Any], known: Sequence[str], where: str, path: Path, name: str
) -> None:
    """Refuse keys a table does not have (a misspelt key would otherwise be ignored)."""
    unknown = sorted(set(table) - set(known))
    if unknown:
        raise RobotDescriptionError(
            f"{path}: {where} has unknown key(s) {unknown}; its keys are {list(known)}",
            path=path,
            name=name,
            value=unknown,
        )
