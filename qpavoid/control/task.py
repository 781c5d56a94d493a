"""The arm's task and where the people around it are: the task file of a description.

Task files
----------
A robot description folder may hold a ``task.toml`` (:data:`TASK_FILE`): the arm's task
and where the people around it are, read by :func:`default_task` (without one, the
paper's: :class:`Task`'s defaults). Everything is in the robot's base frame, m and rad::

    [[waypoints]]                 # the start
    position_m = [0.3524, 0.6105, 0.5779]
    rotation = [[0.25, -0.866, 0.433], [0.433, 0.5, 0.75], [-0.866, 0.0, 0.5]]

    [[waypoints]]                 # the next pose, reached duration_s after the one before
    position_m = [-0.0476, 0.6105, 0.6779]
    rpy_rad = [0.0, 1.047, 0.524] # or the orientation as roll, pitch, yaw
    duration_s = 15.0             # this segment's time, s (> 0)
    sagitta_m = 0.08              # optional: an arc this high above the chord (default 0)

    [[waypoints]]                 # or a configuration: the end effector's pose there
    joints_rad = { A1 = 0.5, A2 = 0.6, A4 = -1.4, A5 = 0.0, A6 = -1.0, A7 = 0.0 }
    duration_s = 5.0

    [operator]                    # the seated operator (qpavoid.human.posture.Operator)
    x_m = 0.15                    # spine along x, m
    distance_m = 1.05             # in front of the base along +y, m
    max_lean_m = 0.35             # how far the upper body leans towards a target out of reach

    [test2]
    operator_x_m = -0.25          # the operator of test 2, along x, m
    operator_distance_m = 1.05    # and along +y (default: [operator]'s), m

    [strikes]                     # where strikes aim besides the sets: a frame's origin,
    shoulder = "A2"               # or an offset in its axes (moving with its body)
    base = { frame = "A1", xyz = [0.0, 0.0, 0.1025] }

    [scaling]                     # optional, documentation checked by the tests
    reference = "iiwa14"          # the task this one was scaled from
    shoulder = "A2"               # the frame the reach is measured from
    reach_m = 0.946               # arm_reach(robot, shoulder)
    scale = 1.0                   # reach_m over the reference's

* A **waypoint** is a pose, ``position_m`` (3 numbers) with either ``rotation`` (the
  rotation matrix's three rows; the nearest rotation is taken, as the paper prints its
  matrices to 3-4 digits: a matrix further than :data:`MAX_ROTATION_DEFECT` from a
  rotation is refused) or ``rpy_rad`` (roll, pitch, yaw about the fixed x, y, z axes:
  ``R = R_z(yaw) R_y(pitch) R_x(roll)``, Pinocchio's ``rpy.rpyToMatrix``); or a joint
  configuration ``joints_rad`` naming every joint of the arm (a locked one only at its
  locked angle), taken as the end effector's pose there (forward kinematics).
* Each waypoint after the first ends a **segment** (an :class:`ArcPath`) from the one
  before, travelled in its ``duration_s`` with the quintic time law: the end effector
  stops at every waypoint. The position follows a straight line, or an arc
  ``sagitta_m`` above the chord in the vertical plane through it; the orientation turns
  from one waypoint's to the next about one fixed axis, or is held where the two differ
  by less than :data:`MIN_TURN_RAD` (the paper's).
* A run starts at the inverse kinematics of the first pose from the description's
  ``[ik_seed]`` (also for a first waypoint given as joint angles).

The iiwa's ``robots/iiwa14/task.toml`` is the paper's task, and gives :class:`ArcPath`'s
references bit for bit; the other arms' files scale it by their reach (their
``[scaling]`` and comments). The file's shape (its keys, types and plausible ranges) is a
schema, :mod:`qpavoid.control.task_schema`. ``docs/tasks.md`` says more: the frames and
units of every key, how to write a task, the operator's seat, and ``qpavoid run --task
FILE``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path

import numpy as np
import pinocchio as pin

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import Robot
from qpavoid.control.path import ArcPath, PlannedPath, WaypointPath
from qpavoid.control.task_schema import (
    MAX_ROTATION_DEFECT,
    ScalingTable,
    StrikeTable,
    TaskFile,
    WaypointTable,
)
from qpavoid.core.checks import one_line
from qpavoid.core.errors import IKNotConvergedError, RobotDescriptionError
from qpavoid.core.file_bounds import NotTOMLError, read_toml
from qpavoid.core.geometry import orthonormalize
from qpavoid.core.schema import convert
from qpavoid.human.posture import Operator

#: The task file of a robot description folder (optional; docs in this module).
TASK_FILE = "task.toml"
#: Most bytes a task file may have (the iiwa's has about 3 kB): checked before reading.
MAX_TASK_BYTES = 2**20
#: Turns below this angle between two waypoints' orientations are rounding: the segment
#: holds the first one (as the paper's, whose two poses print one orientation), rad.
MIN_TURN_RAD = 1e-9
#: How far a locked joint named in ``joints_rad`` may be from its locked angle, rad.
LOCKED_ANGLE_TOLERANCE_RAD = 1e-9


@dataclass(frozen=True)
class BodyTarget:
    """A place a strike aims at besides the robot's sets (``[strikes]``).

    Attributes
    ----------
    name
        Its name (``"shoulder"``, ``"base"`` for the iiwa's).
    frame
        The frame of the robot model it moves with.
    xyz_m
        Offset from the frame's origin in the frame's axes, m.
    """

    name: str
    frame: str
    xyz_m: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class TaskScaling:
    """How a task was made from another arm's (``[scaling]``, documentation checked by
    the tests): every position ``p' = c' + s (p − c)``, ``c`` the shoulder centre
    (:func:`shoulder_centre`), ``s = reach' / reach`` (:func:`arm_reach`).

    Attributes
    ----------
    reference
        The bundled description the task was scaled from (``"iiwa14"``; itself for the
        iiwa's).
    shoulder
        The frame whose origin is the shoulder (the iiwa's ``A2``).
    reach_m
        This arm's reach, m (:func:`arm_reach` from ``shoulder``).
    scale
        ``s``: this arm's reach over the reference's.
    """

    reference: str
    shoulder: str
    reach_m: float
    scale: float


@dataclass(frozen=True)
class Task:
    """What an arm does in the paper's tests and where the people around it are.

    Attributes
    ----------
    path
        The planned end-effector path (default: the paper's arc, :class:`ArcPath`).
    operator
        The seated operator of ``free``, ``test1`` and the random approaches (their
        centre, randomised) (default: the paper's place, 0.15 m along x and 1.05 m in
        front of the iiwa's base).
    test2_operator
        The operator of ``test2``, who reaches towards the scaled set (the paper's: 0.4
        m further to −x, so that leaning in keeps the head clear of the end effector).
    body_targets
        Where a strike aims besides the robot's sets (default: none).
    scaling
        How the task was made from another arm's, if it was.
    file
        The task file it was read from (None: the defaults).
    """

    path: PlannedPath = field(default_factory=ArcPath)
    operator: Operator = field(default_factory=Operator)
    test2_operator: Operator = field(default_factory=lambda: Operator(x_m=-0.25))
    body_targets: tuple[BodyTarget, ...] = ()
    scaling: TaskScaling | None = None
    file: Path | None = None


def default_task(robot: Robot, folder: str | PathLike[str] | None = None) -> Task:
    """The arm's task: the ``task.toml`` of its description folder (:func:`load_task`), or
    without one the paper's (:class:`Task`'s defaults).

    Parameters
    ----------
    robot
        The arm.
    folder
        Its description folder (default: the folder of the control-point file it was read
        from, ``robot.path``; a robot made in code, without one, gets the paper's task).

    Raises
    ------
    RobotDescriptionError
        As :func:`load_task`.
    """
    if folder is None and robot.path is not None:
        folder = robot.path.parent
    file = Path(folder) / TASK_FILE if folder is not None else None
    if file is None or not file.exists():
        return Task()
    return load_task(file, robot)


def load_task(file: str | PathLike[str], robot: Robot) -> Task:
    """Read a task file for ``robot`` (format: this module's docs and ``robots/iiwa14/task.toml``).

    The file's shape is :class:`~qpavoid.control.task_schema.TaskFile`'s, refused in one line
    naming the field's path (``waypoints[1].duration_s must be a number above 0 ...``); what
    needs the robot or several keys is checked here (``<file>: <key>: <what is wrong>``).

    Raises
    ------
    RobotDescriptionError
        With the file, the key at fault and how to fix it: a file that cannot be read or
        is not TOML, an unknown key, fewer than two waypoints, a waypoint that is not one
        position and one rotation (``rotation`` or ``rpy_rad``) or one ``joints_rad``, a
        number that is not finite or out of range, a rotation that is not one, a joint
        or frame the robot lacks, a locked joint away from its angle.
    """
    path = Path(file)
    try:
        data = read_toml(path, MAX_TASK_BYTES)
    except NotTOMLError as exc:
        raise RobotDescriptionError(f"{path}: not TOML: {one_line(exc)}", path=path) from None
    except (OSError, ValueError) as exc:  # missing, too large, not a regular file
        raise RobotDescriptionError(
            f"{path}: cannot read the task file: {one_line(exc)}", path=path
        ) from None
    reader = _TaskReader(path, robot)
    task = convert(data, TaskFile, reader.refused)
    waypoints = task.waypoints
    for key in ("duration_s", "sagitta_m"):
        if getattr(waypoints[0], key) is not None:
            raise reader.error(
                f"waypoints[0].{key}",
                "the first waypoint is the start: give its duration_s and sagitta_m to "
                "the next one (the segment that ends there)",
                getattr(waypoints[0], key),
            )
    poses = [reader.pose(w, k) for k, w in enumerate(waypoints)]
    _check_reachable(poses, robot, reader)
    segments = []
    for k in range(1, len(poses)):
        duration, sagitta = waypoints[k].duration_s, waypoints[k].sagitta_m
        if duration is None:
            raise reader.error(
                f"waypoints[{k}].duration_s", "missing: give it (docs: qpavoid.control.task)"
            )
        R0, R1 = orthonormalize(poses[k - 1][:3, :3]), orthonormalize(poses[k][:3, :3])
        turn = bool(np.linalg.norm(pin.log3(R0.T @ R1)) > MIN_TURN_RAD)
        segments.append(ArcPath(poses[k - 1], poses[k], duration, sagitta or 0.0, turn))
    paper, op, test2 = Task(), task.operator, task.test2
    operator = Operator(
        x_m=_given(op.x_m, paper.operator.x_m),
        distance_m=_given(op.distance_m, paper.operator.distance_m),
        max_lean_m=_given(op.max_lean_m, paper.operator.max_lean_m),
    )
    return Task(
        WaypointPath(tuple(segments)),
        operator,
        replace(
            operator,
            x_m=_given(test2.operator_x_m, paper.test2_operator.x_m),
            distance_m=_given(test2.operator_distance_m, operator.distance_m),
        ),
        reader.body_targets(task.strikes),
        None if task.scaling is None else reader.scaling(task.scaling),
        path,
    )


def _given(value: float | None, default: float) -> float:
    """A key's value, or its default where the file leaves it out."""
    return default if value is None else value


def _check_reachable(poses: list[np.ndarray], robot: Robot, reader: _TaskReader) -> None:
    """Refuse a waypoint the arm cannot reach: the inverse kinematics of each, from the
    description's seed for the first and from the one before's solution for the others
    (the branch the arm tracks along), must converge within the joint limits."""
    q = None
    for k, pose in enumerate(poses):
        target = pose.copy()
        target[:3, :3] = orthonormalize(pose[:3, :3])  # as the path takes it
        try:
            q = inverse_kinematics(robot, target, q)
        except IKNotConvergedError as exc:
            where = "the one before" if k else "the description's [ik_seed]"
            raise reader.error(
                f"waypoints[{k}]",
                f"the arm cannot reach this pose from {where} ({one_line(exc)}); "
                "move it within the arm's reach, or give the description an [ik_seed] "
                "on the branch that reaches it",
                [round(float(v), 4) for v in pose[:3, 3]],
            ) from None


class _TaskReader:
    """Checks what a task file's schema cannot (module docstring of
    :mod:`qpavoid.control.task_schema`), every error naming the file and key."""

    def __init__(self, path: Path, robot: Robot):
        self.path, self.robot = path, robot

    def error(self, key: str, message: str, value: object = None) -> RobotDescriptionError:
        """The error for ``key``: ``<file>: <key>: <message>`` (one line)."""
        return RobotDescriptionError(
            f"{self.path}: {key}: {message}", path=self.path, name=key, value=value
        )

    def refused(self, name: str, message: str, value: object) -> RobotDescriptionError:
        """A schema's refusal (:func:`~qpavoid.core.schema.convert`): ``<file>: <message>``,
        the message naming the field's path."""
        return RobotDescriptionError(
            f"{self.path}: {message}", path=self.path, name=name, value=value
        )

    def pose(self, waypoint: WaypointTable, k: int) -> np.ndarray:
        """The pose (4, 4) of waypoint ``k``: its position and rotation, or the end
        effector's pose at its joint angles (Pinocchio's forward kinematics)."""
        where = f"waypoints[{k}]"
        given = [
            key
            for key in ("position_m", "rotation", "rpy_rad", "joints_rad")
            if getattr(waypoint, key) is not None
        ]
        if waypoint.joints_rad is not None and given == ["joints_rad"]:
            return self.robot.end_effector(self.joints(waypoint.joints_rad, where))
        if len(given) != 2 or given[0] != "position_m" or given[1] == "joints_rad":
            raise self.error(
                where,
                "give position_m and one of rotation (3 rows) or rpy_rad, or joints_rad "
                f"alone; got {given}",
            )
        T = np.eye(4)
        T[:3, 3] = waypoint.position_m
        if waypoint.rpy_rad is not None:
            T[:3, :3] = pin.rpy.rpyToMatrix(*waypoint.rpy_rad)
            return T
        R = np.array(waypoint.rotation, dtype=float)
        defect = float(np.linalg.norm(R.T @ R - np.eye(3)))
        if defect > MAX_ROTATION_DEFECT or np.linalg.det(R) <= 0:
            raise self.error(
                f"{where}.rotation",
                f"not a rotation matrix (‖RᵀR − I‖ = {defect:.2g}, det {np.linalg.det(R):.3g}):"
                " give its rows (orthonormal, det +1, to 2 digits at least) or rpy_rad",
                [list(row) for row in R.tolist()],
            )
        T[:3, :3] = R  # as written: ArcPath takes the nearest rotation
        return T

    def joints(self, value: dict[str, float], where: str) -> np.ndarray:
        """The joint angles (nq,) of a ``joints_rad`` table naming every joint of the
        model (a locked joint only at its locked angle)."""
        robot, key = self.robot, f"{where}.joints_rad"
        q = np.zeros(robot.nq)
        for name, angle in value.items():
            if name in robot.joint_names:
                i = robot.joint_names.index(name)
                if not robot.q_min[i] <= angle <= robot.q_max[i]:
                    raise self.error(
                        f"{key}.{name}",
                        f"{angle:g} rad is outside the joint's limits "
                        f"[{robot.q_min[i]:g}, {robot.q_max[i]:g}]",
                        angle,
                    )
                q[i] = angle
            elif name in robot.locked:
                if abs(angle - robot.locked[name]) > LOCKED_ANGLE_TOLERANCE_RAD:
                    raise self.error(
                        f"{key}.{name}",
                        f"the joint is locked at {robot.locked[name]:g} rad: give that "
                        "angle or leave it out",
                        angle,
                    )
            else:
                raise self.error(
                    f"{key}.{name}", f"no joint {name!r}; the joints are {robot.joint_names}"
                )
        missing = [n for n in robot.joint_names if n not in value]
        if missing:
            raise self.error(key, f"give every joint of the arm: {missing} missing", value)
        return q

    def frame(self, name: str, key: str) -> str:
        """``name`` if it is a frame of the robot's model."""
        if not self.robot.model.existFrame(name):
            frames = [f.name for f in self.robot.model.frames][:40]
            raise self.error(
                key, f"no frame {name!r} in the robot's model; its frames are {frames}", name
            )
        return name

    def body_targets(self, strikes: dict[str, str | StrikeTable]) -> tuple[BodyTarget, ...]:
        """The ``[strikes]`` table: ``<name> = "<frame>"`` or ``{ frame, xyz }``."""
        out = []
        for name, spot in strikes.items():
            key = f"strikes.{name}"
            if name in self.robot.set_names:
                raise self.error(key, "a set's name: strikes aim at every set already; rename it")
            if isinstance(spot, str):
                out.append(BodyTarget(name, self.frame(spot, key)))
            else:
                out.append(BodyTarget(name, self.frame(spot.frame, f"{key}.frame"), spot.xyz))
        return tuple(out)

    def scaling(self, table: ScalingTable) -> TaskScaling:
        """The ``[scaling]`` table, its shoulder a frame of the model."""
        shoulder = self.frame(table.shoulder, "scaling.shoulder")
        return TaskScaling(table.reference, shoulder, table.reach_m, table.scale)
