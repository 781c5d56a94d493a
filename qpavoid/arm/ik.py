"""Inverse kinematics of the end effector: the joint angles that put it at a pose.

Each start runs damped, step-limited Newton iterations (Levenberg-Marquardt) on the error
``e = log6(T(q)⁻¹ T*)`` (Pinocchio's ``log6``, the LOCAL frame), with the frame Jacobian
``J`` of Pinocchio:

    Δq = Jₐᵀ (Jₐ Jₐᵀ + λ I)⁻¹ e,      λ = w ‖e‖² + λ₀,
    q ← clip(q + α Δq, q_min, q_max),  α = min(a, s_max / ‖Δq‖∞)   (a = 1 once ‖e‖ < e_full)

* the damping ``λ`` grows with the squared error, Sugihara's choice (T. Sugihara,
  "Solvability-unconcerned inverse kinematics by the Levenberg-Marquardt method", IEEE
  T-RO 27(5), 2011): far from the target a short, well-conditioned step, near it a pure
  Newton step and quadratic convergence;
* ``Jₐ`` is ``J`` with the columns of the joints at a limit and pushed further out set to
  zero (found again until none is): the other joints take up the work instead of the step
  being clipped away, which stalls a plain clip on the Panda's narrow elbow;
* the step is a fraction ``a`` of the Newton step while far and at most ``s_max`` rad on
  any joint: without it, full steps from the UR5's seed (tool down, target up and out)
  jumped between ±2π for 500 iterations and ended 1.48 away.

:func:`inverse_kinematics` starts from the description's seed (:func:`ik_seed`: it chooses
the branch) and returns that run's solution when it converges; when it does not (a joint
limit in the way, or the seed on another branch than the target's), it starts again from
:attr:`IKConfig.restarts` configurations drawn uniformly inside the limits by a seeded
generator (the same on every machine) and returns, of those that converge, the one nearest
the seed (Euclidean in joint space, rad). A start that stalls (its error not down by
:attr:`IKConfig.stall_ratio` in :attr:`IKConfig.stall_window` iterations) is abandoned
early.

Measured (``python benchmarks/ik.py``, 100 forward-kinematics targets of random
configurations per arm, from the description's seed): docs/robot.md, "Inverse kinematics".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from qpavoid.arm.model import Robot
from qpavoid.core.checks import as_array, check_range, finite_number
from qpavoid.core.errors import IKNotConvergedError, InputError
from qpavoid.core.geometry import orthonormalize

__all__ = ["IKConfig", "IKResult", "ik_seed", "inverse_kinematics", "solve_from"]


@dataclass(frozen=True)
class IKConfig:
    """The inverse kinematics' numbers.

    Attributes
    ----------
    tol
        Residual ``‖log6‖`` (m and rad mixed, as the solver minimises it) at which a start
        has converged: 1e-10, so that the start of a run is the pose to round-off (the
        paper's task starts at its pose bit for bit).
    max_iter
        Iterations per start: the seed converges in 10-20 on every shipped arm; a start
        that needs more is on a bad branch.
    step_fraction
        ``a``: the fraction of the Newton step taken while far (``‖e‖ ≥ full_step_below``).
        0.5 converged on most targets from the seed in 12-16 iterations; 1.0 oscillated
        on the UR5 (benchmarks/ik.py).
    full_step_below
        ``e_full``: the residual below which the full Newton step is taken (quadratic
        convergence), m/rad: 1 cm / 0.01 rad is well inside the basin.
    max_step_rad
        ``s_max``: the largest step of any joint in one iteration, rad (a few tenths keeps
        the linearisation meaningful; 0.5 rad ~ 29°).
    damping
        ``w``: the damping's weight on ``‖e‖²`` (Sugihara's), dimensionless.
    damping_floor
        ``λ₀``: a floor that keeps ``Jₐ Jₐᵀ + λ I`` invertible where the error is zero
        but a column was cleared.
    restarts
        Starts besides the seed, drawn uniformly inside the limits, tried only when the
        seed's run fails: with 32, 297 and 298 of 300 random targets converged on the
        Panda and FR3; with 64, all 300 (docs/robot.md, "Inverse kinematics").
    restart_seed
        The seed of their generator: the same starts, and so the same answer, on every
        machine.
    stall_window
        Every this many iterations a start's progress is checked.
    stall_ratio
        A start whose error is above this fraction of what it was ``stall_window``
        iterations before, while still above ``full_step_below``, is abandoned (it is
        stuck against a limit or circling).
    """

    tol: float = 1e-10
    max_iter: int = 200
    step_fraction: float = 0.5
    full_step_below: float = 1e-2
    max_step_rad: float = 0.5
    damping: float = 1e-3
    damping_floor: float = 1e-12
    restarts: int = 64
    restart_seed: int = 0
    stall_window: int = 20
    stall_ratio: float = 0.9

    def __post_init__(self) -> None:
        for name in ("tol", "full_step_below", "max_step_rad", "damping_floor", "stall_ratio"):
            finite_number(getattr(self, name), name, positive=True)
        check_range(
            "step_fraction",
            finite_number(self.step_fraction, "step_fraction", positive=True),
            0.0,
            1.0,
            "",
        )
        check_range("damping", self.damping, 0.0, math.inf, "")
        for name, low in (("max_iter", 1), ("stall_window", 1), ("restarts", 0)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise InputError(
                    f"{name} must be a whole number >= {low}, got {value!r}", name=name, value=value
                )


@dataclass(frozen=True)
class IKResult:
    """One start's outcome (:func:`solve_from`).

    Attributes
    ----------
    q
        The last iterate (nq,), rad, inside the limits: the solution if ``converged``.
    residual
        ``‖log6(T(q)⁻¹ T*)‖`` there.
    iterations
        Iterations run.
    converged
        ``residual < tol``.
    """

    q: np.ndarray
    residual: float
    iterations: int
    converged: bool


def ik_seed(robot: Robot, target: np.ndarray) -> np.ndarray:
    """The robot description's seed for reaching ``target`` (``[ik_seed]``, docs/robot.md).

    Every joint at 0 but the description's ``angles``, and its ``aim`` joint turned to face
    the wrist centre, ``wrist_to_tool_m`` behind the target along the target's z axis (for
    the iiwa: A1 points the arm at the wrist centre, A2 > 0 leans it forward, the elbow
    joint A4 bends back (< 0), A5 = 0 and A6 < 0: the branch of the reading notes'
    solution). Joints the model lacks (locked) are skipped; the seed is clipped to the
    joint limits (an aim of −3.0 rad on the iiwa's ±2.97 rad A1).
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
    return np.clip(q, robot.q_min, robot.q_max)


def solve_from(
    robot: Robot, target: pin.SE3, q0: np.ndarray, config: IKConfig = IKConfig()
) -> IKResult:
    """One start: the module's damped, step-limited iterations from ``q0`` (nq,), rad,
    towards ``target``; it stops at convergence, at ``max_iter`` or when it stalls."""
    model, lo, hi = robot.model, robot.q_min, robot.q_max
    data = model.createData()  # its own: the robot's data serves the control tick
    q = np.clip(np.asarray(q0, dtype=float), lo, hi)
    eye = np.eye(6)
    history: list[float] = []
    err = np.inf
    for it in range(config.max_iter):
        pin.framesForwardKinematics(model, data, q)
        e = pin.log6(data.oMf[robot.ee_frame].actInv(target)).vector
        err = float(np.linalg.norm(e))
        if err < config.tol:
            return IKResult(q, err, it, True)
        history.append(err)
        if (
            it >= config.stall_window
            and err >= config.full_step_below
            and err > config.stall_ratio * history[it - config.stall_window]
        ):
            return IKResult(q, err, it, False)
        J = pin.computeFrameJacobian(model, data, q, robot.ee_frame, pin.ReferenceFrame.LOCAL)
        # λ > 0 and J finite (q and the target are): the matrix is positive definite and
        # solve() cannot raise LinAlgError.
        lam = config.damping * err * err + config.damping_floor
        free = np.ones(robot.nq, dtype=bool)
        for _ in range(robot.nq):  # clear the columns pushed past a limit, until none is
            Ja = J * free
            dq = Ja.T @ np.linalg.solve(Ja @ Ja.T + lam * eye, e)
            out = free & (((q <= lo) & (dq < 0)) | ((q >= hi) & (dq > 0)))
            if not out.any():
                break
            free &= ~out
        alpha = 1.0 if err < config.full_step_below else config.step_fraction
        largest = float(np.max(np.abs(alpha * dq)))
        if largest > config.max_step_rad:
            alpha *= config.max_step_rad / largest
        q = np.clip(q + alpha * dq, lo, hi)
    return IKResult(q, err, config.max_iter, False)


def inverse_kinematics(
    robot: Robot,
    target: np.ndarray,
    q0: np.ndarray | None = None,
    config: IKConfig = IKConfig(),
) -> np.ndarray:
    """Joint angles (rad) that put the end effector at ``target`` (4, 4), inside the
    position limits: the solution of the run from ``q0`` (default :func:`ik_seed`) if it
    converges, else, of the ``config.restarts`` seeded starts inside the limits that
    converge, the solution nearest ``q0``.

    Raises
    ------
    IKNotConvergedError
        If no start reaches the target within ``config.tol`` (unreachable within the
        limits); it carries the target, the smallest residual of any start, the
        iterations run in all and that start's last iterate. It is an
        :class:`InputError`.
    InputError
        If ``target`` is not a finite (4, 4) array or ``q0`` not a finite (nq,) one.
    """
    target = as_array(target, (4, 4), "target (pose)")
    target_se3 = pin.SE3(orthonormalize(target[:3, :3]), target[:3, 3])
    seed = ik_seed(robot, target) if q0 is None else robot.check_q(q0).copy()
    first = solve_from(robot, target_se3, seed, config)
    if first.converged:
        return first.q
    rng = np.random.default_rng(config.restart_seed)
    starts = rng.uniform(robot.q_min, robot.q_max, (config.restarts, robot.nq))
    results = [first, *(solve_from(robot, target_se3, start, config) for start in starts)]
    converged = [r.q for r in results if r.converged]
    if converged:
        return min(converged, key=lambda q: float(np.linalg.norm(q - seed)))
    best = min(results, key=lambda r: r.residual)
    x, y, z = target[:3, 3]
    iterations = sum(r.iterations for r in results)
    others = f" nor from {config.restarts} other starts" if config.restarts else ""
    raise IKNotConvergedError(
        f"inverse kinematics did not reach the target position ({x:.4g}, {y:.4g}, {z:.4g}) m "
        f"from the seed{others} (smallest residual {best.residual:.2e} > tol "
        f"{config.tol:.0e}): unreachable within the joint limits (the robot description's "
        "[ik_seed] chooses the branch: docs/robot.md)",
        target=target,
        residual=best.residual,
        iterations=iterations,
        q=best.q,
    )
