"""Skeleton formats as data: what a body-tracking sensor's skeletons are made of.

A :class:`SkeletonFormat` says what the library needs to know of a sensor's skeletons,
as mmpose's dataset configs do for their keypoints: the joints' names in the sensor's
order (a joint's id is its row in a frame), each joint's parent, the left/right pairs,
the torso joints, the tracking-state codes, the longest plausible bone per joint, joints
by role (:meth:`SkeletonFormat.group`), and the sensor's frame rate, latency, noise,
field of view, range and bodies per sensor (:class:`CameraSpec`). It is read from a TOML
file (:meth:`SkeletonFormat.load`; ``formats/kinect_v2.toml`` is the Kinect v2's, loaded
by :mod:`qpavoid.human.kinect_v2`) and checked when built: a wrong file is refused with a
:class:`SkeletonFormatError` naming the file, the key and the offending value.

The code sizes its arrays from a format (:attr:`SkeletonFormat.n_joints`) and addresses
joints through it (:attr:`~SkeletonFormat.parent`, :attr:`~SkeletonFormat.mirror`,
:meth:`~SkeletonFormat.group`), never by a literal joint count or index.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields, replace
from functools import cached_property
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from qpavoid.core.checks import one_line
from qpavoid.core.errors import InputError, SkeletonFormatError
from qpavoid.core.file_bounds import NotTOMLError
from qpavoid.core.file_bounds import read_toml as read_toml_file
from qpavoid.human.conversion import Confidence, LandmarkRule, is_number, only_keys, parse_rule

__all__ = [
    "AGE_MARGIN_S",
    "BASES",
    "EVIDENCED",
    "FORMATS_DIR",
    "INFERRED",
    "NOT_TRACKED",
    "TRACKED",
    "TRACKING_STATES",
    "CameraSpec",
    "Evidence",
    "SkeletonFormat",
    "SkeletonFormatError",
]

#: The library's tracking states of a joint: not usable, usable but uncertain, trusted.
#: Frames, recordings, datagrams and the compiled kernels use these codes.
NOT_TRACKED, INFERRED, TRACKED = 0, 1, 2
#: The tracking-state table a format file must hold (key: code).
TRACKING_STATES: tuple[tuple[str, int], ...] = (
    ("not_tracked", NOT_TRACKED),
    ("inferred", INFERRED),
    ("tracked", TRACKED),
)
#: Where the library's own format and body files are.
FORMATS_DIR = Path(__file__).with_name("formats")
#: Largest format or body file read, bytes: the Kinect v2's is 6 kB; 1 MB is junk.
MAX_FORMAT_FILE_BYTES = 2**20

_TOP_KEYS = (
    "name",
    "title",
    "tracking_states",
    "sensor",
    "joints",
    "mirror_pairs",
    "torso",
    "groups",
    "units",
    "axes",
    "confidence",
    "body",
    "landmarks",
    "simulate",
)
#: A format's length units: metres per unit.
UNITS_M = {"m": 1.0, "mm": 0.001}
#: The directions a camera's axes may point, as seen from the camera.
AXIS_DIRECTIONS = {
    "right": (1.0, 0.0, 0.0),
    "left": (-1.0, 0.0, 0.0),
    "down": (0.0, 1.0, 0.0),
    "up": (0.0, -1.0, 0.0),
    "forward": (0.0, 0.0, 1.0),
    "backward": (0.0, 0.0, -1.0),
}
_JOINT_KEYS = ("id", "name", "parent", "max_bone_m")


#: How a camera's number was obtained (``[sensor.evidence]``): a published measurement,
#: the maker's documentation, or our estimate.
BASES = ("measured", "vendor", "estimate")
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
        """``[sensor.evidence]``'s entry for ``key``, checked: a table with a known
        ``basis``, a ``source`` where it is measured or the maker's, a ``note`` where it is
        ours."""
        where = f"sensor.evidence.{key}"
        if not isinstance(value, dict):
            _fail(f"{where} must be a table {{ basis, source, note }}, got {value!r}", where, value)
        only_keys(value, ("basis", "source", "note"), f"{where}.")
        basis = value.get("basis")
        if basis not in BASES:
            _fail(f"{where}.basis must be one of {list(BASES)}, got {basis!r}", where, basis)
        for field_ in ("source", "note"):
            if not isinstance(value.get(field_, ""), str):
                _fail(f"{where}.{field_} must be text", f"{where}.{field_}", value[field_])
        evidence = cls(basis, value.get("source", "").strip(), value.get("note", "").strip())
        if basis != "estimate" and not evidence.source:
            _fail(
                f"{where}: a {basis} number needs its source (authors, title, venue, year, "
                "DOI or URL, and what was measured)",
                f"{where}.source",
                value,
            )
        if basis == "estimate" and not evidence.note:
            _fail(
                f"{where}: an estimate needs its note (why this value, and what was searched "
                "and not found)",
                f"{where}.note",
                value,
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


@dataclass(frozen=True)
class SkeletonFormat:
    """A sensor's skeleton format, checked when built (module docstring).

    Parameters
    ----------
    name
        The format's name (``"kinect_v2"``).
    title
        How messages call the sensor (``"Kinect v2"``).
    joints
        Joint names in the sensor's order: joint ``j`` is row ``j`` of a frame.
    parents
        Each joint's parent (a name of ``joints``), or None for a root and for joints
        outside the modelled tree.
    bone_bounds_m
        Each joint's longest plausible bone to its parent, m (0: no bound; a joint without
        a parent has none).
    mirror_pairs
        (left, right) joint pairs swapped by a left/right relabelling; a joint in no pair
        is its own mirror. The swap must map the tree onto itself.
    torso
        The joints whose mean is a body's centre.
    groups
        Joints by role: ``((group, ((role, joint), ...)), ...)`` (see :meth:`group`).
    sensor
        The camera's numbers (:class:`CameraSpec`, the file's ``[sensor]`` table).
    tracking_states
        ``(state, code)`` pairs; they must be the library's :data:`TRACKING_STATES` (the
        states of the library's frames; a camera's own confidence is :attr:`confidence`).
    unit_m
        Metres per unit of the camera's joint positions (``units``: 1 for m, 0.001 for mm).
    axes
        Where the camera's x, y and z axes point, seen from the camera (``"left"``,
        ``"down"``, ``"forward"``, ...): the frame its joints are given in, which the
        calibration file's transform for a sensor of the format starts from.
    confidence
        What a joint's confidence value is and the state it gives (``[confidence]``).
    body
        The body format whose landmarks ``landmarks`` gives (``""``: the format is the
        body's own, its joints are the landmarks).
    landmarks
        ``((landmark, rule), ...)``: each of the body's landmarks from this format's
        joints (:class:`~qpavoid.human.conversion.LandmarkRule`).
    simulate
        ``((joint, rule), ...)``: each joint of this format from the body's landmarks, for
        the format's simulated camera.
    source
        The file the format was read from (``""``: built in code): its body model is the
        file ``<name>_body.toml`` beside it (:func:`~qpavoid.human.body.body_model`).

    Raises
    ------
    SkeletonFormatError
        For anything inconsistent, naming the key and its value.
    """

    name: str
    title: str
    joints: tuple[str, ...]
    parents: tuple[str | None, ...]
    bone_bounds_m: tuple[float, ...]
    mirror_pairs: tuple[tuple[str, str], ...]
    torso: tuple[str, ...]
    groups: tuple[tuple[str, tuple[tuple[str, str], ...]], ...]
    sensor: CameraSpec
    tracking_states: tuple[tuple[str, int], ...] = TRACKING_STATES
    unit_m: float = 1.0
    axes: tuple[str, str, str] = ("left", "up", "forward")
    confidence: Confidence = Confidence()  # noqa: RUF009 (frozen: one shared default)
    body: str = ""
    landmarks: tuple[tuple[str, LandmarkRule], ...] = ()
    simulate: tuple[tuple[str, LandmarkRule], ...] = ()
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        for key in ("name", "title"):
            value = getattr(self, key)
            if not isinstance(value, str) or not value.strip():
                _fail(f"{key} must be a non-empty string, got {value!r}", key, value)
        self._check_joints()
        self._check_tree()
        self._check_mirror()
        for k, joint in enumerate(self.torso):
            self._known(joint, f"torso[{k}]")
        if not self.torso or len(set(self.torso)) != len(self.torso):
            _fail(f"torso must name distinct joints, got {self.torso!r}", "torso", self.torso)
        for group, roles in self.groups:
            if not roles:
                _fail(f"group {group!r} names no joint", f"groups.{group}", roles)
            for role, joint in roles:
                self._known(joint, f"groups.{group}.{role}")
        if dict(self.tracking_states) != dict(TRACKING_STATES):
            _fail(
                f"tracking_states must be {dict(TRACKING_STATES)} (the codes of the library's "
                f"frames, recordings and datagrams; a sensor with other codes is translated "
                f"by its streamer), got {dict(self.tracking_states)}",
                "tracking_states",
                dict(self.tracking_states),
            )
        self._check_camera()

    def _check_camera(self) -> None:
        if self.unit_m not in UNITS_M.values():
            _fail(f"units must be one of {list(UNITS_M)}", "units", self.unit_m)
        axes = self.axes
        if (
            len(axes) != 3
            or not all(a in AXIS_DIRECTIONS for a in axes)
            or abs(np.linalg.det(np.array([AXIS_DIRECTIONS[a] for a in axes]))) != 1.0
        ):
            _fail(
                f"axes must be three perpendicular directions of {list(AXIS_DIRECTIONS)}, "
                f"got {list(axes)!r}",
                "axes",
                axes,
            )
        if bool(self.body) != bool(self.landmarks):
            _fail(
                "a camera format names its body format and maps its landmarks (body and "
                "[landmarks] together), or neither (a body format)",
                "body",
                self.body,
            )
        for key, rules in (("landmarks", self.landmarks), ("simulate", self.simulate)):
            names = [name for name, _ in rules]
            if len(set(names)) != len(names):
                _fail(f"{key} names a point twice", key, names)
            if key == "simulate":
                for name in names:
                    self._known(name, f"simulate.{name}")
                continue
            for name, rule in rules:
                for joint in rule.sources:
                    self._known(joint, f"landmarks.{name}")
        if self.simulate and set(n for n, _ in self.simulate) != set(self.joints):
            missing = [j for j in self.joints if j not in dict(self.simulate)]
            _fail(f"simulate must place every joint; it lacks {missing}", "simulate", missing)

    @cached_property
    def axes_matrix(self) -> np.ndarray:
        """(3, 3) the camera's axes in the optical frame (x right, y down, z forward):
        column ``k`` is where its axis ``k`` points; ``axes_matrix @ p`` turns a point of
        the camera's frame into the optical frame (read-only)."""
        return _frozen(np.array([AXIS_DIRECTIONS[a] for a in self.axes]).T, np.float64)

    def _check_joints(self) -> None:
        joints = self.joints
        if not joints or not all(isinstance(j, str) and j.strip() for j in joints):
            _fail(f"joints must be non-empty names, got {joints!r}", "joints", joints)
        seen: set[str] = set()
        for k, joint in enumerate(joints):
            if joint in seen:
                _fail(f"joints[{k}]: the name {joint!r} is used twice", f"joints[{k}].name", joint)
            seen.add(joint)
        for key, values in (("parents", self.parents), ("bone_bounds_m", self.bone_bounds_m)):
            if len(values) != len(joints):
                _fail(f"{key} has {len(values)} entries for {len(joints)} joints", key, values)

    def _check_tree(self) -> None:
        for k, (joint, parent, bound) in enumerate(
            zip(self.joints, self.parents, self.bone_bounds_m, strict=True)
        ):
            if parent is not None:
                self._known(parent, f"joints[{k}].parent")
                if parent == joint:
                    _fail(
                        f"joints[{k}]: {joint!r} is its own parent", f"joints[{k}].parent", parent
                    )
            if not is_number(bound) or bound < 0.0:
                _fail(
                    f"joints[{k}].max_bone_m ({joint}) must be a number >= 0, m, got {bound!r}",
                    f"joints[{k}].max_bone_m",
                    bound,
                )
            if parent is None and bound > 0.0:
                _fail(
                    f"joints[{k}]: {joint!r} has a max_bone_m ({bound!r}) but no parent",
                    f"joints[{k}].max_bone_m",
                    bound,
                )
        ids = self.parent
        for start in range(len(self.joints)):
            j, steps = start, 0
            while j >= 0:
                j, steps = int(ids[j]), steps + 1
                if steps > len(self.joints):
                    _fail(
                        f"joints: the parents of {self.joints[start]!r} form a cycle",
                        f"joints[{start}].parent",
                        self.parents[start],
                    )

    def _check_mirror(self) -> None:
        paired: set[str] = set()
        for k, pair in enumerate(self.mirror_pairs):
            if len(pair) != 2 or pair[0] == pair[1]:
                _fail(f"mirror_pairs[{k}] must be two joints, got {pair!r}", "mirror_pairs", pair)
            for joint in pair:
                self._known(joint, f"mirror_pairs[{k}]")
                if joint in paired:
                    _fail(
                        f"mirror_pairs[{k}]: {joint!r} is in two pairs",
                        f"mirror_pairs[{k}]",
                        pair,
                    )
                paired.add(joint)
        mirror, parent, bound = self.mirror, self.parent, self.bone_bounds_m
        for j, m in enumerate(mirror):
            expected = -1 if parent[j] < 0 else mirror[parent[j]]
            if parent[m] != expected or bound[m] != bound[j]:
                _fail(
                    f"mirror_pairs: {self.joints[j]!r} and {self.joints[m]!r} are a pair but "
                    "their parents or max_bone_m do not mirror each other",
                    "mirror_pairs",
                    (self.joints[j], self.joints[m]),
                )

    def _known(self, joint: object, key: str) -> None:
        if not isinstance(joint, str) or joint not in self._ids:
            _fail(f"{key}: unknown joint {joint!r}; the joints are {list(self.joints)}", key, joint)

    def __hash__(self) -> int:
        # the dataclass hash of every field, computed once (kernels' warm-ups and the
        # fusion's lookups are keyed on the format)
        return self._hash

    @cached_property
    def _hash(self) -> int:
        return hash(tuple(getattr(self, f.name) for f in fields(self) if f.compare))

    @cached_property
    def _ids(self) -> dict[str, int]:
        return {name: j for j, name in enumerate(self.joints)}

    @property
    def n_joints(self) -> int:
        """Joints per skeleton (rows of a frame)."""
        return len(self.joints)

    def index(self, joint: str) -> int:
        """The id (row) of the joint called ``joint``.

        Raises
        ------
        InputError
            For a name that is not a joint of the format.
        """
        j = self._ids.get(joint)
        if j is None:
            raise InputError(
                f"{joint!r} is not a joint of the {self.name} format; its joints are "
                f"{list(self.joints)}",
                name="joint",
                value=joint,
            )
        return j

    def indices(self, joints: tuple[str, ...] | list[str]) -> np.ndarray:
        """(n,) int64 ids of the named joints, in the order given."""
        return np.array([self.index(j) for j in joints], dtype=np.int64)

    def group(self, name: str) -> dict[str, int]:
        """The joints of group ``name`` by role, in the file's order (``group("arm_left")
        ["hand"]`` is the left hand's id).

        Raises
        ------
        InputError
            For a group the format does not have.
        """
        roles = self._groups.get(name)
        if roles is None:
            raise InputError(
                f"the {self.name} format has no joint group {name!r}; its groups are "
                f"{list(self._groups)}",
                name="group",
                value=name,
            )
        return dict(roles)

    @cached_property
    def _groups(self) -> dict[str, dict[str, int]]:
        return {
            group: {role: self._ids[joint] for role, joint in roles} for group, roles in self.groups
        }

    @cached_property
    def parent(self) -> np.ndarray:
        """(J,) int64 each joint's parent id, -1 for none (read-only)."""
        return _frozen([-1 if p is None else self._ids[p] for p in self.parents], np.int64)

    @cached_property
    def mirror(self) -> np.ndarray:
        """(J,) int64 each joint's counterpart on the other side (itself on the spine):
        ``joints[mirror]`` undoes a left/right swap (read-only)."""
        out = list(range(self.n_joints))
        for left, right in self.mirror_pairs:
            a, b = self._ids[left], self._ids[right]
            out[a], out[b] = b, a
        return _frozen(out, np.int64)

    @cached_property
    def sided(self) -> np.ndarray:
        """(n,) int64 the joints that change under a left/right swap (read-only)."""
        return _frozen(np.flatnonzero(np.arange(self.n_joints) != self.mirror), np.int64)

    @cached_property
    def torso_ids(self) -> np.ndarray:
        """(n,) int64 the torso joints, in the file's order (read-only)."""
        return _frozen([self._ids[j] for j in self.torso], np.int64)

    @cached_property
    def max_bone_m(self) -> np.ndarray:
        """(J,) float64 each joint's longest plausible bone to its parent, m; 0 for none
        (read-only)."""
        return _frozen(self.bone_bounds_m, np.float64)

    @classmethod
    def load(cls, path: str | Path) -> SkeletonFormat:
        """The format of the TOML file at ``path`` (``formats/kinect_v2.toml`` shows the
        keys, each with its meaning and source).

        Raises
        ------
        SkeletonFormatError
            If the file cannot be read, is not TOML, lacks a key, has an unknown one, or
            is inconsistent; the message names the file, the key and the value.
        """
        data = read_toml(path)
        try:
            return replace(cls.from_mapping(data), source=str(path))
        except SkeletonFormatError as exc:
            raise SkeletonFormatError(
                f"{path}: {exc}", path=path, name=exc.name, value=exc.value
            ) from None

    @classmethod
    def from_mapping(cls, data: Mapping[str, object]) -> SkeletonFormat:
        """The format of a parsed format file (the keys of :meth:`load`)."""
        only_keys(data, _TOP_KEYS, "")
        rows = _require(data, "joints", list, "an array of tables")
        names, parents, bounds = [], [], []
        for k, row in enumerate(rows):
            if not isinstance(row, dict):
                _fail(f"joints[{k}] must be a table, got {row!r}", f"joints[{k}]", row)
            only_keys(row, _JOINT_KEYS, f"joints[{k}].")
            if row.get("id") != k or isinstance(row.get("id"), bool):
                _fail(
                    f"joints[{k}].id must be {k} (ids run 0, 1, 2, ... in file order), "
                    f"got {row.get('id')!r}",
                    f"joints[{k}].id",
                    row.get("id"),
                )
            names.append(_require(row, "name", str, "a string", f"joints[{k}]."))
            parent = row.get("parent")
            if parent is not None and not isinstance(parent, str):
                _fail(f"joints[{k}].parent must be a joint name, got {parent!r}", "parent", parent)
            parents.append(parent)
            bounds.append(row.get("max_bone_m", 0.0))
        pairs = _require(data, "mirror_pairs", list, "an array of [left, right] pairs")
        groups = data.get("groups", {})  # optional: code that needs a role says so
        if not isinstance(groups, dict):
            _fail(f"groups must be a table of tables, got {groups!r}", "groups", groups)
        for group, roles in groups.items():
            if not isinstance(roles, dict):
                _fail(f"groups.{group} must be a table, got {roles!r}", f"groups.{group}", roles)
        sensor = dict(_require(data, "sensor", dict, "a table"))
        only_keys(sensor, tuple(CameraSpec.__dataclass_fields__), "sensor.")
        evidence = sensor.pop("evidence", {})
        if not isinstance(evidence, dict):
            _fail(f"sensor.evidence must be a table, got {evidence!r}", "sensor.evidence", evidence)
        sensor["evidence"] = tuple((k, Evidence.read(k, v)) for k, v in evidence.items())
        missing = [
            k
            for k, f in CameraSpec.__dataclass_fields__.items()
            if k not in sensor and f.default is MISSING
        ]
        if missing:
            _fail(f"sensor has no key {missing[0]!r}", f"sensor.{missing[0]}", None)
        states = data.get("tracking_states", dict(TRACKING_STATES))
        if not isinstance(states, dict):
            _fail(f"tracking_states must be a table, got {states!r}", "tracking_states", states)
        units = data.get("units", "m")
        if units not in UNITS_M:
            _fail(f"units must be one of {list(UNITS_M)}, got {units!r}", "units", units)
        axes = data.get("axes", ["left", "up", "forward"])
        if not isinstance(axes, list):
            _fail(f"axes must be three directions, got {axes!r}", "axes", axes)
        tables = {}
        for key in ("landmarks", "simulate"):
            table = data.get(key, {})
            if not isinstance(table, dict):
                _fail(f"{key} must be a table, got {table!r}", key, table)
            tables[key] = tuple((k, parse_rule(v, f"{key}.{k}")) for k, v in table.items())
        body = data.get("body", "")
        if not isinstance(body, str):
            _fail(f"body must be a format's name, got {body!r}", "body", body)
        return cls(
            name=_require(data, "name", str, "a string"),
            title=_require(data, "title", str, "a string"),
            joints=tuple(names),
            parents=tuple(parents),
            bone_bounds_m=tuple(bounds),
            mirror_pairs=tuple(tuple(p) if isinstance(p, list) else p for p in pairs),
            torso=tuple(_require(data, "torso", list, "an array of joint names")),
            groups=tuple((g, tuple(roles.items())) for g, roles in groups.items()),
            sensor=CameraSpec(
                **{k: tuple(v) if isinstance(v, list) else v for k, v in sensor.items()}  # type: ignore[arg-type]
            ),
            tracking_states=tuple(states.items()),
            unit_m=UNITS_M[units],
            axes=tuple(axes),
            confidence=Confidence.from_mapping(data.get("confidence", {})),
            body=body,
            landmarks=tables["landmarks"],
            simulate=tables["simulate"],
        )


def read_toml(path: str | Path) -> dict:
    """The parsed TOML file at ``path`` (bounded to :data:`MAX_FORMAT_FILE_BYTES`), or a
    :class:`SkeletonFormatError` naming the file."""
    try:
        return read_toml_file(path, MAX_FORMAT_FILE_BYTES)
    except NotTOMLError as exc:
        raise SkeletonFormatError(f"{path}: not TOML: {one_line(exc)}", path=path) from None
    except (OSError, ValueError) as exc:
        raise SkeletonFormatError(
            f"{path}: cannot read the file: {one_line(exc)}", path=path
        ) from None


def _fail(message: str, name: str, value: object) -> NoReturn:
    raise SkeletonFormatError(message, name=name, value=value)


def _require(data: Mapping[str, object], key: str, kind: type, what: str, prefix: str = "") -> Any:
    """``data[key]``, which must be a ``kind`` (``what`` in the message)."""
    if key not in data:
        _fail(f"{prefix}{key} is missing (expected {what})", f"{prefix}{key}", None)
    value = data[key]
    if not isinstance(value, kind):
        _fail(f"{prefix}{key} must be {what}, got {value!r}", f"{prefix}{key}", value)
    return value


def _pair(value: object) -> bool:
    return isinstance(value, tuple) and len(value) == 2 and all(is_number(v) for v in value)


def _frozen(values: object, dtype: type) -> np.ndarray:
    """A read-only array: shared by every user of the format, written by none."""
    out: np.ndarray = np.array(values, dtype=dtype)
    out.setflags(write=False)
    return out
