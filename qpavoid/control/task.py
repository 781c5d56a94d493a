"""The planned task (paper Sect. 3) and the task files that give each arm its own.

The paper gives the initial and final poses but not the curve. :class:`ArcPath` is a
circular arc through both positions in the vertical plane that contains them (y = 0.6105
for the paper's poses), bulging upwards by ``sagitta_m`` at its middle, traversed with
the quintic time law ``σ(τ) = 10τ³ − 15τ⁴ + 6τ⁵``, ``τ = t / T``: zero velocity and
acceleration at both ends. The orientation is the common orientation of both poses (or,
with ``turn``, turns from one to the other about a fixed axis).

The start configuration is the inverse kinematics of the initial pose
(:func:`inverse_kinematics`): damped Newton steps on Pinocchio's ``log6`` error from a
seed on the elbow-up, non-flipped-wrist branch that faces the target.

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
``[scaling]`` and comments).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import pinocchio as pin
from scipy.optimize import minimize

from qpavoid.arm.model import Robot
from qpavoid.core.checks import as_array, finite_number, one_line
from qpavoid.core.errors import IKNotConvergedError, InputError, RobotDescriptionError
from qpavoid.core.file_bounds import NotTOMLError, read_toml
from qpavoid.core.geometry import unit
from qpavoid.human.posture import Operator

#: The paper's initial and final end-effector poses (Sect. 3), base frame, m.
A_IN = np.array(
    [
        [0.25, -0.866, 0.433, 0.3524],
        [0.433, 0.5, 0.75, 0.6105],
        [-0.866, 0.0, 0.5, 0.5779],
        [0.0, 0.0, 0.0, 1.0],
    ]
)
A_FIN = np.array(
    [
        [0.25, -0.866, 0.433, -0.0476],
        [0.433, 0.5, 0.75, 0.6105],
        [-0.866, 0.0, 0.5, 0.6779],
        [0.0, 0.0, 0.0, 1.0],
    ]
)


def orthonormalize(R: np.ndarray) -> np.ndarray:
    """Nearest rotation matrix (the paper prints its matrices to 3-4 digits).

    Raises
    ------
    InputError
        If ``R`` is not a finite (3, 3) array (the SVD would fail on a non-finite one).
    """
    U, _, Vt = np.linalg.svd(as_array(R, (3, 3), "R (rotation matrix)"))
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt


def quintic(tau: float) -> tuple[float, float]:
    """Time law σ(τ) = 10τ³ − 15τ⁴ + 6τ⁵ and dσ/dτ, τ clipped to [0, 1].

    The quintic polynomial from 0 to 1 with zero velocity and acceleration at both ends:
    the minimum-jerk profile of Flash and Hogan, "The coordination of arm movements",
    J. Neurosci. 5(7), 1985. The planned path (:class:`ArcPath`) and the scripted hand
    reaches (:mod:`qpavoid.scenarios.generated`) both move with it.
    """
    t = min(max(tau, 0.0), 1.0)
    return t**3 * (10 - 15 * t + 6 * t * t), 30 * t * t * (1 - t) ** 2


def smoothstep(x: float) -> float:
    """σ(x) of :func:`quintic` alone: 0 → 1 on [0, 1], zero velocity and acceleration at
    both ends."""
    return quintic(x)[0]


@dataclass(frozen=True)
class ArcPath:
    """Circular-arc end-effector path with a quintic time law.

    Parameters
    ----------
    start, goal
        (4, 4) initial and final poses (their rotations taken as the nearest rotation
        matrices, :func:`orthonormalize`).
    duration_s
        Time to travel the path (paper: 15 s).
    sagitta_m
        Height of the arc above the chord at its middle, in the vertical plane through the
        chord (0 gives a straight line).
    turn
        False (the paper's: both its poses have one orientation): the start's orientation
        is held and the goal's ignored. True: the orientation turns from the start's
        ``R₀`` to the goal's ``R₁`` about one fixed axis with the same time law,
        ``R(σ) = R₀ exp(σ [w]×)``, ``w = log₃(R₀ᵀ R₁)``, at the angular velocity (base
        frame) ``ω = R₀ w dσ/dt`` (``R(σ) w = R₀ w``, as ``exp(σ [w]×) w = w``).
    """

    start: np.ndarray = field(default_factory=lambda: A_IN.copy())
    goal: np.ndarray = field(default_factory=lambda: A_FIN.copy())
    duration_s: float = 15.0
    sagitta_m: float = 0.08
    turn: bool = False
    _geom: dict[str, Any] = field(init=False, repr=False)
    _rotation: np.ndarray = field(init=False, repr=False)
    _pose: np.ndarray = field(init=False, repr=False)
    _turn: np.ndarray | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        finite_number(self.duration_s, "duration_s", positive=True)
        finite_number(self.sagitta_m, "sagitta_m")
        start = as_array(self.start, (4, 4), "start (pose)")
        p0 = start[:3, 3]
        p1 = as_array(self.goal, (4, 4), "goal (pose)")[:3, 3]
        chord = p1 - p0
        L = np.linalg.norm(chord)
        up = np.array([0.0, 0.0, 1.0])
        n = up - (up @ chord) / max(L * L, 1e-18) * chord  # in-plane normal, upwards
        if np.linalg.norm(n) < 1e-9 or L < 1e-9 or self.sagitta_m <= 0:
            geom = dict(kind="line", p0=p0, chord=chord)
        else:
            n = unit(n)
            s = self.sagitta_m
            R = (L * L / 4 + s * s) / (2 * s)
            centre = 0.5 * (p0 + p1) + (s - R) * n
            axis = unit(np.cross(p0 - centre, p1 - centre))
            angle = 2 * np.arcsin(min(L / (2 * R), 1.0))
            if s > R:  # more than a half circle
                angle = 2 * np.pi - angle
            e1 = (p0 - centre) / R
            geom = dict(
                kind="arc", centre=centre, radius=R, angle=angle, e1=e1, e2=np.cross(axis, e1)
            )
        object.__setattr__(self, "_geom", geom)
        object.__setattr__(self, "_rotation", orthonormalize(start[:3, :3]))
        turn = None
        if self.turn:
            goal_rotation = orthonormalize(as_array(self.goal, (4, 4), "goal (pose)")[:3, :3])
            turn = pin.log3(self._rotation.T @ goal_rotation)
        object.__setattr__(self, "_turn", turn)
        pose = np.eye(4)
        pose[:3, :3] = self._rotation
        object.__setattr__(self, "_pose", pose)

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) the start's end-effector orientation (held throughout unless ``turn``)."""
        return self._rotation

    def position(self, sigma: float) -> tuple[np.ndarray, np.ndarray]:
        """Point of the path at arc parameter σ in [0, 1] and its derivative dp/dσ."""
        g = self._geom
        if g["kind"] == "line":
            return g["p0"] + sigma * g["chord"], g["chord"].copy()
        phi = g["angle"] * sigma
        c, s = math.cos(phi), math.sin(phi)
        R, e1, e2 = g["radius"], g["e1"], g["e2"]
        return g["centre"] + R * (c * e1 + s * e2), (R * g["angle"]) * (c * e2 - s * e1)

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Desired pose (4, 4) and twist (6,) ``[v; ω]`` (m/s, rad/s) at path time ``t`` (s).

        Before 0 the path waits at its start, after ``duration_s`` at its goal.
        """
        sigma, dsigma = quintic(t / self.duration_s)
        p, dp = self.position(sigma)
        T = self._pose.copy()
        T[:3, 3] = p
        twist = np.zeros(6)
        twist[:3] = dp * (dsigma / self.duration_s)
        if self._turn is not None:
            T[:3, :3] = self._rotation @ pin.exp3(sigma * self._turn)
            twist[3:] = self._rotation @ self._turn * (dsigma / self.duration_s)
        return T, twist

    def length_m(self, n: int = 2001) -> float:
        """Length of the path, m."""
        pts = np.array([self.position(s)[0] for s in np.linspace(0, 1, n)])
        return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


def pose_error(T_desired: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(6,) error ``[p_d − p; log3(R_d Rᵀ)]``, both parts in the base frame (m, rad)."""
    e = np.empty(6)
    e[:3] = T_desired[:3, 3] - T[:3, 3]
    e[3:] = pin.log3(T_desired[:3, :3] @ T[:3, :3].T)
    return e


def ik_seed(robot: Robot, target: np.ndarray) -> np.ndarray:
    """The robot description's seed for reaching ``target`` (``[ik_seed]``, docs/robot.md).

    Every joint at 0 but the description's ``angles``, and its ``aim`` joint turned to face
    the wrist centre, ``wrist_to_tool_m`` behind the target along the target's z axis (for
    the iiwa: A1 points the arm at the wrist centre, A2 > 0 leans it forward, the elbow
    joint A4 bends back (< 0), A5 = 0 and A6 < 0: the branch of the reading notes'
    solution). Joints the model lacks (locked) are skipped.
    """
    seed = robot.ik_seed
    wrist = target[:3, 3] - seed.wrist_to_tool_m * target[:3, 2]
    q = np.zeros(robot.nq)
    guess = dict(seed.angles)
    if seed.aim is not None:
        guess[seed.aim] = float(np.arctan2(wrist[1], wrist[0]))
    for name, value in guess.items():
        if name in robot.joint_names:
            q[robot.joint_names.index(name)] = value
    return q


def inverse_kinematics(
    robot: Robot,
    target: np.ndarray,
    q0: np.ndarray | None = None,
    tol: float = 1e-10,
    max_iter: int = 500,
) -> np.ndarray:
    """Joint angles (rad) that put the end effector at ``target`` (4, 4).

    Damped Newton iterations on the error ``log6(T(q)⁻¹ T_target)`` with the LOCAL
    Jacobian, from ``q0`` (default :func:`ik_seed`), kept inside the position limits.

    Raises
    ------
    IKNotConvergedError
        If the target is not reached within ``tol`` (unreachable, or outside the limits
        on this branch); it carries the target, the final residual, the number of
        iterations and the last iterate. It is an :class:`InputError`.
    InputError
        If ``target`` is not a finite (4, 4) array or ``q0`` not a finite (nq,) one.
    """
    target = as_array(target, (4, 4), "target (pose)")
    target_se3 = pin.SE3(orthonormalize(target[:3, :3]), target[:3, 3])
    q = ik_seed(robot, target) if q0 is None else robot.check_q(q0).copy()
    model = robot.model
    data = model.createData()  # its own: the robot's data serves the control tick
    err, q_err = np.inf, q
    for _ in range(max_iter):
        pin.framesForwardKinematics(model, data, q)
        e = pin.log6(data.oMf[robot.ee_frame].actInv(target_se3)).vector
        err = float(np.linalg.norm(e))
        if err < tol:
            return q
        q_err = q
        J = pin.computeFrameJacobian(model, data, q, robot.ee_frame, pin.ReferenceFrame.LOCAL)
        # q and the target are finite, so J is; J Jᵀ + 1e-8 I is then positive definite
        # and solve() cannot raise LinAlgError.
        step = J.T @ np.linalg.solve(J @ J.T + 1e-8 * np.eye(6), e)
        q = np.clip(q + step, robot.q_min, robot.q_max)
    x, y, z = target[:3, 3]
    raise IKNotConvergedError(
        f"inverse kinematics did not reach the target position ({x:.4g}, {y:.4g}, {z:.4g}) m "
        f"(residual {err:.2e} > tol {tol:.0e} after {max_iter} iterations): unreachable "
        "on this branch (the robot description's [ik_seed] chooses the branch: docs/robot.md)",
        target=target,
        residual=float(err),
        iterations=max_iter,
        q=q_err,
    )


class PlannedPath(Protocol):
    """What a controller and a run need of a planned path (:class:`ArcPath`,
    :class:`WaypointPath`): the reference at a path time, its length in time, its start."""

    @property
    def duration_s(self) -> float:
        """Time to travel the path, s."""
        ...

    @property
    def start(self) -> np.ndarray:
        """(4, 4) the first pose, as given."""
        ...

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Desired pose (4, 4) and twist (6,) ``[v; ω]`` at path time ``t`` (s)."""
        ...


@dataclass(frozen=True)
class WaypointPath:
    """Poses joined one after the other by segments, each with its own quintic time law.

    Segment ``k`` runs from ``T_k = Σ_{i<k} d_i`` to ``T_k + d_k`` (``d_k`` its
    ``duration_s``) and is followed at ``τ = t − T_k``; the end effector stops (zero
    velocity and acceleration) at every waypoint. Before 0 the path waits at its start,
    after :attr:`duration_s` at its goal. A path of one segment is that segment exactly,
    bit for bit (``t − 0.0 = t``).

    Parameters
    ----------
    segments
        The segments in order (:class:`ArcPath`), each starting where the one before ends.
    """

    segments: tuple[ArcPath, ...]
    _starts: tuple[float, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.segments:
            raise InputError("segments must hold at least one segment", name="segments")
        starts, t = [], 0.0
        for segment in self.segments:
            starts.append(t)
            t += segment.duration_s
        object.__setattr__(self, "_starts", tuple(starts))

    @property
    def duration_s(self) -> float:
        """Time to travel the whole path, s: the sum of the segments' durations."""
        return self._starts[-1] + self.segments[-1].duration_s

    @property
    def start(self) -> np.ndarray:
        """(4, 4) the first pose, as given."""
        return self.segments[0].start

    @property
    def goal(self) -> np.ndarray:
        """(4, 4) the last pose, as given."""
        return self.segments[-1].goal

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Desired pose (4, 4) and twist (6,) ``[v; ω]`` (m/s, rad/s) at path time ``t``
        (s): that of the segment ``t`` falls in (the later one at a waypoint, where both
        give the waypoint at rest)."""
        k = max(bisect.bisect_right(self._starts, t) - 1, 0)
        return self.segments[k].reference(t - self._starts[k])

    def length_m(self) -> float:
        """Length of the path, m: the sum of the segments' lengths."""
        return float(sum(segment.length_m() for segment in self.segments))


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
        raise RobotDescriptionError(f"{path}: {one_line(exc)}", path=path) from None
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
            raise reader.error(
                f"waypoints[{k}]",
                f"the arm cannot reach this pose from the one before ({one_line(exc)}); "
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


def shoulder_centre(robot: Robot, frame: str) -> np.ndarray:
    """(3,) the point of the first joint's axis nearest the origin of ``frame`` at the zero
    configuration, base frame, m: where a task is scaled about (:class:`TaskScaling`).

    The iiwa's A2 lies on that axis: (0, 0, 0.36); the UR5's shoulder lift joint is 0.136
    m beside it, and its centre is (0, 0, 0.089). The axis is the angular part of the
    first joint's column of Pinocchio's Jacobian; for a prismatic first joint (no axis)
    the frame's origin itself.
    """
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, robot.neutral())
    pin.updateFramePlacements(model, data)
    p = data.oMf[model.getFrameId(frame)].translation.copy()
    axis = pin.getJointJacobian(model, data, 1, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[3:, 0]
    if np.linalg.norm(axis) < 0.5:
        return p
    origin = data.oMi[1].translation
    return origin + ((p - origin) @ axis) * axis


def arm_reach(
    robot: Robot, frame: str, samples: int = 2000, seed: int = 0
) -> tuple[float, np.ndarray]:
    """The arm's reach from ``frame`` (the shoulder), m, and the configuration (nq,) at it.

    The reach is the largest distance from the origin of ``frame`` to the end-effector
    frame over the joint limits, ``max_q d(q) = ‖p_ee(q) − p_frame(q)‖`` subject to
    ``q_min ≤ q ≤ q_max``: SciPy's bounded L-BFGS-B on ``−d`` with the gradient ``∇d =
    rᵀ (J_ee − J_frame) / d``, ``r = p_ee − p_frame``, from the frames' translation
    Jacobians (Pinocchio), started from the 10 farthest of ``samples`` uniform
    configurations (seeded: the same every time). For an arm that stretches straight (the
    iiwa) it is the sum of the link lengths from the shoulder (0.946 m); an elbow that
    cannot straighten (the Panda's joint 4 stops at −0.07 rad) or offset links make it the
    longest reachable stretch.
    """
    model = robot.model
    data = model.createData()
    fs, fe = model.getFrameId(frame), robot.ee_frame
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

    def negative_distance(q: np.ndarray) -> tuple[float, np.ndarray]:
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        r = data.oMf[fe].translation - data.oMf[fs].translation
        d = float(np.linalg.norm(r))
        J = pin.getFrameJacobian(model, data, fe, lwa) - pin.getFrameJacobian(model, data, fs, lwa)
        return -d, -(r @ J[:3]) / max(d, 1e-12)

    rng = np.random.default_rng(seed)
    starts = rng.uniform(robot.q_min, robot.q_max, (samples, robot.nq))
    far = np.argsort([negative_distance(q)[0] for q in starts])[:10]
    bounds = list(zip(robot.q_min, robot.q_max, strict=True))
    best = min(
        (
            minimize(negative_distance, q, jac=True, method="L-BFGS-B", bounds=bounds)
            for q in starts[far]
        ),
        key=lambda result: float(result.fun),
    )
    return -float(best.fun), np.clip(best.x, robot.q_min, robot.q_max)
