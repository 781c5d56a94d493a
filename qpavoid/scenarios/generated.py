"""Human motions for the paper's tests, generated in code, and random approaches.

A motion is anything with ``frame_at(t) -> (joints (J, 3), state (J,))``: these
scripted reaches, or a :class:`~qpavoid.sensing.recording.Recording`. The simulation samples it
at the camera rate (sample and hold).

* ``free``  the operator works at the table (hands circling 5 cm around their rest) and
  never comes near the robot;
* ``test1`` (paper Sect. 6.1) the right hand reaches to just beside the end effector's
  planned path, ahead of the robot, stays while the robot passes, and withdraws;
* ``test2`` (paper Sect. 6.2) the right hand comes close to L1 (near A3) until f
  exceeds 0.8 and the robot stops; it holds there, then withdraws;
* ``random:SEED`` (:func:`random_approach`) a hand moving at up to 1.6 m/s towards a
  random point of a random robot set, from a random direction, at a random time;
* ``closework:SEED`` (:mod:`qpavoid.scenarios.closework`) the operator working within
  reach of the path, never at the robot: hands resting or working 0.1-0.3 m from it,
  reaching across it, or handing over a part; ``rest_near``, ``work_near``,
  ``reach_across`` and ``handover`` are the fixed cases of
  :data:`~qpavoid.scenarios.closework.FIXED_SEEDS` (``closework:1``, ``closework:5``,
  ``closework:3``, ``closework:0``).

Targets are placed against the robot's *nominal* motion (the path tracked with nobody
near, :func:`nominal_configurations`), so they stay right if the path or radii change.
The path, where the operator sits and the sets aimed at are the arm's own: its task file
(:func:`~qpavoid.control.task.default_task`, the paper's for the iiwa, scaled by the reach
for the other arms) and its description's sets and roles.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import pairwise

import numpy as np

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import Robot
from qpavoid.control.path import ArcPath, PlannedPath, smoothstep
from qpavoid.control.task import Task, default_task
from qpavoid.core.errors import InputError
from qpavoid.core.geometry import unit
from qpavoid.distance.methods import distance_method
from qpavoid.human.body import KinectHuman
from qpavoid.human.posture import Operator
from qpavoid.human.skeleton import TRACKED
from qpavoid.scenarios.closework import (
    FIXED_SEEDS,
    VARIANTS,
    CloseWork,
    closework_case,
    closework_motion,
)


@dataclass(frozen=True)
class ScriptedReach:
    """The seated operator, one hand moving through keyframes, the rest still.

    Parameters
    ----------
    operator
        The operator's body.
    side
        ``"left"`` or ``"right"`` hand.
    keyframes
        ``(t_s, target)`` pairs in increasing time; ``target`` (3,) m is where the hand
        is at that time (``None`` = its rest position). Between keyframes the hand moves
        on a straight line with the quintic time law (:func:`~qpavoid.control.path.quintic`);
        before the first and after the last it holds.
    """

    operator: Operator
    side: str
    keyframes: tuple[tuple[float, np.ndarray | None], ...]

    def hand_position(self, t: float) -> np.ndarray:
        """The hand target at time ``t`` (s)."""
        rest = self.operator.rest()[_hand_joint(self.operator, self.side)]
        pts = [(tk, rest if p is None else np.asarray(p, dtype=float)) for tk, p in self.keyframes]
        if t <= pts[0][0]:
            return pts[0][1]
        for (t0, p0), (t1, p1) in pairwise(pts):
            if t <= t1:
                return p0 + smoothstep((t - t0) / (t1 - t0)) * (p1 - p0)
        return pts[-1][1]

    def frame_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Joints (J, 3) and states (J,) (all tracked) at time ``t``."""
        joints = self.operator.reach(self.operator.rest(), self.side, self.hand_position(t))
        return joints, np.full(len(joints), TRACKED, dtype=np.int8)


@dataclass(frozen=True)
class Working:
    """The ``free`` scenario: both hands circle ``radius_m`` around their rest position."""

    operator: Operator
    radius_m: float = 0.05
    period_s: float = 4.0

    def frame_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        joints = self.operator.rest()
        for side, phase in (("right", 0.0), ("left", np.pi)):
            w = 2 * np.pi * t / self.period_s + phase
            hand = joints[_hand_joint(self.operator, side)]
            target = hand + self.radius_m * np.array([np.cos(w), np.sin(w), 0])
            joints = self.operator.reach(joints, side, target)
        return joints, np.full(len(joints), TRACKED, dtype=np.int8)


def reach_and_return(
    operator: Operator, side: str, target: np.ndarray, times: tuple[float, float, float, float]
) -> ScriptedReach:
    """The ``side`` hand leaves its rest at ``times[0]``, is at ``target`` at ``times[1]``,
    holds it until ``times[2]`` and is back at rest at ``times[3]`` (s)."""
    leave, arrive, hold_until, back = times
    return ScriptedReach(
        operator, side, ((leave, None), (arrive, target), (hold_until, target), (back, None))
    )


def _hand_joint(operator: Operator, side: str) -> int:
    """The id of the ``side`` hand in the operator's skeleton format."""
    return operator.skeleton.group(f"arm_{side}")["hand"]


def nominal_configurations(robot: Robot, path: PlannedPath, times: np.ndarray) -> np.ndarray:
    """Joint angles (len(times), nq) tracking the path exactly, by IK from the start."""
    q = inverse_kinematics(robot, path.reference(0.0)[0])
    out = []
    for t in times:
        q = inverse_kinematics(robot, path.reference(float(t))[0], q0=q)
        out.append(q)
    return np.array(out)


def _clearance_target(
    robot: Robot,
    human: KinectHuman,
    path: PlannedPath,
    operator: Operator,
    side: str,
    anchor: np.ndarray,
    direction: np.ndarray,
    clearance_m: float,
    sets: tuple[str, ...],
    methods: tuple[str, ...] = ("spheres",),
) -> np.ndarray:
    """Hand target ``anchor + s·direction`` whose distance to ``sets`` over the nominal
    motion is ``clearance_m`` at its closest, by every one of the distance ``methods``
    (the largest of them; bisection on s)."""
    times = np.linspace(0, path.duration_s, 61)
    kins = [
        robot.kinematics(q, jacobians=False) for q in nominal_configurations(robot, path, times)
    ]
    tables = [distance_method(m, robot, human) for m in methods]
    rows = [robot.set_index(n) for n in sets]
    hand = human.part_names.index(f"{side}_hand")

    def closest(s: float) -> float:
        joints = operator.reach(operator.rest(), side, anchor + s * direction)
        geo = human.geometry(joints)
        return max(min(m(k, geo).distance[rows, hand].min() for k in kins) for m in tables)

    lo, hi = 0.0, 0.5
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if closest(mid) < clearance_m else (lo, mid)
    return anchor + hi * direction


def make_scenario(
    name: str,
    robot: Robot,
    path: PlannedPath | None = None,
    human: KinectHuman | None = None,
    operator: Operator | None = None,
    task: Task | None = None,
) -> ScriptedReach | Working | CloseWork:
    """The generated motion called ``name`` (``free``, ``test1``, ``test2``, ``random:SEED``,
    ``closework:SEED`` and the fixed close-work cases ``rest_near``, ``work_near``,
    ``reach_across``, ``handover``: module docstring).

    ``task`` (default: the arm's, :func:`~qpavoid.control.task.default_task`) gives the
    path and where the operator sits, unless ``path`` and ``operator`` are given.
    """
    task = task or default_task(robot)
    path = path or task.path
    human = human or KinectHuman()
    op = operator or task.operator
    if name == "free":
        return Working(op)
    if name == "test1":
        # Beside the wrist of the nominal motion at 60 % of the path: from the point half-way
        # between the wrist (the end of the repelled set's capsule nearer the end effector:
        # the iiwa's A6) and the end-effector frame (the flange), square to that axis,
        # towards the operator, so that the sets there come equally close: the nominal
        # motion's closest approach to every set but the scaled one (the iiwa's L2 and EE) is
        # 0.04 m, and the repulsion has to deflect the robot to keep it beyond the 0.05 m
        # stop distance.
        tc = 0.6 * path.duration_s
        kin = robot.kinematics(nominal_configurations(robot, path, np.array([tc]))[0], False)
        flange = kin.ee_placement[:3, 3]
        ends = kin.segments[robot.roles.repelled]
        wrist = ends[np.argmin(np.linalg.norm(ends - flange, axis=1))]
        axis = unit(flange - wrist)
        towards = np.array([0.0, 1.0, 0.3])  # the operator's side, above
        target = _clearance_target(
            robot,
            human,
            path,
            op,
            "right",
            0.5 * (wrist + flange),
            unit(towards - (towards @ axis) * axis),
            0.04,
            tuple(n for n in robot.set_names if n != robot.role_name("scaled")),
        )
        return reach_and_return(op, "right", target, (2.0, 5.0, 11.0, 14.0))
    if name == "test2":
        # Towards A3 (the lower half of L1) of the robot's start configuration, from the
        # operator's right and below L2 (which lies between the operator and L1), to
        # 0.02 m by spheres and by capsules (f = 0.96): the robot must stop, whichever
        # distance method it uses.
        # The operator sits where the task says (for the iiwa 0.4 m further to -x), so
        # that leaning in keeps the head clear of the end effector.
        op = operator or task.test2_operator
        q0 = inverse_kinematics(robot, path.reference(0.0)[0])
        anchor = robot.control_points(q0)[robot.sets[robot.roles.scaled].points[1]]
        target = _clearance_target(
            robot,
            human,
            ArcPath(path.start, path.start, 1.0, 0.0),
            op,
            "right",
            anchor,
            unit([-1.0, 0.5, -0.2]),
            0.02,
            (robot.role_name("scaled"),),
            ("spheres", "capsules"),
        )
        return reach_and_return(op, "right", target, (1.0, 4.0, 9.0, 11.0))
    seed = check_scenario_name(name)
    if name in VARIANTS or name.startswith(CLOSEWORK_PREFIX):
        task = replace(task, path=path, operator=op)
        case = closework_case(FIXED_SEEDS[name] if seed is None else seed, robot, task)
        return closework_motion(case, robot, task=task)
    return random_approach(np.random.default_rng(seed), robot, path, operator, task=task)


def check_scenario_name(name: str) -> int | None:
    """Check that ``name`` is a scenario; return the seed of ``random:SEED`` or
    ``closework:SEED`` (else None).

    Raises
    ------
    InputError
        For any other name, or a seed that is not a whole number >= 0.
    """
    if name in SCENARIOS:
        return None
    prefix = next((p for p in (RANDOM_PREFIX, CLOSEWORK_PREFIX) if name.startswith(p)), None)
    seed = name[len(prefix) :] if prefix is not None else None
    if seed is not None and seed.isdigit() and seed.isascii():
        return int(seed)
    raise InputError(
        f"unknown scenario {name!r}; choose from {', '.join(SCENARIOS)}, "
        f"{RANDOM_PREFIX}SEED or {CLOSEWORK_PREFIX}SEED (SEED a whole number >= 0)",
        name="scenario",
        value=name,
    )


def closework_seed(name: str) -> int | None:
    """The close-work case a scenario name runs (``closework:SEED``, or a fixed variant's
    :data:`~qpavoid.scenarios.closework.FIXED_SEEDS`), else None: its camera draws its
    noise from that seed, in a run as in a sweep (``qpavoid sweep --motion closework``),
    so a sweep's replay line repeats the run.

    Raises
    ------
    InputError
        For a name that is no scenario (:func:`check_scenario_name`).
    """
    seed = check_scenario_name(name)
    if name in VARIANTS:
        return FIXED_SEEDS[name]
    return seed if name.startswith(CLOSEWORK_PREFIX) else None


#: The scenarios by name: the paper's, the operator at work, the fixed close-work cases.
SCENARIOS = ("test1", "test2", "free", *VARIANTS)
#: The seeded scenarios' names start so: ``random:SEED``, ``closework:SEED``.
RANDOM_PREFIX, CLOSEWORK_PREFIX = "random:", "closework:"


def random_approach(
    rng: np.random.Generator,
    robot: Robot,
    path: PlannedPath | None = None,
    operator: Operator | None = None,
    max_speed_mps: float = 1.6,
    nominal: np.ndarray | None = None,
    task: Task | None = None,
) -> ScriptedReach:
    """A hand approaching a random robot set from a random direction at a random time.

    The target is a random control point of the robot's nominal configuration at a random
    path time (a point of any of the description's sets, each point as likely), shifted
    0-0.1 m along a random direction on the operator's side; the hand travels there at a
    random peak speed up to ``max_speed_mps`` (the quintic law peaks at 1.875 times the
    mean speed), holds 1-4 s, and withdraws. The path and the operator are the ``task``'s
    (default: the arm's, :func:`~qpavoid.control.task.default_task`), the operator moved
    by up to 0.2 m either way along x, unless ``path`` and ``operator`` are given.
    """
    task = task or default_task(robot)
    path = path or task.path
    seat = task.operator
    op = operator or replace(seat, x_m=seat.x_m + rng.uniform(-0.2, 0.2))
    times = np.linspace(0, path.duration_s, 31)
    if nominal is None:
        nominal = nominal_configurations(robot, path, times)
    k = rng.integers(len(times))
    P = robot.control_points(nominal[k])
    side = "right" if rng.random() < 0.7 else "left"
    direction = unit(rng.normal(size=3) + np.array([0.0, 1.5, 0.3]))
    target = P[rng.integers(len(P))] + rng.uniform(0.0, 0.1) * direction
    rest = op.rest()[_hand_joint(op, side)]
    peak = rng.uniform(0.3, max_speed_mps)
    travel = np.linalg.norm(target - rest) * 1.875 / peak
    start = max(0.0, times[k] - travel + rng.uniform(-3.0, 2.0))
    hold = rng.uniform(1.0, 4.0)
    return reach_and_return(
        op, side, target, (start, start + travel, start + travel + hold, start + 2 * travel + hold)
    )
