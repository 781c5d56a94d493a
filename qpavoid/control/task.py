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
``[scaling]`` and comments). ``docs/tasks.md`` says more: the frames and units of every
key, how to write a task, the operator's seat, and ``qpavoid run --task FILE``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path

import numpy as np
import pinocchio as pin

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import Robot
from qpavoid.control.path import ArcPath, PlannedPath, WaypointPath
from qpavoid.core.checks import one_line
from qpavoid.core.errors import IKNotConvergedError, RobotDescriptionError
from qpavoid.core.file_bounds import NotTOMLError, read_toml
from qpavoid.core.geometry import orthonormalize
from qpavoid.human.posture import Operator

#: The task file of a robot description folder (optional; docs in this module).
TASK_FILE = "task.toml"
#: Most bytes a task file may have (the iiwa's has about 3 kB): checked before reading.
MAX_TASK_BYTES = 2**20
#: Keys of the task file, of a waypoint, of ``[operator]``, ``[test2]`` and ``[scaling]``
#: (a misspelt one would otherwise be ignored).
TASK_KEYS = ("waypoints", "operator", "test2", "strikes", "scaling")
WAYPOINT_KEYS = ("position_m", "rotation", "rpy_rad", "joints_rad", "duration_s", "sagitta_m")
OPERATOR_KEYS = ("x_m", "distance_m", "max_lean_m")
TEST2_KEYS = ("operator_x_m", "operator_distance_m")
SCALING_KEYS = ("reference", "shoulder", "reach_m", "scale")
#: How far a written rotation matrix may be from a rotation, ``‖RᵀR − I‖`` (Frobenius):
#: the paper prints its matrices to 3-4 digits (8e-5 for its poses); beyond 0.01 it is a
#: typo, not rounding.
MAX_ROTATION_DEFECT = 1e-2
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
    reader.keys(data, TASK_KEYS, "the top level", "")
    waypoints = data.get("waypoints")
    if not isinstance(waypoints, list) or len(waypoints) < 2:
        raise reader.error(
            "waypoints",
            "give at least two [[waypoints]] tables: the start, then each waypoint with "
            "its duration_s",
            waypoints,
        )
    poses = [reader.pose(w, k) for k, w in enumerate(waypoints)]
    _check_reachable(poses, robot, reader)
    segments = []
    for k in range(1, len(poses)):
        where = f"waypoints[{k}]"
        duration = reader.number(waypoints[k], "duration_s", where, low=0.0, strict=True)
        sagitta = reader.number(waypoints[k], "sagitta_m", where, low=0.0, default=0.0)
        R0, R1 = orthonormalize(poses[k - 1][:3, :3]), orthonormalize(poses[k][:3, :3])
        turn = bool(np.linalg.norm(pin.log3(R0.T @ R1)) > MIN_TURN_RAD)
        segments.append(ArcPath(poses[k - 1], poses[k], duration, sagitta, turn))
    for key in ("duration_s", "sagitta_m"):
        if key in waypoints[0]:
            raise reader.error(
                f"waypoints[0].{key}",
                "the first waypoint is the start: give its duration_s and sagitta_m to "
                "the next one (the segment that ends there)",
                waypoints[0][key],
            )
    default = Task()
    op = reader.table(data, "operator", OPERATOR_KEYS)
    operator = Operator(
        x_m=reader.number(op, "x_m", "operator", default=default.operator.x_m),
        distance_m=reader.number(
            op, "distance_m", "operator", low=0.0, strict=True, default=default.operator.distance_m
        ),
        max_lean_m=reader.number(
            op, "max_lean_m", "operator", low=0.0, default=default.operator.max_lean_m
        ),
    )
    test2 = reader.table(data, "test2", TEST2_KEYS)
    test2_x = reader.number(test2, "operator_x_m", "test2", default=default.test2_operator.x_m)
    test2_distance = reader.number(
        test2, "operator_distance_m", "test2", low=0.0, strict=True, default=operator.distance_m
    )
    return Task(
        WaypointPath(tuple(segments)),
        operator,
        replace(operator, x_m=test2_x, distance_m=test2_distance),
        reader.body_targets(data.get("strikes", {})),
        reader.scaling(data),
        path,
    )


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
    """Checks and reads the parts of one task file, every error naming the file and key."""

    def __init__(self, path: Path, robot: Robot):
        self.path, self.robot = path, robot

    def error(self, key: str, message: str, value: object = None) -> RobotDescriptionError:
        """The error for ``key``: ``<file>: <key>: <message>`` (one line)."""
        return RobotDescriptionError(
            f"{self.path}: {key}: {message}", path=self.path, name=key, value=value
        )

    def keys(self, table: object, allowed: tuple[str, ...], where: str, prefix: str) -> None:
        """Refuse a table that is not one, or a key of it that is not ``allowed``."""
        if not isinstance(table, dict):
            raise self.error(where, "must be a table", table)
        for key in table:
            if key not in allowed:
                raise self.error(
                    prefix + str(key), f"unknown key in {where}; known: {', '.join(allowed)}"
                )

    def table(self, data: dict, key: str, allowed: tuple[str, ...]) -> dict:
        """The optional table ``[key]`` (empty if absent), its keys checked."""
        table = data.get(key, {})
        self.keys(table, allowed, f"[{key}]", f"{key}.")
        return table

    def number(
        self,
        table: dict,
        key: str,
        where: str,
        *,
        low: float = -math.inf,
        strict: bool = False,
        default: float | None = None,
    ) -> float:
        """``table[key]`` as a finite float above ``low`` (or at it, unless ``strict``)."""
        name = f"{where}.{key}"
        if key not in table:
            if default is None:
                raise self.error(name, "missing: give it (docs: qpavoid.control.task)")
            return default
        value = table[key]
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        number = float(value) if ok else math.nan
        if not math.isfinite(number) or number < low or (strict and number == low):
            bound = "" if low == -math.inf else f" {'above' if strict else 'at least'} {low:g}"
            raise self.error(name, f"must be a finite number{bound}, got {value!r}", value)
        return number

    def vector(self, table: dict, key: str | int, where: str, n: int) -> np.ndarray:
        """``table[key]`` as ``n`` finite numbers."""
        value = table[key]
        if (
            not isinstance(value, list)
            or len(value) != n
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
            or not all(math.isfinite(v) for v in value)
        ):
            name = f"{where}[{key}]" if isinstance(key, int) else f"{where}.{key}"
            raise self.error(name, f"must be {n} finite numbers, got {value!r}", value)
        return np.array(value, dtype=float)

    def pose(self, waypoint: object, k: int) -> np.ndarray:
        """The pose (4, 4) of waypoint ``k``: its position and rotation, or the end
        effector's pose at its joint angles (Pinocchio's forward kinematics)."""
        where = f"waypoints[{k}]"
        self.keys(waypoint, WAYPOINT_KEYS, where, f"{where}.")
        assert isinstance(waypoint, dict)  # keys() refused anything else
        given = [
            key for key in ("position_m", "rotation", "rpy_rad", "joints_rad") if key in waypoint
        ]
        if given == ["joints_rad"]:
            return self.robot.end_effector(self.joints(waypoint["joints_rad"], where))
        if len(given) != 2 or given[0] != "position_m" or given[1] == "joints_rad":
            raise self.error(
                where,
                "give position_m and one of rotation (3 rows) or rpy_rad, or joints_rad "
                f"alone; got {given}",
            )
        T = np.eye(4)
        T[:3, 3] = self.vector(waypoint, "position_m", where, 3)
        if given[1] == "rpy_rad":
            T[:3, :3] = pin.rpy.rpyToMatrix(*self.vector(waypoint, "rpy_rad", where, 3))
            return T
        rows = waypoint["rotation"]
        if not isinstance(rows, list) or len(rows) != 3:
            raise self.error(
                f"{where}.rotation", f"must be 3 rows of 3 numbers, got {rows!r}", rows
            )
        R = np.array(
            [self.vector(dict(enumerate(rows)), i, f"{where}.rotation", 3) for i in range(3)]
        )
        defect = float(np.linalg.norm(R.T @ R - np.eye(3)))
        if defect > MAX_ROTATION_DEFECT or np.linalg.det(R) <= 0:
            raise self.error(
                f"{where}.rotation",
                f"not a rotation matrix (‖RᵀR − I‖ = {defect:.2g}, det {np.linalg.det(R):.3g}):"
                " give its rows (orthonormal, det +1, to 2 digits at least) or rpy_rad",
                rows,
            )
        T[:3, :3] = R  # as written: ArcPath takes the nearest rotation
        return T

    def joints(self, value: object, where: str) -> np.ndarray:
        """The joint angles (nq,) of a ``joints_rad`` table naming every joint of the
        model (a locked joint only at its locked angle)."""
        robot, key = self.robot, f"{where}.joints_rad"
        if not isinstance(value, dict):
            raise self.error(key, "must be a table { <joint> = <angle, rad>, ... }", value)
        q = np.zeros(robot.nq)
        for name, angle in value.items():
            number = self.number(value, name, key)
            if name in robot.joint_names:
                i = robot.joint_names.index(name)
                if not robot.q_min[i] <= number <= robot.q_max[i]:
                    raise self.error(
                        f"{key}.{name}",
                        f"{number:g} rad is outside the joint's limits "
                        f"[{robot.q_min[i]:g}, {robot.q_max[i]:g}]",
                        angle,
                    )
                q[i] = number
            elif name in robot.locked:
                if abs(number - robot.locked[name]) > LOCKED_ANGLE_TOLERANCE_RAD:
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

    def frame(self, name: object, key: str) -> str:
        """``name`` if it is a frame of the robot's model."""
        if not isinstance(name, str) or not self.robot.model.existFrame(name):
            frames = [f.name for f in self.robot.model.frames][:40]
            raise self.error(
                key, f"no frame {name!r} in the robot's model; its frames are {frames}", name
            )
        return name

    def body_targets(self, strikes: object) -> tuple[BodyTarget, ...]:
        """The ``[strikes]`` table: ``<name> = "<frame>"`` or ``{ frame, xyz }``."""
        if not isinstance(strikes, dict):
            raise self.error("strikes", "must be a table [strikes] of <name> = <frame>", strikes)
        out = []
        for name, spot in strikes.items():
            key = f"strikes.{name}"
            if name in self.robot.set_names:
                raise self.error(key, "a set's name: strikes aim at every set already; rename it")
            if isinstance(spot, str):
                out.append(BodyTarget(name, self.frame(spot, key)))
                continue
            self.keys(spot, ("frame", "xyz"), key, f"{key}.")
            assert isinstance(spot, dict)
            if "frame" not in spot or "xyz" not in spot:
                raise self.error(
                    key, 'must be "<frame>" or { frame = "<frame>", xyz = [x, y, z] }', spot
                )
            x, y, z = (float(v) for v in self.vector(spot, "xyz", key, 3))
            target = BodyTarget(name, self.frame(spot["frame"], f"{key}.frame"), (x, y, z))
            out.append(target)
        return tuple(out)

    def scaling(self, data: dict) -> TaskScaling | None:
        """The optional ``[scaling]`` table."""
        if "scaling" not in data:
            return None
        table = self.table(data, "scaling", SCALING_KEYS)
        for key in ("reference", "shoulder"):
            if not isinstance(table.get(key), str):
                raise self.error(f"scaling.{key}", "must be a name (text)", table.get(key))
        return TaskScaling(
            table["reference"],
            self.frame(table["shoulder"], "scaling.shoulder"),
            self.number(table, "reach_m", "scaling", low=0.0, strict=True),
            self.number(table, "scale", "scaling", low=0.0, strict=True),
        )
