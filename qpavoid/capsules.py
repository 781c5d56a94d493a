"""Exact capsule-capsule distances (coal), the second distance method.

Each robot set and each human part is a capsule; coal's signed distance between every
pair gives the witness points and, under contact, the normal. The result is a
:class:`~qpavoid.distance_table.DistanceTable`, as for the paper's spheres.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin

from .distance_table import FALLBACK_DIRECTION, DistanceTable
from .geometry import TINY, unit
from .human import HumanGeometry, KinectHuman
from .robot import Kinematics, Robot

#: A capsule's axis in its own frame (coal's convention): +z.
EZ = np.array([0.0, 0.0, 1.0])
#: The rotation of a capsule too short to have an axis (a sphere).
NO_ROTATION = pin.Quaternion.Identity()


def axis_rotation(u: np.ndarray) -> pin.Quaternion:
    """The smallest rotation taking +z onto the direction ``u`` (3,) (Pinocchio's
    ``Quaternion.FromTwoVectors``; a half turn about an axis normal to z for u = −z); the
    identity if ``‖u‖ < TINY``."""
    if float(u @ u) < TINY * TINY:
        return NO_ROTATION
    return pin.Quaternion.FromTwoVectors(EZ, u)


def axis_rotations(u: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations taking +z onto the unit vectors ``u`` (N, 3) (:func:`axis_rotation`)."""
    return np.array([axis_rotation(v).matrix() for v in u]).reshape(-1, 3, 3)


class CapsuleDistance:
    """Exact capsule-capsule distances from coal; build once, call every tick.

    The coal shapes, transforms and distance functors are created once; each call only
    moves them (and widens the human ones by their margins). coal's signed distance gives
    the witness points and the normal (from the human capsule to the robot capsule), also
    under penetration.
    """

    method = "capsules"

    def __init__(self, robot: Robot, human: KinectHuman):
        self.set_names, self.part_names = robot.set_names, human.part_names
        robot_shapes = [coal.Capsule(r, 0.0) for r in robot.capsule_radii]
        human_shapes = [coal.Capsule(r, 0.0) for r in human.capsule_radii]
        self._shapes = robot_shapes + human_shapes
        self._human_radii = human.capsule_radii
        self._tfs = [coal.Transform3s() for _ in self._shapes]
        self._functors = [[coal.ComputeDistance(h, r) for h in human_shapes] for r in robot_shapes]
        self._shape = (len(robot_shapes), len(human_shapes))
        self._robot_valid = np.ones(len(robot_shapes), dtype=bool)
        self._minus_one = np.full(self._shape, -1)
        self._minus_one.setflags(write=False)
        self._request = coal.DistanceRequest()
        self._request.enable_signed_distance = True
        self._result = coal.DistanceResult()
        self._placed: HumanGeometry | None = None  # the geometry the human capsules show

    def _place(self, segments: np.ndarray, valid: np.ndarray, first: int = 0) -> None:
        """Move capsules ``first``, ``first + 1``, ... (robot ones, then human ones) onto
        their segments."""
        axis = segments[:, 1] - segments[:, 0]
        half = (0.5 * np.sqrt(np.einsum("nk,nk->n", axis, axis))).tolist()
        centre = 0.5 * (segments[:, 0] + segments[:, 1])
        for k in np.flatnonzero(valid).tolist():
            self._shapes[first + k].halfLength = half[k]
            self._tfs[first + k].setQuatRotation(axis_rotation(axis[k]))
            self._tfs[first + k].setTranslation(centre[k])

    def __call__(self, kin: Kinematics, geo: HumanGeometry) -> DistanceTable:
        """Distance table between the robot capsules at ``kin`` and the human ``geo``."""
        seg = kin.segments
        n_sets, n_parts = self._shape
        self._place(seg, self._robot_valid)
        if geo is not self._placed:  # the person's capsules move once per camera frame
            self._place(np.nan_to_num(geo.segments), geo.segment_valid, n_sets)
            radii = (self._human_radii + geo.part_margin + geo.reach_margin).tolist()
            for j, r in enumerate(radii):
                self._shapes[n_sets + j].radius = r
            self._placed = geo
        req, res = self._request, self._result
        parts = np.flatnonzero(geo.segment_valid).tolist()
        n = n_sets * n_parts
        distance = np.full(n, np.inf)
        robot_point, human_point = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
        contact = []
        for i in range(n_sets):
            tf_r, functors = self._tfs[i], self._functors[i]
            for j in parts:
                k = i * n_parts + j
                res.clear()
                distance[k] = d = functors[j](self._tfs[n_sets + j], tf_r, req, res)
                human_point[k], robot_point[k] = res.getNearestPoint1(), res.getNearestPoint2()
                if d <= 1e-9:  # under contact the witnesses give no direction: coal's normal
                    contact.append((k, res.normal.copy()))
        seen = np.isfinite(distance)
        vector = np.zeros((n, 3))
        vector[seen] = (robot_point[seen] - human_point[seen]) / np.where(
            distance[seen] > 1e-9, distance[seen], 1.0
        )[:, None]
        for k, nrm in contact:  # coal's normal points from the human to the robot
            nn = np.linalg.norm(nrm)
            vector[k] = (
                nrm / nn if nn > 0.5 else unit(human_point[k] - robot_point[k], FALLBACK_DIRECTION)
            )
        # Parameter along the robot capsule's axis of the robot witness point (for its Jacobian).
        a, ab = seg[:, 0], seg[:, 1] - seg[:, 0]  # (S, 3)
        from_a = np.where(seen[:, None], robot_point, 0.0).reshape(n_sets, n_parts, 3) - a[:, None]
        s = (
            np.einsum("skx,sx->sk", from_a, ab)
            / np.maximum(np.einsum("sx,sx->s", ab, ab), 1e-18)[:, None]
        )
        shape = self._shape
        return DistanceTable(
            self.method,
            distance.reshape(shape),
            vector.reshape(*shape, 3),
            self._minus_one,
            np.minimum(np.maximum(s, 0.0), 1.0),
            self._minus_one,
            self.set_names,
            self.part_names,
            (robot_point.reshape(*shape, 3), human_point.reshape(*shape, 3)),
        )
