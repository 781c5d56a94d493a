"""Skeleton formats as data: what a body-tracking sensor's skeletons are made of.

A :class:`SkeletonFormat` says what the library needs to know of a sensor's skeletons,
as mmpose's dataset configs do for their keypoints: the joints' names in the sensor's
order (a joint's id is its row in a frame), each joint's parent, the left/right pairs,
the torso joints, the tracking-state codes, the longest plausible bone per joint, joints
by role (:meth:`SkeletonFormat.group`), and the sensor's frame rate, latency, noise,
field of view, range and bodies per sensor (:class:`~qpavoid.human.camera_spec.CameraSpec`).
It is read from a TOML file (:meth:`SkeletonFormat.load`, the file's shape checked by
:mod:`qpavoid.human.skeleton_file`; ``formats/kinect_v2.toml`` is the Kinect v2's, loaded
by :mod:`qpavoid.human.kinect_v2`) and checked when built: a wrong file is refused with a
:class:`SkeletonFormatError` naming the file, the key and the offending value.

The code sizes its arrays from a format (:attr:`SkeletonFormat.n_joints`) and addresses
joints through it (:attr:`~SkeletonFormat.parent`, :attr:`~SkeletonFormat.mirror`,
:meth:`~SkeletonFormat.group`), never by a literal joint count or index.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from pathlib import Path
from typing import NoReturn

import numpy as np

from qpavoid.core.errors import InputError, SkeletonFormatError
from qpavoid.human.camera_spec import CameraSpec
from qpavoid.human.conversion import Confidence, LandmarkRule, is_number
from qpavoid.human.skeleton_file import UNITS_M, format_fields, read_toml

__all__ = [
    "AXIS_DIRECTIONS",
    "INFERRED",
    "NOT_TRACKED",
    "TRACKED",
    "TRACKING_STATES",
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
#: The directions a camera's axes may point, as seen from the camera.
AXIS_DIRECTIONS = {
    "right": (1.0, 0.0, 0.0),
    "left": (-1.0, 0.0, 0.0),
    "down": (0.0, 1.0, 0.0),
    "up": (0.0, -1.0, 0.0),
    "forward": (0.0, 0.0, 1.0),
    "backward": (0.0, 0.0, -1.0),
}


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
        The camera's numbers (:class:`~qpavoid.human.camera_spec.CameraSpec`, the file's
        ``[sensor]`` table).
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
        """The format of a parsed format file (the keys of :meth:`load`; their shape
        checked by :func:`~qpavoid.human.skeleton_file.format_fields`)."""
        return cls(**format_fields(data))


def _fail(message: str, name: str, value: object) -> NoReturn:
    raise SkeletonFormatError(message, name=name, value=value)


def _frozen(values: object, dtype: type) -> np.ndarray:
    """A read-only array: shared by every user of the format, written by none."""
    out: np.ndarray = np.array(values, dtype=dtype)
    out.setflags(write=False)
    return out
