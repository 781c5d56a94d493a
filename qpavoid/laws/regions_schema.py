"""A body-region file's shape: ``body_regions.toml`` as a schema (msgspec).

The types, ranges, keys known and keys required of the file of ISO/TS 15066 Annex A's body
regions (:func:`qpavoid.laws.pfl.load_regions`; the bundled ``body_regions.toml`` shows
each key with its meaning): one or more ``[[regions]]`` tables. That no two regions share
a name stays code beside the reader; so does whether a body model's parts name regions
the table has (:meth:`qpavoid.laws.pfl.PFLConfig.part_limits`).

Every number's bound is a plausibility bound: beyond it is a unit error (a spring constant
in N/m where N/mm is asked reads 1000 times too stiff), said so in the refusal.
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

from msgspec import Meta, Struct

__all__ = [
    "CONTACT_KINDS",
    "MAX_FORCE_N",
    "MAX_MASS_KG",
    "MAX_SPRING_N_PER_MM",
    "MAX_TRANSIENT_FACTOR",
    "MIN_TRANSIENT_FACTOR",
    "RegionTable",
    "RegionsFile",
]

#: A region's contact kinds: transient contact permitted (power and force limiting), or no
#: contact at all (speed and separation monitoring alone).
CONTACT_KINDS = ("transient", "none")
#: The TS's forces are 65-220 N (Table A.2), its spring constants 10-150 N/mm and its masses
#: 0.6-75 kg (Table A.3): a force over 1000 N, a spring over 1000 N/mm (N/m typed for N/mm)
#: or a mass over 200 kg is a unit error.
MAX_FORCE_N, MAX_SPRING_N_PER_MM, MAX_MASS_KG = 1000.0, 1000.0, 200.0
#: The TS's own bound: transient contact may reach at most twice the quasi-static limit
#: (Table A.2's note), and never less than it.
MIN_TRANSIENT_FACTOR, MAX_TRANSIENT_FACTOR = 1.0, 2.0
#: What a number beyond its bound most likely is.
_BEYOND = "a unit error?"

Text = Annotated[str, Meta(pattern=r"\S", description="a non-empty text")]


class RegionTable(Struct, frozen=True, forbid_unknown_fields=True):
    """One ``[[regions]]`` table: a body region of Annex A, its limits and their source."""

    #: What a body model's parts name (``region = "hand_finger"``).
    name: Annotated[
        str, Meta(pattern=r"^[a-z][a-z0-9_]*$", description="a snake_case name ([a-z][a-z0-9_]*)")
    ]
    #: Its name in the TS.
    title: Text
    contact: Annotated[
        Literal["transient", "none"],
        Meta(description=f"one of {', '.join(map(repr, CONTACT_KINDS))}"),
    ]
    #: F_max, N: above 0 (no force at all is no contact: ``contact = "none"``), at most
    #: 1000 N (module docstring).
    max_force_n: Annotated[
        float, Meta(gt=0, le=MAX_FORCE_N, extra={"unit": "N", "beyond": _BEYOND})
    ]
    #: c: from 1 to the TS's 2 (F_T = c F_max), no unit.
    transient_factor: Annotated[float, Meta(ge=MIN_TRANSIENT_FACTOR, le=MAX_TRANSIENT_FACTOR)]
    #: k, N/mm: above 0 (a region without stiffness stores no energy: eq. A.5 divides by
    #: it), at most 1000 N/mm.
    spring_constant_n_per_mm: Annotated[
        float, Meta(gt=0, le=MAX_SPRING_N_PER_MM, extra={"unit": "N/mm", "beyond": _BEYOND})
    ]
    #: m_H, kg: above 0 (eq. A.3 divides by it), at most 200 kg.
    effective_mass_kg: Annotated[
        float, Meta(gt=0, le=MAX_MASS_KG, extra={"unit": "kg", "beyond": _BEYOND})
    ]
    #: Where the numbers come from.
    source: Text


class RegionsFile(Struct, frozen=True, forbid_unknown_fields=True):
    """A body-region file."""

    docs: ClassVar[str] = "docs/formats.md: The body regions"

    regions: Annotated[
        list[RegionTable],
        Meta(min_length=1, description="one or more [[regions]] tables"),
    ]
