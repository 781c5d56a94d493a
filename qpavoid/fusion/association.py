"""Who is who and whom to believe: bodies matched to people, mirrors undone, outliers settled.

Each sensor numbers the bodies it sees (a Kinect v2 body id, 0-5) on its own. A
:class:`PersonTrack` is one person as the fusion knows them, with a stable ``id``.
:func:`associate` assigns each sensor's bodies to tracks by the distance between torso
centres (an optimal assignment per sensor, scipy's ``linear_sum_assignment``, within
``gate_m``); a body already assigned keeps its track while it stays within the gate, so
ids do not jump. A body that fits no track starts a new one.

A Kinect v2 assumes the person faces it: for a person facing away it labels the left
side as the right one. :func:`reference_rank` picks, for a new person, the body the
others are compared with; :func:`~qpavoid.fusion.person.mirror_costs` compares a body with
that reference (or the person's prediction) as labelled and with left and right swapped,
and the fusion relabels the body when the swap fits better by a margin.

Where sensors disagree on a joint, :func:`~qpavoid.fusion._kernels.believed` chooses whom
to believe.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from qpavoid.fusion._kernels import subset_mean
from qpavoid.human.frames import MIRROR, N_KINECT_JOINTS, JointType, TrackingState

J = JointType

#: Joints whose mean is a body's torso centre (the most stable part of a Kinect skeleton).
TORSO = np.array(
    [
        J.SpineBase,
        J.SpineMid,
        J.SpineShoulder,
        J.Neck,
        J.ShoulderLeft,
        J.ShoulderRight,
        J.HipLeft,
        J.HipRight,
    ]
)


@dataclass
class PersonTrack:
    """One person across sensors and time (the fusion's memory of them); each fusion
    updates its arrays in place (:func:`~qpavoid.fusion.person.fuse_person`).

    Attributes
    ----------
    id
        Stable id, from 0 in order of first appearance.
    joints
        (25, 3) last fused joints, base frame, m (NaN where never seen).
    velocity
        (25, 3) filtered joint velocities, m/s.
    last_seen
        (25,) time each joint was last fused from some sensor, s (-inf never).
    bone
        (25,) running estimate of the length of the bone from each joint to its parent, m
        (0 until measured).
    seen_s
        Last time any sensor saw the person, s.
    born_s
        When the fusion first saw the person, s.
    seen_by
        The sensors that saw the person during their first ``settle_s``.
    flag
        Why the person is suspect ("": not; :attr:`~qpavoid.fusion.fuser.FusedPerson.flag`).
    """

    id: int
    joints: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: np.zeros((N_KINECT_JOINTS, 3)))
    last_seen: np.ndarray = field(default_factory=lambda: np.full(N_KINECT_JOINTS, -np.inf))
    bone: np.ndarray = field(default_factory=lambda: np.zeros(N_KINECT_JOINTS))
    seen_s: float = -np.inf
    born_s: float = -np.inf
    seen_by: set[str] = field(default_factory=set)
    flag: str = ""

    def mirror(self) -> None:
        """Swap the track's left and right (its joints, velocities, times and bones)."""
        for a in (self.joints, self.velocity, self.last_seen, self.bone):
            a[:] = a[MIRROR]

    def centre(self) -> np.ndarray:
        """Torso centre, m (NaN if no joint is known)."""
        return torso_centre(self.joints)


def torso_centre(joints: np.ndarray) -> np.ndarray:
    """Mean of the finite torso joints (of all finite joints if none), m; NaN if none."""
    return subset_mean(joints, TORSO)


def reference_rank(joints: np.ndarray, state: np.ndarray) -> tuple[bool, int]:
    """Sort key of a new person's bodies: the best reference for the others first.

    A Kinect labels every body as if it faced the sensor, so a sensor behind the person
    swaps left and right. Operators face their robot: a body whose labelled front
    (``(ShoulderLeft − ShoulderRight) × up``) points towards the robot's base comes
    first, then the one with more Tracked joints.
    """
    return (not faces_robot(joints), -int((state == TrackingState.Tracked).sum()))


def faces_robot(joints: np.ndarray) -> bool:
    """Whether a skeleton's labelled front, ``(ShoulderLeft − ShoulderRight) × up``, points
    towards the robot's base (False if a shoulder is missing)."""
    left, right = joints[J.ShoulderLeft], joints[J.ShoulderRight]
    front = np.cross(left - right, [0.0, 0.0, 1.0])
    return bool(np.dot(front, -joints[J.SpineShoulder]) > 0)  # NaN compares False


def associate(
    centres: Mapping[int, Sequence[float]],
    track_centres: Mapping[int, Sequence[float]],
    previous: dict[int, int],
    gate_m: float,
) -> dict[int, int | None]:
    """Assign one sensor's bodies to people.

    Parameters
    ----------
    centres
        Torso centre of each body of the sensor, by body id, m.
    track_centres
        Torso centre of each person (track) that may take them, by track id, m.
    previous
        This sensor's earlier assignment, body id → track id.
    gate_m
        Farthest a body may be from a person's centre to be that person, m.

    Returns
    -------
    dict
        Body id → track id, or None for a body that fits nobody (a new person).
    """
    out: dict[int, int | None] = {}
    used: set[int] = set()
    for body, c in centres.items():  # a body keeps its person while within the gate
        tid = previous.get(body)
        if (
            tid is not None
            and tid in track_centres
            and tid not in used
            and _dist(c, track_centres[tid]) <= gate_m
        ):
            out[body] = tid
            used.add(tid)
    bodies = [b for b in centres if b not in out]
    free = [tid for tid in track_centres if tid not in used]
    if bodies and free:
        cost = np.array([[_dist(centres[b], track_centres[tid]) for tid in free] for b in bodies])
        big = 1e6
        rows, cols = linear_sum_assignment(np.where(cost <= gate_m, cost, big))
        for r, c in zip(rows, cols, strict=True):
            if cost[r, c] <= gate_m:
                out[bodies[r]] = free[c]
    for b in bodies:
        out.setdefault(b, None)
    return out


def _dist(a: Sequence[float], b: Sequence[float]) -> float:
    d = math.dist(a, b)
    return d if math.isfinite(d) else float("inf")
