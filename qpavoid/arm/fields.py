"""Reading the fields of a robot description's tables: one rule for every table.

A number within its bounds, a table that must be there, no unknown key: each refusal a
:class:`~qpavoid.core.errors.RobotDescriptionError` naming the file, the key as the file
says it and the offending value (:mod:`qpavoid.arm.control_points`, :mod:`qpavoid.arm.urdf`,
:mod:`qpavoid.arm.joints`, :mod:`qpavoid.arm.roles`, :mod:`qpavoid.arm.dynamics`).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from qpavoid.core.errors import RobotDescriptionError

__all__ = ["number", "table", "unknown_keys"]


def number(
    value: object, where: str, path: Path, low: float, strict: bool, high: float = math.inf
) -> float:
    """``value`` as a finite float above ``low`` (at or above unless ``strict``) and at most
    ``high``, or a :class:`RobotDescriptionError` naming ``where``."""
    number = math.nan
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        with contextlib.suppress(OverflowError):  # an integer beyond any float stays nan
            number = float(value)
    if not (
        math.isfinite(number) and (number > low if strict else number >= low) and number <= high
    ):
        bound = f"{'above' if strict else 'at least'} {low:g}"
        bound += f" and at most {high:g}" if math.isfinite(high) else ""
        raise RobotDescriptionError(
            f"{path}: {where} must be a number {bound}, got {value!r}",
            path=path,
            name=where,
            value=value,
        )
    return number


def table(cfg: Mapping[str, Any], key: str, path: Path, example: str) -> dict:
    """The table ``[key]`` of the file, or a :class:`RobotDescriptionError` showing one."""
    table = cfg.get(key)
    if not isinstance(table, dict):
        raise RobotDescriptionError(
            f"{path}: no [{key}] table; add one, e.g. {example} (docs/robot.md)",
            path=path,
            name=key,
            value=table,
        )
    return table


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
