"""The ``[arm]`` table's shape: the arm's dynamics as a schema (msgspec), each bound's reason.

Types, ranges, the keys known and those required; whether the joints it names are the
URDF's, one acceleration for each of them, a source for each optional fact and a maker's
position range that overlaps the URDF's are checked in code (:mod:`qpavoid.arm.dynamics`).
Every bound below is a plausibility bound: a value beyond it is a unit error or a typo, and
would make speed and separation never move or never stop the arm in time.
"""

from __future__ import annotations

import math
from typing import Annotated, ClassVar, Literal

from msgspec import Meta, Struct

__all__ = [
    "ARM_KEYS",
    "MAX_ACCEL_RADPS2",
    "MAX_JERK_RADPS3",
    "MAX_PAYLOAD_KG",
    "MAX_POSITION_RAD",
    "MAX_REACTION_S",
    "MAX_SPEED_MPS",
    "MAX_STOP_DISTANCE_RAD",
    "MAX_STOP_TIME_S",
    "MAX_VELOCITY_RADPS",
    "MIN_ACCEL_RADPS2",
    "MIN_JERK_RADPS3",
    "OPTIONAL_KEYS",
    "STOP_CATEGORIES",
    "ArmTable",
    "Sources",
    "StoppingTable",
]

#: A reaction slower than 0.1 s, s: arms react within one period of their real-time
#: interface, 1-8 ms for the arms here (1 meant as 1 ms is refused).
MAX_REACTION_S = 0.1
#: A joint braking below 0.1 rad/s² (10 s to stop from 1 rad/s) or above 100 rad/s² (arms
#: brake at 5-50: the iiwa 8.6-15.7, the Panda 7.5-20, the UR5's elbow 19.5; in degrees,
#: 5 rad/s² would read 286 and is refused).
MIN_ACCEL_RADPS2, MAX_ACCEL_RADPS2 = 0.1, 100.0
#: A point faster than 10 m/s (cobots move their tool at up to 1-5 m/s).
MAX_SPEED_MPS = 10.0
#: A joint's jerk: at least 1 rad/s³ (10 s to reach 10 rad/s²: a typo) and at most 10⁶ rad/s³
#: (1000 rad/s² within 1 ms: indistinguishable from no limit; Franka's are 3750-10000).
MIN_JERK_RADPS3, MAX_JERK_RADPS3 = 1.0, 1.0e6
#: A joint's velocity limit: above 0 and at most 20 rad/s (cobot joints turn at 1.3-6.3 rad/s;
#: 85 °/s written as 85 would pass unnoticed above it).
MAX_VELOCITY_RADPS = 20.0
#: A joint's position limit: within ±4π rad (two turns either way; UR joints turn ±2π; an
#: angle in degrees, 170 for 170°, lies beyond).
MAX_POSITION_RAD = 4.0 * math.pi
#: A maker's stop: within 5 s (KUKA's heavy industrial arms stop in 0.2-0.5 s; 244 written
#: for 244 ms lies beyond) and one turn (30° written as 30 lies beyond); the payload at most
#: 1000 kg (a stop's, and an arm's rated payload: above 0 and at most this).
MAX_STOP_TIME_S = 5.0
MAX_STOP_DISTANCE_RAD = 2.0 * math.pi
MAX_PAYLOAD_KG = 1000.0
#: The stop categories of IEC 60204-1 a maker's stopping data may be given for (ISO 10218-1
#: asks for both): 0, power removed at once; 1, a controlled stop, then power removed.
STOP_CATEGORIES = (0, 1)
#: Keys of the ``[arm]`` table that must be given, and those that may be (each of these
#: then needs its source in ``[arm.sources]``).
ARM_KEYS = ("reaction_time_s", "max_acceleration_radps2", "max_point_speed_mps")
OPTIONAL_KEYS = (
    "max_velocity_radps",
    "max_jerk_radps3",
    "position_limits_rad",
    "stopping",
    "rated_payload_kg",
)
#: The table's shape, shown when it is missing.
EXAMPLE = (
    "reaction_time_s = 0.005, max_acceleration_radps2 = { <joint> = 10.0, ... }, "
    "max_point_speed_mps = 3.0"
)

JointNames = Annotated[
    list[Annotated[str, Meta(min_length=1)]],
    Meta(min_length=1, description="a list of distinct joint names"),
]
#: rad/s²: the bounds above.
Acceleration = Annotated[float, Meta(ge=MIN_ACCEL_RADPS2, le=MAX_ACCEL_RADPS2)]
Velocity = Annotated[float, Meta(gt=0.0, le=MAX_VELOCITY_RADPS)]
Jerk = Annotated[float, Meta(ge=MIN_JERK_RADPS3, le=MAX_JERK_RADPS3)]
Position = Annotated[float, Meta(ge=-MAX_POSITION_RAD, le=MAX_POSITION_RAD)]
Payload = Annotated[float, Meta(ge=0.0, le=MAX_PAYLOAD_KG)]

#: A non-empty table keyed by joint names, of one of the above each.
_PER_JOINT = Meta(min_length=1, description="a table { <joint> = number, ... }")
Accelerations = Annotated[dict[str, Acceleration], _PER_JOINT]
Velocities = Annotated[dict[str, Velocity], _PER_JOINT]
Jerks = Annotated[dict[str, Jerk], _PER_JOINT]
PositionLimits = Annotated[
    dict[
        str,
        Annotated[tuple[Position, Position], Meta(description="[lower, upper] in rad")],
    ],
    Meta(min_length=1, description="a table { <joint> = [lower, upper], ... }"),
]


class StoppingTable(Struct, frozen=True, forbid_unknown_fields=True):
    """One ``[[arm.stopping]]`` entry: a stop the maker measured (ISO 10218-1 Annex B)."""

    docs: ClassVar[str] = "docs/robot.md: Arm"

    joints: JointNames
    category: Annotated[Literal[0, 1], Meta(description="the stop category 0 or 1 of IEC 60204-1")]
    #: v₀, rad/s.
    speed_radps: Velocity
    #: D₀, rad: within one turn.
    distance_rad: Annotated[float, Meta(gt=0.0, le=MAX_STOP_DISTANCE_RAD)]
    #: T₀, s.
    time_s: Annotated[float, Meta(gt=0.0, le=MAX_STOP_TIME_S)]
    #: A fraction of the arm's reach (1.0: stretched).
    extension: Annotated[float, Meta(gt=0.0, le=1.0)]
    payload_kg: Payload


Source = Annotated[str, Meta(description="the text of the fact's source")]


class Sources(Struct, frozen=True, forbid_unknown_fields=True):
    """``[arm.sources]``: each fact's source, as text (a fact left out has ``""``)."""

    reaction_time_s: Source = ""
    max_acceleration_radps2: Source = ""
    max_point_speed_mps: Source = ""
    max_velocity_radps: Source = ""
    max_jerk_radps3: Source = ""
    position_limits_rad: Source = ""
    stopping: Source = ""
    rated_payload_kg: Source = ""


class ArmTable(Struct, frozen=True, forbid_unknown_fields=True):
    """The ``[arm]`` table (``docs/robot.md``: Arm); the optional facts are None if not given."""

    docs: ClassVar[str] = "docs/robot.md: Arm"

    #: s: from a command to the arm starting to follow it.
    reaction_time_s: Annotated[float, Meta(ge=0.0, le=MAX_REACTION_S)]
    #: rad/s² (m/s² for a prismatic joint), one for each joint of the URDF.
    max_acceleration_radps2: Accelerations
    #: m/s: no point of the arm moves faster.
    max_point_speed_mps: Annotated[float, Meta(gt=0.0, le=MAX_SPEED_MPS)]
    sources: Sources = Sources()
    max_velocity_radps: Velocities | None = None
    max_jerk_radps3: Jerks | None = None
    position_limits_rad: PositionLimits | None = None
    stopping: (
        Annotated[
            list[StoppingTable],
            Meta(
                min_length=1,
                description="one or more [[arm.stopping]] tables, each with joints, "
                "category, speed_radps, distance_rad, time_s, extension, payload_kg "
                "(docs/robot.md: Arm)",
            ),
        ]
        | None
    ) = None
    #: kg: the heaviest payload the arm is rated to carry at its flange.
    rated_payload_kg: Annotated[float, Meta(gt=0.0, le=MAX_PAYLOAD_KG)] | None = None


class ArmOf(Struct, frozen=True):
    """A control-point file's ``[arm]`` alone (its other tables are the file's schema's)."""

    arm: Annotated[
        ArmTable,
        Meta(
            description=f"a table, e.g. [arm] {EXAMPLE}",
            extra={"missing": f"no [arm] table; add one, e.g. {EXAMPLE}"},
        ),
    ]
