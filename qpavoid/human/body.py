"""The human: Kinect v2 skeleton joints and the paper's upper-body model (Sect. 4).

The Kinect v2 gives 25 joints, each with a tracking state. The paper keeps the upper
body: 8 parts, 21 points (13 Kinect joints plus one mid-point per part). Each part is
covered by spheres of one radius centred on its points (eq. 1) and, for the exact method,
by one capsule along its chain of joints.

A joint is *usable* when its coordinates are finite and its state is not NotTracked
(Inferred joints are used, as the Kinect SDK's consumers usually do). A mid-point is
usable when both its ends are. A part whose points are all unusable is left out of the
distances (distance +inf), so a lost limb never becomes a NaN command; the controller's
:class:`~qpavoid.perception.tracker.Tracker` keeps a lost joint at its last known position instead,
with an uncertainty radius that :meth:`KinectHuman.geometry` adds to the part's radius.

The fingers (HandTip, Thumb) are the hands' *reach* joints: not model points (the paper's
21 points and spheres stay as published), but the capsule method widens a hand's capsule
by however far they stick out of it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from qpavoid.core.compiling import kernel_input
from qpavoid.human._kernels import tracked_body, warm_up
from qpavoid.human.frames import N_KINECT_JOINTS, HumanFrame, JointType, TrackingState

__all__ = [
    "N_KINECT_JOINTS",
    "UPPER_BODY",
    "BodyPart",
    "HumanFrame",
    "HumanGeometry",
    "JointType",
    "KinectHuman",
    "TrackingState",
]


J = JointType

#: Order of the Kinect joints among the model points (spine up, then left and right arm).
POINT_ORDER = (
    J.SpineBase,
    J.SpineMid,
    J.SpineShoulder,
    J.Neck,
    J.Head,
    J.ShoulderLeft,
    J.ElbowLeft,
    J.WristLeft,
    J.HandLeft,
    J.ShoulderRight,
    J.ElbowRight,
    J.WristRight,
    J.HandRight,
)


@dataclass(frozen=True)
class BodyPart:
    """One part of the upper-body model.

    Attributes
    ----------
    name
        Part name.
    chain
        Kinect joints along the part, proximal first. The capsule runs between the first
        and the last usable joint of the chain.
    mid
        The two joints whose mid-point is the part's extra point (paper Fig. 3).
    sphere_radius_m
        Radius r_j of the part's spheres (eq. 1), m.
    capsule_radius_m
        Radius of the part's capsule (exact method), m.
    reach
        Joints beyond the chain that the capsule must cover (a hand's HandTip and Thumb):
        the capsule is widened, each frame, by how far they stick out of it.
    """

    name: str
    chain: tuple[JointType, ...]
    mid: tuple[JointType, JointType]
    sphere_radius_m: float
    capsule_radius_m: float
    reach: tuple[JointType, ...] = ()


def _arm(
    side: str,
    shoulder: JointType,
    elbow: JointType,
    wrist: JointType,
    hand: JointType,
    fingers: tuple[JointType, JointType],
) -> tuple[BodyPart, ...]:
    # Sphere radii cover the capsule between consecutive points (spacing h):
    # r_sphere >= sqrt(r_capsule^2 + (h/2)^2), with h about 0.14 m (upper arm),
    # 0.125 m (forearm) and 0.045 m (hand) for an adult skeleton.
    return (
        BodyPart(f"{side}_upper_arm", (shoulder, elbow), (shoulder, elbow), 0.09, 0.055),
        BodyPart(f"{side}_forearm", (elbow, wrist), (elbow, wrist), 0.08, 0.045),
        BodyPart(f"{side}_hand", (wrist, hand), (wrist, hand), 0.06, 0.05, fingers),
    )


#: The paper's eight parts, in the order of the distance tables' columns.
UPPER_BODY: tuple[BodyPart, ...] = (
    BodyPart("head", (J.Neck, J.Head), (J.Neck, J.Head), 0.11, 0.10),
    # The trunk's extra point is on the chest (SpineShoulder-SpineMid), the part of the
    # trunk at the height of the robot's links when the operator sits at the table.
    BodyPart(
        "trunk",
        (J.SpineShoulder, J.SpineMid, J.SpineBase),
        (J.SpineShoulder, J.SpineMid),
        0.17,
        0.15,
    ),
    *_arm(
        "left", J.ShoulderLeft, J.ElbowLeft, J.WristLeft, J.HandLeft, (J.HandTipLeft, J.ThumbLeft)
    ),
    *_arm(
        "right",
        J.ShoulderRight,
        J.ElbowRight,
        J.WristRight,
        J.HandRight,
        (J.HandTipRight, J.ThumbRight),
    ),
)


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
class KinectHuman:
    """The upper-body model on top of a Kinect v2 skeleton.

    Parameters
    ----------
    parts
        The body parts, in table-column order (default: the paper's eight).

    Attributes
    ----------
    joint_ids
        (13,) Kinect joints used as points, in point order.
    point_part
        (M, K) bool, True where point m belongs to part k.
    """

    parts: tuple[BodyPart, ...] = UPPER_BODY
    joint_ids: np.ndarray = field(init=False, repr=False)
    point_part: np.ndarray = field(init=False, repr=False)
    _mid_ids: np.ndarray = field(init=False, repr=False)
    _chains: np.ndarray = field(init=False, repr=False)
    _members: np.ndarray = field(init=False, repr=False)
    _reach: np.ndarray = field(init=False, repr=False)
    _radii: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        members = np.zeros((len(self.parts), N_KINECT_JOINTS), dtype=bool)
        for k, p in enumerate(self.parts):
            members[k, [int(j) for j in (*p.chain, *p.mid, *p.reach)]] = True
        object.__setattr__(self, "_members", members)
        object.__setattr__(self, "_radii", np.array([p.capsule_radius_m for p in self.parts]))
        warm_up()
        reach = [(k, int(j)) for k, p in enumerate(self.parts) for j in p.reach]
        object.__setattr__(self, "_reach", np.array(reach, dtype=int).reshape(-1, 2))
        used = {int(j) for p in self.parts for j in (*p.chain, *p.mid)}
        joints = [int(j) for j in POINT_ORDER if int(j) in used] + sorted(used - set(POINT_ORDER))
        n_points = len(joints) + len(self.parts)
        member = np.zeros((n_points, len(self.parts)), dtype=bool)
        for k, p in enumerate(self.parts):
            for j in p.chain:
                member[joints.index(int(j)), k] = True
            member[len(joints) + k, k] = True
        object.__setattr__(self, "joint_ids", np.array(joints))
        object.__setattr__(self, "point_part", member)
        object.__setattr__(
            self, "_mid_ids", np.array([[int(a), int(b)] for a, b in (p.mid for p in self.parts)])
        )
        width = max(len(p.chain) for p in self.parts)
        object.__setattr__(
            self,
            "_chains",
            np.array(
                [
                    [int(j) for j in p.chain] + [int(p.chain[-1])] * (width - len(p.chain))
                    for p in self.parts
                ]
            ),
        )

    @property
    def part_names(self) -> tuple[str, ...]:
        """Names of the parts, in column order."""
        return tuple(p.name for p in self.parts)

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
        """The model points (21, 3) from (25, 3) Kinect joints, m.

        Rows are the 13 joints (SpineBase, SpineMid, SpineShoulder, Neck, Head, then
        Shoulder, Elbow, Wrist, Hand left and right) followed by the 8 mid-points in part
        order. Unusable points are NaN.
        """
        return self.geometry(joints, state).points

    def tracked_geometry(
        self, frame: HumanFrame, joint_radius: np.ndarray, joint_velocity: np.ndarray
    ) -> tuple[HumanGeometry, np.ndarray]:
        """A tracker's frame (:class:`~qpavoid.perception.tracker.Perceived`) in one compiled call:
        :meth:`geometry` with ``joint_radius`` (25,), m, and each part's velocity (K, 3),
        m/s, that of its fastest joint (:func:`~qpavoid.perception.tracker.part_velocities`).

        Each part's capsule runs between the first and last usable joints of its chain;
        how far the fingers stick out of it widens it (:func:`qpavoid.human._kernels.capsules`)."""
        points, point_valid, segments, segment_valid, reach, margin, velocity = tracked_body(
            kernel_input(frame.joints, np.float64),
            kernel_input(frame.state, np.int8),
            kernel_input(joint_radius, np.float64),
            kernel_input(joint_velocity, np.float64),
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
        """(K, 25) bool: the Kinect joints of each part (chain, mid-point ends and reach)."""
        return self._members.copy()

    def geometry(
        self, joints: object, state: object = None, joint_radius: np.ndarray | None = None
    ) -> HumanGeometry:
        """Points, capsules and their usability at one frame.

        ``joints`` is a :class:`~qpavoid.human.frames.HumanFrame` (already checked: used as is)
        or (25, 3) joints with optional (25,) states (checked here). ``joint_radius``
        (25,), m, is each joint's position uncertainty (default 0); a part's
        ``part_margin`` is the largest of its joints'.
        """
        frame = HumanFrame.check(joints, state)
        radius = np.zeros(N_KINECT_JOINTS) if joint_radius is None else joint_radius
        return self.tracked_geometry(frame, radius, np.zeros((N_KINECT_JOINTS, 3)))[0]
