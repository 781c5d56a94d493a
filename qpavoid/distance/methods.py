"""Robot-human distances, two methods, one result type (paper Sect. 4, eq. 1).

* **spheres** (the paper's method): for robot set i and human part j, the minimum-norm
  difference d*_ij between any robot point of i and any human point of j, and
  ``‖d_ij‖ = ‖d*_ij‖ - r_R - r_j`` (eq. 1). Vectorised over all pairs.

Both methods widen a part by its uncertainty (``HumanGeometry.part_margin``: lost or
inferred joints); the capsule method also by how far its fingers stick out of it
(``reach_margin``).
* **capsules** (exact, the default): the signed distance between the capsule of set i and
  the capsule of part j, the whole table in one compiled pass
  (:mod:`qpavoid.distance.capsules`); **capsules-coal** is the same table from coal's
  capsule distance (:mod:`qpavoid.distance.coal_capsules`), its judge in the tests.

Both fill a :class:`~qpavoid.distance.table.DistanceTable` (its witness points, the
convention for parts not seen). This module is the one to import from: it holds the
sphere method and re-exports the table and the capsule methods.

For use in a control loop, build :class:`SphereDistance` or :class:`CapsuleDistance`
once and call it every tick with the robot's :class:`~qpavoid.arm.model.Kinematics` and the
human's :class:`~qpavoid.human.body.HumanGeometry`; the free functions
:func:`sphere_distances` and :func:`capsule_distances` are the one-shot form.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from qpavoid.arm.model import Kinematics, Robot
from qpavoid.core.errors import InputError
from qpavoid.distance._kernels import sphere_table, warm_up
from qpavoid.distance.capsules import CapsuleDistance
from qpavoid.distance.coal_capsules import CoalCapsuleDistance, axis_rotations
from qpavoid.distance.table import FALLBACK_DIRECTION, DistanceTable, closest_of
from qpavoid.human.body import BodyModel, HumanGeometry

__all__ = [
    "FALLBACK_DIRECTION",
    "METHODS",
    "CapsuleDistance",
    "CoalCapsuleDistance",
    "DistanceMethod",
    "DistanceTable",
    "PointDistance",
    "SphereDistance",
    "axis_rotations",
    "capsule_distances",
    "distance_method",
    "geometry",
    "sphere_distances",
]


class SphereDistance:
    """The paper's sphere distances (eq. 1), vectorised; build once, call every tick.

    Parameters
    ----------
    robot
        Gives the control points' set membership and sphere radii.
    human
        Gives the points' part membership and sphere radii.
    """

    method = "spheres"  #: the table's geometry
    name = "spheres"  #: the distance method's name (``--distance``)

    def __init__(self, robot: Robot, human: BodyModel):
        n_sets, n_parts = len(robot.sets), len(human.parts)
        self.set_names, self.part_names = robot.set_names, human.part_names
        # For every (set, part) the flat indices p * M + m of its (robot point, human point)
        # pairs, padded with P * M (no pair): one pass of distance_kernels.sphere_table.
        n_human = human.n_points
        pad = len(robot.point_set) * n_human
        pairs = [
            [
                [
                    p * n_human + m
                    for p in robot.sets[i].points
                    for m in np.flatnonzero(human.point_part[:, j])
                ]
                for j in range(n_parts)
            ]
            for i in range(n_sets)
        ]
        width = max(len(x) for row in pairs for x in row)
        self._pairs = np.full((n_sets * n_parts, width), pad)
        for i in range(n_sets):
            for j in range(n_parts):
                self._pairs[i * n_parts + j, : len(pairs[i][j])] = pairs[i][j]
        self._no_s = np.full((n_sets, n_parts), np.nan)
        self._no_s.setflags(write=False)
        r_robot = np.array([s.sphere_radius_m for s in robot.sets])
        self._r_robot_flat = np.repeat(r_robot, n_parts)
        self._r_human_flat = np.tile(human.sphere_radii, n_sets)
        self._radii = self._r_robot_flat + self._r_human_flat
        self._shape = (n_sets, n_parts)
        warm_up()

    def __call__(self, kin: Kinematics, geo: HumanGeometry) -> DistanceTable:
        """Distance table between the robot at ``kin`` and the human ``geo``."""
        P, H = kin.points, geo.points
        part_margin = geo.part_margin
        assert part_margin is not None  # filled in by HumanGeometry
        d, vector, p_idx, m_idx = sphere_table(
            P, H, geo.point_valid, self._pairs, self._radii, part_margin, FALLBACK_DIRECTION
        )
        shape = self._shape
        return DistanceTable(  # eq. (1)
            self.method,
            d.reshape(shape),
            vector.reshape(*shape, 3),
            p_idx.reshape(shape),
            self._no_s,
            m_idx.reshape(shape),
            self.set_names,
            self.part_names,
            (P, H, self._r_robot_flat, self._r_human_flat, part_margin),
        )

    def closest(
        self, kin: Kinematics, geos: list[HumanGeometry]
    ) -> tuple[DistanceTable, np.ndarray]:
        """Per robot set and body part, the closest of the people ``geos``: the table and
        ``who`` (S, K), the index of each entry's person
        (:func:`~qpavoid.human.people.closest_of`)."""
        return closest_of([self(kin, g) for g in geos])


class PointDistance:
    """Eq. (1) between one robot control point and every human part; build once, call
    every tick.

    Each part's distance is the smallest of its points' ``‖x − h_m‖ − r_R − r_j``, through
    the sphere table's own compiled pass (:func:`~qpavoid.distance._kernels.sphere_table`,
    one row per part); the parts' uncertainty margins are not added.

    Parameters
    ----------
    point
        Index of the robot point among the control points.
    n_points
        Number of control points (the rows of ``Kinematics.points``).
    radius_m
        Sphere radius r_R of the robot point, m.
    human
        Gives the points' part membership and the parts' sphere radii r_j.
    """

    def __init__(self, point: int, n_points: int, radius_m: float, human: BodyModel):
        M = human.n_points
        members = [np.flatnonzero(human.point_part[:, j]) for j in range(len(human.parts))]
        width = max(len(m) for m in members)
        self._pairs = np.full((len(members), width), n_points * M)  # padded: no pair
        for j, m in enumerate(members):
            self._pairs[j, : len(m)] = point * M + m
        self._radii = radius_m + np.asarray(human.sphere_radii, dtype=float)
        self._no_margin = np.zeros(len(members))
        warm_up()

    def __call__(self, points: np.ndarray, geo: HumanGeometry) -> tuple[np.ndarray, np.ndarray]:
        """(K,) distance of the point to each part, m (+inf for a part not seen), and (K, 3)
        unit directions from the part to the point, for the robot's control ``points``."""
        d, vector, _, _ = sphere_table(
            points,
            geo.points,
            geo.point_valid,
            self._pairs,
            self._radii,
            self._no_margin,
            FALLBACK_DIRECTION,
        )
        return d, vector


#: A distance method of the tables (rows: robot sets, columns: body parts).
DistanceMethod = SphereDistance | CapsuleDistance | CoalCapsuleDistance

METHODS: dict[str, type[SphereDistance] | type[CapsuleDistance] | type[CoalCapsuleDistance]] = {
    "spheres": SphereDistance,
    "capsules": CapsuleDistance,
    "capsules-coal": CoalCapsuleDistance,
}


def geometry(name: str) -> str:
    """The shapes the distance method ``name`` measures between: ``"spheres"`` or
    ``"capsules"`` (both capsule methods), as a table's ``method`` says."""
    return "spheres" if name == "spheres" else "capsules"


def distance_method(name: str, robot: Robot, human: BodyModel) -> DistanceMethod:
    """Build the distance method called ``name`` (a key of :data:`METHODS`)."""
    if name not in METHODS:
        raise InputError(
            f"unknown distance method {name!r}; choose from {sorted(METHODS)}",
            name="distance",
            value=name,
        )
    return METHODS[name](robot, human)


def sphere_distances(
    robot: Robot, q: ArrayLike, human: BodyModel, joints: object, state: object = None
) -> DistanceTable:
    """The paper's sphere distance table (eq. 1) at robot angles ``q`` (rad).

    Parameters
    ----------
    robot, q
        The robot and its joint angles (nq,), rad.
    human, joints, state
        The body model, its skeleton's (J, 3) joints (m, robot base frame; J = 25 for the
        Kinect v2) and optional (J,) tracking states (None = all tracked).
    """
    return SphereDistance(robot, human)(
        robot.kinematics(q, jacobians=False), human.geometry(joints, state)
    )


def capsule_distances(
    robot: Robot, q: ArrayLike, human: BodyModel, joints: object, state: object = None
) -> DistanceTable:
    """The exact capsule distance table at robot angles ``q`` (rad).

    Same arguments as :func:`sphere_distances`.
    """
    return CapsuleDistance(robot, human)(
        robot.kinematics(q, jacobians=False), human.geometry(joints, state)
    )
