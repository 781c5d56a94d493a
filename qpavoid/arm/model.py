"""The robot: a Pinocchio model with its control points and capsules (paper Sect. 4).

A robot description is a folder with a URDF and a control-point file (TOML, see
``docs/robot.md``); :mod:`qpavoid.arm.description` reads it into a Pinocchio model with
one operational frame per control point and capsule end (locked joints removed), so
positions and Jacobians come from Pinocchio.

Typical use::

    robot = load_robot("iiwa14")            # A3 locked, robot.model.nv == 6
    kin = robot.kinematics(q)               # positions and Jacobians at q
    kin.points                              # (9, 3) control points, base frame, m
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from qpavoid.arm._kernels import frame_jacobians
from qpavoid.arm._kernels import warm_up as warm_up_kernels
from qpavoid.arm.control_points import ControlSet
from qpavoid.arm.coverage import check_coverage
from qpavoid.arm.description import read_description
from qpavoid.arm.dynamics import ArmDynamics
from qpavoid.arm.joints import IKSeed
from qpavoid.arm.roles import ROLE_NAMES, Roles
from qpavoid.core.checks import as_array
from qpavoid.core.errors import InputError

__all__ = ["Q_LIMIT_TOLERANCE_RAD", "Kinematics", "Robot", "joint_columns", "load_robot"]

#: How far beyond a joint's limit :meth:`Robot.check_q` still accepts an angle, rad: a hair
#: for round-off (a configuration computed at a limit, an inverse kinematics' result clipped
#: to it, lands within 1e-15 rad of it), far below any mistake a configuration given by
#: hand makes (an angle of a wrong joint, degrees for radians, the Panda's joint 4 at 0:
#: 0.07 rad out). The controllers never call it on a measured angle: an arm may read a
#: little past a limit, and the position-limit rows steer it back.
Q_LIMIT_TOLERANCE_RAD = 1e-9


@dataclass(frozen=True)
class Kinematics:
    """Everything the distance methods and the controllers need at one configuration.

    All positions are in the base frame (m); Jacobians map joint velocities (rad/s) to
    linear velocities (m/s) of the point, expressed in the base frame, and for the end
    effector to its twist ``[v; omega]`` in LOCAL_WORLD_ALIGNED coordinates.

    Attributes
    ----------
    q
        Joint angles (nq,), rad.
    points
        Control points (P, 3).
    point_jacobians
        (P, 3, nv), or ``None`` if not computed.
    segments
        Capsule axes (S, 2, 3): start and end point of each set's capsule.
    segment_jacobians
        (S, 2, 3, nv) Jacobians of the capsule ends, or ``None``.
    ee_placement
        (4, 4) homogeneous pose of the end-effector frame.
    ee_jacobian
        (6, nv) end-effector Jacobian, or ``None``.
    """

    q: np.ndarray
    points: np.ndarray
    point_jacobians: np.ndarray | None
    segments: np.ndarray
    segment_jacobians: np.ndarray | None
    ee_placement: np.ndarray
    ee_jacobian: np.ndarray | None

    def segment_point_jacobian(
        self, set_index: int | np.ndarray, s: float | np.ndarray
    ) -> np.ndarray:
        """Jacobian (3, nv) of the point at parameter ``s`` in [0, 1] on a capsule axis.

        One rigid body carries each capsule's axis (checked when the description is read:
        both ends on one link, or on the axis of every joint between them), so the
        velocity of the point ``(1 - s) a + s b`` on that body is exactly
        ``(1 - s) v_a + s v_b``. With (A,) arrays of sets and parameters: (A, 3, nv).
        """
        if self.segment_jacobians is None:
            raise InputError(
                "kinematics were computed without Jacobians", name="jacobians", value=False
            )
        ends = self.segment_jacobians[set_index]  # (2, 3, nv) or (A, 2, 3, nv)
        s = np.asarray(s, dtype=float)[..., None, None]
        return (1.0 - s) * ends[..., 0, :, :] + s * ends[..., 1, :, :]


def frame_translations(data: pin.Data, n_frames: int) -> np.ndarray | None:
    """Every frame's position in ``data`` (``data.oMf[f].translation``), m, as one
    read-only (n_frames, 3) view that ``updateFramePlacements`` rewrites in place; None if
    the placements do not lie at one stride in memory (then read them one by one).

    ``data.oMf`` is a ``std::vector`` of SE3, sized once by ``createData``; each
    placement's ``translation`` is a view into it. Gathering the frames through one view
    replaces a Python read per frame, which was the larger half of a tick's kinematics
    (docs/performance.md §2g). The view does not keep ``data`` alive: hold the two together
    (:attr:`Robot.data` does, in one tuple).
    """
    first = data.oMf[0].translation
    if n_frames < 2 or first.dtype != np.float64 or first.strides != (8,):
        return None
    base = first.__array_interface__["data"][0]
    stride = data.oMf[1].translation.__array_interface__["data"][0] - base
    for f in range(n_frames):  # every placement where the stride puts it
        if data.oMf[f].translation.__array_interface__["data"][0] != base + f * stride:
            return None
    view = np.lib.stride_tricks.as_strided(first, (n_frames, 3), (stride, 8), writeable=False)
    return view


class Robot:
    """A serial arm as a Pinocchio model plus its control-point description.

    Parameters
    ----------
    model
        Pinocchio model (possibly reduced), with one operational frame per control point
        and per capsule end.
    sets
        The control sets, in order (their points are consecutive).
    point_frames
        Frame id of every control point, set after set.
    ee_frame
        Frame id of the end effector.
    name
        Name of the description (folder name).
    locked
        Joints removed from the model and the angle (rad) they are locked at.
    roles
        Which set plays which part in the paper's laws, and on which joints.
    arm
        The arm's reaction time, acceleration limits and fastest point speed.
    ik_seed
        Where the inverse kinematics starts.
    urdf
        The URDF the model was built from (its collision meshes: :mod:`qpavoid.arm.meshes`).
    mesh_dirs
        Folders where the URDF's ``package://`` meshes are looked for.
    coverage_exclude
        Collision objects the description leaves outside its capsules and spheres, and
        why (``[coverage] exclude``; :mod:`qpavoid.arm.coverage`).
    path
        The control-point file the robot was read from, or None.
    home
        The description's ``home``: angles (rad) of the joints :meth:`neutral` does not put
        at its default (joints locked here keep their locked angle).
    """

    def __init__(
        self,
        model: pin.Model,
        sets: Sequence[ControlSet],
        point_frames: Sequence[int],
        ee_frame: int,
        name: str,
        locked: Mapping[str, float],
        roles: Roles,
        arm: ArmDynamics,
        ik_seed: IKSeed,
        urdf: Path | None = None,
        mesh_dirs: Sequence[Path] = (),
        coverage_exclude: Mapping[str, str] | None = None,
        path: Path | None = None,
        home: Mapping[str, float] | None = None,
    ):
        self.model = model
        self.urdf, self.mesh_dirs = urdf, tuple(mesh_dirs)
        self.coverage_exclude = dict(coverage_exclude or {})
        self.path = path
        self.roles, self.arm, self.ik_seed = roles, arm, ik_seed
        self.sets = tuple(sets)
        self.point_frames = tuple(point_frames)
        self.ee_frame = ee_frame
        self.name = name
        self.locked = dict(locked)
        self.joint_names = tuple(model.names[i] for i in range(1, model.njoints))
        self.q_min = np.array(model.lowerPositionLimit, dtype=float)
        self.q_max = np.array(model.upperPositionLimit, dtype=float)
        self.dq_max = np.array(model.velocityLimit, dtype=float)
        given = dict(home or {})
        self._home = np.array(
            [
                given[n] if n in given else 0.0 if lo <= 0.0 <= hi else 0.5 * (lo + hi)
                for n, lo, hi in zip(self.joint_names, self.q_min, self.q_max, strict=True)
            ]
        )
        self.check_q(self._home)  # a home given in code: within the limits too
        self.set_names = tuple(s.name for s in self.sets)
        self.point_set = np.concatenate([[k] * len(s.points) for k, s in enumerate(self.sets)])
        self.sphere_radii = np.array([self.sets[k].sphere_radius_m for k in self.point_set])
        self.capsule_radii = np.array([s.capsule_radius_m for s in self.sets])
        # Frames whose positions/Jacobians a tick needs, each once: the control points, then
        # any capsule end that is not a control point (for the iiwa only the shoulder).
        placement: dict[tuple[int, tuple[float, ...]], int] = {}
        for f in self.point_frames:
            placement.setdefault(self._frame_key(f), f)
        frames = list(self.point_frames)
        seg_idx = []
        for s in self.sets:
            pair = []
            for f in s.capsule_frames:
                key = self._frame_key(f)
                if key not in placement:
                    placement[key] = f
                    frames.append(f)
                pair.append(frames.index(placement[key]))
            seg_idx.append(pair)
        self._frames = tuple(frames)
        self._frame_array = np.array(frames, dtype=np.intp)
        self._segment_index = np.array(seg_idx)
        self._n_points = len(self.point_frames)
        # the velocity columns of the joints that carry each frame (its Jacobian's nonzero
        # columns), for arm._kernels.frame_jacobians
        self._support = np.array([self._carried_by(f) for f in frames], dtype=np.bool_)
        self._ee_support = self._carried_by(self.ee_frame)
        warm_up_kernels()
        self.data = model.createData()

    def _carried_by(self, frame: int) -> np.ndarray:
        """(nv,) True for the velocity columns of the joints that move ``frame``."""
        out = np.zeros(self.model.nv, dtype=np.bool_)
        for j in self.model.supports[self.model.frames[frame].parentJoint]:
            joint = self.model.joints[j]
            if j > 0 and joint.nv > 0:
                out[joint.idx_v : joint.idx_v + joint.nv] = True
        return out

    @property
    def data(self) -> pin.Data:
        """The Pinocchio data that :meth:`kinematics` computes in (assignable: a thread of
        its own gets its own)."""
        return self._held[0]

    @data.setter
    def data(self, data: pin.Data) -> None:
        # the placements a tick reads, held with their data as one tuple (read at once, so
        # a data assigned meanwhile never mixes with another's placements): each
        # ``data.oMf[f]`` is a reference that updateFramePlacements rewrites, so they are
        # indexed once, not every tick
        # and the view of every frame's position into the same data (None: read one by one)
        self._held = (
            data,
            tuple(data.oMf[f] for f in self._frames),
            data.oMf[self.ee_frame],
            frame_translations(data, self.model.nframes),
        )

    def for_thread(self) -> Robot:
        """A copy that computes :meth:`kinematics` in Pinocchio data of its own, for another
        thread (a viewer's, the ROS 2 outputs'): two threads computing in one data corrupt
        each other's placements (a run's commands changed by up to 0.014 rad/s, measured)."""
        out = copy.copy(self)
        out.data = self.model.createData()
        return out

    def __getstate__(self) -> dict:
        # copies and pickles carry the data, never references into it
        state = {k: v for k, v in self.__dict__.items() if k != "_held"}
        return {**state, "data": self.data}

    def __setstate__(self, state: dict) -> None:
        state = dict(state)
        data = state.pop("data")
        self.__dict__.update(state)
        self.data = data

    def _frame_key(self, frame_id: int) -> tuple[int, tuple[float, ...]]:
        """Identity of a frame's origin: its parent joint and placement (rounded)."""
        f = self.model.frames[frame_id]
        return (f.parentJoint, tuple(np.round(f.placement.translation, 12)))

    @property
    def nq(self) -> int:
        """Number of configuration variables."""
        return self.model.nq

    @property
    def nv(self) -> int:
        """Number of joint velocities (6 for the iiwa with A3 locked, 7 without)."""
        return self.model.nv

    def role_name(self, role: str) -> str:
        """Name of the set playing ``role`` (one of :data:`ROLE_NAMES`), e.g. ``"L2"``."""
        if role not in ROLE_NAMES:
            raise InputError(
                f"unknown role {role!r}; roles are {ROLE_NAMES}", name="role", value=role
            )
        return self.set_names[getattr(self.roles, role)]

    @property
    def role_names(self) -> tuple[str, str, str]:
        """Names of the scaled, repelled and end-effector sets (the iiwa's L1, L2, EE)."""
        scaled, repelled, end_effector = (self.set_names[r] for r in self.roles.rows)
        return scaled, repelled, end_effector

    def set_index(self, name: str) -> int:
        """Index of the control set called ``name``."""
        try:
            return self.set_names.index(name)
        except ValueError:
            raise InputError(
                f"unknown control set {name!r}; sets are {self.set_names}", name="set", value=name
            ) from None

    def check_q(self, q: ArrayLike, tolerance_rad: float = Q_LIMIT_TOLERANCE_RAD) -> np.ndarray:
        """``q`` as a float array (nq,), a configuration the arm can take: finite and each
        joint within its limits (:attr:`q_min`, :attr:`q_max`), to ``tolerance_rad``.

        Where a configuration enters as a start or a target: a simulation's and a
        simulated arm's start, the QP's rest posture, the inverse kinematics' start. The
        kinematics take any finite ``q`` (finite differences step past a limit; an arm
        may read a hair past one).

        Raises
        ------
        InputError
            For a wrong shape, a value that is not finite, or an angle outside its joint's
            limits (by more than ``tolerance_rad``), naming the joint, the angle and the
            limits (``name="q"``, ``value`` the array).
        """
        q = as_array(q, (self.nq,), "q (joint angles, rad)")
        outside = np.flatnonzero(
            (q < self.q_min - tolerance_rad) | (q > self.q_max + tolerance_rad)
        )
        if outside.size:
            i = int(outside[0])
            more = f" (and {outside.size - 1} more joints)" if outside.size > 1 else ""
            raise InputError(
                f"q (joint angles, rad): {self.joint_names[i]} = {q[i]:.6g} rad is outside "
                f"its limits [{self.q_min[i]:.6g}, {self.q_max[i]:.6g}] rad{more} "
                f"(robot {self.name!r}; robot.neutral() is a configuration within them)",
                name="q",
                value=q,
            )
        return q

    def kinematics(self, q: ArrayLike, jacobians: bool = True) -> Kinematics:
        """Forward kinematics (and Jacobians) of every control point, capsule and the EE.

        Parameters
        ----------
        q
            Joint angles (nq,), rad, in the model's joint order.
        jacobians
            Also compute the Jacobians (needed by the controllers, not by distances).
        """
        q = as_array(q, (self.nq,), "q (joint angles, rad)")  # any finite q: check_q's docs
        model, (data, placements, ee_placement, translations) = self.model, self._held
        if jacobians:
            pin.computeJointJacobians(model, data, q)
        else:
            pin.forwardKinematics(model, data, q)
        pin.updateFramePlacements(model, data)
        if translations is not None:  # (F, 3), contiguous: one gather
            pos = translations[self._frame_array]
        else:
            pos = np.array([m.translation for m in placements])
        points, segments = pos[: self._n_points], pos[self._segment_index]
        ee = ee_placement.homogeneous  # a copy
        pj = sj = ej = None
        if jacobians:  # every frame's from the joints' in one compiled call
            at = ee[:3, 3].copy()
            jac, ej = frame_jacobians(data.J.T, pos, self._support, at, self._ee_support)
            pj, sj = jac[: self._n_points], jac[self._segment_index]
        return Kinematics(q, points, pj, segments, sj, ee, ej)

    def control_points(self, q: ArrayLike) -> np.ndarray:
        """Control points (P, 3) at ``q``, base frame, m; for the iiwa L1(4), L2(4), EE(1)."""
        return self.kinematics(q, jacobians=False).points

    def capsules(self, q: ArrayLike) -> np.ndarray:
        """Capsule axes (S, 2, 3) at ``q``, one per control set, m."""
        return self.kinematics(q, jacobians=False).segments

    def end_effector(self, q: ArrayLike) -> np.ndarray:
        """End-effector pose (4, 4) at ``q`` in the base frame."""
        return self.kinematics(q, jacobians=False).ee_placement

    def neutral(self) -> np.ndarray:
        """The arm's home configuration (nq,), rad, within the joint limits: the
        description's ``home`` (the Franka arms' is Franka's ready pose, 0, −π/4, 0,
        −3π/4, 0, π/2, π/4), each joint it does not name at 0, or in the middle of its
        range where 0 is outside it (a copy).

        Not Pinocchio's ``pin.neutral(robot.model)``, every joint at 0, which is outside
        the limits of the Panda's and the FR3's joint 4 (and the FR3's joint 6).
        """
        return self._home.copy()

    def full_configuration(self, q: ArrayLike) -> dict[str, float]:
        """Angle of every joint of the description, locked ones included, by name (rad)."""
        q = as_array(q, (self.nq,), "q (joint angles, rad)")
        out = dict(zip(self.joint_names, q.tolist(), strict=False))
        out.update(self.locked)
        return out


def load_robot(
    name: str | Path = "iiwa14",
    locked: Mapping[str, float] | Sequence[str] | None = None,
    coverage: bool = True,
) -> Robot:
    """Load a robot description and build its (reduced) Pinocchio model.

    Parameters
    ----------
    name
        A bundled description (``"iiwa14"``), a folder holding a URDF and a
        ``control_points.toml``, or the path of such a TOML file.
    locked
        Joints to lock, in place of the description's ``locked``: ``None`` uses the
        description's (A3 at 0 for the iiwa), ``()`` locks nothing, a sequence of names
        locks them at the description's value (or 0), a mapping gives the angles (rad),
        each within the joint's limits.
    coverage
        Check that the capsules and spheres hold every collision-mesh vertex the
        description does not exclude (:func:`qpavoid.arm.coverage.check_coverage`);
        ``False`` only to inspect a description that fails it (``qpavoid robot check``).

    Returns
    -------
    Robot

    Raises
    ------
    RobotDescriptionError
        For an unknown description, a malformed file or URDF, a frame it lacks, or
        anything else the controllers could not use (``docs/robot.md``, "Refusals"),
        locking every joint or a joint of the description's ``[roles]`` included, and
        a collision-mesh vertex outside the capsules or spheres that its ``[coverage]
        exclude`` does not name (:func:`qpavoid.arm.coverage.check_coverage`).
    InputError
        For a ``locked`` that is text, names a joint the model does not have, or gives an
        angle that is not a number, not finite or outside the joint's limits.
    """
    robot = Robot(*read_description(name, locked))
    if coverage:
        check_coverage(robot, robot.path or Path(str(name)))
    return robot


def joint_columns(robot: Robot, names: tuple[str, ...] | None, option: str) -> np.ndarray:
    """Columns of the joints ``names`` among the robot's active joints.

    ``option`` names the setting the joints come from; ``names=None`` takes the robot
    description's joints of that setting, the attribute ``option`` of :attr:`Robot.roles`
    (``"scaled_joints"`` or ``"repelled_joints"``).

    Raises
    ------
    InputError
        If a name is not an active joint (``option`` names the setting at fault), or
        ``names`` is None and the description has no joints for ``option``.
    """
    if names is None:
        names = getattr(robot.roles, option, None)
        if names is None:
            raise InputError(
                f"{option}: the robot description gives no such joints; name them",
                name=option,
                value=None,
            )
    missing = [n for n in names if n not in robot.joint_names]
    if missing:
        raise InputError(
            f"{option}: joints {missing} are not active joints of {robot.joint_names}",
            name=option,
            value=tuple(names),
        )
    return np.array([robot.joint_names.index(n) for n in names])
