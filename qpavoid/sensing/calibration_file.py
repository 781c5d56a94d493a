"""The calibration file (TOML): read, checked, turned into a
:class:`~qpavoid.sensing.calibration.Calibration` (its format: :mod:`qpavoid.sensing.calibration`).

The file's shape (types, ranges, the keys known, so that a typo cannot pass silently, and
those required) is :class:`~qpavoid.sensing.calibration_schema.CalibrationFile`'s, refused
in one line naming the field's path (``sensors.cam.latency_s``). A transform whose rotation
block is not a rotation (``RᵀR = I`` and ``det R = +1`` within
:data:`~qpavoid.sensing.calibration.RIGID_TOLERANCE`), whose last row is not ``[0, 0, 0, 1]`` or
that holds a non-finite number is refused here; so are a format the library does not ship,
a file that is not a regular file of at most :data:`MAX_CALIBRATION_BYTES`, and key files
that cannot be loaded (:mod:`qpavoid.sensing.keys`). The rotation is then
re-orthonormalised by scipy (``Rotation.from_matrix``), so that six printed decimals do
not turn into a scale error.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

import msgspec
import numpy as np
from scipy.spatial.transform import Rotation

from qpavoid.core.checks import one_line
from qpavoid.core.errors import CalibrationError
from qpavoid.core.file_bounds import NotTOMLError, read_toml
from qpavoid.core.schema import convert
from qpavoid.sensing.calibration import (
    MAX_TRANSLATION_M,
    RIGID_TOLERANCE,
    Calibration,
    SensorCalibration,
    check_format_name,
)
from qpavoid.sensing.calibration_schema import CalibrationFile, SensorTable
from qpavoid.sensing.keys import SensorKeys, load_key_file

__all__ = ["MAX_CALIBRATION_BYTES", "SENSOR_KEYS", "calibration_from_dict", "load_calibration"]

#: The keys a sensor's table may hold.
SENSOR_KEYS = tuple(f.encode_name for f in msgspec.structs.fields(SensorTable))
#: A calibration file is a few tables of numbers (about 400 bytes a sensor): 1 MiB holds
#: thousands, and refuses a device or a huge file before it is read (``--sensors /dev/zero``
#: once read until the memory ran out).
MAX_CALIBRATION_BYTES = 1 << 20


def calibration_from_dict(data: Mapping, path: str | None = None) -> Calibration:
    """A calibration from the parsed TOML (``{"cell": ..., "sensors": {name: {...}}}``).

    Its shape is :class:`~qpavoid.sensing.calibration_schema.CalibrationFile`'s; what needs
    more than the file (a rigid transform, a known format, the key files) is checked here.

    Raises
    ------
    CalibrationError
        As :func:`load_calibration`.
    """
    where = f"calibration {path}: " if path else "calibration: "
    names = list(data.get("sensors") or ()) if isinstance(data, Mapping) else []

    def refused(name: str, message: str, value: object) -> CalibrationError:
        sensor = next((n for n in names if name.startswith(f"sensors.{n}")), None)
        return CalibrationError(
            f"{where}{message}", path=path, sensor=sensor, name=name or None, value=value
        )

    file = convert(data, CalibrationFile, refused)
    out, keys, key_files = {}, {}, {}
    for name, table in file.sensors.items():

        def fail(message: str, key: str | None, value: object, name: str = name) -> Exception:
            return refused(f"sensors.{name}.{key}" if key else f"sensors.{name}", message, value)

        out[name] = _sensor(name, table, fail)
        if table.key_file is not None:
            keys[name], key_files[name] = _keys(name, table, where, path)
    return Calibration(out, path, file.cell, keys, key_files)


def _keys(name: str, table: SensorTable, where: str, path: str | None) -> tuple[SensorKeys, str]:
    """A sensor's keys: its ``key_file`` (relative to the calibration file), restricted to
    its ``key_ids`` if it names them; and the key file's absolute path."""
    folder = Path(path).parent if path else Path(".")
    key_file = folder / str(table.key_file)
    keys = load_key_file(key_file, name)
    if table.key_ids is None:
        return keys, str(key_file.absolute())
    return keys.only(tuple(table.key_ids), where), str(key_file.absolute())


def _sensor(
    name: str, table: SensorTable, fail: Callable[[str, str | None, object], Exception]
) -> SensorCalibration:
    """One sensor's calibration: what its table's schema cannot say checked."""
    T = _rigid(
        table.base_from_camera,
        lambda message, value: fail(f"sensors.{name}.{message}", "base_from_camera", value),
    )
    if table.range_m is not None and not table.range_m[0] < table.range_m[1]:
        raise fail(
            f"sensors.{name}.range_m must be two increasing positive numbers (m), got "
            f"{list(table.range_m)}",
            "range_m",
            table.range_m,
        )
    problem = check_format_name(table.format)
    if problem is not None:
        raise fail(f"sensors.{name}.{problem}", "format", table.format)
    try:
        return SensorCalibration(
            name,
            T,
            table.time_offset_s,
            table.weight,
            field_of_view_deg=table.field_of_view_deg,
            range_m=table.range_m,
            format=table.format,
            latency_s=table.latency_s,
            topic=table.topic,
        )
    except CalibrationError as exc:
        raise fail(f"sensors.{name}.{str(exc).split(': ', 1)[-1]}", exc.name, exc.value) from None


def _rigid(rows: tuple, fail: Callable[[str, object], Exception]) -> np.ndarray:
    """A 4×4 rigid transform from its schema's rows, re-orthonormalised, or ``fail``'s error
    (``fail(message, value)``, the message naming ``base_from_camera``'s path) raised."""
    key = "base_from_camera"
    T = np.array(rows, dtype=float)
    if not np.isfinite(T).all():
        raise fail(f"{key} has a non-finite entry", T)
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=RIGID_TOLERANCE):
        raise fail(f"{key}'s last row must be [0, 0, 0, 1], got {T[3].tolist()}", T)
    if np.abs(T[:3, 3]).max() > MAX_TRANSLATION_M:
        raise fail(
            f"{key}'s translation {T[:3, 3].tolist()} is beyond {MAX_TRANSLATION_M:g} m "
            "(not metres?)",
            T,
        )
    R = T[:3, :3]
    orth = float(np.abs(R.T @ R - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if orth > RIGID_TOLERANCE or abs(det - 1.0) > RIGID_TOLERANCE:
        raise fail(
            f"{key} is not rigid: its rotation block has max |RᵀR − I| = {orth:.2g} and "
            f"det R = {det:.6g} (a rotation has 0 and 1, within {RIGID_TOLERANCE})",
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
