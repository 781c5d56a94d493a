"""Exact capsule-capsule distances (coal), the second distance method.

Each robot set and each human part is a capsule; coal's signed distance between every
pair gives the witness points and, under contact, the normal. The result is a
:class:`~qpavoid.distance_table.DistanceTable`, as for the paper's spheres.
"""

from __future__ import annotations

import coal
import numpy as np

from .distance_table import FALLBACK_DIRECTION, DistanceTable
from .geometry import unit
from .human import HumanGeometry, KinectHuman
from .robot import Kinematics, Robot


def axis_rotations(u: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations taking +z onto the unit vectors ``u`` (N, 3) (Rodrigues).

    ``R = I + [w]x + [w]x² / (1 + z)`` with ``w = ez × u``; for ``u`` = −z, a half turn
    about x.
    """
    x, y, z = u.T
    k = 1.0 / np.maximum(1.0 + z, 1e-12)
    xy = -x * y * k
    R = np.stack([1 - x * x * k, xy, x, xy, 1 - y * y * k, y, -x, -y, z], axis=1).reshape(-1, 3, 3)
    flip = z < -1 + 1e-9
    if flip.any():
        R[flip] = np.diag([1.0, -1.0, -1.0])
    return R


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
        length = np.sqrt(np.einsum("nk,nk->n", axis, axis))
        R = axis_rotations(unit(axis, FALLBACK_DIRECTION, norm=length))
        centre = 0.5 * (segments[:, 0] + segments[:, 1])
        half = (0.5 * length).tolist()
        for k in np.flatnonzero(valid).tolist():
            self._shapes[first + k].halfLength = half[k]
            self._tfs[first + k].setRotation(R[k])
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
        dist, rp, hp, normal, where = [], [], [], [], []
        for i in range(n_sets):
            tf_r, functors = self._tfs[i], self._functors[i]
            for j in parts:
                res.clear()
                d = functors[j](self._tfs[n_sets + j], tf_r, req, res)
                dist.append(d)
                hp.append(res.getNearestPoint1())
                rp.append(res.getNearestPoint2())
                # Only under contact is the witness difference no direction: keep coal's normal.
                normal.append(res.normal if d <= 1e-9 else None)
                where.append(i * n_parts + j)
        distance = np.full(n_sets * n_parts, np.inf)
        robot_point = np.full((n_sets * n_parts, 3), np.nan)
        human_point = np.full((n_sets * n_parts, 3), np.nan)
        vector = np.zeros((n_sets * n_parts, 3))
        if where:
            d = np.array(dist)
            r_pts, h_pts = np.array(rp), np.array(hp)
            distance[where], robot_point[where], human_point[where] = d, r_pts, h_pts
            v = (r_pts - h_pts) / np.where(d > 1e-9, d, 1.0)[:, None]
            for n, nrm in enumerate(normal):
                if nrm is not None:  # coal's normal points from the human to the robot
                    nn = np.linalg.norm(nrm)
                    v[n] = nrm / nn if nn > 0.5 else unit(h_pts[n] - r_pts[n], FALLBACK_DIRECTION)
            vector[where] = v
        # Parameter along the robot capsule's axis of the robot witness point (for its Jacobian).
        a = np.repeat(seg[:, 0], n_parts, axis=0)
        ab = np.repeat(seg[:, 1] - seg[:, 0], n_parts, axis=0)
        s = np.einsum(
            "nk,nk->n", np.where(np.isnan(robot_point), 0.0, robot_point) - a, ab
        ) / np.maximum(np.einsum("nk,nk->n", ab, ab), 1e-18)
        shape = self._shape
        return DistanceTable(
            self.method,
            distance.reshape(shape),
            vector.reshape(*shape, 3),
            self._minus_one,
            np.clip(s, 0.0, 1.0).reshape(shape),
            self._minus_one,
            self.set_names,
            self.part_names,
            (robot_point.reshape(*shape, 3), human_point.reshape(*shape, 3)),
        )
