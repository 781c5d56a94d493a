"""Frames judged by what they are: lost and inferred joints, frozen frames, the person's speed.

The controller sees the person only through camera frames. :class:`Tracker` turns the
stream of frames into what the distances may trust (:class:`Perceived`):

* **A joint that stops being tracked does not vanish.** It stays at its last known
  position with an uncertainty radius growing at the largest human speed
  (``max_human_speed_mps``, ISO 13855's 2.0 m/s) since it was last seen.
* **Inferred joints** (the SDK's guesses for occluded joints) carry
  ``inferred_uncertainty_m`` plus the same growth since the joint was last Tracked: an
  Inferred joint that has not moved for a second is a second old.
* **Every joint not tracked now, lost, Inferred or never seen at all, is within the reach
  of its nearest tracked ancestor**: the bones between, each at the longest it has been
  seen or the format's bound (:attr:`~qpavoid.human.skeleton.SkeletonFormat.max_bone_m`),
  whichever is larger (a Kinect folds a forearm onto the elbow
  just before losing the hand; that frame must not shrink the reach). Where that bound is
  the tighter one the joint is placed at the ancestor with the reach as its radius (a
  hand never seen, under a tracked shoulder, is a ball of an arm's length there). The
  distances widen each part by the largest radius of its joints, so a hidden limb pushes
  the robot away or stops it instead of disappearing; an Inferred hand is bounded too,
  so it cannot stop the robot for good. A joint with nothing tracked above it and never
  seen stays missing (nothing to bound it by).
* **Frozen frames**: a real depth sensor never repeats a skeleton bit for bit;
  ``identical`` counts consecutive bit-identical skeletons and the controller treats more
  than ``max_identical_frames`` as stale.
* **Out-of-order frames** (a capture time not after the last one) are ignored.
* **The person's velocity**, per joint, from an α-β filter on the frames' positions and
  capture times (:mod:`qpavoid.human.alpha_beta`, the fusion's too; docs/safety.md
  measures its lag and noise), and per part as the velocity of its fastest joint.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from qpavoid.core.compiling import kernel_input
from qpavoid.core.errors import InputError
from qpavoid.human._kernels import fastest_joint
from qpavoid.human.frames import HumanFrame
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.perception._kernels import track, warm_up


@dataclass(frozen=True)
class PerceptionConfig:
    """How much the controller trusts a frame.

    Attributes
    ----------
    max_human_speed_mps
        How fast a lost joint's uncertainty grows, m/s (ISO 13855: 2.0 m/s for hands and
        arms within 0.5 m).
    inferred_uncertainty_m
        Uncertainty of an Inferred joint, m, on top of its growth since last Tracked
        (docs/safety.md: the error of inferred joints is several times that of tracked ones).
    max_identical_frames
        More consecutive bit-identical skeletons than this, each with a usable joint, are
        a frozen sensor (stale);
        None switches the check off (for a perfect simulated sensor, whose still person
        is bit-identical). Default 3: 0.1 s at 30 Hz.
    velocity_alpha, velocity_beta
        Gains of the α-β velocity filter (position and velocity correction).
    landmark_uncertainty_m
        (J,) how far each of the body's landmarks may be from where the cell's cameras put
        it, m, added to its uncertainty radius: a landmark a camera's format lacks and
        derives (:attr:`~qpavoid.human.landmarks.LandmarkMap.uncertainty_m`; MediaPipe's
        neck, a hand tip it does not see). Empty (the default): none, every landmark is
        one the camera measures (the Kinect v2).
    """

    max_human_speed_mps: float = 2.0
    inferred_uncertainty_m: float = 0.10
    max_identical_frames: int | None = 3
    velocity_alpha: float = 0.5
    velocity_beta: float = 0.3
    landmark_uncertainty_m: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        extra = self.landmark_uncertainty_m
        if extra and not all(
            isinstance(u, (int, float)) and math.isfinite(u) and 0.0 <= u <= 0.5 for u in extra
        ):
            raise InputError(
                "landmark_uncertainty_m must be numbers in [0, 0.5] m, one per landmark",
                name="landmark_uncertainty_m",
                value=extra,
            )


class Perceived(NamedTuple):
    """What the controller may trust of the latest frame.

    Attributes
    ----------
    frame
        The frame with every joint ever seen at its best known position (lost joints
        filled in and flagged Inferred).
    joint_radius
        (J,) uncertainty of each joint, m (0 for a tracked joint).
    joint_velocity
        (J, 3) filtered velocity of each joint, m/s (0 where unknown).
    identical
        How many frames in a row repeated the previous skeleton bit for bit.
    capture_time_s
        Capture time of the newest frame accepted, s (the caller's clock).
    """

    frame: HumanFrame
    joint_radius: np.ndarray
    joint_velocity: np.ndarray
    identical: int
    capture_time_s: float

    @classmethod
    def untracked(cls, frame: HumanFrame) -> Perceived:
        """A frame taken as it is (no memory, no uncertainty, no velocity)."""
        n = frame.joints.shape[0]
        return cls(frame, np.zeros(n), np.zeros((n, 3)), 0, float("nan"))


class Tracker:
    """Memory of the person across frames (one per controller; :meth:`update` per frame).

    Parameters
    ----------
    cfg
        How much to trust a frame.
    skeleton
        The frames' skeleton format (its joints, parents and bone bounds).
    """

    def __init__(self, cfg: PerceptionConfig | None = None, skeleton: SkeletonFormat = KINECT_V2):
        self.cfg = cfg or PerceptionConfig()
        self.skeleton = skeleton
        n = skeleton.n_joints
        self.position = np.full((n, 3), np.nan)
        self.velocity = np.zeros((n, 3))
        self.last_seen = np.full(n, -np.inf)
        self.last_tracked = np.full(n, -np.inf)
        # longest bone to the parent: seen, or the format's bound
        self.bone = np.array(skeleton.max_bone_m)
        # a writable copy: numba types read-only arrays apart, and dispatches them slower
        self._parent = np.array(skeleton.parent)
        extra = self.cfg.landmark_uncertainty_m
        if extra and len(extra) != n:
            raise InputError(
                f"landmark_uncertainty_m has {len(extra)} values for the {n} landmarks of "
                f"{skeleton.title}",
                name="landmark_uncertainty_m",
                value=extra,
            )
        self._extra = np.array(extra, dtype=np.float64) if any(extra) else None
        self._last: HumanFrame | None = None
        self._perceived: Perceived | None = None
        warm_up(skeleton)

    @property
    def latest(self) -> Perceived | None:
        """What the last frame taken gave (None before the first)."""
        return self._perceived

    def update(
        self, frame: HumanFrame, capture_time_s: float, extra_m: np.ndarray | None = None
    ) -> Perceived:
        """Take a new frame captured at ``capture_time_s`` (s) and return what to trust;
        ``extra_m`` (J,), m: the frame's camera's landmark uncertainty, if larger than the
        configured one (``cfg.landmark_uncertainty_m``) somewhere."""
        cfg = self.cfg
        if self._perceived is not None and capture_time_s <= self._perceived.capture_time_s:
            return self._perceived  # out of order or repeated: keep the newer one
        last = self._last
        identical = 0
        if last is not None and self._perceived is not None:
            # bit for bit (a repeated frame is a copy; NaN equals NaN): cheaper than
            # np.array_equal(..., equal_nan=True)
            # a frame with no usable joint (a person the fusion keeps unseen) is not a
            # sensor repeating itself: its lost joints are bounded by their growing
            # uncertainty instead (an unseen person's frames are all alike; counted, they
            # would stop the robot as "frozen" until seen again: docs/security.md)
            same = (
                bool(frame.state.any())
                and frame.joints.tobytes() == last.joints.tobytes()
                and frame.state.tobytes() == last.state.tobytes()
            )
            identical = self._perceived.identical + 1 if same else 0
        # the α-β filter, the bones, each joint's uncertainty and the lost joints placed
        # within reach of their nearest tracked ancestor (_kernels.track)
        joints, state, radius, velocity = track(
            self.position,
            self.velocity,
            self.last_seen,
            self.last_tracked,
            self.bone,
            self._parent,
            kernel_input(frame.joints, np.float64),
            kernel_input(frame.state, np.int8),
            float(capture_time_s),
            float(cfg.velocity_alpha),
            float(cfg.velocity_beta),
            float(cfg.inferred_uncertainty_m),
            float(cfg.max_human_speed_mps),
        )
        extra = self._extra if extra_m is None else extra_m
        if self._extra is not None and extra_m is not None:
            extra = np.maximum(self._extra, extra_m)
        if extra is not None:  # derived landmarks: only within this of where they are put
            radius = radius + extra
        self._last = frame
        self._perceived = Perceived(
            HumanFrame(joints, state),
            radius,
            velocity,
            identical,
            float(capture_time_s),
        )
        return self._perceived


class PeopleTracker:
    """One :class:`Tracker` per person id; a person no longer reported is forgotten."""

    def __init__(self, cfg: PerceptionConfig | None = None, skeleton: SkeletonFormat = KINECT_V2):
        self.cfg = cfg or PerceptionConfig()
        self.skeleton = skeleton
        self.trackers: dict[int, Tracker] = {}

    def person(self, pid: int) -> Tracker:
        """Person ``pid``'s tracker (made on first use)."""
        tracker = self.trackers.get(pid)
        if tracker is None:  # (setdefault would build, and drop, one every frame)
            tracker = self.trackers[pid] = Tracker(self.cfg, self.skeleton)
        return tracker

    def update(
        self,
        ids: tuple[int, ...],
        frames: tuple[HumanFrame, ...],
        capture_time_s: float,
        extra_m: np.ndarray | None = None,
        held: bool = False,
    ) -> list[Perceived]:
        """Each person's :meth:`Tracker.update`, in the order of ``ids``; the people not
        listed are forgotten.

        ``held``: the frame is the one in hand, already taken
        (:class:`~qpavoid.perception.freshness.FrameClock`), under another list of people
        (the fusion dropped or admitted someone with no newer capture): a person tracked
        already is as their tracker last saw them (it learns nothing from the frame), a
        person new to the list is tracked from it.
        """
        self.trackers = {i: self.person(i) for i in ids}
        out = []
        for i, frame in zip(ids, frames, strict=True):
            tracker = self.trackers[i]
            latest = tracker.latest if held else None
            if latest is None:
                latest = tracker.update(frame, capture_time_s, extra_m)
            out.append(latest)
        return out


def part_velocities(
    velocity: list[np.ndarray], part_joints: np.ndarray, who: np.ndarray | None = None
) -> np.ndarray:
    """Velocity of each body part, m/s: that of its fastest joint.

    ``velocity`` holds each person's (J, 3) joint velocities; ``part_joints`` (K, J)
    bool membership. Without ``who``, (K, 3) of the first person; with ``who`` (S, K) (the
    person closest to each robot set and part, :func:`~qpavoid.human.people.closest_of`),
    (S, K, 3): the velocity of each pair's own person's part.
    """
    if who is None:
        return fastest_joint(part_joints, np.asarray(velocity[0], dtype=np.float64))
    parts = np.array(
        [fastest_joint(part_joints, np.asarray(v, dtype=np.float64)) for v in velocity]
    )
    return parts[who, np.arange(who.shape[1])[None, :]]  # (S, K, 3)
