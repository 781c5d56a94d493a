"""The human: the paper's upper-body model (Sect. 4) on a skeleton, as data.

A body model is parts of a skeleton format's joints (:class:`BodyPart`): each part is
covered by spheres of one radius centred on its points (eq. 1) and, for the exact
method, by one capsule along its chain of joints. :class:`BodyModel` is any such model
(:meth:`BodyModel.load` reads one from a TOML file); :class:`KinectHuman` is the paper's
on the Kinect v2 (``formats/kinect_v2_body.toml``): 8 parts, 21 points (13 joints plus
one mid-point per part).

A joint is *usable* when its coordinates are finite and its state is not NotTracked
(Inferred joints are used, as the Kinect SDK's consumers usually do). A mid-point is
usable when both its ends are. A part whose points are all unusable is left out of the
distances (distance +inf), so a lost limb never becomes a NaN command; the controller's
:class:`~qpavoid.perception.tracker.Tracker` keeps a lost joint at its last known position
instead, with an uncertainty radius that :meth:`BodyModel.geometry` adds to the part's
radius.

A part's *reach* joints (a hand's fingers: HandTip, Thumb) are not model points (the
paper's 21 points and spheres stay as published), but the capsule method widens the
part's capsule by however far they stick out of it.

A model's *centres* are points of its own format's joints that no joint is (the middle of
the shoulders for a camera without a spine joint): each is the mean of its joints, usable
when all of them are, as uncertain as the most uncertain of them (a mean of points each
within r of the truth is within r of the true mean) and moving at the mean of their
velocities. Parts name them as they name joints. Each camera's body model is on its own
joints (``formats/<format>_body.toml``, :func:`body_model`): nothing is mapped from
another format, so nothing is widened for a mapping.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from qpavoid.core.compiling import kernel_input
from qpavoid.core.errors import SkeletonFormatError
from qpavoid.human._kernels import append_centres, tracked_body, warm_up
from qpavoid.human.frames import HumanFrame
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import skeleton_format
from qpavoid.human.skeleton import FORMATS_DIR, SkeletonFormat, read_toml

__all__ = [
    "KINECT_V2_BODY_FILE",
    "KINECT_V2_BODY_PARTS",
    "UPPER_BODY",
    "BodyModel",
    "BodyPart",
    "HumanGeometry",
    "KinectHuman",
    "body_model",
]

#: A joint of a part: its name in the skeleton format, or its id (row).
Joint = str | int

#: The paper's model on the Kinect v2.
KINECT_V2_BODY_FILE = FORMATS_DIR / "kinect_v2_body.toml"
#: A part's radius, m: a finger is 1 cm thick; a capsule over 1 m wide covers no body part.
MIN_RADIUS_M, MAX_RADIUS_M = 0.01, 1.0

_BODY_KEYS = ("format", "points", "centres", "parts")
_PART_KEYS = (
    "name",
    "chain",
    "mid",
    "sphere_radius_m",
    "capsule_radius_m",
    "reach",
    "moves_with_body",
    "region",
)


@dataclass(frozen=True)
class BodyPart:
    """One part of an upper-body model.

    Attributes
    ----------
    name
        Part name.
    chain
        Joints along the part, proximal first (names in the skeleton format, or ids). The
        capsule runs between the first and the last usable joint of the chain.
    mid
        The two joints whose mid-point is the part's extra point (paper Fig. 3).
    sphere_radius_m
        Radius r_j of the part's spheres (eq. 1), m.
    capsule_radius_m
        Radius of the part's capsule (exact method), m.
    reach
        Joints beyond the chain that the capsule must cover (a hand's HandTip and Thumb):
        the capsule is widened, each frame, by how far they stick out of it.
    moves_with_body
        The part moves with the body, not the arm (the head and trunk of a seated
        person): speed and separation monitoring gives it the body's approach speed.
        Default False: an arm's part, the faster case.
    region
        The ISO/TS 15066 Annex A body region the part is (a name of
        ``qpavoid/laws/body_regions.toml``, e.g. ``"hand_finger"``): power and force limiting
        takes its limits from it (:mod:`qpavoid.laws.pfl`). None (the default): no region.
    """

    name: str
    chain: tuple[Joint, ...]
    mid: tuple[Joint, Joint]
    sphere_radius_m: float
    capsule_radius_m: float
    reach: tuple[Joint, ...] = ()
    moves_with_body: bool = False
    region: str | None = None


@dataclass(frozen=True)
class HumanGeometry:
    """The human's points and capsules at one camera frame (what the distances need).

    Attributes
    ----------
    points
        (M, 3) model points, m; rows of unusable points are NaN.
    point_valid
        (M,) True where the point is usable.
    segments
        (K, 2, 3) capsule axis of each part, m; NaN for a part with no usable joint.
    segment_valid
        (K,) True where the part has at least one usable joint.
    part_margin
        (K,) uncertainty added to each part's radius in both methods, m: the largest
        uncertainty radius of its joints (lost or inferred joints, see
        :class:`~qpavoid.perception.tracker.Tracker`); zeros if not given.
    reach_margin
        (K,) how far a part's reach joints (the fingers) stick out of its capsule, m;
        added to the capsule radius by the capsule method only.
    filled_points, point_penalty
        Derived: ``points`` with unusable rows set to 0, and 0 / +inf per point.
    """

    points: np.ndarray
    point_valid: np.ndarray
    segments: np.ndarray
    segment_valid: np.ndarray
    part_margin: np.ndarray | None = None
    reach_margin: np.ndarray | None = None

    def __post_init__(self) -> None:
        zeros = np.zeros(len(self.segments))
        for name in ("part_margin", "reach_margin"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, zeros)

    # For vectorised distances: unusable points at the origin, with +inf added to any
    # distance to them (so they never win a minimum and never make a NaN).
    @cached_property
    def filled_points(self) -> np.ndarray:
        """``points`` with unusable rows set to 0, m."""
        return np.where(self.point_valid[:, None], self.points, 0.0)

    @cached_property
    def point_penalty(self) -> np.ndarray:
        """(M,) 0 for a usable point, +inf for the others."""
        return np.where(self.point_valid, 0.0, np.inf)


@dataclass(frozen=True)
class BodyModel:
    """An upper-body model on a skeleton format.

    Parameters
    ----------
    parts
        The body parts, in table-column order.
    skeleton
        The skeleton format their joints belong to.
    point_order
        Joints that are model points, in point order; a part's chain joint missing here
        comes after them, in format order. The parts' mid-points follow, in part order.
    centres
        ``(name, joints)`` pairs: points that are the mean of two or more of the format's
        joints (module docstring); parts and ``point_order`` name them as joints.

    Attributes
    ----------
    joint_ids
        (P,) the joints used as points, in point order.
    point_part
        (M, K) bool, True where point m belongs to part k.

    Raises
    ------
    SkeletonFormatError
        For a part that names a joint the format does not have, two parts of one name, a
        radius that is not a positive number, or a region that is not a name (whether the
        region table has it is :mod:`qpavoid.laws.pfl`'s to check).
    """

    parts: tuple[BodyPart, ...]
    skeleton: SkeletonFormat
    point_order: tuple[Joint, ...] = ()
    centres: tuple[tuple[str, tuple[Joint, ...]], ...] = ()
    # derived in __post_init__ (not compared: two models of the same parts are equal)
    joint_ids: np.ndarray = field(init=False, repr=False, compare=False)
    point_part: np.ndarray = field(init=False, repr=False, compare=False)
    _mid_ids: np.ndarray = field(init=False, repr=False, compare=False)
    _chains: np.ndarray = field(init=False, repr=False, compare=False)
    _members: np.ndarray = field(init=False, repr=False, compare=False)
    _reach: np.ndarray = field(init=False, repr=False, compare=False)
    _radii: np.ndarray = field(init=False, repr=False, compare=False)
    _centre_of: np.ndarray = field(init=False, repr=False, compare=False)
    _centre_ids: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        parts, skeleton = self.parts, self.skeleton
        self._check_parts()
        object.__setattr__(self, "_centre_of", self._read_centres())
        width = max([int(row.sum()) for row in self._centre_of], default=1)
        ids = np.full((len(self._centre_of), width), -1, dtype=np.int64)
        for c, row in enumerate(self._centre_of):  # the kernel's form: ids, padded with -1
            ids[c, : row.sum()] = np.flatnonzero(row)
        object.__setattr__(self, "_centre_ids", ids)
        chains = [[self._joint(j, f"{p.name}.chain") for j in p.chain] for p in parts]
        mids = [[self._joint(j, f"{p.name}.mid") for j in p.mid] for p in parts]
        reaches = [[self._joint(j, f"{p.name}.reach") for j in p.reach] for p in parts]
        order = [self._joint(j, "point_order") for j in self.point_order]
        members = np.zeros((len(parts), self.n_nodes), dtype=bool)
        for k in range(len(parts)):
            members[k, [*chains[k], *mids[k], *reaches[k]]] = True
        n = skeleton.n_joints  # a centre's joints are its parts' too (the fastest of them)
        members[:, :n] |= (members[:, n:].astype(int) @ self._centre_of) > 0
        self._check_one_tree(np.asarray(members[:, :n].any(axis=0)))
        used = {j for k in range(len(parts)) for j in (*chains[k], *mids[k])}
        joints = [j for j in order if j in used] + sorted(used - set(order))
        member = np.zeros((len(joints) + len(parts), len(parts)), dtype=bool)
        for k in range(len(parts)):
            for j in chains[k]:
                member[joints.index(j), k] = True
            member[len(joints) + k, k] = True
        width = max(len(c) for c in chains)
        padded = [c + [c[-1]] * (width - len(c)) for c in chains]
        reach = [(k, j) for k in range(len(parts)) for j in reaches[k]]
        for name, value in (
            ("_members", members),
            ("_radii", np.array([p.capsule_radius_m for p in parts], dtype=np.float64)),
            ("_reach", np.array(reach, dtype=np.int64).reshape(-1, 2)),
            ("joint_ids", np.array(joints, dtype=np.int64)),
            ("point_part", member),
            ("_mid_ids", np.array(mids, dtype=np.int64)),
            ("_chains", np.array(padded, dtype=np.int64)),
        ):
            object.__setattr__(self, name, value)
        warm_up(skeleton)

    def _check_parts(self) -> None:
        if not self.parts:
            raise SkeletonFormatError("a body model needs parts", name="parts", value=self.parts)
        names = [p.name for p in self.parts]
        for p in self.parts:
            if not isinstance(p.name, str) or not p.name.strip():
                raise SkeletonFormatError(
                    f"a part's name must be a non-empty string, got {p.name!r}",
                    name="parts",
                    value=p.name,
                )
            if names.count(p.name) > 1:
                raise SkeletonFormatError(
                    f"two parts are called {p.name!r}", name="parts", value=names
                )
            for key in ("sphere_radius_m", "capsule_radius_m"):
                r = getattr(p, key)
                if not isinstance(r, (int, float)) or isinstance(r, bool) or not r > 0:
                    raise SkeletonFormatError(
                        f"part {p.name!r}: {key} must be a number > 0, m, got {r!r}",
                        name=f"{p.name}.{key}",
                        value=r,
                    )
                if not math.isfinite(r):
                    raise SkeletonFormatError(
                        f"part {p.name!r}: {key} is {r!r}", name=f"{p.name}.{key}", value=r
                    )
                if not MIN_RADIUS_M <= r <= MAX_RADIUS_M:
                    raise SkeletonFormatError(
                        f"part {p.name!r}: {key} must be between {MIN_RADIUS_M} and "
                        f"{MAX_RADIUS_M} m (a body part's), got {r!r}",
                        name=f"{p.name}.{key}",
                        value=r,
                    )
            if p.region is not None and (not isinstance(p.region, str) or not p.region.strip()):
                raise SkeletonFormatError(
                    f"part {p.name!r}: region must name a body region (text) or be absent, "
                    f"got {p.region!r}",
                    name=f"{p.name}.region",
                    value=p.region,
                )
            if not p.chain or len(p.mid) != 2:
                raise SkeletonFormatError(
                    f"part {p.name!r} needs a chain of joints and two mid joints, got chain "
                    f"{p.chain!r} and mid {p.mid!r}",
                    name=f"{p.name}.chain",
                    value=(p.chain, p.mid),
                )

    def _check_one_tree(self, used: np.ndarray) -> None:
        """The joints the parts use are all in one tree of the format's parents: the
        tracker bounds a joint never seen by the nearest seen joint along the tree, and a
        joint in a tree of its own would be bounded by nothing (a part would shrink)."""
        skeleton = self.skeleton
        roots: dict[str, str] = {}  # root: the first joint found in its tree
        for j in np.flatnonzero(used):
            r = int(j)
            while skeleton.parent[r] >= 0:
                if not skeleton.bone_bounds_m[r] > 0.0:  # a bone of unknown length
                    raise SkeletonFormatError(
                        f"joint {skeleton.joints[r]!r} of the {skeleton.name} format has a "
                        "parent but no max_bone_m: a joint never seen through it would be "
                        "bounded by nothing (the body's parts use it)",
                        name="max_bone_m",
                        value=skeleton.joints[r],
                    )
                r = int(skeleton.parent[r])
            roots.setdefault(skeleton.joints[r], skeleton.joints[int(j)])
        if len(roots) > 1:
            raise SkeletonFormatError(
                f"the body's joints are in {len(roots)} trees of the {skeleton.name} format "
                f"(rooted at {', '.join(roots)}): a joint never seen is bounded only by the "
                "seen joints of its tree; give the roots parents in the format file",
                name="parts",
                value=sorted(roots),
            )

    def _read_centres(self) -> np.ndarray:
        """(C, J) bool: the joints each centre is the mean of, checked."""
        skeleton, names = self.skeleton, [name for name, _ in self.centres]
        out = np.zeros((len(self.centres), skeleton.n_joints), dtype=bool)
        for c, (name, joints) in enumerate(self.centres):
            key = f"centres.{name}"
            if not isinstance(name, str) or not name.strip() or name in skeleton.joints:
                raise SkeletonFormatError(
                    f"{key}: a centre needs a name that is no joint of the {skeleton.name} "
                    f"format, got {name!r}",
                    name=key,
                    value=name,
                )
            if names.count(name) > 1:
                raise SkeletonFormatError(f"two centres are called {name!r}", name=key, value=names)
            ids = [self._joint(j, key, centres=False) for j in joints]
            if len(set(ids)) != len(ids):
                raise SkeletonFormatError(
                    f"{key}: a joint is named twice in {list(joints)!r} (the mean weighs each "
                    "joint once)",
                    name=key,
                    value=list(joints),
                )
            if len(set(ids)) < 2:
                raise SkeletonFormatError(
                    f"{key}: a centre is the mean of two or more different joints, got "
                    f"{list(joints)!r}",
                    name=key,
                    value=list(joints),
                )
            out[c, ids] = True
        return out

    @property
    def n_nodes(self) -> int:
        """The format's joints and then the model's centres: the rows the kernels see."""
        return self.skeleton.n_joints + len(self.centres)

    def _joint(self, joint: Joint, key: str, centres: bool = True) -> int:
        """The id of ``joint`` (a name or an id) in the format, a centre's (after the
        format's joints), or SkeletonFormatError."""
        skeleton = self.skeleton
        if isinstance(joint, str) and joint in skeleton.joints:
            return skeleton.index(joint)
        names = [name for name, _ in self.centres]
        if centres and isinstance(joint, str) and joint in names:
            return skeleton.n_joints + names.index(joint)
        is_id = isinstance(joint, (int, np.integer)) and not isinstance(joint, bool)
        if is_id and 0 <= int(joint) < skeleton.n_joints:
            return int(joint)
        raise SkeletonFormatError(
            f"{key}: {joint!r} is not a joint of the {skeleton.name} format"
            + (f" nor a centre of the model ({names})" if centres and names else "")
            + f"; its joints are {list(skeleton.joints)}",
            name=key,
            value=joint,
        )

    @classmethod
    def load(cls, path: str | Path, skeleton: SkeletonFormat | None = None) -> BodyModel:
        """The body model of the TOML file at ``path`` (``formats/kinect_v2_body.toml``
        shows the keys, each with its meaning).

        Parameters
        ----------
        path
            The body file; its ``format`` key names the skeleton format, a file
            ``<format>.toml`` beside it.
        skeleton
            That format, if already loaded (it must have the name the file gives).

        Raises
        ------
        SkeletonFormatError
            For a file that cannot be read, is not TOML, lacks a key or has an unknown
            one, or names a joint its format does not have; the message names the file.
        """
        points, parts, format_name, centres = read_body_file(path)
        if skeleton is None:
            try:
                skeleton = SkeletonFormat.load(Path(path).with_name(f"{format_name}.toml"))
            except SkeletonFormatError as exc:
                raise SkeletonFormatError(
                    f"{path}: its format {format_name!r}: {exc}",
                    path=path,
                    name=f"format: {exc.name}" if exc.name else "format",
                    value=exc.value if exc.name else format_name,
                ) from None
        if skeleton.name != format_name:
            raise SkeletonFormatError(
                f"{path}: the body is on the {format_name!r} format, not {skeleton.name!r}",
                path=path,
                name="format",
                value=format_name,
            )
        try:
            return cls(parts, skeleton, points, centres)
        except SkeletonFormatError as exc:
            raise SkeletonFormatError(
                f"{path}: {exc}", path=path, name=exc.name, value=exc.value
            ) from None

    @property
    def part_names(self) -> tuple[str, ...]:
        """Names of the parts, in column order."""
        return tuple(p.name for p in self.parts)

    @property
    def body_parts(self) -> tuple[str, ...]:
        """Names of the parts that move with the body (:attr:`BodyPart.moves_with_body`)."""
        return tuple(p.name for p in self.parts if p.moves_with_body)

    @property
    def regions(self) -> tuple[str | None, ...]:
        """Each part's ISO/TS 15066 body region (:attr:`BodyPart.region`), None where the
        part names none; power and force limiting's ``part_regions``
        (:meth:`qpavoid.laws.pfl.PFLConfig.part_limits`)."""
        return tuple(p.region for p in self.parts)

    @property
    def sphere_radii(self) -> np.ndarray:
        """(K,) sphere radius of each part, m."""
        return np.array([p.sphere_radius_m for p in self.parts])

    @property
    def capsule_radii(self) -> np.ndarray:
        """(K,) capsule radius of each part, m."""
        return np.array([p.capsule_radius_m for p in self.parts])

    @property
    def n_points(self) -> int:
        """Number of model points (21 for the paper's model)."""
        return self.point_part.shape[0]

    def points(self, joints: object, state: object = None) -> np.ndarray:
        """The model points (M, 3) from a frame's (J, 3) joints, m.

        Rows are the joints of :attr:`joint_ids` (for the paper's model SpineBase,
        SpineMid, SpineShoulder, Neck, Head, then Shoulder, Elbow, Wrist, Hand left and
        right) followed by the mid-points in part order. Unusable points are NaN.
        """
        return self.geometry(joints, state).points

    def tracked_geometry(
        self, frame: HumanFrame, joint_radius: np.ndarray, joint_velocity: np.ndarray
    ) -> tuple[HumanGeometry, np.ndarray]:
        """A tracker's frame (:class:`~qpavoid.perception.tracker.Perceived`) in one compiled call:
        :meth:`geometry` with ``joint_radius`` (J,), m, and each part's velocity (K, 3),
        m/s, that of its fastest joint (:func:`~qpavoid.perception.tracker.part_velocities`).

        Each part's capsule runs between the first and last usable joints of its chain;
        how far the fingers stick out of it widens it (:func:`qpavoid.human._kernels.capsules`)."""
        rows = (
            kernel_input(frame.joints, np.float64),
            kernel_input(frame.state, np.int8),
            kernel_input(joint_radius, np.float64),
            kernel_input(joint_velocity, np.float64),
        )
        if self.centres:  # their rows after the frame's (module docstring)
            rows = append_centres(*rows, self._centre_ids)
        points, point_valid, segments, segment_valid, reach, margin, velocity = tracked_body(
            *rows,
            self.joint_ids,
            self._mid_ids,
            self._chains,
            self._reach,
            self._radii,
            self._members,
        )
        geometry = HumanGeometry(points, point_valid, segments, segment_valid, margin, reach)
        return geometry, velocity

    def part_joints(self) -> np.ndarray:
        """(K, J) bool: the joints of each part (chain, mid-point ends and reach; a centre's
        joints for a part that names the centre)."""
        return self._members[:, : self.skeleton.n_joints].copy()

    def geometry(
        self, joints: object, state: object = None, joint_radius: np.ndarray | None = None
    ) -> HumanGeometry:
        """Points, capsules and their usability at one frame.

        ``joints`` is a :class:`~qpavoid.human.frames.HumanFrame` (already checked: used as is)
        or (J, 3) joints with optional (J,) states (checked here). ``joint_radius``
        (J,), m, is each joint's position uncertainty (default 0); a part's
        ``part_margin`` is the largest of its joints'.
        """
        frame = HumanFrame.check(joints, state, self.skeleton)
        n = self.skeleton.n_joints
        radius = np.zeros(n) if joint_radius is None else joint_radius
        return self.tracked_geometry(frame, radius, np.zeros((n, 3)))[0]


def read_body_file(
    path: str | Path,
) -> tuple[tuple[str, ...], tuple[BodyPart, ...], str, tuple[tuple[str, tuple[Joint, ...]], ...]]:
    """The point order, the parts, the format's name and the centres of the body file at
    ``path``.

    Raises
    ------
    SkeletonFormatError
        For a file that cannot be read, is not TOML, or lacks a key or has an unknown one
        (joint names are checked against the format by :class:`BodyModel`).
    """
    data = read_toml(path)

    def fail(message: str, key: str, value: object) -> SkeletonFormatError:
        return SkeletonFormatError(f"{path}: {message}", path=path, name=key, value=value)

    unknown = [k for k in data if k not in _BODY_KEYS]
    if unknown:
        raise fail(
            f"unknown key {unknown[0]}; the keys are {', '.join(_BODY_KEYS)}",
            unknown[0],
            data[unknown[0]],
        )
    format_name, points, rows = data.get("format"), data.get("points", []), data.get("parts")
    if not isinstance(format_name, str):
        raise fail(
            f"format must name a skeleton format, got {format_name!r}", "format", format_name
        )
    if not isinstance(points, list) or not all(isinstance(p, str) for p in points):
        raise fail(f"points must be an array of joint names, got {points!r}", "points", points)
    if len(set(points)) != len(points):
        raise fail(f"points names a joint twice: {points!r}", "points", points)
    if not format_name.replace("_", "").replace("-", "").isalnum():
        raise fail(
            f"format must be a format's name (letters, digits, _ and -), got {format_name!r}",
            "format",
            format_name,
        )
    if not isinstance(rows, list) or not rows:
        raise fail(f"parts must be an array of tables ([[parts]]), got {rows!r}", "parts", rows)
    table = data.get("centres", {})
    if not isinstance(table, dict) or not all(
        isinstance(v, list) and all(isinstance(j, str) for j in v) for v in table.values()
    ):
        raise fail(
            f"centres must be a table of names to arrays of joint names, got {table!r}",
            "centres",
            table,
        )
    centres = tuple((name, tuple(joints)) for name, joints in table.items())
    parts = []
    for k, row in enumerate(rows):
        if not isinstance(row, dict):
            raise fail(f"parts[{k}] must be a table, got {row!r}", f"parts[{k}]", row)
        unknown = [key for key in row if key not in _PART_KEYS]
        missing = [key for key in _PART_KEYS[:5] if key not in row]
        if unknown or missing:
            key = (unknown or missing)[0]
            what = "unknown key" if unknown else "missing key"
            raise fail(
                f"parts[{k}]: {what} {key}; the keys are {', '.join(_PART_KEYS)}",
                f"parts[{k}].{key}",
                row.get(key),
            )
        for key in ("chain", "mid", "reach"):
            joints = row.get(key, [])
            if not isinstance(joints, list) or not all(isinstance(j, str) for j in joints):
                raise fail(
                    f"parts[{k}].{key} must be an array of joint names, got {joints!r}",
                    f"parts[{k}].{key}",
                    joints,
                )
        moves = row.get("moves_with_body", False)
        if not isinstance(moves, bool):
            raise fail(
                f"parts[{k}].moves_with_body must be true or false, got {moves!r}",
                f"parts[{k}].moves_with_body",
                moves,
            )
        region = row.get("region")
        if region is not None and (not isinstance(region, str) or not region.strip()):
            raise fail(
                f"parts[{k}].region must name a body region (text), got {region!r}",
                f"parts[{k}].region",
                region,
            )
        parts.append(
            BodyPart(
                row["name"],
                tuple(row["chain"]),
                tuple(row["mid"]),
                row["sphere_radius_m"],
                row["capsule_radius_m"],
                tuple(row.get("reach", ())),
                moves,
                region,
            )
        )
    return tuple(points), tuple(parts), format_name, centres


_POINTS, _PARTS, _FORMAT, _ = read_body_file(KINECT_V2_BODY_FILE)
if KINECT_V2.name != _FORMAT:
    raise SkeletonFormatError(
        f"{KINECT_V2_BODY_FILE}: the body is on the {_FORMAT!r} format, not {KINECT_V2.name!r}",
        path=KINECT_V2_BODY_FILE,
        name="format",
        value=_FORMAT,
    )

#: The paper's eight parts on the Kinect v2 (``formats/kinect_v2_body.toml``), in the order
#: of the distance tables' columns.
UPPER_BODY: tuple[BodyPart, ...] = _PARTS
#: Those of the paper's parts that move with the body, not the arm (the head and the trunk):
#: speed and separation monitoring's default ``body_parts``.
KINECT_V2_BODY_PARTS: tuple[str, ...] = tuple(p.name for p in UPPER_BODY if p.moves_with_body)


@dataclass(frozen=True)
class KinectHuman(BodyModel):
    """The paper's upper-body model on a Kinect v2 skeleton (``formats/kinect_v2_body.toml``).

    Parameters
    ----------
    parts
        The body parts, in table-column order (default: the paper's eight).
    skeleton
        The skeleton format (default: the Kinect v2's).
    point_order
        The joints that are model points, in point order (default: the file's).
    """

    parts: tuple[BodyPart, ...] = UPPER_BODY
    skeleton: SkeletonFormat = KINECT_V2
    point_order: tuple[Joint, ...] = _POINTS


def body_model(skeleton: str | SkeletonFormat) -> BodyModel:
    """The body model on ``skeleton``'s own joints (the file ``<format>_body.toml`` beside
    the format's file, ``formats/`` for the shipped ones; the Kinect v2's is
    :class:`KinectHuman`), read once per process.

    Parameters
    ----------
    skeleton
        A skeleton format, or its name (``"k4abt"``, one of
        :data:`~qpavoid.human.landmarks.FORMAT_NAMES`) or the path of a camera's own
        format file (``"mycam.toml"``), as :func:`~qpavoid.human.landmarks.skeleton_format`
        takes them.

    Raises
    ------
    InputError
        For a name that is no format, naming the formats.
    SkeletonFormatError
        If the format has no body file, or its body file is wrong (naming the file).
    """
    fmt = skeleton_format(skeleton)
    # keyed on the file too: two equal formats of two folders have two body files
    return _body_model(fmt, fmt.source)


@functools.cache
def _body_model(skeleton: SkeletonFormat, source: str) -> BodyModel:
    """:func:`body_model`, read once per format and file."""
    if skeleton.name == KINECT_V2.name:
        return KinectHuman()
    where = Path(source).parent if source else FORMATS_DIR
    path = where / f"{skeleton.name}_body.toml"
    if not path.is_file():
        raise SkeletonFormatError(
            f"the {skeleton.name} format has no body model ({path.name} beside its file)",
            path=path,
            name="format",
            value=skeleton.name,
        )
    return BodyModel.load(path, skeleton)
