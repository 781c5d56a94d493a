"""Who is who and whom to believe: bodies matched to people, mirrors undone, outliers settled.

Each sensor numbers the bodies it sees (a Kinect v2 body id, 0-5) on its own. A
:class:`PersonTrack` is one person as the fusion knows them, with a stable ``id``.
:func:`associate` assigns each sensor's bodies to tracks by the distance between torso
centres (an optimal assignment per sensor, scipy's ``linear_sum_assignment``, within
``gate_m``); a body already assigned keeps its track while it stays within the gate, so
ids do not jump. A body that fits no track starts a new one.

A Kinect v2 assumes the person faces it: for a person facing away it labels the left
side as the right one. :func:`mirror_cost` compares a body with a reference skeleton as
labelled and with left and right swapped (``frames.MIRROR``); the fusion relabels the
body when the swapped labelling fits better by a margin.

Where sensors disagree on a joint, :func:`~qpavoid.fusion_kernels.believed` chooses whom
to believe.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from .frames import MIRROR, N_KINECT_JOINTS, JointType, TrackingState
from .fusion_kernels import mean_gaps, subset_mean, update_track
from .perception import PARENT

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
#: Joints that change under a left/right swap (the others are on the spine).
SIDED = np.flatnonzero(np.arange(N_KINECT_JOINTS) != MIRROR)


@dataclass
class PersonTrack:
    """One person across sensors and time (the fusion's memory of them).

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
    """

    id: int
    joints: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: np.zeros((N_KINECT_JOINTS, 3)))
    last_seen: np.ndarray = field(default_factory=lambda: np.full(N_KINECT_JOINTS, -np.inf))
    bone: np.ndarray = field(default_factory=lambda: np.zeros(N_KINECT_JOINTS))
    seen_s: float = -np.inf

    def update(
        self,
        joints: np.ndarray,
        state: np.ndarray,
        t: float,
        alpha: float,
        beta: float,
        max_gap_s: float,
    ) -> None:
        """Take the fused ``joints`` (25, 3) (NaN where none) and ``state`` at ``t``: one
        α-β step of the joints and velocities (a joint unseen for over ``max_gap_s``
        restarts where it is, at rest), and the bone lengths learnt from Tracked joints
        (:func:`~qpavoid.fusion_kernels.update_track`)."""
        update_track(
            self.joints,
            self.velocity,
            self.last_seen,
            self.bone,
            PARENT,
            joints,
            state,
            float(t),
            float(alpha),
            float(beta),
            float(max_gap_s),
        )
        self.seen_s = t

    def centre(self) -> np.ndarray:
        """Torso centre, m (NaN if no joint is known)."""
        return torso_centre(self.joints)

    def predicted(self, t: float, horizon_s: float) -> np.ndarray:
        """(25, 3) joints moved along their velocity to time ``t`` (at most ``horizon_s``)."""
        dt = np.maximum(
            np.minimum(t - self.last_seen, horizon_s), 0.0
        )  # never seen: NaN joints stay NaN
        return self.joints + self.velocity * dt[:, None]


def torso_centre(joints: np.ndarray) -> np.ndarray:
    """Mean of the finite torso joints (of all finite joints if none), m; NaN if none."""
    return subset_mean(joints, TORSO)


def mirror_cost(
    joints: np.ndarray, usable: np.ndarray, reference: np.ndarray
) -> tuple[float, float]:
    """Median distance of the sided joints to ``reference``, as labelled and mirrored, m.

    Only joints usable in ``joints`` (and their mirror) and finite in ``reference`` count;
    (inf, inf) when none does.
    """
    ref_ok = np.isfinite(reference).all(axis=1)
    keep = SIDED[usable[SIDED] & ref_ok[SIDED]]
    keep_m = SIDED[usable[MIRROR[SIDED]] & ref_ok[SIDED]]
    if keep.size == 0 or keep_m.size == 0:
        return float("inf"), float("inf")
    as_is = np.median(np.linalg.norm(joints[keep] - reference[keep], axis=1))
    mirrored = np.median(np.linalg.norm(joints[MIRROR[keep_m]] - reference[keep_m], axis=1))
    return float(as_is), float(mirrored)


def reference_rank(joints: np.ndarray, state: np.ndarray) -> tuple[bool, int]:
    """Sort key of a new person's bodies: the best reference for the others first.

    A Kinect labels every body as if it faced the sensor, so a sensor behind the person
    swaps left and right. Operators face their robot: a body whose labelled front
    (``(ShoulderLeft − ShoulderRight) × up``) points towards the robot's base comes
    first, then the one with more Tracked joints.
    """
    left, right = joints[J.ShoulderLeft], joints[J.ShoulderRight]
    front = np.cross(left - right, [0.0, 0.0, 1.0])
    faces_robot = bool(np.dot(front, -joints[J.SpineShoulder]) > 0)  # NaN compares False
    return (not faces_robot, -int((state == TrackingState.Tracked).sum()))


#: A body whose sided joints are on average this close to the person's prediction is not
#: checked for a left/right swap (a swap moves them by a shoulder's width), m.
MIRROR_CHECK_M = 0.1


def mirror_suspects(bodies: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(S,) True for the bodies (S, 25, 3) whose sided joints lie on average farther than
    :data:`MIRROR_CHECK_M` from ``reference`` (25, 3): only those may be swapped.

    Joints missing in a body or in the reference do not count; a body with nothing to
    compare is not a suspect.
    """
    return np.asarray(mean_gaps(bodies, reference, SIDED) > MIRROR_CHECK_M)  # NaN: no check


def unmirrored(
    joints: np.ndarray, state: np.ndarray, reference: np.ndarray, margin_m: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """``joints`` and ``state`` relabelled left/right if that fits ``reference`` better
    by ``margin_m`` (:func:`mirror_cost`), else None."""
    as_is, swapped = mirror_cost(joints, ~np.isnan(joints[:, 0]), reference)
    if swapped + margin_m < as_is:
        return joints[MIRROR], state[MIRROR]
    return None


def associate(
    centres: dict[int, np.ndarray],
    track_centres: dict[int, np.ndarray],
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


def _dist(a: np.ndarray, b: np.ndarray) -> float:
    d = math.dist(a, b)
    return d if math.isfinite(d) else float("inf")
