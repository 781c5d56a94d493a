"""Capsule–capsule distances from coal: the judge of the compiled ones.

Each robot set and each human part is a capsule; coal's signed distance between every
pair gives the witness points and, under contact, the normal. The result is a
:class:`~qpavoid.distance.table.DistanceTable`, as for the paper's spheres.
:class:`~qpavoid.distance.capsules.CapsuleDistance` computes the same table in one
compiled pass (``--distance capsules``); this one is ``--distance capsules-coal``, the
tests' reference for it, and the truth's distance (:mod:`qpavoid.loop.truth`).
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin

from qpavoid.arm.model import Kinematics, Robot
from qpavoid.core.compiling import kernel_input
from qpavoid.core.geometry import TINY, unit
from qpavoid.distance._kernels import capsule_axes, capsule_directions
from qpavoid.distance._kernels import warm_up as warm_up_kernels
from qpavoid.distance.table import FALLBACK_DIRECTION, DistanceTable, require_people
from qpavoid.human.body import BodyModel, HumanGeometry

#: A capsule's axis in its own frame (coal's convention): +z.
EZ = np.array([0.0, 0.0, 1.0])
#: A person is skipped for a pair only if their lower bound exceeds the best distance by
#: more than this (far above coal's and floating-point error), m.
BOUND_SLACK_M = 1e-6
#: The witness point of a pair not measured (a part not seen).
NO_POINT = np.full(3, np.nan)
NO_POINT.setflags(write=False)
#: The rotation of a capsule too short to have an axis (a sphere).
NO_ROTATION = pin.Quaternion.Identity()
#: A half turn about x: it takes +z onto −z (quaternion w = 0, x = 1).
HALF_TURN_X = pin.Quaternion(0.0, 1.0, 0.0, 0.0)


def axis_rotation(u: np.ndarray) -> pin.Quaternion:
    """A rotation taking +z onto the unit direction ``u`` (3,); the identity if
    ``‖u‖ < TINY``.

    For ``u_z ≥ 0`` the smallest one, Pinocchio's ``Quaternion.FromTwoVectors(z, u)``. For
    ``u_z < 0`` that quaternion is ill-conditioned: its scalar part is
    ``√((1 + u_z)/2)``, and as ``u`` nears −z the cancellation in ``1 + u_z`` turns the
    rounding of ``u`` into an error of order ``ε / (1 + u_z)`` in where z lands (1.3e-10
    rad at ``1 + u_z = 9e-7``: enough to spoil a finite difference of the capsule
    distance). There the rotation is ``FromTwoVectors(−z, u) · R_x(π)``: the half turn
    ``R_x(π)`` takes z onto −z exactly, and ``FromTwoVectors(−z, u)`` is well conditioned
    (``1 − u_z ≥ 1``). A capsule is symmetric about its axis, so which turn about the
    axis either gives changes no distance.
    """
    if float(u @ u) < TINY * TINY:
        return NO_ROTATION
    if u[2] >= 0.0:
        return pin.Quaternion.FromTwoVectors(EZ, u)
    return pin.Quaternion.FromTwoVectors(-EZ, u) * HALF_TURN_X


def axis_rotations(u: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations taking +z onto the unit vectors ``u`` (N, 3) (:func:`axis_rotation`)."""
    return np.array([axis_rotation(v).matrix() for v in u]).reshape(-1, 3, 3)


class _Capsules:
    """Coal capsules (shapes and transforms) built once, then only moved and widened."""

    def __init__(self, radii: np.ndarray):
        self.radii = np.asarray(radii, dtype=float)
        self.shapes = [coal.Capsule(r, 0.0) for r in self.radii]
        self.tfs = [coal.Transform3s() for _ in self.shapes]
        self.centre = np.zeros((len(self.shapes), 3))
        self.reach = np.zeros(len(self.shapes))  #: half length + radius: a bounding sphere
        self.placed: HumanGeometry | None = None  # for a person's: the geometry shown

    def place(self, segments: np.ndarray, valid: np.ndarray, widen: np.ndarray | None) -> None:
        """Move the valid capsules onto their ``segments`` (N, 2, 3; others may be NaN),
        radii + ``widen``."""
        axis, half, self.centre = capsule_axes(kernel_input(segments, np.float64))
        radii = self.radii if widen is None else self.radii + widen
        self.reach = half + radii
        half_list, radii_list = half.tolist(), radii.tolist()
        for k in np.flatnonzero(valid).tolist():
            self.shapes[k].halfLength = half_list[k]
            if widen is not None:
                self.shapes[k].radius = radii_list[k]
            self.tfs[k].setQuatRotation(axis_rotation(axis[k]))
            self.tfs[k].setTranslation(self.centre[k])


class CoalCapsuleDistance:
    """Exact capsule-capsule distances from coal; build once, call every tick.

    The coal shapes, transforms and distance functors are created once (the robot's, and
    each person's as people appear); each call only moves them (a person's once per camera
    frame, widened by the margins). coal's signed distance gives the witness points and
    the normal (from the human capsule to the robot capsule), also under penetration.

    With several people (:meth:`closest`), each robot set × body part pair needs only the
    closest person's distance: people are tried in order of a lower bound (the distance
    between the two capsules' bounding spheres) and coal is not called for a person whose
    bound exceeds the best distance found: the result is exact.
    """

    method = "capsules"  #: the table's geometry
    name = "capsules-coal"  #: the distance method's name (``--distance``)

    def __init__(self, robot: Robot, human: BodyModel):
        self.set_names, self.part_names = robot.set_names, human.part_names
        self._robot = _Capsules(robot.capsule_radii)
        self._robot_valid = np.ones(len(self._robot.shapes), dtype=bool)
        self._human_radii = human.capsule_radii
        self._people: list[tuple[_Capsules, list[list[coal.ComputeDistance]]]] = []
        self._shape = (len(self._robot.shapes), len(human.capsule_radii))
        self._request = coal.DistanceRequest()
        self._request.enable_signed_distance = True
        self._result = coal.DistanceResult()
        warm_up_kernels()

    def _person(self, k: int, geo: HumanGeometry) -> tuple[_Capsules, list]:
        """The ``k``-th person's capsules, showing ``geo`` (moved only when it changes)."""
        while len(self._people) <= k:
            caps = _Capsules(self._human_radii)
            functors = [
                [coal.ComputeDistance(h, r) for h in caps.shapes] for r in self._robot.shapes
            ]
            self._people.append((caps, functors))
        caps, functors = self._people[k]
        if geo is not caps.placed:
            assert geo.part_margin is not None and geo.reach_margin is not None  # filled in
            caps.place(geo.segments, geo.segment_valid, geo.part_margin + geo.reach_margin)
            caps.placed = geo
        return caps, functors

    def __call__(self, kin: Kinematics, geo: HumanGeometry) -> DistanceTable:
        """Distance table between the robot capsules at ``kin`` and the human ``geo``."""
        return self.closest(kin, [geo])[0]

    def closest(
        self, kin: Kinematics, geos: list[HumanGeometry]
    ) -> tuple[DistanceTable, np.ndarray]:
        """The table and ``who`` of
        :meth:`CapsuleDistance.closest <qpavoid.distance.capsules.CapsuleDistance.closest>`,
        from coal; the same ``InputError`` for no geometry."""
        require_people(geos)
        seg = kin.segments
        n_sets, n_parts = self._shape
        robot = self._robot
        robot.place(seg, self._robot_valid, None)
        people = [self._person(k, g) for k, g in enumerate(geos)]
        if len(people) == 1:  # nobody to choose from: only parts not seen are skipped
            row = [[0.0] if v else [np.inf] for v in geos[0].segment_valid.tolist()]
            bound_list, order = [row] * n_sets, [[[0]] * n_parts] * n_sets
        else:  # lower bounds (S, K, P): the bounding spheres' distance
            seen = np.stack([g.segment_valid for g in geos], axis=1)  # (K, P)
            gap = np.stack([caps.centre for caps, _ in people], axis=2)  # (K, 3, P)
            bound = np.sqrt(((robot.centre[:, None, :, None] - gap[None]) ** 2).sum(axis=2))
            bound -= robot.reach[:, None, None] + np.stack([c.reach for c, _ in people], 1)[None]
            bound = np.where(seen[None], bound, np.inf)
            order = np.argsort(bound, axis=2, kind="stable").tolist()
            bound_list = bound.tolist()
        req, res = self._request, self._result
        n = n_sets * n_parts
        # Python lists while coal fills them (a numpy row per entry costs more than coal)
        distance, who = [np.inf] * n, [0] * n
        robot_point, human_point = [NO_POINT] * n, [NO_POINT] * n
        contact = []
        for i in range(n_sets):
            tf_r = robot.tfs[i]
            for j in range(n_parts):
                k, best, normal = i * n_parts + j, np.inf, None
                for p in order[i][j]:
                    lower = bound_list[i][j][p]
                    if lower == np.inf or lower > best + BOUND_SLACK_M:
                        break  # sorted: nobody after can be closer
                    caps, functors = people[p]
                    res.clear()
                    d = functors[i][j](caps.tfs[j], tf_r, req, res)
                    if d < best or (d == best and p < who[k]):  # ties: the first person
                        best = distance[k] = d
                        who[k] = p
                        human_point[k] = res.getNearestPoint1()  # copies
                        robot_point[k] = res.getNearestPoint2()
                        normal = res.normal.copy() if d <= 1e-9 else None
                if normal is not None:  # under contact the witnesses give no direction
                    contact.append((k, normal))
        table = self._table(
            seg, np.array(distance), np.array(robot_point), np.array(human_point), contact
        )
        return table, np.array(who, dtype=np.intp).reshape(self._shape)

    def _table(
        self,
        seg: np.ndarray,
        distance: np.ndarray,
        robot_point: np.ndarray,
        human_point: np.ndarray,
        contact: list[tuple[int, np.ndarray]],
    ) -> DistanceTable:
        """The table from coal's distances and witness points (and normals under contact)."""
        # the unit vectors human → robot, and the robot witness point's parameter along its
        # set's axis (for its Jacobian), in one compiled pass
        vector, s = capsule_directions(
            kernel_input(seg, np.float64), distance, robot_point, human_point
        )
        for k, nrm in contact:  # coal's normal points from the human to the robot
            nn = np.linalg.norm(nrm)
            vector[k] = (
                nrm / nn if nn > 0.5 else unit(human_point[k] - robot_point[k], FALLBACK_DIRECTION)
            )
        names = (self.set_names, self.part_names)
        return DistanceTable.of_capsules(names, distance, vector, s, robot_point, human_point)
