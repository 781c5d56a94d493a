"""A body file's shape: ``<format>_body.toml`` as a schema (msgspec).

The types, ranges, keys known and keys required of a body model's file
(``formats/kinect_v2_body.toml`` shows each key with its meaning). Whether the joints it
names are its format's, each part's chain and mid joints, the centres' names and the
parts' tree are checked with the format (:class:`~qpavoid.human.body.BodyModel`,
:mod:`qpavoid.human.body_parts`); so is a part's name given twice.
"""

from __future__ import annotations

from typing import Annotated

from msgspec import Meta, Struct

from qpavoid.human.body_parts import MAX_RADIUS_M, MIN_RADIUS_M

__all__ = ["BodyFile", "PartTable"]

Joints = Annotated[list[str], Meta(description="an array of joint names")]
#: m: a finger is 1 cm thick; a capsule over 1 m wide covers no body part.
Radius = Annotated[float, Meta(ge=MIN_RADIUS_M, le=MAX_RADIUS_M, extra={"unit": "m"})]


class PartTable(Struct, frozen=True, forbid_unknown_fields=True):
    """One ``[[parts]]`` entry: a part of the body, its capsule and spheres."""

    name: Annotated[str, Meta(pattern=r"\S", description="a part's name (text)")]
    #: Joints along the part, proximal first.
    chain: Joints
    #: The two joints whose mid-point is the part's extra point.
    mid: Annotated[tuple[str, str], Meta(description="two joint names")]
    #: r_j of the part's spheres (eq. 1), m.
    sphere_radius_m: Radius
    #: The part's capsule radius (exact method), m.
    capsule_radius_m: Radius
    #: Joints beyond the chain the capsule must cover (a hand's fingers).
    reach: Joints = []
    moves_with_body: Annotated[bool, Meta(description="true or false")] = False
    #: The body region of ISO/TS 15066 Annex A it is (power and force limiting).
    region: (
        Annotated[str, Meta(pattern=r"\S", description="must name a body region (text)")] | None
    ) = None


class BodyFile(Struct, frozen=True, forbid_unknown_fields=True):
    """A body model's file."""

    format: Annotated[
        str,
        Meta(pattern=r"^[A-Za-z0-9_-]+$", description="a format's name (letters, digits, _ and -)"),
    ]
    parts: Annotated[
        list[PartTable], Meta(min_length=1, description="an array of tables ([[parts]])")
    ]
    #: The joints that are model points, in point order.
    points: Joints = []
    centres: Annotated[
        dict[str, list[str]], Meta(description="a table of names to arrays of joint names")
    ] = {}
