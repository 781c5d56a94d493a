"""Synthetic skeletons: a seated operator and arm reaches.

The generated scenarios (``test1``, ``test2``, ``free``, random approaches), the tests
and the benchmarks need plausible (J, 3) skeletons in the robot base frame (by default
Kinect v2 ones). Joints are placed by role (the format's groups ``spine``, ``arm_left``,
``arm_right``, ``leg_left``, ``leg_right``: :meth:`~qpavoid.human.skeleton.SkeletonFormat.group`),
never by index. The
operator sits at the table facing the robot (the paper's layout, Sect. 2): the robot base
is on the table top (z = 0), the operator's chest is ``Operator.distance_m`` in front of
it along +y and ``Operator.x_m`` along x, and the arms reach with a two-link inverse
kinematics so segment lengths stay those of the skeleton.

Where the operator sits is the arm's: its task file's ``[operator]``
(:func:`qpavoid.control.task.default_task`) places the seat relative to the robot's base,
scaled by the arm's reach (the defaults here are the paper's place beside the iiwa); the
person's own sizes and the table's height do not change with the arm.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from qpavoid.core.geometry import unit
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.skeleton import SkeletonFormat

#: The roles of an arm's joints, in the order of :func:`arm` (each a role of the format's
#: ``arm_<side>`` group).
ARM_ROLES = ("shoulder", "elbow", "wrist", "hand", "hand_tip", "thumb")
#: The roles of a leg's joints, in the order of :func:`leg`.
LEG_ROLES = ("hip", "knee", "ankle", "foot")


def arm(skeleton: SkeletonFormat, side: str) -> tuple[int, ...]:
    """The ``side`` arm's joint ids: shoulder, elbow, wrist, hand, hand tip, thumb."""
    group = skeleton.group(f"arm_{side}")
    return tuple(group[role] for role in ARM_ROLES)


def leg(skeleton: SkeletonFormat, side: str) -> tuple[int, ...]:
    """The ``side`` leg's joint ids: hip, knee, ankle, foot."""
    group = skeleton.group(f"leg_{side}")
    return tuple(group[role] for role in LEG_ROLES)


#: Per-side Kinect v2 arm joints (shoulder, elbow, wrist, hand, hand tip, thumb): :func:`arm`.
ARM = {side: arm(KINECT_V2, side) for side in ("left", "right")}


@dataclass(frozen=True)
class Operator:
    """A seated adult operator facing the robot (all lengths in m).

    Attributes
    ----------
    x_m, distance_m
        Position of the spine along x and in front of the robot base along +y (default:
        the paper's place beside the iiwa; each arm's task file gives its own).
    upper_arm_m, forearm_m, hand_m
        Segment lengths shoulder-elbow, elbow-wrist, wrist-hand.
    shoulder_half_width_m
        Half the distance between the shoulders.
    max_lean_m
        How far the upper body may lean towards an out-of-reach target.
    skeleton
        The skeleton format of the frames made (default: the Kinect v2's).
    """

    x_m: float = 0.15
    distance_m: float = 1.05
    upper_arm_m: float = 0.28
    forearm_m: float = 0.25
    hand_m: float = 0.08
    shoulder_half_width_m: float = 0.18
    max_lean_m: float = 0.35
    skeleton: SkeletonFormat = KINECT_V2
    _rest: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # the rest pose once (every generated frame starts from it: 0.24 ms each time)
        object.__setattr__(self, "_rest", self._rest_pose())

    def arm(self, side: str) -> tuple[int, ...]:
        """The ``side`` arm's joint ids (:func:`arm`)."""
        return arm(self.skeleton, side)

    def rest(self) -> np.ndarray:
        """(J, 3) skeleton at rest: seated upright, forearms on the table, hands in front
        (a copy: the caller may move it)."""
        return self._rest.copy()

    def _rest_pose(self) -> np.ndarray:
        """:meth:`rest`, computed."""
        x, y = self.x_m, self.distance_m
        spine = self.skeleton.group("spine")
        j = np.zeros((self.skeleton.n_joints, 3))
        j[spine["base"]] = (x, y + 0.05, -0.20)
        j[spine["mid"]] = (x, y + 0.02, 0.08)
        j[spine["chest"]] = (x, y, 0.32)
        j[spine["neck"]] = (x, y, 0.40)
        j[spine["head"]] = (x, y - 0.02, 0.52)
        for side, sign in (("left", 1.0), ("right", -1.0)):
            # Facing -y, the operator's left is +x. Hands rest on the table 0.3 m in
            # front of the chest, a little inside the shoulders.
            sh = np.array([x + sign * self.shoulder_half_width_m, y, 0.30])
            hand = np.array([sh[0] - sign * 0.08, y - 0.30, 0.06])
            j[self.arm(side)[0]] = sh
            self._place_arm(j, side, hand)
            # Seated: thighs forward along -y, shins down, hips 0.1 m either side.
            hx = x + sign * 0.1
            hip, knee, ankle, foot = leg(self.skeleton, side)
            j[hip] = (hx, y + 0.05, -0.25)
            j[knee] = (hx, y - 0.35, -0.25)
            j[ankle] = (hx, y - 0.35, -0.70)
            j[foot] = (hx, y - 0.45, -0.72)
        return j

    def reach(self, joints: np.ndarray, side: str, target: ArrayLike) -> np.ndarray:
        """Copy of ``joints`` with the ``side`` hand (Hand joint) moved to ``target`` (3,).

        The elbow hangs below the shoulder-wrist line. A target beyond the arm's reach
        makes the operator lean: the upper body (from SpineShoulder up, both arms) shifts
        horizontally towards it by the missing length, at most ``max_lean_m`` (SpineMid
        by half as much, SpineBase not at all). What is still out of reach is approached
        as far as the arm goes along the shoulder-target line.
        """
        out = np.array(joints, dtype=float, copy=True)
        target = np.asarray(target, dtype=float)
        shoulder = out[self.arm(side)[0]]
        missing = np.linalg.norm(target - shoulder) - 0.98 * (
            self.upper_arm_m + self.forearm_m + self.hand_m
        )
        horizontal = (target - shoulder) * [1.0, 1.0, 0.0]
        if missing > 0 and np.linalg.norm(horizontal) > 1e-9:
            lean = min(missing, self.max_lean_m) * horizontal / np.linalg.norm(horizontal)
            out[list(self._upper())] += lean
            out[self.skeleton.group("spine")["mid"]] += 0.5 * lean
        self._place_arm(out, side, target)
        return out

    def _upper(self) -> tuple[int, ...]:
        """Joints that move with the upper body when the operator leans: the spine from
        the chest up, and both arms."""
        spine = self.skeleton.group("spine")
        return (
            spine["chest"],
            spine["neck"],
            spine["head"],
            *self.arm("left"),
            *self.arm("right"),
        )

    def _place_arm(self, j: np.ndarray, side: str, hand: np.ndarray) -> None:
        s_id, e_id, w_id, h_id, tip_id, th_id = self.arm(side)
        a, b, c = self.upper_arm_m, self.forearm_m, self.hand_m
        s = j[s_id]
        to_hand = hand - s
        dist = float(np.linalg.norm(to_hand))
        u = to_hand / dist if dist > 1e-9 else np.array([0.0, -1.0, 0.0])
        dist = min(dist, a + b + c - 1e-6)
        hand = s + dist * u
        wrist = hand - c * u
        sw = wrist - s
        L = np.clip(np.linalg.norm(sw), abs(a - b) + 1e-6, a + b - 1e-6)
        n = unit(sw, floor=1e-9)
        down = np.array([0.0, 0.0, -1.0])
        m = down - (down @ n) * n
        if np.linalg.norm(m) < 1e-6:
            m = np.array([1.0, 0.0, 0.0]) - n[0] * n
        m = unit(m)
        cos_t = (a * a + L * L - b * b) / (2 * a * L)
        t = np.arccos(np.clip(cos_t, -1.0, 1.0))
        j[e_id] = s + a * (np.cos(t) * n + np.sin(t) * m)
        j[w_id] = s + L * n
        j[h_id] = j[w_id] + c * u
        j[tip_id] = j[h_id] + 0.05 * u
        j[th_id] = j[h_id] + 0.03 * u + 0.02 * m


def random_posture(
    rng: np.random.Generator,
    robot_points: np.ndarray,
    operator: Operator | None = None,
    spread_m: float = 0.25,
) -> np.ndarray:
    """A random seated posture with one hand near the robot.

    Parameters
    ----------
    rng
        Random generator.
    robot_points
        (P, 3) points on the robot; the hand goes near a random one of them.
    operator
        The operator (default :class:`Operator`), shifted by up to 0.15 m in x and y.
    spread_m
        Standard deviation of the hand target around the robot point, m.
    """
    op = operator or Operator()
    op = Operator(
        x_m=op.x_m + rng.uniform(-0.15, 0.15),
        distance_m=op.distance_m + rng.uniform(-0.15, 0.1),
        skeleton=op.skeleton,
    )
    joints = op.rest()
    side = "right" if rng.random() < 0.5 else "left"
    target = robot_points[rng.integers(len(robot_points))] + rng.normal(0.0, spread_m, 3)
    joints = op.reach(joints, side, target)
    return joints + rng.normal(0.0, 0.005, joints.shape)
