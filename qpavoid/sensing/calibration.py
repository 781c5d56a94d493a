"""Sensor calibration: where each camera is, as a rigid transform into the robot base frame.

A calibration file (TOML) names any number of sensors, each with the 4×4 rigid transform
from its camera frame to the robot base frame, m (docs/sensors.md)::

    [sensors.kinect_left]
    base_from_camera = [[r11, r12, r13, tx],
                        [r21, r22, r23, ty],
                        [r31, r32, r33, tz],
                        [0, 0, 0, 1]]
    time_offset_s = 0.0     # optional: added to the sensor's time stamps (its clock -> ours)
    weight = 1.0            # optional: trust in this sensor relative to the others
    key_file = "kinect_left.key"   # its datagrams' key (sensing.keys), relative to this file
    key_ids = [2, 1]        # optional: the key ids accepted, the first signing (default: all)
    field_of_view_deg = [70.6, 60.0]  # optional: what it sees, horizontal and vertical ...
    range_m = [0.5, 4.5]              # ... between these depths (a Kinect v2's): a person
                                      # in its view that it does not see is suspect
    format = "kinect_v2"    # optional: its skeleton format (qpavoid.human.landmarks), the
                            # joints of its recordings and datagrams (default kinect_v2)
    latency_s = 0.104       # optional: its latency as measured (qpavoid latency), s; sets
                            # how old its frames may be (default: its format's latency)

with, when the sensors have keys, the cell's name at the top (``cell = "cell-1"``): it is
signed into every datagram, so that one cell's datagrams are refused by another's. Either
every sensor has a ``key_file`` or none does (docs/security.md).

:func:`qpavoid.sensing.calibration_file.load_calibration` reads and checks one.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from functools import cache
from types import MappingProxyType

import numpy as np

from qpavoid.core.errors import CalibrationError
from qpavoid.human.camera_spec import AGE_MARGIN_S
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import FORMAT_NAMES, skeleton_format
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.sensing.keys import SensorKeys, sensor_name_error, toml_string

__all__ = [
    "DEFAULT_FORMAT",
    "Calibration",
    "SensorCalibration",
    "check_format_name",
    "known_formats",
    "latency_error",
    "pair_within",
    "settings_error",
]

#: A sensor's skeleton format when its calibration names none (every file before formats
#: were data was the Kinect v2's).
DEFAULT_FORMAT = KINECT_V2.name

#: How far a printed rotation may be from orthonormal: ``max |RᵀR − I|`` and ``|det R − 1|``.
#: 1e-4 admits a matrix written with five or six decimals, and refuses a scale or a shear.
RIGID_TOLERANCE = 1e-4
#: Bounds on a sensor's settings: a camera within 100 m of the robot (a Kinect sees 4.5 m;
#: more is a unit error), a clock offset within a day, a weight within 1e-3 to 1e3 of the
#: others' (beyond, float arithmetic, not trust, would decide).
MAX_TRANSLATION_M = 100.0
MAX_TIME_OFFSET_S = 86_400.0
MIN_WEIGHT, MAX_WEIGHT = 1e-3, 1e3
#: A cell's name: a short printable label, signed into every datagram.
_CELL_NAME = re.compile(r"[A-Za-z0-9._:-]{1,64}")


@dataclass(frozen=True)
class SensorCalibration:
    """One sensor's place and clock.

    Attributes
    ----------
    name
        The sensor's name (as in the data: a recording's ``sensor``, a datagram's ``sensor``).
    base_from_camera
        (4, 4) rigid transform from the camera frame to the robot base frame, m.
    time_offset_s
        Added to the sensor's time stamps to put them on the controller's clock, s
        (default 0: the sensors' clocks are already synchronised, e.g. by PTP).
    weight
        Trust in this sensor's joints relative to the others' (default 1).
    field_of_view_deg, range_m
        What the sensor sees: its full horizontal and vertical angles of view, deg, and
        the nearest and farthest depth it measures, m (None: not known; then
        :meth:`sees` is False everywhere). The camera frame is the format's
        (:attr:`~qpavoid.human.skeleton.SkeletonFormat.axes`; every format's looks along +z).
    format
        The sensor's skeleton format (a name of
        :data:`~qpavoid.human.landmarks.FORMAT_NAMES`; default ``"kinect_v2"``): its
        recordings and datagrams carry frames of this format's joints, in metres, with the
        library's tracking states.
    latency_s
        The sensor's latency from capture to arrival, s, as measured on the cell
        (``qpavoid latency``), or None: its format's (:attr:`~qpavoid.human.skeleton.
        CameraSpec.latency_s`). It sets :attr:`age_limit_s`.
    topic
        The ROS 2 topic its driver publishes its bodies on (``"/k4a/body_tracking_data"``),
        or None: the sensor is not read from ROS 2 (docs/ros2.md).
    """

    name: str
    base_from_camera: np.ndarray
    time_offset_s: float = 0.0
    weight: float = 1.0
    field_of_view_deg: tuple[float, float] | None = None
    range_m: tuple[float, float] | None = None
    format: str = DEFAULT_FORMAT
    latency_s: float | None = None
    topic: str | None = None

    def __post_init__(self) -> None:
        """The same limits as a calibration file's (a weight of 0 made seen joints
        missing with a positive confidence: adversarial tester)."""
        bad_name = sensor_name_error(self.name)
        if bad_name is not None:
            shown = repr(self.name)[:80]
            raise CalibrationError(
                f"sensor {shown}: {bad_name}", sensor=str(self.name)[:80], name="sensor"
            )
        T = np.asarray(self.base_from_camera, dtype=float)
        if T.shape != (4, 4) or not np.isfinite(T).all():
            raise CalibrationError(
                f"sensor {self.name!r}: base_from_camera must be a finite 4x4 transform",
                sensor=self.name,
                name="base_from_camera",
                value=self.base_from_camera,
            )
        object.__setattr__(self, "base_from_camera", T)
        for key, pair, low, high, what in (
            ("field_of_view_deg", self.field_of_view_deg, 0.0, 180.0, "(horizontal, vertical)"),
            ("range_m", self.range_m, 0.0, MAX_TRANSLATION_M, "(nearest, farthest)"),
        ):
            if pair is not None and not pair_within(pair, low, high, key == "range_m"):
                raise CalibrationError(
                    f"sensor {self.name!r}: {key} must be two numbers above {low:g}, at most "
                    f"{high:g} {what}",
                    sensor=self.name,
                    name=key,
                    value=pair,
                )
        bad = settings_error(self.time_offset_s, self.weight)
        if bad is not None:
            key, message, value = bad
            raise CalibrationError(
                f"sensor {self.name!r}: {message}", sensor=self.name, name=key, value=value
            )
        problem = check_format_name(self.format)
        if problem is not None:
            raise CalibrationError(
                f"sensor {self.name!r}: {problem}",
                sensor=self.name,
                name="format",
                value=self.format,
            )
        bad_latency = latency_error(self.latency_s)
        if bad_latency is not None:
            raise CalibrationError(
                f"sensor {self.name!r}: {bad_latency}",
                sensor=self.name,
                name="latency_s",
                value=self.latency_s,
            )

    @property
    def age_limit_s(self) -> float:
        """How old the sensor's frames may be when they arrive and when they are fused, s:
        its latency (:attr:`latency_s`, else its format's), one frame period and a margin
        (:meth:`~qpavoid.human.camera_spec.CameraSpec.age_limit_s`)."""
        return self.skeleton.sensor.age_limit_s(self.latency_s)

    @property
    def latency_used_s(self) -> float:
        """The latency its age limit counts, s: :attr:`latency_s`, else its format's."""
        return self.skeleton.sensor.latency_s if self.latency_s is None else self.latency_s

    def age_limit_reason(self) -> str:
        """How :attr:`age_limit_s` is made, for messages: the latency and where it comes
        from, the frame period, the margin."""
        spec = self.skeleton.sensor
        source = (
            "its calibration's latency_s"
            if self.latency_s is not None
            else (f"{self.format}'s latency")
        )
        return (
            f"{self.name}'s age limit {self.age_limit_s:.3f} s = {source} "
            f"{self.latency_used_s:.3f} s + a frame {1.0 / spec.frame_rate_hz:.3f} s + "
            f"{AGE_MARGIN_S:.4f} s"
        )

    @property
    def skeleton(self) -> SkeletonFormat:
        """The sensor's skeleton format (:attr:`format`, loaded once per process)."""
        return known_formats()[self.format]

    def to_base(self, joints: np.ndarray) -> np.ndarray:
        """Joint positions (..., 3) in the camera frame → the robot base frame, m."""
        T = self.base_from_camera
        return np.asarray(joints, dtype=float) @ T[:3, :3].T + T[:3, 3]

    def sees(self, point: np.ndarray) -> bool:
        """True if ``point`` (3,), base frame, m, is inside the sensor's view (its angles
        and depths; False if they are not known)."""
        if self.field_of_view_deg is None or self.range_m is None:
            return False
        T = self.base_from_camera
        local = (np.asarray(point, dtype=float) - T[:3, 3]) @ T[:3, :3]
        x, y, z = self.skeleton.axes_matrix @ local  # the optical frame: z forward
        half_h, half_v = (math.radians(a) / 2 for a in self.field_of_view_deg)
        return bool(
            self.range_m[0] <= z <= self.range_m[1]
            and abs(math.atan2(x, z)) <= half_h
            and abs(math.atan2(y, z)) <= half_v
        )


@dataclass(frozen=True)
class Calibration:
    """The sensors of a cell, by name (:func:`load_calibration`).

    Attributes
    ----------
    sensors
        Each sensor's place and clock, by name.
    path
        The file read, if any.
    cell
        The cell's name, signed into every datagram ("" without keys).
    keys
        Each sensor's keys (:mod:`qpavoid.sensing.keys`), by name: every sensor or none.
    key_files
        The key files they were read from, by sensor (absolute paths; a listener reads
        them again when they change: a key rotated without a stop).
    """

    sensors: Mapping[str, SensorCalibration]
    path: str | None = None
    cell: str = ""
    keys: Mapping[str, SensorKeys] = field(default_factory=dict)
    key_files: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Keys for every sensor or for none, and a cell name with them."""
        where = self._where()
        if self.keys:
            missing = [name for name in self.sensors if name not in self.keys]
            extra = [name for name in self.keys if name not in self.sensors]
            if missing or extra:
                which = sorted(set(self.keys) & set(self.sensors)) or sorted(self.keys)
                raise CalibrationError(
                    f"{where}names a key for {', '.join(which)} only: every sensor needs a "
                    f"key_file, or none does",
                    path=self.path,
                    sensor=(missing or extra)[0],
                    name="key_file",
                )
            if not _CELL_NAME.fullmatch(self.cell):
                raise CalibrationError(
                    f"{where}with keys, cell must be the cell's name (1 to 64 letters, digits, "
                    f"'.', '_', ':' or '-'), got {repr(self.cell)[:80]}",
                    path=self.path,
                    name="cell",
                    value=self.cell,
                )

    @property
    def authenticated(self) -> bool:
        """True if the sensors have keys (their datagrams are signed: wire format v2)."""
        return bool(self.keys)

    def __getitem__(self, name: str) -> SensorCalibration:
        try:
            return self.sensors[name]
        except KeyError:
            raise CalibrationError(
                f"{self._where()}has no sensor {str(name)!r} (sensors: "
                f"{', '.join(sorted(self.sensors)) or 'none'})",
                path=self.path,
                sensor=name,
                name="sensor",
                value=name,
            ) from None

    def check_names(self, names: Iterable[str]) -> None:
        """Raise :class:`CalibrationError` for the first name that is not a sensor here."""
        for name in names:
            self[name]

    def check_format(self, sensor: str, format: str, what: str = "a recording") -> None:
        """Raise :class:`CalibrationError` (an :class:`~qpavoid.core.errors.InputError`)
        unless ``format`` is the calibrated format of ``sensor`` (which must be here):
        ``what`` names the data in the message."""
        calibrated = self[sensor].format
        if format != calibrated:
            raise CalibrationError(
                f"{self._where()}{what} of sensor {sensor!r} holds {format} frames, but the "
                f"sensor is calibrated as {calibrated} (its format key)",
                path=self.path,
                sensor=sensor,
                name="format",
                value=format,
            )

    def with_latency(self, latency_s: float | None) -> Calibration:
        """This calibration with ``latency_s`` (s; ``--latency``) as the latency of every
        sensor whose calibration names none (itself for None).

        Raises
        ------
        CalibrationError
            If a sensor's calibration names another latency (two latencies for one
            camera: which one is measured?).
        """
        if latency_s is None:
            return self
        for cal in self.sensors.values():
            if cal.latency_s is not None and cal.latency_s != latency_s:
                raise CalibrationError(
                    f"{self._where()}sensor {cal.name!r} has latency_s = {cal.latency_s:g} "
                    f"s, and --latency says {latency_s:g} s: give one (the calibration's is "
                    "per sensor)",
                    path=self.path,
                    sensor=cal.name,
                    name="latency_s",
                    value=latency_s,
                )
        sensors = {name: replace(cal, latency_s=latency_s) for name, cal in self.sensors.items()}
        return replace(self, sensors=sensors)

    @property
    def age_limits_s(self) -> dict[str, float]:
        """Each sensor's :attr:`SensorCalibration.age_limit_s`, s, by name."""
        return {name: cal.age_limit_s for name, cal in self.sensors.items()}

    @property
    def formats(self) -> tuple[str, ...]:
        """The sensors' skeleton formats, in the file's order (:attr:`names`)."""
        return tuple(cal.format for cal in self.sensors.values())

    @property
    def names(self) -> tuple[str, ...]:
        """The sensors' names, in the file's order."""
        return tuple(self.sensors)

    def to_toml(self, key_files: Mapping[str, str] | None = None) -> str:
        """The calibration as the text of a calibration file (:func:`load_calibration`);
        ``key_files`` names each sensor's key file (relative to the calibration file)."""
        lines = [f"cell = {toml_string(self.cell)}", ""] if key_files else []
        for cal in self.sensors.values():
            rows = ",\n                    ".join(
                "[" + ", ".join(repr(float(v)) for v in row) + "]" for row in cal.base_from_camera
            )
            lines += [
                f"[sensors.{toml_string(cal.name)}]",
                f"base_from_camera = [{rows}]",
                f"time_offset_s = {cal.time_offset_s!r}",
                f"weight = {cal.weight!r}",
            ]
            if key_files:
                lines.append(f"key_file = {toml_string(key_files[cal.name])}")
            for key in ("field_of_view_deg", "range_m"):
                value = getattr(cal, key)
                if value is not None:
                    lines.append(f"{key} = [{float(value[0])!r}, {float(value[1])!r}]")
            if cal.format != DEFAULT_FORMAT:
                lines.append(f"format = {toml_string(cal.format)}")
            if cal.latency_s is not None:
                lines.append(f"latency_s = {cal.latency_s!r}")
            if cal.topic is not None:
                lines.append(f"topic = {toml_string(cal.topic)}")
            lines.append("")
        return "\n".join(lines)

    def _where(self) -> str:
        return f"calibration {self.path}: " if self.path else "calibration "


def check_format_name(name: object) -> str | None:
    """Why ``name`` is not a skeleton format the library has (None if it is one)."""
    if isinstance(name, str) and name in known_formats():
        return None
    return (
        f"format must be one of the skeleton formats {', '.join(known_formats())}, got "
        f"{repr(name)[:80]}"
    )


@cache
def known_formats() -> Mapping[str, SkeletonFormat]:
    """The skeleton formats of :data:`~qpavoid.human.landmarks.FORMAT_NAMES` whose file
    the library ships, by name (read once per process: a datagram's format is looked up
    here, never read from a file)."""
    return MappingProxyType({name: skeleton_format(name) for name in FORMAT_NAMES})


def pair_within(value: object, low: float, high: float, increasing: bool) -> bool:
    """True if ``value`` is two finite numbers in (low, high] (``increasing``: the first
    smaller, and from ``low`` on)."""
    if not (
        isinstance(value, (list, tuple))
        and len(value) == 2
        and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            for v in value
        )
    ):
        return False
    a, b = value
    if increasing:
        return bool(low <= a < b <= high)
    return bool(low < a <= high and low < b <= high)


#: A sensor's measured latency may be at most this, s (a camera's is 0.03-0.25 s; more
#: is a unit error, or no camera to drive a robot by).
MAX_LATENCY_S = 1.0


def latency_error(latency_s: object) -> str | None:
    """Why ``latency_s`` is not a sensor's latency (None if it is one, or None)."""
    if latency_s is None:
        return None
    if (
        isinstance(latency_s, (int, float, np.floating, np.integer))
        and not isinstance(latency_s, bool)
        and 0.0 <= latency_s <= MAX_LATENCY_S
    ):
        return None
    return f"latency_s must be a number from 0 to {MAX_LATENCY_S:g} s, got {latency_s!r}"


def settings_error(offset: object, weight: object) -> tuple[str, str, object] | None:
    """(key, message, value) of the first setting out of its limits, or None."""
    for key, value, low, high, kind in (
        ("time_offset_s", offset, -MAX_TIME_OFFSET_S, MAX_TIME_OFFSET_S, "s"),
        ("weight", weight, MIN_WEIGHT, MAX_WEIGHT, "relative"),
    ):
        if (
            not isinstance(value, (int, float, np.floating, np.integer))
            or isinstance(value, bool)
            or not math.isfinite(value)
            or not low <= value <= high
        ):
            shown = float(value) if isinstance(value, (np.floating, np.integer)) else value
            return (
                key,
                f"{key} must be a number from {low:g} to {high:g} ({kind}), got {shown!r}",
                value,
            )
    return None
