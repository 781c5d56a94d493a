"""A task file's shape: ``task.toml`` (``--task FILE``) as a schema (msgspec).

The types, ranges, keys known and keys required of a task file (:mod:`qpavoid.control.task`,
``docs/tasks.md`` §2): its ``[[waypoints]]``, ``[operator]``, ``[test2]``, ``[strikes]`` and
``[scaling]``. What needs the arm or more than one key stays code beside the reader: which
of a waypoint's keys make its pose (``position_m`` with ``rotation`` or ``rpy_rad``, or
``joints_rad`` alone), a duration on every waypoint but the first, a rotation that is one,
the joints and frames the robot has, its joint limits and locked joints, and whether the
arm reaches each pose. Every bound below is a plausibility bound: beyond it is a unit error
(mm written for m, degrees for radians, ms for s), said so in the refusal.
"""

from __future__ import annotations

import math
from typing import Annotated, ClassVar

from msgspec import Meta, Struct

from qpavoid.arm.dynamics_schema import MAX_POSITION_RAD

__all__ = [
    "MAX_DURATION_S",
    "MAX_LEAN_M",
    "MAX_PLACE_M",
    "MAX_ROTATION_DEFECT",
    "MAX_ROTATION_ENTRY",
    "MAX_SCALE",
    "OperatorTable",
    "ScalingTable",
    "StrikeTable",
    "TaskFile",
    "Test2Table",
    "WaypointTable",
]

#: How far a written rotation matrix may be from a rotation, ``‖RᵀR − I‖`` (Frobenius):
#: the paper prints its matrices to 3-4 digits (8e-5 for its poses); beyond 0.01 it is a
#: typo, not rounding (checked in code: it needs the whole matrix).
MAX_ROTATION_DEFECT = 1e-2
#: A rotation's entries lie within ±1; rounded within :data:`MAX_ROTATION_DEFECT`, within
#: ±1.01 (beyond, no rotation, whatever the rounding).
MAX_ROTATION_ENTRY = 1.0 + MAX_ROTATION_DEFECT
#: m: a place (a waypoint, the operator's seat, a strike's offset, an arc's height) within
#: 10 m of the base: cobots reach 0.5-1.8 m and the cameras see 0.5-5 m; a position in mm
#: (352 for 0.352 m) lies beyond.
MAX_PLACE_M = 10.0
#: s: a segment of up to an hour (the paper's takes 15 s; 15000, ms written for s, lies
#: beyond).
MAX_DURATION_S = 3600.0
#: m: a seated operator's upper body leans at most about its own length (hips to
#: shoulders, 0.5-0.6 m: the bundled tasks lean 0.35-0.54 m); 1 m leaves room.
MAX_LEAN_M = 1.0
#: A task scaled by more than 10 (either way) from its reference's is another kind of arm.
MAX_SCALE = 10.0
_BEYOND = "a unit error?"

#: A coordinate in the base frame or an offset in a frame's axes, m.
Coordinate = Annotated[
    float, Meta(ge=-MAX_PLACE_M, le=MAX_PLACE_M, extra={"unit": "m", "beyond": _BEYOND})
]
#: A distance in front of the base along +y, m: above 0 (the operator cannot sit in the
#: base).
Distance = Annotated[float, Meta(gt=0, le=MAX_PLACE_M, extra={"unit": "m", "beyond": _BEYOND})]
Point = Annotated[
    tuple[Coordinate, Coordinate, Coordinate], Meta(description="3 finite numbers (x, y, z), m")
]
#: An angle about a fixed axis (roll, pitch or yaw), rad: within ±2π (90 for 90° lies
#: beyond).
Angle = Annotated[
    float, Meta(ge=-2 * math.pi, le=2 * math.pi, extra={"unit": "rad", "beyond": _BEYOND})
]
#: One entry of a rotation matrix (module docstring).
Entry = Annotated[float, Meta(ge=-MAX_ROTATION_ENTRY, le=MAX_ROTATION_ENTRY)]
Row = tuple[Entry, Entry, Entry]
#: A joint's angle, rad: within ±4π, two turns either way (:mod:`qpavoid.arm.dynamics_schema`);
#: the joint's own limits are checked in code.
JointAngle = Annotated[
    float, Meta(ge=-MAX_POSITION_RAD, le=MAX_POSITION_RAD, extra={"unit": "rad", "beyond": _BEYOND})
]
Name = Annotated[str, Meta(pattern=r"\S", description="a name (text)")]


class WaypointTable(Struct, frozen=True, forbid_unknown_fields=True):
    """One ``[[waypoints]]`` table: a pose, or a configuration, and how its segment gets
    there (which keys make the pose is checked in code)."""

    position_m: Point | None = None
    rotation: Annotated[tuple[Row, Row, Row], Meta(description="3 rows of 3 numbers")] | None = None
    rpy_rad: (
        Annotated[
            tuple[Angle, Angle, Angle], Meta(description="3 finite numbers (roll, pitch, yaw), rad")
        ]
        | None
    ) = None
    joints_rad: (
        Annotated[
            dict[str, JointAngle], Meta(description="a table { <joint> = <angle, rad>, ... }")
        ]
        | None
    ) = None
    #: The segment's time, s: above 0 (the arm cannot be in two places at once).
    duration_s: (
        Annotated[float, Meta(gt=0, le=MAX_DURATION_S, extra={"unit": "s", "beyond": _BEYOND})]
        | None
    ) = None
    #: The arc's height above its chord, m: at least 0 (0, a straight line).
    sagitta_m: (
        Annotated[float, Meta(ge=0, le=MAX_PLACE_M, extra={"unit": "m", "beyond": _BEYOND})] | None
    ) = None


class OperatorTable(Struct, frozen=True, forbid_unknown_fields=True):
    """``[operator]``: the seated operator (each key defaults to the paper's seat)."""

    x_m: Coordinate | None = None
    distance_m: Distance | None = None
    #: How far the upper body leans, m: at least 0 (0, upright), at most :data:`MAX_LEAN_M`.
    max_lean_m: (
        Annotated[float, Meta(ge=0, le=MAX_LEAN_M, extra={"unit": "m", "beyond": _BEYOND})] | None
    ) = None


class Test2Table(Struct, frozen=True, forbid_unknown_fields=True):
    """``[test2]``: test 2's operator (default: x -0.25 m, ``[operator]``'s distance)."""

    operator_x_m: Coordinate | None = None
    operator_distance_m: Distance | None = None


class StrikeTable(Struct, frozen=True, forbid_unknown_fields=True):
    """A ``[strikes]`` entry given as ``{ frame, xyz }``: an offset in a frame's axes."""

    frame: Name
    xyz: Point


class ScalingTable(Struct, frozen=True, forbid_unknown_fields=True):
    """``[scaling]``: how the task was made from another arm's (documentation)."""

    reference: Name
    shoulder: Name
    #: This arm's reach, m: above 0, within 10 m.
    reach_m: Distance
    #: This arm's reach over the reference's: above 0 and at most :data:`MAX_SCALE`.
    scale: Annotated[float, Meta(gt=0, le=MAX_SCALE)]


class TaskFile(Struct, frozen=True, forbid_unknown_fields=True):
    """A task file."""

    docs: ClassVar[str] = "docs/tasks.md §2"

    waypoints: Annotated[
        list[WaypointTable],
        Meta(
            min_length=2,
            description="must give at least two [[waypoints]] tables: the start, then each "
            "waypoint with its duration_s",
            extra={
                "missing": "give at least two [[waypoints]] tables: the start, then each "
                "waypoint with its duration_s"
            },
        ),
    ]
    operator: OperatorTable = OperatorTable()
    test2: Test2Table = Test2Table()
    strikes: Annotated[
        dict[
            str,
            Annotated[
                str | StrikeTable,
                Meta(description='must be "<frame>" or { frame = "<frame>", xyz = [x, y, z] }'),
            ],
        ],
        Meta(description="a table [strikes] of <name> = <frame>"),
    ] = {}
    scaling: ScalingTable | None = None
