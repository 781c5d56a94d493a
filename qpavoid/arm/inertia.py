"""The arm's effective mass at a point along a direction (power and force limiting).

A point p of the arm with translational Jacobian J (3, nv) (its velocity ``J q̇``), in an arm
of joint-space mass matrix M(q), presents along the unit direction n the effective mass

    m_R = (nᵀ J M⁻¹ Jᵀ n)⁻¹

(the inverse of the point's operational-space inverse inertia ``Λ⁻¹ = J M⁻¹ Jᵀ`` seen along
n; Khatib 1987, and ISO/TS 15066 Annex A's m_R made exact, :mod:`qpavoid.laws.pfl`). It is the
mass a unit impulse along n meets at p, and twice the smallest kinetic energy ``½ q̇ᵀ M q̇``
that moves p at unit speed along n (reached at ``q̇ = M⁻¹ Jᵀ n``). A point no joint moves
along n (the base; to rounding, :data:`ROUNDING`) has ``m_R = inf``, the heaviest case.

M and M⁻¹ are Pinocchio's (``pin.crba``, ``pin.computeMinverse``: the articulated-body
algorithm, without forming M), on a copy of the robot's (possibly reduced) model to which the
payload is added as a point mass at the end-effector frame's origin, on the inertia of the
joint that carries that frame. The robot's own model is never changed.

Typical use::

    mass = EffectiveMass(robot, payload_kg=2.0)     # once per controller
    kin = robot.kinematics(q)
    m_r = mass(q, kin.point_jacobians, normals)     # (A,) kg, one per point and normal
"""

from __future__ import annotations

import math
import numbers
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from qpavoid.arm.dynamics import MAX_PAYLOAD_KG
from qpavoid.arm.model import Robot
from qpavoid.core.checks import as_array
from qpavoid.core.errors import InputError, RobotDescriptionError

__all__ = ["EffectiveMass"]

#: A mass matrix whose smallest eigenvalue is below this fraction of its largest is refused as
#: not positive definite (a joint that moves no mass: ``nᵀ J M⁻¹ Jᵀ n`` would be noise).
MIN_CONDITION = 1e-12
#: ``nᵀ J M⁻¹ Jᵀ n`` below this fraction of its largest possible value, ``‖J‖² tr M⁻¹``, is
#: rounding: the point does not move along n, its effective mass is ``inf``.
ROUNDING = 1e-12


class EffectiveMass:
    """Effective masses of the arm's points along given directions (build once per robot).

    Parameters
    ----------
    robot
        The robot (its Pinocchio model, possibly reduced, and its end-effector frame).
    payload_kg
        The payload at the end effector, kg: a point mass at the end-effector frame's origin
        added to the inertia of the joint carrying it. At least 0, finite, and at most the
        arm's rated payload (``[arm] rated_payload_kg``; without one, at most
        :data:`~qpavoid.arm.dynamics.MAX_PAYLOAD_KG`).

    Attributes
    ----------
    model, data
        The Pinocchio model with the payload (a copy of the robot's) and its data.
    payload_kg
        The payload, kg.

    Raises
    ------
    InputError
        For a payload that is negative, not finite or above the arm's rated payload.
    RobotDescriptionError
        In one line naming the robot, if its description has no usable inertias: no moving
        link has mass, or the mass matrix is not positive definite at the neutral
        configuration (a joint that moves no mass, a URDF without ``<inertial>``).
    """

    def __init__(self, robot: Robot, payload_kg: float = 0.0):
        rated = getattr(robot.arm, "rated_payload_kg", None)  # older pickles have none
        self._build(robot.model, robot.ee_frame, robot.name, payload_kg, rated, robot.path)

    @classmethod
    def from_model(
        cls,
        model: pin.Model,
        ee_frame: int,
        *,
        name: str,
        payload_kg: float = 0.0,
        rated_payload_kg: float | None = None,
    ) -> EffectiveMass:
        """The effective masses of a bare Pinocchio ``model`` (no robot description), with the
        payload at the origin of frame ``ee_frame``; ``name`` names it in errors."""
        out = cls.__new__(cls)
        out._build(model, ee_frame, name, payload_kg, rated_payload_kg, None)
        return out

    def _build(
        self,
        model: pin.Model,
        ee_frame: int,
        name: str,
        payload_kg: float,
        rated_payload_kg: float | None,
        path: Path | None,
    ) -> None:
        self.name = name
        self.payload_kg = _check_payload(payload_kg, rated_payload_kg, name)
        self.model = model.copy()
        if self.payload_kg > 0.0:
            frame = self.model.frames[ee_frame]
            joint = frame.parentJoint
            point = pin.Inertia(self.payload_kg, frame.placement.translation, np.zeros((3, 3)))
            self.model.inertias[joint] = self.model.inertias[joint] + point
        self.data = self.model.createData()
        self.nq, self.nv = self.model.nq, self.model.nv
        _check_inertias(self.model, self.data, name, path)

    def minverse(self, q: ArrayLike) -> np.ndarray:
        """M(q)⁻¹ (nv, nv), symmetric, payload included (``pin.computeMinverse``, which fills
        the upper triangle only)."""
        q = as_array(q, (self.nq,), "q (joint angles, rad)")
        upper = pin.computeMinverse(self.model, self.data, q)
        return np.triu(upper) + np.triu(upper, 1).T

    def __call__(self, q: ArrayLike, jacobians: ArrayLike, normals: ArrayLike) -> np.ndarray:
        """m_R = (nᵀ J M⁻¹ Jᵀ n)⁻¹ of each point along its direction, (A,) kg.

        Parameters
        ----------
        q
            Joint angles (nq,), rad, in the model's order.
        jacobians
            (A, 3, nv) translational Jacobians of the points at ``q`` (m/rad).
        normals
            (A, 3) directions, one per point; normalised here (the effective mass is along a
            direction, its sign irrelevant). A zero direction gives ``inf``, as does a
            point that no joint moves along its direction: the largest mass, the smallest
            speed a transient contact may then have (never a lighter arm).

        Raises
        ------
        InputError
            For arrays of the wrong shape or with non-finite entries.
        """
        q = as_array(q, (self.nq,), "q (joint angles, rad)")
        jac = as_array(jacobians, (None, 3, self.nv), "jacobians (A, 3, nv)")
        n = as_array(normals, (jac.shape[0], 3), "normals (A, 3)")
        length = np.linalg.norm(n, axis=1)
        return self.along_unit(q, jac, n / np.where(length > 0.0, length, 1.0)[:, None])

    def along_unit(self, q: np.ndarray, jacobians: np.ndarray, units: np.ndarray) -> np.ndarray:
        """:meth:`__call__` without its checks, for a controller's tick: ``q`` (nq,),
        ``jacobians`` (A, 3, nv) and ``units`` (A, 3) already float arrays of those shapes,
        each direction of length 1 or 0 (the distance table's), kg (A,)."""
        upper = pin.computeMinverse(self.model, self.data, q)
        minv = np.triu(upper) + np.triu(upper, 1).T
        jac = jacobians
        row = np.einsum("ax,axv->av", units, jac)  # nᵀ J, (A, nv)
        inverse = np.einsum("av,av->a", row @ minv, row)  # nᵀ J M⁻¹ Jᵀ n ≥ 0
        # at most ‖J‖² tr M⁻¹: a value below ROUNDING of that is rounding, not motion
        bound = np.einsum("axv,axv->a", jac, jac) * np.trace(minv)
        moves = inverse > ROUNDING * bound
        return np.where(moves, 1.0 / np.where(moves, inverse, 1.0), np.inf)


def _check_payload(payload_kg: object, rated_payload_kg: float | None, name: str) -> float:
    """The payload as a float, or InputError (negative, not finite, above the rating)."""
    is_real = isinstance(payload_kg, numbers.Real) and not isinstance(payload_kg, bool)
    p = float(payload_kg) if is_real else math.nan  # type: ignore[arg-type]
    if not (math.isfinite(p) and p >= 0.0):
        raise InputError(
            f"payload_kg must be a finite number of kg at least 0, got {payload_kg!r}",
            name="payload_kg",
            value=payload_kg,
        )
    limit = MAX_PAYLOAD_KG if rated_payload_kg is None else rated_payload_kg
    if p > limit:
        what = (
            f"the {name} arm's rated payload, {limit:g} kg ([arm] rated_payload_kg)"
            if rated_payload_kg is not None
            else f"{limit:g} kg (the {name} description gives no rated payload)"
        )
        raise InputError(
            f"payload_kg = {p!r} kg is above {what}", name="payload_kg", value=payload_kg
        )
    return p


def _check_inertias(model: pin.Model, data: pin.Data, name: str, path: Path | None) -> None:
    """Refuse a model whose mass matrix is not positive definite at its neutral configuration."""
    moving = sum(model.inertias[j].mass for j in range(1, model.njoints))
    if not moving > 0.0:
        raise RobotDescriptionError(
            f"{name}: no moving link has mass (a URDF without <inertial> elements?); power and "
            "force limiting needs the arm's inertias",
            path=path,
            name="inertias",
            value=moving,
        )
    upper = pin.crba(model, data, pin.neutral(model))
    m = np.triu(upper) + np.triu(upper, 1).T
    try:
        eig = np.linalg.eigvalsh(m) if np.all(np.isfinite(m)) else np.array([np.nan])
    except np.linalg.LinAlgError:  # never leaves the library (qpavoid.core.errors)
        eig = np.array([np.nan])
    if not (np.all(np.isfinite(eig)) and eig[0] > MIN_CONDITION * max(eig[-1], 0.0)):
        raise RobotDescriptionError(
            f"{name}: the mass matrix at the neutral configuration is not positive definite "
            f"(eigenvalues {eig[0]:.3g} to {eig[-1]:.3g} kg m²): a joint moves no mass; give "
            "every moving link its <inertial>",
            path=path,
            name="inertias",
            value=float(eig[0]),
        )
