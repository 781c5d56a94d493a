"""Adversarial strikes: hands driven into the robot at a chosen speed, with sensor faults.

A :class:`StrikeCase` is one randomized attack on the controller: one or both hands move
from rest straight *into* a robot set (the target is on the set's capsule axis, so a robot
that does not get out of the way is hit), arriving at a random path time with a chosen
peak speed, holding there, then withdrawing. The targets (:func:`strike_targets`) are the
robot description's sets by name (``L1``, ``L2``, ``EE`` for the iiwa), then the places
its task file's ``[strikes]`` names (:func:`~qpavoid.control.task.default_task`; for the
iiwa the ``shoulder``, A2, and the ``base`` column 0.1 m under it). The operator sits where
the task file places it, moved by up to 0.15 m either way along x.
A fault can be laid on top (:class:`~qpavoid.loop.camera.CameraFault`): the striking hand
``lost`` or ``inferred`` as it arrives, a ``frozen`` sensor, a ``gap`` in the frames, or
``jitter`` (delayed and dropped frames all run long).

:func:`strike_case` draws a case from a seed; :func:`strike_motion` and
:func:`strike_camera` turn it into the true motion and the camera the controller sees through.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from qpavoid.arm.model import Robot, load_robot
from qpavoid.control.path import PlannedPath
from qpavoid.control.task import Task, default_task
from qpavoid.core.errors import InputError
from qpavoid.human.posture import ARM
from qpavoid.loop.camera import CameraConfig, CameraFault
from qpavoid.scenarios.generated import ScriptedReach, nominal_configurations, reach_and_return

#: Faults a case may carry ("none" for a clean sensor).
FAULTS = ("none", "lost", "inferred", "frozen", "gap", "jitter")


@dataclass(frozen=True)
class StrikeCase:
    """One randomized strike (all times on the run clock, s).

    Attributes
    ----------
    seed
        The seed it was drawn from.
    target
        One of the robot's :func:`strike_targets`.
    speed_mps
        Peak speed of the hand, m/s (the quintic time law peaks at 1.875 × the mean).
    side
        The striking hand, ``"right"`` or ``"left"``.
    both_hands
        The other hand strikes the next target at the same time.
    arrival_s
        When the hand reaches its target.
    fault
        One of :data:`FAULTS`.
    """

    seed: int
    target: str
    speed_mps: float
    side: str
    both_hands: bool
    arrival_s: float
    fault: str

    @property
    def duration_s(self) -> float:
        """How long to simulate: the approach, 1.5 s of holding, and 0.5 s more."""
        return self.arrival_s + 2.0


def strike_targets(robot: Robot, task: Task | None = None) -> tuple[str, ...]:
    """Where a strike may aim on ``robot``: each of its sets by name, then the places its
    ``task`` names (default: the arm's task file's ``[strikes]``,
    :func:`~qpavoid.control.task.default_task`)."""
    task = task or default_task(robot)
    return (*robot.set_names, *(target.name for target in task.body_targets))


@functools.cache
def _default_robot() -> Robot:
    """The default robot description (:func:`~qpavoid.arm.model.load_robot`), read once."""
    return load_robot()


def strike_case(
    seed: int, max_speed_mps: float = 2.0, robot: Robot | None = None, task: Task | None = None
) -> StrikeCase:
    """The strike of ``seed`` on ``robot`` (default: the default robot description): target
    (:func:`strike_targets` of ``task``, default the arm's), speed (0.5 to
    ``max_speed_mps``), fault, timing."""
    targets = strike_targets(robot or _default_robot(), task)
    rng = np.random.default_rng([seed, 9])
    return StrikeCase(
        seed,
        targets[int(rng.integers(len(targets)))],
        float(rng.uniform(0.5, max_speed_mps)),
        "right" if rng.random() < 0.7 else "left",
        bool(rng.random() < 0.25),
        float(rng.uniform(1.0, 6.0)),
        FAULTS[int(rng.integers(len(FAULTS)))],
    )


def _aim(
    robot: Robot, q: np.ndarray, target: str, rng: np.random.Generator, task: Task
) -> np.ndarray:
    """A point inside the robot at joint angles ``q``: on the named set's capsule axis, at
    ``a + u (b − a)``, u uniform in [0.2, 1]; or the place of the task's ``[strikes]``
    called ``target``: its frame's placement applied to its offset (Pinocchio)."""
    for body in task.body_targets:
        if body.name == target:
            data = robot.model.createData()
            pin.framesForwardKinematics(robot.model, data, q)
            return data.oMf[robot.model.getFrameId(body.frame)].act(np.array(body.xyz_m))
    a, b = robot.capsules(q)[robot.set_index(target)]
    return a + rng.uniform(0.2, 1.0) * (b - a)


class TwoHands:
    """Both hands scripted at once (the right hand's motion, then the left's on top)."""

    def __init__(self, right: ScriptedReach, left: ScriptedReach):
        self.right, self.left = right, left

    def frame_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        joints, state = self.right.frame_at(t)
        op = self.left.operator
        return op.reach(joints, "left", self.left.hand_position(t)), state


def strike_motion(
    case: StrikeCase, robot: Robot, path: PlannedPath | None = None, task: Task | None = None
) -> ScriptedReach | TwoHands:
    """The true motion of ``case``: hands from rest into their targets, held 1.5 s, back.

    The path (unless ``path`` is given), the operator's seat and the targets besides the
    sets are the ``task``'s (default: the arm's, :func:`~qpavoid.control.task.default_task`).
    """
    task = task or default_task(robot)
    path = path or task.path
    rng = np.random.default_rng([case.seed, 11])
    (q,) = nominal_configurations(robot, path, np.array([min(case.arrival_s, path.duration_s)]))
    op = replace(task.operator, x_m=task.operator.x_m + rng.uniform(-0.15, 0.15))
    reaches = {}
    sides = ("right", "left") if case.both_hands else (case.side,)
    targets = strike_targets(robot, task)
    if case.target not in targets:
        raise InputError(
            f"strike target {case.target!r} is not one of {targets}",
            name="target",
            value=case.target,
        )
    for n, side in enumerate(sides):
        target = targets[(targets.index(case.target) + n) % len(targets)]
        aim = _aim(robot, q, target, rng, task)
        start = op.reach(op.rest(), side, aim)[ARM[side][3]]  # where the hand can get to
        rest = op.rest()[ARM[side][3]]
        travel = float(np.linalg.norm(start - rest)) * 1.875 / case.speed_mps
        t0 = max(case.arrival_s - travel, 0.0)
        times = (t0, case.arrival_s, case.arrival_s + 1.5, case.arrival_s + 1.5 + travel)
        reaches[side] = reach_and_return(op, side, aim, times)
    if case.both_hands:
        return TwoHands(reaches["right"], reaches["left"])
    return reaches[case.side]


def strike_camera(case: StrikeCase, base: CameraConfig | None = None) -> CameraConfig:
    """The camera of ``case``: ``base`` (a Kinect v2) with the case's fault laid on."""
    base = base or CameraConfig(seed=case.seed)
    hand = [int(j) for j in ARM[case.side][2:]]  # wrist, hand, fingers
    window = (case.arrival_s - 0.3, case.arrival_s + 0.6)
    if case.fault in ("lost", "inferred"):
        return replace(base, faults=(CameraFault(case.fault, *window, tuple(hand)),))
    if case.fault == "frozen":
        return replace(base, faults=(CameraFault("freeze", *window),))
    if case.fault == "gap":
        return replace(base, faults=(CameraFault("gap", *window),))
    if case.fault == "jitter":
        return replace(base, jitter_s=0.03, dropout_probability=0.1)
    return base


__all__ = [
    "FAULTS",
    "StrikeCase",
    "TwoHands",
    "strike_camera",
    "strike_case",
    "strike_motion",
    "strike_targets",
]
