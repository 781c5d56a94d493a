"""A calibration file's shape: ``--sensors <cell>.toml`` as a schema (msgspec).

The types, ranges, keys known and keys required of a cell's calibration
(``docs/calibrations/k4abt.toml`` is a worked one; ``docs/sensors.md``): ``cell`` and one
``[sensors.NAME]`` table per sensor. What needs more than the file stays code beside the
reader (:mod:`qpavoid.sensing.calibration_file`): that ``base_from_camera`` is rigid, its
last row ``[0, 0, 0, 1]`` and its numbers finite and within reach, that a range's near end
lies before its far one, that the format is one the library ships, and the key files
(:mod:`qpavoid.sensing.keys`).
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from msgspec import Meta, Struct

from qpavoid.sensing.calibration import (
    DEFAULT_FORMAT,
    MAX_LATENCY_S,
    MAX_TIME_OFFSET_S,
    MAX_WEIGHT,
    MIN_WEIGHT,
)
from qpavoid.sensing.ros2_cell_schema import TOPIC

__all__ = ["CalibrationFile", "SensorTable"]

#: A row of ``base_from_camera``: four numbers (finiteness and rigidity are checked in code).
Row = tuple[float, float, float, float]
#: A field of view's angle, degrees: above 0 and at most a full turn (more is no angle of
#: a view). A range's end, m: from 0 (the camera's own place) to 1 km (cameras see 0.3-20 m;
#: more is a unit error, mm written as m).
MAX_VIEW_DEG, MAX_RANGE_M = 360.0, 1000.0
Angle = Annotated[float, Meta(gt=0.0, le=MAX_VIEW_DEG, extra={"unit": "deg"})]
Distance = Annotated[float, Meta(ge=0.0, le=MAX_RANGE_M, extra={"unit": "m"})]


class SensorTable(Struct, frozen=True, forbid_unknown_fields=True):
    """One ``[sensors.NAME]`` table: a sensor's place, clock, keys, view and format."""

    docs: ClassVar[str] = "docs/sensors.md §1"

    base_from_camera: Annotated[
        tuple[Row, Row, Row, Row],
        Meta(description="4 rows of 4 numbers (shape (4, 4): a rigid transform, m)"),
    ]
    #: s: the sensor's clock minus the controller's; within a day (more is a wrong clock).
    time_offset_s: Annotated[
        float, Meta(ge=-MAX_TIME_OFFSET_S, le=MAX_TIME_OFFSET_S, extra={"unit": "s"})
    ] = 0.0
    #: Relative to the other sensors': within 1e-3 to 1e3 of theirs (beyond, float
    #: arithmetic, not trust, would decide).
    weight: Annotated[float, Meta(ge=MIN_WEIGHT, le=MAX_WEIGHT, extra={"unit": "relative"})] = 1.0
    key_file: Annotated[str, Meta(min_length=1, description="a path")] | None = None
    key_ids: Annotated[list[int], Meta(min_length=1, description="a list of key ids")] | None = None
    #: degrees, (horizontal, vertical).
    field_of_view_deg: (
        Annotated[tuple[Angle, Angle], Meta(description="two positive numbers (deg)")] | None
    ) = None
    #: m, (near, far): near before far is checked in code.
    range_m: (
        Annotated[
            tuple[Distance, Distance], Meta(description="two increasing positive numbers (m)")
        ]
        | None
    ) = None
    #: One of the skeleton formats the library ships (checked in code).
    format: Annotated[str, Meta(description="a skeleton format's name")] = DEFAULT_FORMAT
    #: s, measured (``qpavoid latency``): a camera's is 0.03-0.25 s; above 1 s is a unit
    #: error, or no camera to drive a robot by.
    latency_s: Annotated[float, Meta(ge=0.0, le=MAX_LATENCY_S, extra={"unit": "s"})] | None = None
    #: A ROS 2 topic name (ROS 2's rules), at most 256 characters.
    topic: (
        Annotated[
            str,
            Meta(
                pattern=TOPIC,
                max_length=256,
                description="a ROS 2 topic name (/ then letters, digits, _ and /)",
            ),
        ]
        | None
    ) = None


class CalibrationFile(Struct, frozen=True, forbid_unknown_fields=True):
    """A cell's calibration file."""

    docs: ClassVar[str] = "docs/sensors.md §1"

    sensors: Annotated[
        dict[str, Annotated[SensorTable, Meta(description="a table with base_from_camera")]],
        Meta(
            min_length=1,
            description="at least one [sensors.NAME] table",
            extra={"missing": "no sensor: expected at least one [sensors.NAME] table"},
        ),
    ]
    #: The cell's name, signed into every datagram (its characters checked in code).
    cell: Annotated[str, Meta(description="a string")] = ""
