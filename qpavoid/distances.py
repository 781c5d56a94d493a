"""Robot-human distances, two methods, one result type (paper Sect. 4, eq. 1).

* **spheres** (the paper's method): for robot set i and human part j, the minimum-norm
  difference d*_ij between any robot point of i and any human point of j, and
  ``‖d_ij‖ = ‖d*_ij‖ - r_R - r_j`` (eq. 1). Vectorised over all pairs.
* **capsules** (exact): coal's capsule-capsule distance between the capsule of set i and
  the capsule of part j.

Both fill a :class:`DistanceTable`. Its witness points lie on the surfaces of the two
shapes (for spheres: the sphere centres moved by their radius along the direction), so
that ``distance == (robot_point - human_point) @ vector`` in both methods. A part with
no usable point has distance +inf, a zero vector and NaN witness points.

For use in a control loop, build :class:`SphereDistance` or :class:`CapsuleDistance`
once and call it every tick with the robot's :class:`~qpavoid.robot.Kinematics` and the
human's :class:`~qpavoid.human.HumanGeometry`; the free functions
:func:`sphere_distances` and :func:`capsule_distances` are the one-shot form.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import coal
import numpy as np

from .errors import InputError
from .human import HumanGeometry, KinectHuman
from .robot import Kinematics, Robot

#: Direction used when two witness points coincide (deep penetration): straight up, m.
FALLBACK_DIRECTION = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class DistanceTable:
    """Distances between every robot set (rows) and human part (columns).

    Attributes
    ----------
    method
        ``"spheres"`` or ``"capsules"``.
    distance
        (S, K) signed distance, m (eq. 1); negative = penetration; +inf = part not seen.
    vector
        (S, K, 3) unit direction from the human to the robot at the closest pair.
    robot_index
        (S, K) index of the robot control point that realised the minimum (spheres; the
        point whose Jacobian eq. (6) uses), -1 for capsules and for parts not seen.
    robot_s
        (S, K) parameter in [0, 1] along the set's capsule axis of the robot point
        (capsules), NaN for spheres.
    human_index
        (S, K) index of the human model point (spheres), -1 for capsules.
    set_names, part_names
        Row and column labels.
    robot_point, human_point
        (S, K, 3) witness points on the robot and human surfaces, base frame, m (NaN for
        parts not seen). For spheres they are computed on first access.
    """

    method: str
    distance: np.ndarray
    vector: np.ndarray
    robot_index: np.ndarray
    robot_s: np.ndarray
    human_index: np.ndarray
    set_names: tuple[str, ...]
    part_names: tuple[str, ...]
    _witness: tuple = field(repr=False, default=())

    @cached_property
    def robot_point(self) -> np.ndarray:
        return self._witnesses[0]

    @cached_property
    def human_point(self) -> np.ndarray:
        return self._witnesses[1]

    @cached_property
    def _witnesses(self) -> tuple[np.ndarray, np.ndarray]:
        if self.method == "capsules":
            return self._witness
        # spheres: the centres moved by their radii along the direction.
        P, H, r_robot, r_human = self._witness
        shape = self.distance.shape
        v = self.vector.reshape(-1, 3)
        p_idx, m_idx = self.robot_index.ravel(), self.human_index.ravel()
        rp = P[p_idx] - r_robot[:, None] * v
        hp = H[m_idx] + r_human[:, None] * v
        rp[p_idx < 0] = np.nan
        hp[p_idx < 0] = np.nan
        return rp.reshape(*shape, 3), hp.reshape(*shape, 3)

    def min_per_set(self) -> np.ndarray:
        """(S,) minimum distance of each robot set over all parts, m."""
        return self.distance.min(axis=1)

    def closest_part(self, set_index: int) -> int:
        """Column of the part closest to robot set ``set_index``."""
        return int(np.argmin(self.distance[set_index]))

    def robot_jacobian(self, kin: Kinematics, set_index: int, part: int) -> np.ndarray:
        """(3, nv) Jacobian of the robot point of pair (set, part) at ``kin``.

        For spheres, the Jacobian of the control point that realised the minimum (the
        sphere centre, as in eq. 6); for capsules, that of the closest point on the axis.
        """
        k = self.robot_index[set_index, part]
        if k >= 0:
            return kin.point_jacobians[k]
        return kin.segment_point_jacobian(set_index, float(self.robot_s[set_index, part]))


def _unit(diff: np.ndarray, norm: np.ndarray) -> np.ndarray:
    """diff / norm along the last axis, FALLBACK_DIRECTION where norm is ~0."""
    small = norm < 1e-12
    out = diff / np.where(small, 1.0, norm)[..., None]
    out[small] = FALLBACK_DIRECTION
    return out


class SphereDistance:
    """The paper's sphere distances (eq. 1), vectorised; build once, call every tick.

    Parameters
    ----------
    robot
        Gives the control points' set membership and sphere radii.
    human
        Gives the points' part membership and sphere radii.
    """

    method = "spheres"

    def __init__(self, robot: Robot, human: KinectHuman):
        n_sets, n_parts = len(robot.sets), len(human.parts)
        self.set_names, self.part_names = robot.set_names, human.part_names
        # For every (set, part) the flat indices p * M + m of its (robot point, human point)
        # pairs, padded with an index that points at +inf: one gather, one argmin per tick.
        n_human = human.n_points
        pad = len(robot.point_set) * n_human
        pairs = [[[p * n_human + m for p in robot.sets[i].points
                   for m in np.flatnonzero(human.point_part[:, j])] for j in range(n_parts)]
                 for i in range(n_sets)]
        width = max(len(x) for row in pairs for x in row)
        self._pairs = np.full((n_sets * n_parts, width), pad)
        for i in range(n_sets):
            for j in range(n_parts):
                self._pairs[i * n_parts + j, :len(pairs[i][j])] = pairs[i][j]
        self._rows = np.arange(n_sets * n_parts)
        self._pairs_pad = pad
        # Flat pair index -> robot point, human point (-1 for the padding index).
        self._p_of = np.append(np.arange(pad) // n_human, -1)
        self._m_of = np.append(np.arange(pad) % n_human, -1)
        self._no_s = np.full((n_sets, n_parts), np.nan)
        self._no_s.setflags(write=False)
        self._n_human = n_human
        r_robot = np.array([s.sphere_radius_m for s in robot.sets])
        self._r_robot_flat = np.repeat(r_robot, n_parts)
        self._r_human_flat = np.tile(human.sphere_radii, n_sets)
        self._radii = self._r_robot_flat + self._r_human_flat
        self._shape = (n_sets, n_parts)

    def __call__(self, kin: Kinematics, geo: HumanGeometry) -> DistanceTable:
        """Distance table between the robot at ``kin`` and the human ``geo``."""
        P, H = kin.points, geo.filled_points
        diff = P[:, None, :] - H[None, :, :]                                         # (P, M, 3)
        buf = np.empty(self._pairs_pad + 1)
        buf[-1] = np.inf
        np.add(np.sqrt(np.einsum("pmk,pmk->pm", diff, diff)), geo.point_penalty,
               out=buf[:-1].reshape(len(P), -1))
        best = self._pairs[self._rows, buf[self._pairs].argmin(axis=1)]             # flat pair
        d_star = buf[best]
        vector = diff.reshape(-1, 3)[np.minimum(best, self._pairs_pad - 1)]
        with np.errstate(invalid="ignore", divide="ignore"):
            vector /= d_star[:, None]                                               # inf -> 0
        if d_star.min() < 1e-12:
            vector[d_star < 1e-12] = FALLBACK_DIRECTION
        p_idx, m_idx = self._p_of[best], self._m_of[best]                           # -1: unseen
        shape = self._shape
        return DistanceTable(
            self.method, (d_star - self._radii).reshape(shape), vector.reshape(*shape, 3),  # eq. (1)
            p_idx.reshape(shape), self._no_s, m_idx.reshape(shape), self.set_names,
            self.part_names, (P, H, self._r_robot_flat, self._r_human_flat))


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
    moves them. coal's signed distance gives the witness points and the normal (from the
    human capsule to the robot capsule), also under penetration.
    """

    method = "capsules"

    def __init__(self, robot: Robot, human: KinectHuman):
        self.set_names, self.part_names = robot.set_names, human.part_names
        robot_shapes = [coal.Capsule(r, 0.0) for r in robot.capsule_radii]
        human_shapes = [coal.Capsule(r, 0.0) for r in human.capsule_radii]
        self._shapes = robot_shapes + human_shapes
        self._tfs = [coal.Transform3s() for _ in self._shapes]
        self._functors = [[coal.ComputeDistance(h, r) for h in human_shapes] for r in robot_shapes]
        self._shape = (len(robot_shapes), len(human_shapes))
        self._robot_valid = np.ones(len(robot_shapes), dtype=bool)
        self._minus_one = np.full(self._shape, -1)
        self._minus_one.setflags(write=False)
        self._request = coal.DistanceRequest()
        self._request.enable_signed_distance = True
        self._result = coal.DistanceResult()

    def _place(self, segments: np.ndarray, valid: np.ndarray) -> None:
        """Move every capsule (robot ones first, then human ones) onto its segment."""
        axis = segments[:, 1] - segments[:, 0]
        length = np.sqrt(np.einsum("nk,nk->n", axis, axis))
        R = axis_rotations(_unit(axis, length))
        centre = 0.5 * (segments[:, 0] + segments[:, 1])
        half = (0.5 * length).tolist()
        for k in np.flatnonzero(valid).tolist():
            self._shapes[k].halfLength = half[k]
            self._tfs[k].setRotation(R[k])
            self._tfs[k].setTranslation(centre[k])

    def __call__(self, kin: Kinematics, geo: HumanGeometry) -> DistanceTable:
        """Distance table between the robot capsules at ``kin`` and the human ``geo``."""
        seg = kin.segments
        n_sets, n_parts = self._shape
        self._place(np.concatenate([seg, np.nan_to_num(geo.segments)]),
                    np.concatenate([self._robot_valid, geo.segment_valid]))
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
                if nrm is not None:   # coal's normal points from the human to the robot
                    nn = np.linalg.norm(nrm)
                    v[n] = nrm / nn if nn > 0.5 else _unit(-(r_pts[n] - h_pts[n])[None],
                                                           np.linalg.norm(r_pts[n] - h_pts[n])[None])[0]
            vector[where] = v
        # Parameter along the robot capsule's axis of the robot witness point (for its Jacobian).
        a = np.repeat(seg[:, 0], n_parts, axis=0)
        ab = np.repeat(seg[:, 1] - seg[:, 0], n_parts, axis=0)
        s = np.einsum("nk,nk->n", np.where(np.isnan(robot_point), 0.0, robot_point) - a, ab) \
            / np.maximum(np.einsum("nk,nk->n", ab, ab), 1e-18)
        shape = self._shape
        return DistanceTable(self.method, distance.reshape(shape), vector.reshape(*shape, 3),
                             self._minus_one, np.clip(s, 0.0, 1.0).reshape(shape), self._minus_one,
                             self.set_names, self.part_names,
                             (robot_point.reshape(*shape, 3), human_point.reshape(*shape, 3)))


METHODS = {"spheres": SphereDistance, "capsules": CapsuleDistance}


def distance_method(name: str, robot: Robot, human: KinectHuman):
    """Build the distance method called ``name`` (``"spheres"`` or ``"capsules"``)."""
    if name not in METHODS:
        raise InputError(f"unknown distance method {name!r}; choose from {sorted(METHODS)}",
                         name="distance", value=name)
    return METHODS[name](robot, human)


def sphere_distances(robot: Robot, q, human: KinectHuman, joints, state=None) -> DistanceTable:
    """The paper's sphere distance table (eq. 1) at robot angles ``q`` (rad).

    Parameters
    ----------
    robot, q
        The robot and its joint angles (nq,), rad.
    human, joints, state
        The human model, its (25, 3) Kinect joints (m, robot base frame) and optional
        (25,) tracking states (None = all tracked).
    """
    return SphereDistance(robot, human)(robot.kinematics(q, jacobians=False),
                                        human.geometry(joints, state))


def capsule_distances(robot: Robot, q, human: KinectHuman, joints, state=None) -> DistanceTable:
    """The exact capsule distance table (coal) at robot angles ``q`` (rad).

    Same arguments as :func:`sphere_distances`.
    """
    return CapsuleDistance(robot, human)(robot.kinematics(q, jacobians=False),
                                         human.geometry(joints, state))
