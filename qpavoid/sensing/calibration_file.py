"""The calibration file (TOML): read, checked, turned into a
:class:`~qpavoid.sensing.calibration.Calibration` (its format: :mod:`qpavoid.sensing.calibration`).

A transform whose rotation block is not a rotation (``RᵀR = I`` and ``det R = +1`` within
:data:`~qpavoid.sensing.calibration.RIGID_TOLERANCE`), whose last row is not ``[0, 0, 0, 1]`` or
that holds a non-finite number is refused; so are unknown keys (a typo must not pass
silently), a file that is not a regular file of at most :data:`MAX_CALIBRATION_BYTES`,
and key files that cannot be loaded (:mod:`qpavoid.sensing.keys`). The rotation is then
re-orthonormalised by scipy (``Rotation.from_matrix``), so that six printed decimals do
not turn into a scale error.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from qpavoid.core.checks import one_line
from qpavoid.core.errors import CalibrationError
from qpavoid.core.file_bounds import NotTOMLError, read_toml
from qpavoid.sensing.calibration import (
    DEFAULT_FORMAT,
    MAX_TRANSLATION_M,
    RIGID_TOLERANCE,
    Calibration,
    SensorCalibration,
    check_format_name,
    latency_error,
    pair_within,
    settings_error,
)
from qpavoid.sensing.keys import SensorKeys, load_key_file

__all__ = ["MAX_CALIBRATION_BYTES", "SENSOR_KEYS", "calibration_from_dict", "load_calibration"]

#: The keys a sensor's table may hold.
SENSOR_KEYS = (
    "base_from_camera",
    "time_offset_s",
    "weight",
    "key_file",
    "key_ids",
    "field_of_view_deg",
    "range_m",
    "format",
    "latency_s",
    "topic",
)
#: A calibration file is a few tables of numbers (about 400 bytes a sensor): 1 MiB holds
#: thousands, and refuses a device or a huge file before it is read (``--sensors /dev/zero``
#: once read until the memory ran out).
MAX_CALIBRATION_BYTES = 1 << 20


def calibration_from_dict(data: Mapping, path: str | None = None) -> Calibration:
    """A calibration from the parsed TOML (``{"cell": ..., "sensors": {name: {...}}}``).

    Raises
    ------
    CalibrationError
        As :func:`load_calibration`.
    """
    where = f"calibration {path}: " if path else "calibration: "
    sensors = data.get("sensors") if isinstance(data, Mapping) else None
    extra = sorted(set(data) - {"sensors", "cell"}) if isinstance(data, Mapping) else []
    if extra:
        raise CalibrationError(
            f"{where}unknown top-level key {extra[0]!r} (expected cell and [sensors.NAME] tables)",
            path=path,
            name=extra[0],
        )
    if not isinstance(sensors, Mapping) or not sensors:
        raise CalibrationError(
            f"{where}no sensor: expected at least one [sensors.NAME] table", path=path
        )
    out, keys, key_files = {}, {}, {}
    for name, table in sensors.items():
        out[name] = _sensor(name, table, where, path)
        if isinstance(table, Mapping) and "key_file" in table:
            keys[name], key_files[name] = _keys(name, table, where, path)
    cell = data.get("cell", "")
    if not isinstance(cell, str):
        raise CalibrationError(f"{where}cell must be a string", path=path, name="cell")
    return Calibration(out, path, cell, keys, key_files)


def _keys(name: str, table: Mapping, where: str, path: str | None) -> tuple[SensorKeys, str]:
    """A sensor's keys: its ``key_file`` (relative to the calibration file), restricted to
    its ``key_ids`` if it names them; and the key file's absolute path."""
    key_file, ids = table["key_file"], table.get("key_ids")
    if not isinstance(key_file, str) or not key_file:
        raise CalibrationError(
            f"{where}sensor {name!r}: key_file must be a path", path=path, sensor=name
        )
    folder = Path(path).parent if path else Path(".")
    where_key = str((folder / key_file).absolute())
    keys = load_key_file(folder / key_file, name)
    if ids is None:
        return keys, where_key
    if (
        not isinstance(ids, list)
        or not ids
        or not all(isinstance(i, int) and not isinstance(i, bool) for i in ids)
    ):
        raise CalibrationError(
            f"{where}sensor {name!r}: key_ids must be a list of key ids, got {ids!r}",
            path=path,
            sensor=name,
            name="key_ids",
            value=ids,
        )
    return keys.only(tuple(ids), where), where_key


def _sensor(name: str, table: object, where: str, path: str | None) -> SensorCalibration:
    def fail(message: str, key: str | None = None, value: object = None) -> CalibrationError:
        return CalibrationError(
            f"{where}sensor {name!r}: {message}", path=path, sensor=name, name=key, value=value
        )

    if not isinstance(table, Mapping):
        raise fail("must be a table with base_from_camera")
    unknown = sorted(set(table) - set(SENSOR_KEYS))
    if unknown:
        raise fail(
            f"unknown key {unknown[0]!r} (keys: {', '.join(SENSOR_KEYS)})", unknown[0], table
        )
    if "base_from_camera" not in table:
        raise fail("base_from_camera is missing (a 4x4 rigid transform, m)", "base_from_camera")
    T = _rigid(table["base_from_camera"], fail)
    offset, weight = table.get("time_offset_s", 0.0), table.get("weight", 1.0)
    bad = settings_error(offset, weight)
    if bad is not None:
        raise fail(bad[1], bad[0], bad[2])
    view = {}
    for key in ("field_of_view_deg", "range_m"):
        value = table.get(key)
        if value is not None:
            if not pair_within(value, 0.0, math.inf, key == "range_m"):
                what = "increasing positive numbers" if key == "range_m" else "positive numbers"
                raise fail(f"{key} must be two {what}, got {str(value)[:80]}", key, value)
            view[key] = (float(value[0]), float(value[1]))
    fmt = table.get("format", DEFAULT_FORMAT)
    problem = check_format_name(fmt)
    if problem is not None:
        raise fail(problem, "format", fmt)
    latency = table.get("latency_s")
    problem = latency_error(latency)
    if problem is not None:
        raise fail(problem, "latency_s", latency)
    topic = table.get("topic")
    if topic is not None and not _ros_topic(topic):
        raise fail(
            f"topic must be a ROS 2 topic name (/ then letters, digits, _ and /), got "
            f"{str(topic)[:80]!r}",
            "topic",
            topic,
        )
    try:
        return SensorCalibration(
            name,
            T,
            float(offset),
            float(weight),
            **view,
            format=fmt,
            latency_s=None if latency is None else float(latency),
            topic=topic,
        )
    except CalibrationError as exc:
        raise fail(str(exc).split(": ", 1)[-1], exc.name, exc.value) from None


def _ros_topic(value: object) -> bool:
    """A fully qualified ROS 2 topic name: ``/`` then tokens of letters, digits and ``_``,
    not starting with a digit, joined by single ``/`` (ROS 2's topic name rules)."""
    return (
        isinstance(value, str)
        and re.fullmatch(r"(/[A-Za-z_][A-Za-z0-9_]*)+", value) is not None
        and "__" not in value
        and len(value) <= 256
    )


def _rigid(value: object, fail: Callable[..., CalibrationError]) -> np.ndarray:
    """A 4×4 rigid transform from nested lists, re-orthonormalised, or ``fail(...)`` raised."""
    key = "base_from_camera"
    numbers = isinstance(value, list) and all(
        isinstance(row, list)
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in row)
        for row in value
    )
    if not numbers:  # no booleans, strings or deeper nesting taken as numbers
        raise fail(f"{key} must be 4 rows of 4 numbers, got {str(value)[:80]}", key, value)
    try:
        T = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise fail(
            f"{key} must be 4 rows of 4 numbers, got {str(value)[:80]}", key, value
        ) from None
    if T.shape != (4, 4):
        raise fail(f"{key} must be 4 rows of 4 numbers (shape (4, 4)), got {T.shape}", key, T)
    if not np.isfinite(T).all():
        raise fail(f"{key} has a non-finite entry", key, T)
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=RIGID_TOLERANCE):
        raise fail(f"{key}'s last row must be [0, 0, 0, 1], got {T[3].tolist()}", key, T)
    if np.abs(T[:3, 3]).max() > MAX_TRANSLATION_M:
        raise fail(
            f"{key}'s translation {T[:3, 3].tolist()} is beyond {MAX_TRANSLATION_M:g} m "
            "(not metres?)",
            key,
            T,
        )
    R = T[:3, :3]
    orth = float(np.abs(R.T @ R - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if orth > RIGID_TOLERANCE or abs(det - 1.0) > RIGID_TOLERANCE:
        raise fail(
            f"{key} is not rigid: its rotation block has max |RᵀR − I| = {orth:.2g} and "
            f"det R = {det:.6g} (a rotation has 0 and 1, within {RIGID_TOLERANCE})",
            key,
            T,
        )
    out = np.eye(4)
    out[:3, :3] = Rotation.from_matrix(R).as_matrix()
    out[:3, 3] = T[:3, 3]
    out.setflags(write=False)
    return out


def load_calibration(path: str | Path) -> Calibration:
    """Read a calibration file (TOML, see the module docstring).

    Raises
    ------
    CalibrationError
        If the file cannot be read or parsed, is not a regular file of at most
        :data:`MAX_CALIBRATION_BYTES`, holds no sensor, an unknown key, a transform that
        is malformed or not rigid, or keys that cannot be loaded (:mod:`qpavoid.sensing.keys`) or
        are given for some sensors only; the message names the file, the sensor and the
        key.
    """
    p = str(path)
    try:
        data = read_toml(p, MAX_CALIBRATION_BYTES)
    except NotTOMLError as exc:
        raise CalibrationError(
            f"calibration {p} is not valid TOML: {one_line(exc)}", path=p
        ) from None
    except (OSError, ValueError) as exc:
        raise CalibrationError(
            f"cannot read calibration {p}: {one_line(exc)}", path=p, name="path", value=p
        ) from None
    return calibration_from_dict(data, p)
