"""A skeleton format file's shape: ``formats/<format>.toml`` as a schema (msgspec).

The types, ranges, keys known and keys required of a camera's format file
(``formats/kinect_v2.toml`` shows each key with its meaning and source): its joints, the
camera's ``[sensor]`` numbers and their ``[sensor.evidence]``, ``[confidence]`` and the
tables of rules ``[landmarks]`` and ``[simulate]``. What ties the keys together stays code
beside the dataclasses they make: the joints' tree and mirror pairs
(:class:`~qpavoid.human.skeleton.SkeletonFormat`), a score's thresholds within its range
(:class:`~qpavoid.human.conversion.Confidence`), a rule's one form and weights summing to 1
(:func:`~qpavoid.human.conversion.parse_rule`), a number's evidence and the camera's
numbers against one another (:class:`~qpavoid.human.camera_spec.CameraSpec`).
"""

from __future__ import annotations

from typing import Annotated, Literal

from msgspec import Meta, Struct, field

__all__ = [
    "BASES",
    "CONFIDENCE_KINDS",
    "MAX_RULE_UNCERTAINTY_M",
    "SENSOR_CEILINGS",
    "ConfidenceTable",
    "EvidenceTable",
    "FormatFile",
    "JointRow",
    "Rule",
    "RuleTable",
    "SensorTable",
]

#: How a camera's number was obtained (``[sensor.evidence]``): a published measurement,
#: the maker's documentation, or our estimate.
BASES = ("measured", "vendor", "estimate")
#: The kinds of a joint's confidence value a format may declare.
CONFIDENCE_KINDS = ("states", "levels", "score")
#: Largest uncertainty a rule may add, m: a derived landmark further off than this is no
#: landmark (the longest bone of the body is 0.40 m).
MAX_RULE_UNCERTAINTY_M = 0.5
#: The largest plausible value of each of ``[sensor]``'s numbers: a body-tracking camera
#: beyond 1 kHz, a latency beyond 1 s (``--latency``'s range), a noise or Z_d beyond 1 m, a
#: stereo reference beyond 100 m or swaps beyond 10 per second (or lasting over a minute)
#: is a wrong file.
SENSOR_CEILINGS = {
    "frame_rate_hz": 1000.0,
    "latency_s": 1.0,
    "noise_m": 1.0,
    "tracked_uncertainty_m": 1.0,
    "noise_reference_range_m": 100.0,
    "left_right_swap_per_s": 10.0,
    "left_right_swap_s": 60.0,
}
#: A bone longer than 2 m is no person's (the longest, a thigh, is about 0.5 m).
MAX_BONE_M = 2.0

Names = Annotated[list[str], Meta(description="an array of joint names")]


class JointRow(Struct, frozen=True, forbid_unknown_fields=True):
    """One ``joints`` entry: a joint in the sensor's order."""

    #: Its row, 0, 1, 2, ... in file order (checked with the rows).
    id: Annotated[int, Meta(ge=0)]
    name: Annotated[str, Meta(min_length=1, description="a joint's name (text)")]
    parent: Annotated[str, Meta(description="a joint name")] | None = None
    #: The longest plausible bone to the parent, m (0: unbounded).
    max_bone_m: Annotated[float, Meta(ge=0.0, le=MAX_BONE_M, extra={"unit": "m"})] = 0.0


class EvidenceTable(Struct, frozen=True, forbid_unknown_fields=True):
    """How one ``[sensor]`` number was obtained: ``{ basis, source, note }``."""

    basis: Annotated[
        Literal["measured", "vendor", "estimate"],
        Meta(description=f"one of {list(BASES)}"),
    ]
    source: Annotated[str, Meta(description="text")] = ""
    note: Annotated[str, Meta(description="text")] = ""


def _ceiling(key: str, low: float = 0.0) -> Meta:
    """A ``[sensor]`` number's range: at least ``low``, at most its ceiling; its unit."""
    unit = "Hz" if key.endswith("_hz") else "per s" if key.endswith("_per_s") else key[-1]
    return Meta(ge=low, le=SENSOR_CEILINGS[key], extra={"unit": unit})


class SensorTable(Struct, frozen=True, forbid_unknown_fields=True):
    """``[sensor]``: the camera's numbers (:class:`~qpavoid.human.camera_spec.CameraSpec`)."""

    #: Hz: at least 1 (a camera's).
    frame_rate_hz: Annotated[float, _ceiling("frame_rate_hz", 1.0)]
    #: s, capture to controller.
    latency_s: Annotated[float, _ceiling("latency_s")]
    #: m, per axis.
    noise_m: Annotated[float, _ceiling("noise_m")]
    #: m: Z_d of speed and separation monitoring.
    tracked_uncertainty_m: Annotated[float, _ceiling("tracked_uncertainty_m")]
    #: degrees, (horizontal, vertical): each in [1, 180).
    field_of_view_deg: Annotated[
        tuple[float, float], Meta(description="two angles in [1, 180) degrees")
    ]
    #: m, (near, far): 0 <= near < far <= 100.
    range_m: Annotated[
        tuple[float, float], Meta(description="[near, far] with 0 <= near < far <= 100, m")
    ]
    max_bodies: Annotated[int, Meta(ge=1, le=100, description="a whole number from 1 to 100")]
    #: m: 0, or the range at which the noise is ``noise_m`` (stereo depth).
    noise_reference_range_m: Annotated[float, _ceiling("noise_reference_range_m")] = 0.0
    #: per s.
    left_right_swap_per_s: Annotated[float, _ceiling("left_right_swap_per_s")] = 0.0
    #: s.
    left_right_swap_s: Annotated[float, _ceiling("left_right_swap_s")] = 0.5
    evidence: dict[
        str, Annotated[EvidenceTable, Meta(description="a table { basis, source, note }")]
    ] = {}


class ConfidenceTable(Struct, frozen=True, forbid_unknown_fields=True):
    """``[confidence]``: what a joint's confidence value is."""

    kind: Annotated[
        Literal["states", "levels", "score"], Meta(description=f"one of {CONFIDENCE_KINDS}")
    ] = "states"
    levels: list[int] = []
    level_names: list[str] = []
    range: tuple[float, float] = (0.0, 0.0)
    inferred_at: float = 0.0
    tracked_at: float = 0.0


class RuleTable(Struct, frozen=True, forbid_unknown_fields=True):
    """A rule as a table: one of ``joint``, ``mean``, ``lerp`` (with ``t``) or ``weights``."""

    joint: str | None = None
    mean: Names | None = None
    lerp: Names | None = None
    weights: Annotated[dict[str, float], Meta(description="joint = weight pairs")] | None = None
    #: Where along ``lerp``'s two joints: in [-1, 2] (no point far off its joints).
    t: Annotated[float, Meta(ge=-1.0, le=2.0)] | None = None
    #: m: how far the true landmark may be from the point.
    uncertainty_m: Annotated[
        float, Meta(ge=0.0, le=MAX_RULE_UNCERTAINTY_M, extra={"unit": "m"})
    ] = 0.0


#: A ``[landmarks]`` or ``[simulate]`` entry: a joint's name, or a table.
Rule = Annotated[
    str | RuleTable,
    Meta(
        description="a joint name or a table with one of joint, mean, lerp or weights (and t, "
        "uncertainty_m)"
    ),
]


class FormatFile(Struct, frozen=True, forbid_unknown_fields=True):
    """A skeleton format's file."""

    name: str
    title: str
    joints: Annotated[list[JointRow], Meta(description="an array of tables")]
    mirror_pairs: Annotated[
        list[Annotated[list[str], Meta(description="[left, right], two joints")]],
        Meta(description="an array of [left, right] pairs"),
    ]
    torso: Names
    sensor: SensorTable
    tracking_states: dict[str, int] | None = None
    groups: Annotated[
        dict[str, dict[str, str]], Meta(description="a table of tables of joint names")
    ] = {}
    units: Annotated[Literal["m", "mm"], Meta(description="one of ['m', 'mm']")] = "m"
    axes: Annotated[list[str], Meta(description="three directions")] = field(
        default_factory=lambda: ["left", "up", "forward"]
    )
    confidence: ConfidenceTable = ConfidenceTable()
    body: Annotated[str, Meta(description="a format's name")] = ""
    landmarks: dict[str, Rule] = {}
    simulate: dict[str, Rule] = {}
