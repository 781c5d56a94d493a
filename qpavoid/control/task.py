"""The planned task (paper Sect. 3): a curved end-effector path in 15 s, orientation held.

The paper gives the initial and final poses but not the curve. :class:`ArcPath` is a
circular arc through both positions in the vertical plane that contains them (y = 0.6105
for the paper's poses), bulging upwards by ``sagitta_m`` at its middle, traversed with
the quintic time law ``σ(τ) = 10τ³ − 15τ⁴ + 6τ⁵``, ``τ = t / T``: zero velocity and
acceleration at both ends. The orientation is the common orientation of both poses.

The start configuration is the inverse kinematics of the initial pose
(:func:`inverse_kinematics`): damped Newton steps on Pinocchio's ``log6`` error from a
seed on the elbow-up, non-flipped-wrist branch that faces the target.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from qpavoid.arm.model import Robot
from qpavoid.core.checks import as_array, finite_number
from qpavoid.core.errors import IKNotConvergedError
from qpavoid.core.geometry import unit

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
        (4, 4) initial and final poses; the goal's orientation is ignored (held at the
        start's, as in the paper where both are equal).
    duration_s
        Time to travel the path (paper: 15 s).
    sagitta_m
        Height of the arc above the chord at its middle, in the vertical plane through the
        chord (0 gives a straight line).
    """

    start: np.ndarray = field(default_factory=lambda: A_IN.copy())
    goal: np.ndarray = field(default_factory=lambda: A_FIN.copy())
    duration_s: float = 15.0
    sagitta_m: float = 0.08
    _geom: dict[str, Any] = field(init=False, repr=False)
    _rotation: np.ndarray = field(init=False, repr=False)
    _pose: np.ndarray = field(init=False, repr=False)

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
        pose = np.eye(4)
        pose[:3, :3] = self._rotation
        object.__setattr__(self, "_pose", pose)

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) the held end-effector orientation."""
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
