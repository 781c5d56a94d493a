"""The human: the paper's upper-body model (Sect. 4) on a skeleton, as data.

A body model is parts of a skeleton format's joints
(:class:`~qpavoid.human.body_parts.BodyPart`, checked by :mod:`qpavoid.human.body_parts`):
each part is covered by spheres of one radius centred on its points (eq. 1) and, for the
exact method, by one capsule along its chain of joints. :class:`BodyModel` is any such
model (:meth:`BodyModel.load` reads one from a TOML file, its shape checked by
:mod:`qpavoid.human.body_file`); :class:`KinectHuman` is the paper's
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
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from qpavoid.core.compiling import kernel_input
from qpavoid.core.errors import SkeletonFormatError
from qpavoid.human._kernels import append_centres, tracked_body, warm_up
from qpavoid.human.body_file import read_body_file
from qpavoid.human.body_parts import (
    BodyPart,
    Joint,
    centre_joints,
    check_one_tree,
    check_parts,
    joint_id,
)
from qpavoid.human.frames import HumanFrame
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import skeleton_format
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.human.skeleton_file import FORMATS_DIR

__all__ = [
    "KINECT_V2_BODY_FILE",
    "KINECT_V2_BODY_PARTS",
    "UPPER_BODY",
    "BodyModel",
    "HumanGeometry",
    "KinectHuman",
    "body_model",
]

#: The paper's model on the Kinect v2.
KINECT_V2_BODY_FILE = FORMATS_DIR / "kinect_v2_body.toml"


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
        check_parts(parts)
        object.__setattr__(self, "_centre_of", centre_joints(skeleton, self.centres))
        width = max([int(row.sum()) for row in self._centre_of], default=1)
        ids = np.full((len(self._centre_of), width), -1, dtype=np.int64)
        for c, row in enumerate(self._centre_of):  # the kernel's form: ids, padded with -1
            ids[c, : row.sum()] = np.flatnonzero(row)
        object.__setattr__(self, "_centre_ids", ids)
        joint = functools.partial(joint_id, skeleton, self.centres)
        chains = [[joint(j, f"{p.name}.chain") for j in p.chain] for p in parts]
        mids = [[joint(j, f"{p.name}.mid") for j in p.mid] for p in parts]
        reaches = [[joint(j, f"{p.name}.reach") for j in p.reach] for p in parts]
        order = [joint(j, "point_order") for j in self.point_order]
        members = np.zeros((len(parts), self.n_nodes), dtype=bool)
        for k in range(len(parts)):
            members[k, [*chains[k], *mids[k], *reaches[k]]] = True
        n = skeleton.n_joints  # a centre's joints are its parts' too (the fastest of them)
        members[:, :n] |= (members[:, n:].astype(int) @ self._centre_of) > 0
        check_one_tree(skeleton, np.asarray(members[:, :n].any(axis=0)))
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

    @property
    def n_nodes(self) -> int:
        """The format's joints and then the model's centres: the rows the kernels see."""
        return self.skeleton.n_joints + len(self.centres)

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
