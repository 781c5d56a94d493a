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

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from qpavoid.fusion._kernels import subset_mean
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.skeleton import TRACKED, SkeletonFormat


@dataclass
class PersonTrack:
    """One person across sensors and time (the fusion's memory of them); each fusion
    updates its arrays in place (:func:`~qpavoid.fusion.person.fuse_person`).

    Attributes
    ----------
    id
        Stable id, from 0 in order of first appearance.
    joints
        (J, 3) last fused joints, base frame, m (NaN where never seen).
    velocity
        (J, 3) filtered joint velocities, m/s (zeros at first).
    last_seen
        (J,) time each joint was last fused from some sensor, s (-inf: never).
    bone
        (J,) running estimate of the length of the bone from each joint to its parent, m
        (0 until measured).
    seen_s
        Last time any sensor saw the person, s.
    born_s
        When the fusion first saw the person, s.
    seen_by
        The sensors that saw the person during their first ``settle_s``.
    flag
        Why the person is suspect ("": not; :attr:`~qpavoid.fusion.fuser.FusedPerson.flag`).
    skeleton
        The format of the person's joints (default: the Kinect v2's).
    """

    id: int
    joints: np.ndarray
    seen_s: float = -np.inf
    born_s: float = -np.inf
    seen_by: set[str] = field(default_factory=set)
    flag: str = ""
    skeleton: SkeletonFormat = KINECT_V2
    # sized from ``joints``: a person has as many joints as their frames
    velocity: np.ndarray = field(init=False)
    last_seen: np.ndarray = field(init=False)
    bone: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        n = self.joints.shape[0]
        self.velocity = np.zeros((n, 3))
        self.last_seen = np.full(n, -np.inf)
        self.bone = np.zeros(n)

    def mirror(self) -> None:
        """Swap the track's left and right (its joints, velocities, times and bones)."""
        mirror = self.skeleton.mirror
        for a in (self.joints, self.velocity, self.last_seen, self.bone):
            a[:] = a[mirror]

    def centre(self) -> np.ndarray:
        """Torso centre, m (NaN if no joint is known)."""
        return torso_centre(self.joints, self.skeleton)


def torso_centre(joints: np.ndarray, skeleton: SkeletonFormat = KINECT_V2) -> np.ndarray:
    """Mean of the finite torso joints of ``skeleton`` (of all finite joints if none), m;
    NaN if none."""
    return subset_mean(joints, skeleton.torso_ids)


def reference_rank(
    joints: np.ndarray, state: np.ndarray, skeleton: SkeletonFormat = KINECT_V2
) -> tuple[bool, int]:
    """Sort key of a new person's bodies: the best reference for the others first.

    A Kinect labels every body as if it faced the sensor, so a sensor behind the person
    swaps left and right. Operators face their robot: a body whose labelled front
    (``(ShoulderLeft − ShoulderRight) × up``) points towards the robot's base comes
    first, then the one with more Tracked joints.
    """
    return (not faces_robot(joints, skeleton), -int((state == TRACKED).sum()))


def faces_robot(joints: np.ndarray, skeleton: SkeletonFormat = KINECT_V2) -> bool:
    """Whether a skeleton's labelled front, ``(left shoulder − right shoulder) × up``, points
    from its chest towards the robot's base (False if a shoulder is missing, or if the
    format names no shoulders and chest: the roles ``arm_left.shoulder``,
    ``arm_right.shoulder`` and ``spine.chest`` of
    :meth:`~qpavoid.human.skeleton.SkeletonFormat.group`)."""
    roles = _facing_joints(skeleton)
    if roles is None:
        return False
    left, right, chest = (joints[j] for j in roles)
    front = np.cross(left - right, [0.0, 0.0, 1.0])
    return bool(np.dot(front, -chest) > 0)  # NaN compares False


@functools.cache
def _facing_joints(skeleton: SkeletonFormat) -> tuple[int, int, int] | None:
    """The ids of the left and right shoulders and the chest, or None if the format has
    no such roles."""
    groups = {g for g, _ in skeleton.groups}
    if not {"arm_left", "arm_right", "spine"} <= groups:
        return None
    left, right = skeleton.group("arm_left"), skeleton.group("arm_right")
    chest = skeleton.group("spine").get("chest")
    if "shoulder" not in left or "shoulder" not in right or chest is None:
        return None
    return left["shoulder"], right["shoulder"], chest


def associate(
    centres: Mapping[int, Sequence[float]],
    track_centres: Mapping[int, Sequence[float]],
    previous: dict[int, int],
    gate_m: float | Mapping[int, float],
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
        Farthest a body may be from a person's centre to be that person, m: one for all,
        or each person's by track id (wider for a person unseen a while:
        :meth:`~qpavoid.fusion.fuser.Fuser.fuse`).

    Returns
    -------
    dict
        Body id → track id, or None for a body that fits nobody (a new person).
    """
    gates = gate_m if isinstance(gate_m, Mapping) else dict.fromkeys(track_centres, gate_m)
    out: dict[int, int | None] = {}
    used: set[int] = set()
    for body, c in centres.items():  # a body keeps its person while within the gate
        tid = previous.get(body)
        if (
            tid is not None
            and tid in track_centres
            and tid not in used
            and _dist(c, track_centres[tid]) <= gates[tid]
        ):
            out[body] = tid
            used.add(tid)
    bodies = [b for b in centres if b not in out]
    free = [tid for tid in track_centres if tid not in used]
    if bodies and free:
        cost = np.array([[_dist(centres[b], track_centres[tid]) for tid in free] for b in bodies])
        inside = cost <= np.array([gates[tid] for tid in free])
        big = 1e6
        rows, cols = linear_sum_assignment(np.where(inside, cost, big))
        for r, c in zip(rows, cols, strict=True):
            if inside[r, c]:
                out[bodies[r]] = free[c]
    for b in bodies:
        out.setdefault(b, None)
    return out


def _dist(a: Sequence[float], b: Sequence[float]) -> float:
    d = math.dist(a, b)
    return d if math.isfinite(d) else float("inf")
