"""Close work: a seated operator working within reach of the robot's path, never at it.

Where :mod:`qpavoid.scenarios.strikes` drives hands *into* the robot, a close-work case is
the ordinary work beside it that keeps a speed-and-separation robot stopped:
the productivity side of power and force limiting. Each case is one of :data:`VARIANTS`:

``rest_near``
    One hand, or both, held still near the robot's path (resting on a part or a fixture:
    beside the iiwa's path, some 0.3 m above the table): each arm's closest approach to
    the robot's nominal swept capsules is from 0.10 to 0.30 m, with a small natural drift
    (5-15 mm circles over 5-10 s).
``work_near``
    Both hands at small working motions (20-50 mm circles over 2.5-5 s, as ``free``'s
    :class:`~qpavoid.scenarios.generated.Working`), centred 0.10-0.30 m from the nominal
    swept capsules (the circles included).
``reach_across``
    One hand reaches across the path: from its rest to the near side of the corridor
    the end effector sweeps, then straight through it (through a point of the end
    effector's capsule at a chosen path time) to a point on its far side, at 0.3-1.0 m/s
    peak; it holds there 0.5-1.5 s and comes back the same way. The far point is at
    least 0.05 m from every nominal swept capsule (the hand aims beside the robot, never
    at it), but the forearm lies across the corridor while it holds: a robot that does
    not slow can touch it. The hand gets to the far side from 2 s before the robot
    passes there (on its nominal path) to 0.5 s after.
``handover``
    One hand moves to a handover point beside the end effector's nominal position at a
    chosen path time, towards the operator (the arm 0.03-0.08 m from every nominal swept
    capsule: the hand some 0.15-0.25 m from the flange), at 0.3-0.8 m/s peak, and holds
    it 1-2 s while the robot comes by, as if taking a part, then withdraws.

The other hand rests where the operator's rest pose puts it. Places are found against the
robot's *nominal* motion (the path tracked with nobody near): its capsules
(:meth:`~qpavoid.arm.model.Robot.capsules`) at :data:`NOMINAL_SAMPLES` path times, the
operator's posed body (:class:`~qpavoid.human.body.KinectHuman`'s capsules) measured
against all of them (:func:`swept_clearance_m`), so the cases fit every arm. The operator
sits where the arm's task file places it (:func:`~qpavoid.control.task.default_task`),
moved by up to 0.1 m either way along x. No strike, no sensor fault: the camera is the
format's own (its noise and latency).

:func:`closework_case` draws a case from a seed; :func:`closework_motion` turns it into the
true motion. ``qpavoid run`` takes ``closework:SEED`` and the fixed cases of
:data:`FIXED_SEEDS` by their variant's name; ``qpavoid sweep --motion closework`` runs
them by the thousand (:mod:`qpavoid.experiments.sweep`, kind ``"closework"``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from itertools import pairwise

import numpy as np

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import Robot, load_robot
from qpavoid.control.path import PlannedPath, smoothstep
from qpavoid.control.task import Task, default_task
from qpavoid.core.checks import check_choice
from qpavoid.core.errors import InputError
from qpavoid.core.geometry import unit
from qpavoid.human.body import KinectHuman
from qpavoid.human.posture import Operator
from qpavoid.human.skeleton import TRACKED

__all__ = [
    "ACROSS_CLEARANCE_M",
    "FIXED_SEEDS",
    "NEAR_BAND_M",
    "NOMINAL_SAMPLES",
    "SLACK_S",
    "VARIANTS",
    "CloseWork",
    "CloseWorkCase",
    "HandTrack",
    "arm_parts",
    "closework_case",
    "closework_motion",
    "nominal_capsules",
    "swept_clearance_m",
]

#: The kinds of close work (module docstring).
VARIANTS = ("rest_near", "work_near", "reach_across", "handover")
#: The seed of each variant's fixed case (``qpavoid run rest_near`` is ``closework:1``): the
#: first seed that draws it.
FIXED_SEEDS = {"rest_near": 1, "work_near": 5, "reach_across": 3, "handover": 0}
#: Path times at which the nominal motion is sampled to place the hands.
NOMINAL_SAMPLES = 121
#: A case lasts the path and this much more, s: room to wait for the person.
SLACK_S = 15.0
#: The band of a resting or working hand's closest approach to the swept capsules, m.
NEAR_BAND_M = (0.10, 0.30)
#: A reaching hand's far point and near point are this far from every swept capsule, m.
ACROSS_CLEARANCE_M = 0.05
#: How far a joint target may be from where the posed hand lands, m (reachable targets).
REACH_TOLERANCE_M = 1e-3
#: Candidate places tried before a case is refused.
ATTEMPTS = 200


@dataclass(frozen=True)
class CloseWorkCase:
    """One randomized case of close work (times on the run clock, s; distances, m).

    Attributes
    ----------
    seed
        The seed it was drawn from.
    variant
        One of :data:`VARIANTS`.
    side
        The hand the variant is about (``"right"`` or ``"left"``): the one resting or
        working nearest, reaching across or handing over.
    both_hands
        The other hand is near the path too (always for ``work_near``, never for
        ``reach_across`` and ``handover``).
    path_time_s
        The nominal path time the ``side`` hand's place is taken against: the end
        effector's position then anchors it.
    clearance_m
        ``rest_near``, ``work_near``: the ``side`` hand's place's closest approach to the
        swept capsules (its drift or circle aside); ``handover``: the handover point's;
        ``reach_across``: 0 (its far point is :data:`ACROSS_CLEARANCE_M` away or more).
    sway_m, period_s
        The radius of a resting hand's drift or a working hand's circles, and their
        period (0 and 1 s for a moving hand).
    speed_mps
        ``reach_across``, ``handover``: the hand's peak speed, m/s (the quintic time law
        peaks at 1.875 × the mean); 0 otherwise.
    arrival_s
        ``reach_across``: when the hand reaches its far point; ``handover``: the handover
        point (or as soon after as the hand can get there from rest); 0 otherwise.
    hold_s
        How long it holds there (0 for ``rest_near`` and ``work_near``).
    duration_s
        How long to simulate: the path and :data:`SLACK_S` more.
    """

    seed: int
    variant: str
    side: str
    both_hands: bool
    path_time_s: float
    clearance_m: float
    sway_m: float
    period_s: float
    speed_mps: float
    arrival_s: float
    hold_s: float
    duration_s: float

    def __post_init__(self) -> None:
        check_choice("close-work variant", self.variant, VARIANTS)
        check_choice("hand (side)", self.side, ("right", "left"))


@functools.cache
def _default_robot() -> Robot:
    """The default robot description (:func:`~qpavoid.arm.model.load_robot`), read once."""
    return load_robot()


@functools.cache
def _human() -> KinectHuman:
    """The body model the hands are placed with (the operator's Kinect v2 skeleton)."""
    return KinectHuman()


def closework_case(
    seed: int, robot: Robot | None = None, task: Task | None = None
) -> CloseWorkCase:
    """The close-work case of ``seed`` on ``robot`` (default: the default robot description),
    along the path of ``task`` (default: the arm's,
    :func:`~qpavoid.control.task.default_task`): the variant (drawn first, so a seed's
    variant is the same on every arm), the hand, the timing and the distances."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(
            f"a close-work seed is a whole number >= 0, got {seed!r}", name="seed", value=seed
        )
    task = task or default_task(robot or _default_robot())
    period = task.path.duration_s
    rng = np.random.default_rng([int(seed), 29])
    variant = VARIANTS[int(rng.integers(len(VARIANTS)))]
    side = "right" if rng.random() < 0.6 else "left"
    if variant in ("rest_near", "work_near"):
        resting = variant == "rest_near"
        sway = float(rng.uniform(0.005, 0.015) if resting else rng.uniform(0.02, 0.05))
        low, high = NEAR_BAND_M
        return CloseWorkCase(
            int(seed),
            variant,
            side,
            both_hands=bool(rng.random() < 0.5) if resting else True,
            path_time_s=float(rng.uniform(0.0, period)),
            clearance_m=float(rng.uniform(low + sway, high - sway)),
            sway_m=sway,
            period_s=float(rng.uniform(5.0, 10.0) if resting else rng.uniform(2.5, 5.0)),
            speed_mps=0.0,
            arrival_s=0.0,
            hold_s=0.0,
            duration_s=period + SLACK_S,
        )
    across = variant == "reach_across"
    path_time = float(rng.uniform(0.2, 0.8) * period)
    hold = float(rng.uniform(0.5, 1.5) if across else rng.uniform(1.0, 2.0))
    # across: the crossing around when the robot passes (from 2 s before to 0.5 s after);
    # handover: the hand waits at its point while the robot comes by
    arrival = path_time + (rng.uniform(-2.0, 0.5) if across else -rng.uniform(0.0, hold))
    return CloseWorkCase(
        int(seed),
        variant,
        side,
        both_hands=False,
        path_time_s=path_time,
        clearance_m=0.0 if across else float(rng.uniform(0.03, 0.08)),
        sway_m=0.0,
        period_s=1.0,
        speed_mps=float(rng.uniform(0.3, 1.0) if across else rng.uniform(0.3, 0.8)),
        arrival_s=float(arrival),
        hold_s=hold,
        duration_s=period + SLACK_S,
    )


@dataclass(frozen=True)
class HandTrack:
    """Where one hand is: keyframes, with a circle on top.

    Attributes
    ----------
    side
        ``"right"`` or ``"left"``.
    keyframes
        ``(t_s, position (3,) m)`` in increasing time: straight lines between them with
        the quintic time law (:func:`~qpavoid.control.path.smoothstep`), held before the
        first and after the last.
    radius_m, period_s, phase_rad
        A horizontal circle of this radius, m, and period, s, around the keyframes'
        position (0: none).
    """

    side: str
    keyframes: tuple[tuple[float, np.ndarray], ...]
    radius_m: float = 0.0
    period_s: float = 1.0
    phase_rad: float = 0.0

    def position(self, t: float) -> np.ndarray:
        """The hand's target at time ``t`` (s), m."""
        here = self.keyframes[0][1]
        for (t0, p0), (t1, p1) in pairwise(self.keyframes):
            if t <= t0:
                break
            here = p1 if t >= t1 else p0 + smoothstep((t - t0) / (t1 - t0)) * (p1 - p0)
        if self.radius_m == 0.0:
            return np.array(here, dtype=float)
        w = 2.0 * np.pi * t / self.period_s + self.phase_rad
        return here + self.radius_m * np.array([np.cos(w), np.sin(w), 0.0])


@dataclass(frozen=True)
class CloseWork:
    """The seated operator, each of the ``hands`` on its own track, the body still.

    The first track is posed first: a hand out of reach makes the operator lean
    (:meth:`~qpavoid.human.posture.Operator.reach`), and the tracks after it are posed from
    the leaned body (a resting hand stays where it rests).
    """

    operator: Operator
    hands: tuple[HandTrack, ...]

    def frame_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Joints (J, 3) and states (J,) (all tracked) at time ``t`` (s)."""
        joints = self.operator.rest()
        for hand in self.hands:
            joints = self.operator.reach(joints, hand.side, hand.position(t))
        return joints, np.full(len(joints), TRACKED, dtype=np.int8)


def nominal_capsules(robot: Robot, path: PlannedPath, n: int = NOMINAL_SAMPLES) -> np.ndarray:
    """(n, S, 2, 3) the robot's capsule axes over its nominal motion, m: the path tracked
    exactly (inverse kinematics from the start, each from the one before: the
    configurations :func:`~qpavoid.scenarios.generated.nominal_configurations` gives) at
    ``n`` evenly spaced path times from 0 to its duration."""
    q = inverse_kinematics(robot, path.reference(0.0)[0])
    out = []
    for t in np.linspace(0.0, path.duration_s, n):
        q = inverse_kinematics(robot, path.reference(float(t))[0], q0=q)
        out.append(robot.capsules(q))
    return np.array(out)


def _segment_distances(
    p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray
) -> np.ndarray:
    """Distances between segments [p0, p1] and [q0, q1] (broadcast over the leading axes),
    m: the closest points' (Ericson, *Real-Time Collision Detection*, 5.1.9)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e = np.einsum("...i,...i", d1, d1), np.einsum("...i,...i", d2, d2)
    b, c, f = (
        np.einsum("...i,...i", d1, d2),
        np.einsum("...i,...i", d1, r),
        np.einsum("...i,...i", d2, r),
    )
    tiny = 1e-12
    a_ok, e_ok = a > tiny, e > tiny
    denom = a * e - b * b
    s = np.where(
        denom > tiny, np.clip((b * f - c * e) / np.where(denom > tiny, denom, 1.0), 0, 1), 0.0
    )
    s = np.where(a_ok, s, 0.0)
    t = np.where(e_ok, (b * s + f) / np.where(e_ok, e, 1.0), 0.0)
    safe_a = np.where(a_ok, a, 1.0)
    s = np.where(
        t < 0.0, np.clip(-c / safe_a, 0, 1), np.where(t > 1.0, np.clip((b - c) / safe_a, 0, 1), s)
    )
    s = np.where(a_ok, s, 0.0)
    t = np.clip(t, 0.0, 1.0)
    gap = (p0 + s[..., None] * d1) - (q0 + t[..., None] * d2)
    return np.sqrt(np.einsum("...i,...i", gap, gap))


def swept_clearance_m(
    joints: np.ndarray,
    capsules: np.ndarray,
    radii_m: np.ndarray,
    parts: tuple[str, ...] | None = None,
) -> float:
    """The smallest distance between the person posed as ``joints`` (Kinect v2, (25, 3))
    and any of the robot ``capsules`` (..., S, 2, 3) of radii ``radii_m`` (S,), m
    (negative: they overlap): the exact capsule distance, the body's capsules with their
    reach (the fingers), over the body ``parts`` by name (default: all of them)."""
    human = _human()
    geo = human.geometry(joints)
    keep = [human.part_names.index(p) for p in parts] if parts else slice(None)
    seg = geo.segments[keep]
    reach = (human.capsule_radii + geo.reach_margin)[keep]
    caps = capsules.reshape(-1, 2, 3)
    radii = np.broadcast_to(radii_m, capsules.shape[:-2]).reshape(-1)
    d = _segment_distances(seg[:, None, 0], seg[:, None, 1], caps[None, :, 0], caps[None, :, 1])
    return float((d - reach[:, None] - radii[None, :]).min())


class _Place:
    """Where the hands can go: the operator and the robot's nominal motion (its capsules at
    path times ``times``)."""

    def __init__(self, robot: Robot, path: PlannedPath, operator: Operator):
        self.robot, self.path, self.op = robot, path, operator
        self.capsules = nominal_capsules(robot, path)
        self.radii = robot.capsule_radii
        self.times = np.linspace(0.0, path.duration_s, len(self.capsules))

    def rest(self, side: str) -> np.ndarray:
        """The ``side`` hand's rest position, m."""
        return self.op.rest()[self.op.arm(side)[3]]

    def reaches(self, side: str, target: np.ndarray, lean: bool = False) -> bool:
        """Whether the ``side`` hand gets to ``target`` (leaning, if ``lean``)."""
        joints = self.op.reach(self.op.rest(), side, target)
        hand = joints[self.op.arm(side)[3]]
        chest = self.op.skeleton.group("spine")["chest"]
        leaned = not np.allclose(joints[chest], self.op.rest()[chest])
        return bool((lean or not leaned) and np.linalg.norm(hand - target) <= REACH_TOLERANCE_M)

    def clearance(self, side: str, target: np.ndarray) -> float:
        """The ``side`` arm's clearance to every swept capsule, its hand at ``target``
        (leaning if it must), m."""
        joints = self.op.reach(self.op.rest(), side, target)
        return swept_clearance_m(joints, self.capsules, self.radii, arm_parts(side))

    def point_clearance(self, points: np.ndarray) -> np.ndarray:
        """(N,) a hand's sphere (the hand capsule's radius) at each of ``points`` (N, 3):
        its clearance to every swept capsule, m."""
        caps = self.capsules.reshape(-1, 2, 3)
        radii = np.broadcast_to(self.radii, self.capsules.shape[:-2]).reshape(-1)
        p = np.asarray(points, dtype=float)[:, None]
        d = _segment_distances(p, p, caps[None, :, 0], caps[None, :, 1])
        hand = _human().capsule_radii[_human().part_names.index("right_hand")]
        return np.asarray((d - radii - hand).min(axis=1))

    def first_clear(self, points: np.ndarray, clearance_m: float) -> np.ndarray | None:
        """The first of ``points`` (N, 3) whose hand sphere is ``clearance_m`` or more
        from every swept capsule, if any."""
        clear = np.flatnonzero(self.point_clearance(points) >= clearance_m)
        return points[clear[0]] if len(clear) else None

    def at(self, path_time_s: float) -> int:
        """The sample nearest path time ``path_time_s``."""
        return int(np.argmin(np.abs(self.times - path_time_s)))

    def flange(self, path_time_s: float) -> np.ndarray:
        """The end effector's nominal position at ``path_time_s``, m."""
        return np.asarray(self.path.reference(path_time_s)[0][:3, 3], dtype=float)

    def at_clearance(
        self,
        side: str,
        anchor: np.ndarray,
        towards: np.ndarray,
        clearance_m: float,
        lean: bool = False,
    ) -> np.ndarray | None:
        """The point ``anchor + s (towards − anchor)``, s in [0, 1], where the ``side``
        arm's clearance is ``clearance_m`` (bisection on s), if the hand gets there
        (leaning, if ``lean``)."""
        far = towards - anchor
        if self.clearance(side, towards) < clearance_m:
            return None
        lo, hi = 0.0, 1.0
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            lo, hi = (
                (mid, hi) if self.clearance(side, anchor + mid * far) < clearance_m else (lo, mid)
            )
        point = anchor + hi * far
        return point if self.reaches(side, point, lean) else None


def arm_parts(side: str) -> tuple[str, str, str]:
    """The body parts of the ``side`` arm (:class:`~qpavoid.human.body.KinectHuman`'s)."""
    return (f"{side}_upper_arm", f"{side}_forearm", f"{side}_hand")


def _circle_points(centre: np.ndarray, radius_m: float, n: int = 12) -> np.ndarray:
    """``n`` points of the horizontal circle of ``radius_m`` around ``centre``, m."""
    w = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return centre + radius_m * np.stack([np.cos(w), np.sin(w), np.zeros(n)], axis=1)


def _near_track(
    place: _Place,
    case: CloseWorkCase,
    side: str,
    path_time_s: float,
    clearance_m: float,
    rng: np.random.Generator,
) -> HandTrack:
    """A resting or working hand (``rest_near``, ``work_near``) whose place is
    ``clearance_m`` from the swept capsules, anchored at the end effector at
    ``path_time_s``, its drift or circles within :data:`NEAR_BAND_M`."""
    anchor, rest = place.flange(path_time_s), place.rest(side)
    low, high = NEAR_BAND_M
    for _ in range(ATTEMPTS):
        towards = rest + rng.normal(0.0, 0.12, 3) * [1.0, 1.0, 0.5]
        towards[2] = max(towards[2], rest[2])
        centre = place.at_clearance(side, anchor, towards, clearance_m)
        if centre is None:
            continue
        ring = _circle_points(centre, case.sway_m)
        if all(place.reaches(side, p) for p in ring) and all(
            low <= place.clearance(side, p) <= high for p in ring
        ):
            phase = float(rng.uniform(0.0, 2.0 * np.pi))
            return HandTrack(side, ((0.0, centre),), case.sway_m, case.period_s, phase)
    raise InputError(
        f"no place for the {side} hand of close-work case {case.seed} ({case.variant})",
        name="seed",
        value=case.seed,
    )


def _travel_s(length_m: float, speed_mps: float) -> float:
    """The time to travel ``length_m`` with the quintic time law peaking at ``speed_mps``."""
    return length_m * 1.875 / speed_mps


def _across_track(place: _Place, case: CloseWorkCase, rng: np.random.Generator) -> HandTrack:
    """The reach across the corridor (``reach_across``): rest, near side, far side (held),
    near side, rest."""
    side, robot = case.side, place.robot
    caps = place.capsules[place.at(case.path_time_s), robot.roles.end_effector]
    shoulder = place.op.rest()[place.op.arm(side)[0]]
    rest = place.rest(side)
    steps = np.arange(0.08, 0.45, 0.01)
    for _ in range(ATTEMPTS):
        cross = caps[0] + rng.uniform(0.5, 1.0) * (caps[1] - caps[0])
        away = (cross - shoulder) * [1.0, 1.0, 0.0]
        azimuth, elevation = rng.uniform(-0.7, 0.7), rng.uniform(-0.5, 0.25)
        c, s = np.cos(azimuth), np.sin(azimuth)
        heading = unit([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]] @ unit(away))
        n = unit(np.cos(elevation) * heading + [0.0, 0.0, np.sin(elevation)])
        far = place.first_clear(cross + steps[:, None] * n, ACROSS_CLEARANCE_M)
        near = place.first_clear(cross - steps[:, None] * n, ACROSS_CLEARANCE_M)
        if far is None or near is None or near[2] < 0.05 or far[2] < 0.05:
            continue
        if not place.reaches(side, far, lean=True):
            continue  # out of reach even leaning
        lift = np.linspace(rest, near, 8)
        if min(place.clearance(side, p) for p in lift) <= 0.02:
            continue  # the way to the near side must not touch the robot
        t_cross = _travel_s(float(np.linalg.norm(far - near)), case.speed_mps)
        t_lift = _travel_s(float(np.linalg.norm(near - rest)), case.speed_mps)
        arrive = max(case.arrival_s, t_lift + t_cross)
        leave = arrive + case.hold_s
        keys = (
            (arrive - t_cross - t_lift, rest),
            (arrive - t_cross, near),
            (arrive, far),
            (leave, far),
            (leave + t_cross, near),
            (leave + t_cross + t_lift, rest),
        )
        return HandTrack(side, keys)
    raise InputError(
        f"no reach across the path for close-work case {case.seed}", name="seed", value=case.seed
    )


def _handover_track(place: _Place, case: CloseWorkCase, rng: np.random.Generator) -> HandTrack:
    """The hand to the handover point beside the end effector at the case's path time,
    towards the operator, held, and back (``handover``)."""
    side, rest = case.side, place.rest(side=case.side)
    anchor = place.flange(case.path_time_s)
    chest = place.op.rest()[place.op.skeleton.group("spine")["chest"]]
    for _ in range(ATTEMPTS):
        towards = chest + rng.normal(0.0, 0.15, 3)
        point = place.at_clearance(side, anchor, towards, case.clearance_m, lean=True)
        if point is None:
            continue
        if min(place.clearance(side, p) for p in np.linspace(rest, point, 10)) <= 0.0:
            continue  # the way there must stay clear of the robot
        travel = _travel_s(float(np.linalg.norm(point - rest)), case.speed_mps)
        arrive = max(case.arrival_s, travel)
        leave = arrive + case.hold_s
        keys = ((arrive - travel, rest), (arrive, point), (leave, point), (leave + travel, rest))
        return HandTrack(side, keys)
    raise InputError(
        f"no handover point for close-work case {case.seed}", name="seed", value=case.seed
    )


def closework_motion(
    case: CloseWorkCase, robot: Robot, path: PlannedPath | None = None, task: Task | None = None
) -> CloseWork:
    """The true motion of ``case`` on ``robot`` (module docstring).

    The path (unless ``path`` is given) and the operator's seat are the ``task``'s
    (default: the arm's, :func:`~qpavoid.control.task.default_task`).

    Raises
    ------
    InputError
        If no place fits the case (a path that leaves no room beside it).
    """
    task = task or default_task(robot)
    path = path or task.path
    rng = np.random.default_rng([case.seed, 31])
    op = replace(task.operator, x_m=task.operator.x_m + rng.uniform(-0.1, 0.1))
    place = _Place(robot, path, op)
    other = "left" if case.side == "right" else "right"
    if case.variant in ("rest_near", "work_near"):
        hands = [_near_track(place, case, case.side, case.path_time_s, case.clearance_m, rng)]
        if case.both_hands:
            low, high = NEAR_BAND_M
            when = float(rng.uniform(0.0, path.duration_s))
            clearance = float(rng.uniform(low + case.sway_m, high - case.sway_m))
            hands.append(_near_track(place, case, other, when, clearance, rng))
        else:
            hands.append(HandTrack(other, ((0.0, place.rest(other)),)))
        return CloseWork(op, tuple(hands))
    track = (_across_track if case.variant == "reach_across" else _handover_track)(place, case, rng)
    # the moving hand first: if it leans, the resting hand stays where it rests
    return CloseWork(op, (track, HandTrack(other, ((0.0, place.rest(other)),))))
