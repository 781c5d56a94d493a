"""Power and force limiting (``safety="pfl"``): each pair's permitted contact speed, per tick.

ISO/TS 15066 §5.5.5 permits contact with the body regions of its Annex A other than the
head, face, neck and trunk, as long as the robot's speed towards the region at the moment
of contact keeps the transferred energy within the region's limit (Annex A's force form,
:func:`~qpavoid.laws.pfl.transient_speed_limit_mps`):

    v_max = F_T / sqrt(μ k),    μ = (1/m_H + 1/m_R)⁻¹,    m_R = (nᵀ J_p M⁻¹ J_pᵀ n)⁻¹

with F_T the region's transient permissible force, k its effective spring constant, m_H
its effective mass (Tables A.2 and A.3, :mod:`qpavoid.laws.pfl`), and m_R the arm's
effective mass at the pair's robot point p along the pair's normal n, from the mass
matrix M (payload included) and the point's Jacobian J_p (:class:`~qpavoid.arm.inertia.
EffectiveMass`). Annex A's masses bounce apart; a position-controlled arm keeps moving
until it has stopped, so it must also stop within the part's allowance δ = F_T / k past
the surface it sees (:func:`~qpavoid.laws.pfl.stopping_contact_speed_mps`):

    v_c = (d − C − Z_d − Z_r + δ) / (T_r + T_s/2)

For a pair whose part permits contact, the speed and separation bound on the robot
point's approach speed ``−nᵀ J_p q̇`` becomes

    −nᵀ J_p q̇  ≤  max(v_SSM(d), min(v_max, v_c))   (separation holds, or a transient contact)

and ``max(v_SSM(d), min(v_max, v_c, 0))`` where the part could be pinned against the fixed
surface (the table its forearms and hands rest on, :func:`~qpavoid.laws.pfl.clampable`).
The robot never pushes on into a part it sees, nor towards one it could clamp. The head
and trunk keep the speed and separation bound (docs/safety.md §9).
"""

from __future__ import annotations

import numpy as np

from qpavoid.arm.inertia import EffectiveMass
from qpavoid.arm.model import Kinematics, Robot
from qpavoid.distance.table import DistanceTable
from qpavoid.human.body import BodyModel, HumanGeometry
from qpavoid.laws.pfl import (
    PFLConfig,
    clampable,
    compression_allowance_m,
    stopping_contact_speed_mps,
    transient_speed_limit_mps,
)
from qpavoid.laws.ssm import SSMConfig, fixed_terms

__all__ = ["ContactLimits"]


class ContactLimits:
    """The permitted contact speed of every set × part pair (build once per controller).

    Parameters
    ----------
    robot
        The arm (its inertias: a description without them cannot use ``pfl``).
    human
        The body model (each part's Annex A region, ``BodyModel.regions``).
    config
        The payload and the regions' table (:class:`~qpavoid.laws.pfl.PFLConfig`).

    Raises
    ------
    RobotDescriptionError
        If the arm's description has no inertias.
    InputError
        If the payload is outside the arm's rating, or a part names a region the table
        lacks.
    """

    def __init__(self, robot: Robot, human: BodyModel, config: PFLConfig):
        self.mass = EffectiveMass(robot, config.payload_kg)
        contact, force, spring, mass = config.part_limits(human.regions)
        #: (K,) True for the parts whose region permits transient contact
        self.contact = np.asarray(contact, dtype=bool)
        self.force_n, self.spring_npm = np.asarray(force), np.asarray(spring)
        self.human_kg = np.asarray(mass)
        #: (K,) δ = F_T / k of each part, m (0 where no contact is permitted)
        self.allowance_m = np.where(
            self.contact, compression_allowance_m(self.force_n, self.spring_npm), 0.0
        )
        self.radii = np.asarray(human.capsule_radii, dtype=float)
        self.surface_z_m, self.clamp_gap_m = config.surface_z_m, config.clamp_gap_m
        #: A speed and separation bound at or above this cannot bind (the description's
        #: ``[arm] max_point_speed_mps``): its pair needs no contact speed, m/s.
        self.above_mps = float(robot.arm.max_point_speed_mps)

    def __call__(
        self,
        kin: Kinematics,
        table: DistanceTable,
        geos: list[HumanGeometry],
        who: np.ndarray,
        ssm: SSMConfig,
        bound: np.ndarray,
    ) -> np.ndarray:
        """(S, K) each pair's permitted contact speed, m/s: ``min(v_max, v_c)`` where the
        pair's part permits contact and is seen (no more than 0 where it could be clamped),
        −inf elsewhere (the head and trunk, parts not seen: no contact permitted).

        Parameters
        ----------
        kin
            The arm's kinematics (with Jacobians).
        table
            The distance table (its witness points and directions).
        geos, who
            Everybody's geometry as perceived and the person of each pair (S, K): the
            parts' radii, widened by their uncertainty, for :func:`~qpavoid.laws.pfl.
            clampable`.
        ssm
            This tick's speed and separation constants (resolved, with this tick's T_s):
            C + Z_d + Z_r and T_r + T_s/2 of :func:`~qpavoid.laws.pfl.
            stopping_contact_speed_mps`.
        bound
            (S, K) the pairs' speed and separation bounds, m/s: a pair whose bound no point
            of the arm reaches (+inf for a part not seen) needs no contact speed (−inf),
            since the separation row takes the larger and its damper is beyond reach too
            (the dampers act within 0.15 m, where the bound is below 1 m/s).
        """
        d = table.distance
        out = np.full(d.shape, -np.inf)
        pairs = self.contact[None, :] & (bound < self.above_mps) & np.isfinite(d)
        if not pairs.any():
            return out
        sets, parts = np.nonzero(pairs)
        jac = table.robot_jacobians(kin, sets, parts)
        m_robot = self.mass.along_unit(kin.q, jac, table.vector[sets, parts])
        v_max = transient_speed_limit_mps(
            self.force_n[parts], self.spring_npm[parts], self.human_kg[parts], m_robot
        )
        pinned = self._pinned(table, geos, who[sets, parts], sets, parts)
        assert ssm.reaction_time_s is not None  # resolved by the controller
        v_stop = stopping_contact_speed_mps(
            d[sets, parts],
            self.allowance_m[parts],
            fixed_terms(ssm),
            ssm.reaction_time_s + ssm.stop_time_s / 2.0,
        )
        v = np.minimum(v_max, v_stop)
        out[sets, parts] = np.where(pinned, np.minimum(v, 0.0), v)
        return out

    def _pinned(
        self,
        table: DistanceTable,
        geos: list[HumanGeometry],
        people: np.ndarray,
        sets: np.ndarray,
        parts: np.ndarray,
    ) -> np.ndarray:
        """(A,) True where the pair's part could be clamped (:func:`~qpavoid.laws.pfl.
        clampable`), whatever the distance method: the part as its capsule, widened by its
        uncertainty and its fingers' reach, around the axis point under the table's witness
        point (a sphere's witness point lies further out, on a larger radius)."""
        segments = np.stack([g.segments for g in geos])[people, parts]  # (A, 2, 3)
        a, b = segments[:, 0], segments[:, 1]
        widen = np.stack([np.asarray(g.part_margin) + np.asarray(g.reach_margin) for g in geos])[
            people, parts
        ]
        h, n = table.human_point[sets, parts], table.vector[sets, parts]
        axis = b - a
        u = np.clip(
            np.einsum("ax,ax->a", h - a, axis)
            / np.maximum(np.einsum("ax,ax->a", axis, axis), 1e-300),
            0.0,
            1.0,
        )
        radius = self.radii[parts] + widen
        surface = a + u[:, None] * axis + radius[:, None] * n
        return clampable(surface, n, radius, self.surface_z_m, self.clamp_gap_m)

    def protected(self) -> np.ndarray:
        """(K,) True for the parts whose region permits no contact (head, trunk)."""
        return ~self.contact
