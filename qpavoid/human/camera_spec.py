"""A body-tracking camera's numbers: a format file's ``[sensor]`` table, each with its source.

:class:`CameraSpec` is what the library needs of the camera behind a skeleton format: its
frame rate, latency, noise, Z_d, field of view, range and bodies per sensor, and, for the
simulated camera, how its noise grows with range and how often it swaps a person's sides.
Each number is checked against a camera's plausible range (:data:`SENSOR_CEILINGS`), and
the numbers safety rests on (:data:`EVIDENCED`) must say how they were obtained
(:class:`Evidence`, ``[sensor.evidence]``): a wrong table is refused with a
:class:`~qpavoid.core.errors.SkeletonFormatError` naming the key and the offending value.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import NoReturn

import msgspec

from qpavoid.core.errors import SkeletonFormatError
from qpavoid.core.schema import convert
from qpavoid.human.conversion import is_number, refused
from qpavoid.human.format_schema import BASES, SENSOR_CEILINGS, EvidenceTable

__all__ = [
    "AGE_MARGIN_S",
    "BASES",
    "EVIDENCED",
    "SENSOR_CEILINGS",
    "CameraSpec",
    "Evidence",
]

#: The numbers of ``[sensor]`` that safety rests on (speed and separation's latency term,
#: Z_d, the simulated noise): each must say how it was obtained.
EVIDENCED = ("latency_s", "noise_m", "tracked_uncertainty_m")


@dataclass(frozen=True)
class Evidence:
    """How one number of a camera's ``[sensor]`` table was obtained (``[sensor.evidence]``).

    Attributes
    ----------
    basis
        ``"measured"`` (a published measurement: cited in ``source``), ``"vendor"`` (the
        maker's documentation: cited in ``source``) or ``"estimate"`` (ours: ``note`` says
        why, and what was searched and not found).
    source
        The citation: authors, title, venue, year and DOI or URL (an SDK issue's number),
        with what exactly was measured.
    note
        What the number is and why this value: for an estimate, its reasoning.
    """

    basis: str
    source: str = ""
    note: str = ""

    @classmethod
    def read(cls, key: str, value: object) -> Evidence:
        """``[sensor.evidence]``'s entry for ``key``: its shape the schema's
        (:class:`~qpavoid.human.format_schema.EvidenceTable`), then :meth:`of`."""
        where = f"sensor.evidence.{key}"
        return cls.of(where, convert(value, EvidenceTable, refused, prefix=where))

    @classmethod
    def of(cls, where: str, table: EvidenceTable) -> Evidence:
        """The evidence of a table its schema read: a ``source`` where the number is
        measured or the maker's, a ``note`` where it is ours."""
        basis = table.basis
        evidence = cls(basis, table.source.strip(), table.note.strip())
        if basis != "estimate" and not evidence.source:
            _fail(
                f"{where}: a {basis} number needs its source (authors, title, venue, year, "
                "DOI or URL, and what was measured)",
                f"{where}.source",
                msgspec.structs.asdict(table),
            )
        if basis == "estimate" and not evidence.note:
            _fail(
                f"{where}: an estimate needs its note (why this value, and what was searched "
                "and not found)",
                f"{where}.note",
                msgspec.structs.asdict(table),
            )
        return evidence


#: What a frame's age limit allows beyond the camera's latency and one frame period, s
#: (:meth:`CameraSpec.age_limit_s`): 6.7 ms for the network and the loop's tick, so that a
#: 30 Hz camera's limit is its latency + 40 ms, the stale limit of the paper's bench.
AGE_MARGIN_S = 0.04 - 1.0 / 30.0


@dataclass(frozen=True)
class CameraSpec:
    """The body-tracking camera's numbers, as its format file's ``[sensor]`` table gives
    them (with their sources there).

    Attributes
    ----------
    frame_rate_hz
        Skeleton frames per second, Hz.
    latency_s
        From capture to the frame reaching the controller, s.
    noise_m
        Standard deviation of a tracked joint's noise per axis, m.
    tracked_uncertainty_m
        Z_d of speed and separation monitoring: a tracked joint's position error, m.
    field_of_view_deg
        The depth camera's (horizontal, vertical) field of view, degrees.
    range_m
        (near, far) distance at which the sensor sees a person, m.
    max_bodies
        Most bodies the sensor tracks at once (body ids 0 to ``max_bodies - 1``).
    noise_reference_range_m
        0: ``noise_m`` at any range; else the range at which the noise is ``noise_m``, m,
        growing with the square of the range (stereo depth: a ZED).
    left_right_swap_per_s
        How often the camera labels a person's left side right and the reverse, per s
        (each swap lasts ``left_right_swap_s``): a pose model that guesses the sides
        (MediaPipe) when it cannot see the face.
    left_right_swap_s
        How long such a swap lasts, s.
    evidence
        How each number was obtained, by key (``[sensor.evidence]``, :class:`Evidence`):
        every one of :data:`EVIDENCED` at least.
    """

    frame_rate_hz: float
    latency_s: float
    noise_m: float
    tracked_uncertainty_m: float
    field_of_view_deg: tuple[float, float]
    range_m: tuple[float, float]
    max_bodies: int
    noise_reference_range_m: float = 0.0
    left_right_swap_per_s: float = 0.0
    left_right_swap_s: float = 0.5
    evidence: tuple[tuple[str, Evidence], ...] = ()

    def age_limit_s(self, latency_s: float | None = None) -> float:
        """The oldest a frame of this camera may be when it arrives and when it is used, s:
        its latency (``latency_s``, e.g. one measured with ``qpavoid latency``, else the
        format's :attr:`latency_s`), one frame period (a frame held until the next
        arrives) and :data:`AGE_MARGIN_S`. A 30 Hz camera's limit is its latency + 40 ms."""
        latency = self.latency_s if latency_s is None else latency_s
        return latency + (1.0 / self.frame_rate_hz + AGE_MARGIN_S)

    def __post_init__(self) -> None:
        for key, low, value in (
            ("frame_rate_hz", 0.0, self.frame_rate_hz),
            ("latency_s", None, self.latency_s),
            ("noise_m", None, self.noise_m),
            ("tracked_uncertainty_m", None, self.tracked_uncertainty_m),
            ("noise_reference_range_m", None, self.noise_reference_range_m),
            ("left_right_swap_per_s", None, self.left_right_swap_per_s),
            ("left_right_swap_s", None, self.left_right_swap_s),
        ):
            if not is_number(value) or not (value > low if low is not None else value >= 0):
                rule = "a number > 0" if low is not None else "a number >= 0"
                _fail(f"sensor.{key} must be {rule}, got {value!r}", f"sensor.{key}", value)
            if value > SENSOR_CEILINGS[key]:
                _fail(
                    f"sensor.{key} must be at most {SENSOR_CEILINGS[key]} (a camera's), got "
                    f"{value!r}",
                    f"sensor.{key}",
                    value,
                )
        reference = self.noise_reference_range_m
        if 0.0 < reference < 0.1:
            _fail(
                "sensor.noise_reference_range_m must be 0 (no growth) or at least 0.1 m, got "
                f"{reference!r}",
                "sensor.noise_reference_range_m",
                reference,
            )
        if self.left_right_swap_per_s > 0.0 and not self.left_right_swap_s > 0.0:
            _fail(
                "sensor.left_right_swap_s must be > 0 where left_right_swap_per_s is, got "
                f"{self.left_right_swap_s!r}",
                "sensor.left_right_swap_s",
                self.left_right_swap_s,
            )
        if self.frame_rate_hz < 1.0:
            _fail(
                "sensor.frame_rate_hz must be at least 1 Hz (a camera's), got "
                f"{self.frame_rate_hz!r}",
                "sensor.frame_rate_hz",
                self.frame_rate_hz,
            )
        fov = self.field_of_view_deg
        if not _pair(fov) or not all(1.0 <= v < 180.0 for v in fov):
            _fail(
                f"sensor.field_of_view_deg must be two angles in [1, 180) degrees, got {fov!r}",
                "sensor.field_of_view_deg",
                fov,
            )
        near_far = self.range_m
        if not _pair(near_far) or not 0.0 <= near_far[0] < near_far[1] <= 100.0:
            _fail(
                f"sensor.range_m must be [near, far] with 0 <= near < far <= 100, m, got "
                f"{near_far!r}",
                "sensor.range_m",
                near_far,
            )
        if (
            not isinstance(self.max_bodies, int)
            or isinstance(self.max_bodies, bool)
            or not 1 <= self.max_bodies <= 100
        ):
            _fail(
                f"sensor.max_bodies must be a whole number from 1 to 100, got {self.max_bodies!r}",
                "sensor.max_bodies",
                self.max_bodies,
            )
        given = dict(self.evidence)
        numbers = [f.name for f in fields(self) if f.name != "evidence"]
        unknown = [k for k in given if k not in numbers]
        if unknown:
            _fail(
                f"sensor.evidence.{unknown[0]} names no number of [sensor]; they are "
                f"{', '.join(numbers)}",
                f"sensor.evidence.{unknown[0]}",
                given[unknown[0]],
            )
        missing = [k for k in EVIDENCED if k not in given]
        if missing:
            _fail(
                f"sensor.evidence.{missing[0]} is missing: say how the number was obtained "
                f"(basis = one of {list(BASES)}, with its source or note)",
                f"sensor.evidence.{missing[0]}",
                None,
            )

    def basis(self, key: str) -> Evidence:
        """How the number ``key`` was obtained (KeyError if the file does not say)."""
        return dict(self.evidence)[key]


def _fail(message: str, name: str, value: object) -> NoReturn:
    raise SkeletonFormatError(message, name=name, value=value)


def _pair(value: object) -> bool:
    return isinstance(value, tuple) and len(value) == 2 and all(is_number(v) for v in value)
