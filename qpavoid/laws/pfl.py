"""Power and force limiting (ISO/TS 15066 §5.5.5, Annex A): how fast the robot may touch a person.

Transient contact (the body part free to recoil) with a region of the arm or hand is permitted
as long as the energy it transfers stays within the region's limit. Annex A models the
contact as two bodies meeting through the region's tissue, a spring of effective constant k:

* the tissue compressed to the force F stores ``E = F² / (2k)`` (Annex A, eq. A.1);
* a robot point of effective mass m_R meeting a region of effective mass m_H at the relative
  speed v transfers ``E = ½ μ v²`` (A.2), μ the reduced mass of the two bodies

      μ = (1/m_H + 1/m_R)⁻¹                                          (A.3)

  (μ → m_H as m_R → ∞: a point that cannot be pushed back);
* the region bears transient contact up to ``F_T = c F_max``, F_max its quasi-static limit
  (Table A.2) and c the TS's transient factor, 2 (the factor its energy limits, Table A.4,
  are computed with; ``body_regions.toml`` cites the cross-checks);

so equating the two energies at F_T gives the largest permissible relative speed

      v_rel,max = F_T / √(μ k)                                        (A.5)

(the annex's speed from the force; A.6 is the same from the pressure, ``p_T A``, not used here:
it needs the contact area), and its inverse the force a contact at speed v reaches,
``F = v √(μ k)`` (:func:`contact_force_n`). Equation numbers as the annex's calculators quote
them (ISO 10218-2:2025 Annex A, which took over the TS's method); the TS's own numbering
was not checked against its text.

The robot's effective mass. The TS approximates m_R by ``M/2 + m_L`` (half the moving mass
plus the payload, A.4); here it is the exact mass the contact point presents along the
contact normal n (unit), the inverse of its operational-space inverse inertia:

      m_R = (nᵀ J M⁻¹ Jᵀ n)⁻¹

with J the point's (3, nv) translational Jacobian and M the joint-space mass matrix, the
payload included (:class:`qpavoid.arm.inertia.EffectiveMass`): the mass a unit impulse along
n meets at the point, and twice the smallest kinetic energy that moves it at unit speed along
n. The TS's ``M/2 + m_L`` may be lighter or heavier than it, posture by posture.

The regions' values are data (``body_regions.toml``, :func:`load_regions`); a body model's
parts name their region (``region = "hand_finger"``, :attr:`qpavoid.human.body.BodyModel.regions`)
and :meth:`PFLConfig.part_limits` turns them into per-part arrays. Every function is pure and
works element-wise on arrays (every set × part pair at once); NaN stays NaN. Units: N, N/m,
kg, m/s (the file's spring constants are in N/mm, as the TS gives them).
"""

from __future__ import annotations

import functools
import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path

import msgspec
import numpy as np
from numpy.typing import ArrayLike

from qpavoid.arm.dynamics import MAX_PAYLOAD_KG
from qpavoid.core.checks import one_line
from qpavoid.core.errors import DataFileError, InputError
from qpavoid.core.file_bounds import NotTOMLError, read_toml
from qpavoid.core.schema import convert
from qpavoid.laws.regions_schema import CONTACT_KINDS, RegionsFile, RegionTable

__all__ = [
    "BODY_REGIONS",
    "BODY_REGIONS_FILE",
    "CONTACT_KINDS",
    "BodyRegion",
    "PFLConfig",
    "clampable",
    "compression_allowance_m",
    "contact_force_n",
    "load_regions",
    "reduced_mass_kg",
    "stopping_contact_speed_mps",
    "transient_speed_limit_mps",
]

#: The body regions of ISO/TS 15066 Annex A (Tables A.2 and A.3), with their sources.
BODY_REGIONS_FILE = Path(__file__).with_name("body_regions.toml")
#: The largest body-region file read, bytes (the bundled one is 8 kB).
MAX_REGIONS_FILE_BYTES = 1 << 20


@dataclass(frozen=True)
class BodyRegion:
    """One body region of ISO/TS 15066 Annex A (a ``[[regions]]`` table of the file).

    Attributes
    ----------
    name
        Its name, snake_case (``"hand_finger"``): what a body model's parts name.
    title
        Its name in the TS (``"Hands and fingers"``).
    contact
        ``"transient"``: power and force limiting may allow transient contact; ``"none"``:
        never touched by design (speed and separation monitoring alone).
    max_force_n
        F_max: the maximum permissible force of quasi-static contact, N (Table A.2).
    transient_factor
        c: transient contact may reach ``c F_max``, from 1 to the TS's 2.
    spring_constant_n_per_mm
        k: the region's effective spring constant, N/mm (Table A.3; in N/m:
        :attr:`spring_constant_n_per_m`).
    effective_mass_kg
        m_H: the region's effective mass, kg (Table A.3).
    source
        Where the numbers come from.

    Raises
    ------
    InputError
        For a field not of :class:`~qpavoid.laws.regions_schema.RegionTable`'s shape: a
        name that is not snake_case, an empty title or source, an unknown contact kind, or
        a number that is not a number within its bounds; ``name`` is the field.
    """

    name: str
    title: str
    contact: str
    max_force_n: float
    transient_factor: float
    spring_constant_n_per_mm: float
    effective_mass_kg: float
    source: str

    def __post_init__(self) -> None:
        def fail(name: str, message: str, value: object) -> InputError:
            return InputError(message, name=name, value=value)

        given = {key: getattr(self, key) for key in _FIELDS}  # numpy's numbers as floats
        given |= {k: float(v) for k, v in given.items() if k in _NUMBERS and _is_real(v)}
        region = convert(given, RegionTable, fail)
        for key in _NUMBERS:
            object.__setattr__(self, key, getattr(region, key))

    @property
    def spring_constant_n_per_m(self) -> float:
        """k in N/m."""
        return self.spring_constant_n_per_mm * 1000.0

    @property
    def transient_force_n(self) -> float:
        """F_T = c F_max: the largest force of a transient contact, N."""
        return self.transient_factor * self.max_force_n

    @property
    def contact_permitted(self) -> bool:
        """True where power and force limiting may allow transient contact."""
        return self.contact == "transient"


def _is_real(value: object) -> bool:
    """A real number (numpy's too), not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


_FIELDS = tuple(f.name for f in fields(BodyRegion))
_NUMBERS = tuple(key for key in _FIELDS if key.endswith(("_n", "_factor", "_mm", "_kg")))


def load_regions(path: str | Path | None = None) -> dict[str, BodyRegion]:
    """The body regions of the file at ``path`` (default: the bundled
    ``body_regions.toml``), by name, in the file's order.

    The file's shape is :class:`~qpavoid.laws.regions_schema.RegionsFile`'s, refused in one
    line naming the field's path (``region 'hand_finger': regions[9].max_force_n must be a
    number above 0 ...``); two regions of one name are refused here.

    Raises
    ------
    DataFileError
        (an :class:`InputError`) in one line naming the file and the key's path: a file that
        cannot be read or is not TOML, a key other than ``regions``, no ``[[regions]]``
        table, an unknown or missing key in a region, an unknown contact kind, a number out
        of its bounds, or two regions of one name.
    """
    file = BODY_REGIONS_FILE if path is None else Path(path)

    def fail(key: str | None, message: str, value: object) -> DataFileError:
        return DataFileError(f"{file}: {message}", path=file, name=key or None, value=value)

    try:
        data = read_toml(file, MAX_REGIONS_FILE_BYTES)
    except NotTOMLError as exc:
        raise fail(None, f"not TOML: {one_line(exc)}", None) from None
    except (OSError, ValueError) as exc:
        raise fail(None, f"cannot read the file: {one_line(exc)}", None) from None
    out: dict[str, BodyRegion] = {}
    for k, row in enumerate(convert(data, RegionsFile, fail).regions):
        if row.name in out:
            raise fail(
                f"regions[{k}].name",
                f"regions[{k}].name: a second region called {row.name!r}",
                row.name,
            )
        out[row.name] = BodyRegion(**msgspec.structs.asdict(row))
    return out


#: The bundled regions (``body_regions.toml``), in the file's order.
BODY_REGIONS: tuple[BodyRegion, ...] = tuple(load_regions().values())


def _positive(value: ArrayLike, name: str, *, inf: bool = False) -> np.ndarray:
    """``value`` as a float array whose entries are above 0 (``+inf`` too if ``inf``; NaN
    passes through), else :class:`InputError` naming the first bad entry."""
    a = np.asarray(value, dtype=float)
    bad = (a <= 0.0) if inf else (a <= 0.0) | np.isinf(a)
    if bad.any():
        first = a[bad].flat[0]
        what = "above 0 (+inf allowed)" if inf else "finite and above 0"
        raise InputError(f"{name} must be {what}, got {first}", name=name, value=value)
    return a


def reduced_mass_kg(m_h_kg: ArrayLike, m_r_kg: ArrayLike) -> np.ndarray:
    """μ = (1/m_H + 1/m_R)⁻¹ (Annex A, eq. A.3), kg, element-wise.

    Parameters
    ----------
    m_h_kg
        m_H: the body region's effective mass, kg, above 0.
    m_r_kg
        m_R: the robot point's effective mass, kg, above 0; ``inf`` (a point that cannot be
        pushed back along the normal) gives μ = m_H.

    Raises
    ------
    InputError
        For a mass at or below 0 (or an infinite m_H).
    """
    m_h = _positive(m_h_kg, "m_h_kg")
    m_r = _positive(m_r_kg, "m_r_kg", inf=True)
    return 1.0 / (1.0 / m_h + 1.0 / m_r)


def transient_speed_limit_mps(
    force_n: ArrayLike, spring_n_per_m: ArrayLike, m_h_kg: ArrayLike, m_r_kg: ArrayLike
) -> np.ndarray:
    """v_rel,max = F_T / √(μ k) (Annex A, eq. A.5), m/s, element-wise: the largest relative
    speed at which a transient contact stays within the force F_T.

    Parameters
    ----------
    force_n
        F_T: the permissible transient force, N, at least 0 (0 gives 0 m/s).
    spring_n_per_m
        k: the region's effective spring constant, N/m, above 0.
    m_h_kg, m_r_kg
        The region's and the robot point's effective masses, kg (:func:`reduced_mass_kg`).

    Raises
    ------
    InputError
        For a negative or infinite force, a spring constant or a mass out of its range.
    """
    f = np.asarray(force_n, dtype=float)
    if np.any(f < 0.0) or np.any(np.isinf(f)):
        bad = f[(f < 0.0) | np.isinf(f)].flat[0]
        raise InputError(
            f"force_n must be finite and at least 0, got {bad}", name="force_n", value=force_n
        )
    k = _positive(spring_n_per_m, "spring_n_per_m")
    return f / np.sqrt(reduced_mass_kg(m_h_kg, m_r_kg) * k)


def contact_force_n(
    speed_mps: ArrayLike,
    spring_n_per_m: ArrayLike,
    m_h_kg: ArrayLike,
    m_r_kg: ArrayLike,
    pinned: ArrayLike = False,
) -> np.ndarray:
    """F = v √(μ k), N, element-wise: the peak force of a transient contact at the relative
    speed v (the inverse of :func:`transient_speed_limit_mps`; from ``½ μ v² = F² / (2k)``,
    Annex A eqs. A.1-A.2). A speed at or below 0 (the two moving apart) gives 0 N.

    Parameters
    ----------
    speed_mps
        v: the robot point's speed towards the region, m/s.
    spring_n_per_m, m_h_kg, m_r_kg
        As for :func:`transient_speed_limit_mps`.
    pinned
        The region cannot recoil (clamped against a fixed surface): the robot's energy
        ``½ m_R v²`` goes into the tissue alone, μ = m_R (infinite force from an
        immovable robot point approaching at all).

    Raises
    ------
    InputError
        For an infinite speed, a spring constant or a mass out of its range.
    """
    v = np.asarray(speed_mps, dtype=float)
    if np.any(np.isinf(v)):
        bad = v[np.isinf(v)].flat[0]
        raise InputError(f"speed_mps must be finite, got {bad}", name="speed_mps", value=speed_mps)
    k = _positive(spring_n_per_m, "spring_n_per_m")
    mu = np.where(pinned, _positive(m_r_kg, "m_r_kg", inf=True), reduced_mass_kg(m_h_kg, m_r_kg))
    with np.errstate(invalid="ignore"):  # 0 m/s into an immovable point: 0 N, not 0 × inf
        return np.where(v > 0.0, v * np.sqrt(mu * k), np.where(np.isnan(v), v, 0.0))


def compression_allowance_m(force_n: ArrayLike, spring_n_per_m: ArrayLike) -> np.ndarray:
    """δ = F_T / k: how far a driven robot point may compress the region's tissue before
    the force reaches F_T (the spring of Annex A), m. A position-controlled arm does not
    bounce off a contact as Annex A's free masses do: it keeps moving until it has
    stopped, so its advance into the part after the first touch must stay within δ
    (:func:`stopping_contact_speed_mps`). NaN stays NaN; 0 N gives 0 m."""
    return np.asarray(force_n, dtype=float) / _positive(spring_n_per_m, "spring_n_per_m")


def stopping_contact_speed_mps(
    distance_m: ArrayLike, allowance_m: ArrayLike, fixed_m: float, stop_s: float
) -> np.ndarray:
    """The fastest approach from which a robot point still stops within the allowance
    ``δ`` past a part standing at ``distance_m``, m/s:

        v_c = (d − C − Z_d − Z_r + δ) / (T_r + T_s/2)

    speed and separation's bound (:func:`~qpavoid.laws.ssm.max_approach_speed`) without
    S_h (the part's own approach, whose contact with a robot no faster than v_max is the
    transient contact Annex A permits) and with δ (:func:`compression_allowance_m`) of room
    beyond the part's surface. ``fixed_m`` is C + Z_d + Z_r (m), ``stop_s`` T_r + T_s/2
    (s). Negative past ``δ − C − Z_d − Z_r`` inside the part: the robot must back off."""
    d = np.asarray(distance_m, dtype=float)
    return (d - fixed_m + np.asarray(allowance_m, dtype=float)) / stop_s


def clampable(
    human_point: ArrayLike,
    normal: ArrayLike,
    radius_m: ArrayLike,
    surface_z_m: float | None,
    gap_m: float,
) -> np.ndarray:
    """True where a body part touched at ``human_point`` could be pinned against the fixed
    surface: a quasi-static contact (clamping), outside transient contact's limits.

    The part's far side along the robot's approach, ``h − 2 r n`` (``human_point`` h on the
    part's surface nearest the robot, ``normal`` n the unit direction from the part to the
    robot, ``radius_m`` r the part's radius), lies over the surface (``n_z > 0``) within
    ``gap_m`` of it along that approach: ``(h_z − 2 r n_z − z_s) / n_z ≤ gap``. (..., 3)
    points and normals, (...) radii; all False without a surface.
    """
    h, n = np.asarray(human_point, dtype=float), np.asarray(normal, dtype=float)
    if surface_z_m is None:
        return np.zeros(h.shape[:-1], dtype=bool)
    nz = n[..., 2]
    height = h[..., 2] - 2.0 * np.asarray(radius_m, dtype=float) * nz - surface_z_m
    with np.errstate(divide="ignore", invalid="ignore"):
        return (nz > 0.0) & (height <= gap_m * nz)


@dataclass(frozen=True)
class PFLConfig:
    """Constants of power and force limiting.

    Attributes
    ----------
    payload_kg
        The payload at the end effector, kg: a point mass at the end-effector frame's origin,
        added to the arm's inertia (:class:`qpavoid.arm.inertia.EffectiveMass`, which also
        holds it to the arm's rated payload). At least 0, finite.
    regions
        The body-region table (default: the bundled ``body_regions.toml``,
        :data:`BODY_REGIONS`; another file: :meth:`from_file`). Held as values, not a path,
        so that a config is complete, comparable and picklable on its own.
    surface_z_m
        The height of the fixed surface a part may be pressed against, base frame, m: the
        table top the arm stands on (z = 0 in every bundled task's layout, where the
        seated operator's forearms and hands rest); None: no such surface. A part against
        it cannot recoil, so a contact there is quasi-static, not transient
        (:func:`clampable`).
    clamp_gap_m
        How far from that surface a part counts as against it, m: 0.05, about a hand's
        thickness, the room a hand pushed down has before it is pinned.

    Raises
    ------
    InputError
        For a payload that is negative, not finite or above :data:`MAX_PAYLOAD_KG`, no
        regions, an entry that is not a :class:`BodyRegion`, or two regions of one name.
    """

    payload_kg: float = 0.0
    regions: tuple[BodyRegion, ...] = field(default=BODY_REGIONS)
    surface_z_m: float | None = 0.0
    clamp_gap_m: float = 0.05

    def __post_init__(self) -> None:
        p = self.payload_kg
        if not _is_real(p) or not (math.isfinite(p) and 0.0 <= p <= MAX_PAYLOAD_KG):
            raise InputError(
                f"payload_kg must be a finite number of kg between 0 and {MAX_PAYLOAD_KG:g}, "
                f"got {p!r}",
                name="payload_kg",
                value=p,
            )
        regions = tuple(self.regions)
        if not regions or not all(isinstance(r, BodyRegion) for r in regions):
            raise InputError(
                "regions must be one or more BodyRegion (load_regions)",
                name="regions",
                value=self.regions,
            )
        names = [r.name for r in regions]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise InputError(
                f"regions: two regions called {twice[0]!r}", name="regions", value=twice
            )
        object.__setattr__(self, "payload_kg", float(p))
        object.__setattr__(self, "regions", regions)
        gap = self.clamp_gap_m
        if not _is_real(gap) or not (math.isfinite(gap) and 0.0 <= gap <= 1.0):
            raise InputError(
                f"clamp_gap_m must be between 0 and 1 m, got {gap!r}", name="clamp_gap_m", value=gap
            )
        z = self.surface_z_m
        if z is not None and not (_is_real(z) and math.isfinite(z)):
            raise InputError(
                f"surface_z_m must be a finite height (m) or None, got {z!r}",
                name="surface_z_m",
                value=z,
            )

    @classmethod
    def from_file(cls, path: str | Path, payload_kg: float = 0.0) -> PFLConfig:
        """The config with the regions of the file at ``path`` (:func:`load_regions`)."""
        return cls(payload_kg=payload_kg, regions=tuple(load_regions(path).values()))

    def region(self, name: str) -> BodyRegion:
        """The region called ``name``, or :class:`InputError` listing the table's."""
        for r in self.regions:
            if r.name == name:
                return r
        raise InputError(
            f"a body-region table entry missing: no region {name!r}; the table has "
            f"{[r.name for r in self.regions]}",
            name="region",
            value=name,
        )

    def part_limits(
        self, part_regions: Sequence[str | None]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each body part's power and force limits, (K,) arrays (read-only, cached).

        Parameters
        ----------
        part_regions
            The region of each part (:attr:`qpavoid.human.body.BodyModel.regions`), or None
            for a part that names none.

        Returns
        -------
        contact
            (K,) bool: True where the part's region permits transient contact: the only
            pairs whose speed bound may be raised to the transient limit.
        force_n
            (K,) F_T = c F_max of the region where contact is permitted, N; 0 N where it is
            not (no force is permissible there).
        spring_n_per_m
            (K,) the region's k, N/m; NaN for a part without a region.
        mass_kg
            (K,) the region's m_H, kg; NaN for a part without a region.

        Raises
        ------
        InputError
            For a part that names a region the table lacks (a body-region table entry
            missing), or an entry that is neither a name nor None.
        """
        names = tuple(part_regions)
        for k, name in enumerate(names):
            if name is not None and not isinstance(name, str):
                raise InputError(
                    f"part_regions[{k}] must be a region's name or None, got {name!r}",
                    name="part_regions",
                    value=name,
                )
        return _part_limits(self.regions, names)


@functools.lru_cache(maxsize=16)
def _part_limits(
    regions: tuple[BodyRegion, ...], part_regions: tuple[str | None, ...]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`PFLConfig.part_limits`, once per table and body model."""
    table = {r.name: r for r in regions}
    k_parts = len(part_regions)
    contact = np.zeros(k_parts, dtype=bool)
    force = np.zeros(k_parts)
    spring = np.full(k_parts, np.nan)
    mass = np.full(k_parts, np.nan)
    for k, name in enumerate(part_regions):
        if name is None:
            continue
        region = table.get(name)
        if region is None:
            raise InputError(
                f"a body-region table entry missing: part {k} names region {name!r}, which "
                f"the table lacks; its regions are {list(table)}",
                name="part_regions",
                value=name,
            )
        contact[k] = region.contact_permitted
        force[k] = region.transient_force_n if region.contact_permitted else 0.0
        spring[k], mass[k] = region.spring_constant_n_per_m, region.effective_mass_kg
    for a in (contact, force, spring, mass):
        a.setflags(write=False)
    return contact, force, spring, mass
