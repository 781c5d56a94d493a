"""The control-point file's shape: ``control_points.toml`` as a schema (msgspec).

The types, ranges, keys known and keys required of every table of a robot description's
own file (``docs/robot.md``): the URDF, the end effector, ``locked``, ``held`` and
``home``, the ``[[sets]]`` with their points and capsules, ``[roles]``, ``[arm]``
(:mod:`qpavoid.arm.dynamics_schema`), ``[ik_seed]`` and ``[coverage]``. What needs the
URDF's model stays code beside the readers: that a frame or a joint exists, that an angle
lies within its joint's limits, that a role's joints move its set, that the capsules cover
the arm (:mod:`qpavoid.arm.frames`, :mod:`qpavoid.arm.joints`,
:mod:`qpavoid.arm.model_checks`, :mod:`qpavoid.arm.coverage`); so do the checks across
entries (a set's name given twice, a joint listed twice).
"""

from __future__ import annotations

import math
import re
from typing import Annotated, ClassVar

from msgspec import Meta, Struct, field

from qpavoid.arm.dynamics_schema import EXAMPLE, ArmTable

__all__ = [
    "SET_NAME",
    "Capsule",
    "ControlPointFile",
    "ControlSetTable",
    "CoverageTable",
    "IKSeedTable",
    "Offset",
    "RolesTable",
    "UrdfPackage",
]

#: What a set's name may hold: it becomes part of frame names, log keys and file names
#: (``fig10_distance_<name>.png``).
SET_NAME = re.compile(r"[A-Za-z0-9_.-]+")
#: How far a point may lie from the frame it is given from, m: an arm's links are at most
#: about 1 m long; 100 (cm written as m) lies beyond.
MAX_OFFSET_M = 10.0
#: A sphere's or a capsule's radius, m: above 0 and at most 1 m (a cobot's links are
#: 0.03-0.15 m in radius; 70 meant as 70 mm lies beyond).
MAX_RADIUS_M = 1.0
#: The IK seed's angles, rad: within ±4π (two turns; degrees lie beyond).
MAX_SEED_RAD = 4.0 * math.pi
#: From the wrist centre to the tool frame, m: at most 2 m (a cobot's reach is 0.8-1.3 m).
MAX_WRIST_TO_TOOL_M = 2.0

Name = Annotated[str, Meta(min_length=1)]
Frames = Annotated[list[Name], Meta(min_length=1)]
Coordinate = Annotated[float, Meta(ge=-MAX_OFFSET_M, le=MAX_OFFSET_M)]
Radius = Annotated[float, Meta(gt=0.0, le=MAX_RADIUS_M)]
#: An angle of a joint, rad (its bounds are the joint's URDF limits: checked with the model).
Angle = Annotated[float, Meta(description="an angle (rad)")]


class Offset(Struct, frozen=True, forbid_unknown_fields=True):
    """A point given as an offset from a frame, in the frame's axes: ``{ frame, xyz }``."""

    frame: Name
    #: m, in the frame's axes.
    xyz: tuple[Coordinate, Coordinate, Coordinate]


#: A point: the centroid of the frames it lists, or an offset from one frame.
Spot = Frames | Offset
POINTS_SHAPE = (
    'points = [["<frame>"], ["<frame>", "<frame>"], { frame = "<frame>", xyz = [x, y, z] }]'
)


#: A capsule's end: a frame name, or a point.
End = Annotated[
    Name | Frames | Offset,
    Meta(
        description='a frame name or an offset from one, { frame = "<frame>", xyz = [x, y, z] } (m)'
    ),
]


class Capsule(Struct, frozen=True, forbid_unknown_fields=True):
    """A set's capsule: its two ends (a frame name, or a point) and its radius, m."""

    from_: End = field(name="from")
    to: End
    capsule_radius_m: Radius


class ControlSetTable(Struct, frozen=True, forbid_unknown_fields=True):
    """One ``[[sets]]`` entry: a set of control points and its capsule."""

    name: Annotated[
        str,
        Meta(
            pattern=f"^{SET_NAME.pattern}$",
            description="letters, digits, '_', '.' and '-' only (it becomes part of frame "
            "names, log keys and figure file names)",
        ),
    ]
    #: m: r_R of the spheres on the set's points (eq. 1).
    sphere_radius_m: Radius
    points: Annotated[
        list[Spot],
        Meta(
            min_length=1,
            description="a non-empty list of control points, each the list of the frames it "
            f"is the centroid of, e.g. {POINTS_SHAPE}",
        ),
    ]
    capsule: Annotated[
        Capsule,
        Meta(description='a table { from = "<frame>", to = "<frame>", capsule_radius_m = <m> }'),
    ]


class SetRole(Struct, frozen=True, forbid_unknown_fields=True):
    """A role played by a set, on the joints that move it."""

    docs: ClassVar[str] = "docs/robot.md: Roles"

    set: Name
    joints: list[str]


class EndEffectorRole(Struct, frozen=True, forbid_unknown_fields=True):
    """The end-effector role: a set."""

    docs: ClassVar[str] = "docs/robot.md: Roles"

    set: Name


_ROLE = '{ set = "<set>", joints = ["<joint>", ...] }'


def _role(name: str, shape: str = "set = ..., joints = ...") -> Meta:
    """A role's words: its table's shape, and what ``[roles]`` needs without it."""
    return Meta(
        description=f"a table {{ {shape} }}", extra={"missing": f"needs {name} = {{ {shape} }}"}
    )


class RolesTable(Struct, frozen=True, forbid_unknown_fields=True):
    """``[roles]``: which set plays which part in the paper's laws
    (:class:`~qpavoid.arm.roles.Roles`)."""

    docs: ClassVar[str] = "docs/robot.md: Roles"

    scaled: Annotated[SetRole, _role("scaled")]
    repelled: Annotated[SetRole, _role("repelled")]
    end_effector: Annotated[EndEffectorRole, _role("end_effector", "set = ...")]
    elbow: (
        Annotated[
            Spot,
            Meta(
                description="one control point as its set's points give it (the list of its "
                "frames, or its { frame, xyz } table)"
            ),
        ]
        | None
    ) = None


class IKSeedTable(Struct, frozen=True, forbid_unknown_fields=True):
    """``[ik_seed]``: where the inverse kinematics of a pose starts."""

    aim: Name | None = None
    angles: Annotated[
        dict[str, Annotated[float, Meta(ge=-MAX_SEED_RAD, le=MAX_SEED_RAD)]],
        Meta(description="a table of joint names to angles (rad)"),
    ] = {}
    #: m, along the end-effector frame's z axis.
    wrist_to_tool_m: Annotated[float, Meta(ge=0.0, le=MAX_WRIST_TO_TOOL_M)] = 0.0


class CoverageTable(Struct, frozen=True, forbid_unknown_fields=True):
    """``[coverage]``: the collision objects left outside the model, each with its reason."""

    exclude: Annotated[
        dict[str, Annotated[str, Meta(pattern=r"\S")]],
        Meta(
            description="must map each collision object it leaves out to the reason, "
            'e.g. exclude = { "link_0_0" = "fixed to the base: never moves" }'
        ),
    ] = {}


class UrdfPackage(Struct, frozen=True, forbid_unknown_fields=True):
    """A URDF shipped in an installed Python package: ``{ package, path }``."""

    package: Name
    path: Name


#: ``locked`` and ``held``: a table of angles, or a list of joint names locked at 0.
_LOCKED = (
    "a table of angles (rad), e.g. {0} = {{ <joint> = 0.0 }}, or a list of joint names locked "
    'at 0, e.g. {0} = ["<joint>"]'
)
Locked = Annotated[dict[str, Angle] | list[Name], Meta(description=_LOCKED.format("locked"))]
Held = Annotated[dict[str, Angle] | list[Name], Meta(description=_LOCKED.format("held"))]
Home = Annotated[
    dict[str, Angle],
    Meta(description="a table of joint angles (rad), e.g. home = { <joint> = -0.785 }"),
]


class ControlPointFile(Struct, frozen=True, forbid_unknown_fields=True):
    """A robot description's ``control_points.toml`` (``docs/robot.md``)."""

    docs: ClassVar[str] = "docs/robot.md"

    urdf: Annotated[
        Name | UrdfPackage,
        Meta(
            description='a file name or a table { package = "<Python package>", path = '
            '"<file inside it>" }'
        ),
    ]
    sets: Annotated[
        list[ControlSetTable],
        Meta(
            min_length=1,
            description="an array of tables, one [[sets]] per set, at least one (docs/robot.md)",
        ),
    ]
    end_effector: Annotated[Name, Meta(description="a frame name (text)")]
    roles: Annotated[
        RolesTable,
        Meta(
            description=f"a table, e.g. scaled = {_ROLE}",
            extra={"missing": f"no [roles] table; add one, e.g. scaled = {_ROLE}"},
        ),
    ]
    arm: Annotated[
        ArmTable,
        Meta(
            description="a table (docs/robot.md: Arm)",
            extra={"missing": f"no [arm] table; add one, e.g. {EXAMPLE}"},
        ),
    ]
    locked: Locked | None = None
    held: Held | None = None
    home: Home | None = None
    ik_seed: IKSeedTable | None = None
    coverage: CoverageTable = CoverageTable()
