"""The result of every distance method: one table of robot-set x human-part distances.

Its witness points lie on the surfaces of the two shapes (for spheres: the sphere centres
moved by their radius along the direction), so that
``distance == (robot_point - human_point) @ vector`` in both methods. A part with no
usable point has distance +inf, a zero vector and NaN witness points.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cache, cached_property, partial

import numpy as np

from qpavoid.arm.model import Kinematics
from qpavoid.core.errors import InputError

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
    _witness: tuple | Callable[[], tuple[np.ndarray, np.ndarray]] = field(repr=False, default=())

    @cached_property
    def robot_point(self) -> np.ndarray:
        return self._witnesses[0]

    @cached_property
    def human_point(self) -> np.ndarray:
        return self._witnesses[1]

    @cached_property
    def _witnesses(self) -> tuple[np.ndarray, np.ndarray]:
        if callable(self._witness):  # several people's: picked from theirs when asked
            return self._witness()
        if len(self._witness) == 2:  # capsules
            return self._witness
        # spheres: the centres moved by their radii along the direction.
        P, H, r_robot, r_human, part_margin = self._witness
        r_human = r_human + np.tile(part_margin, len(r_human) // len(part_margin))
        shape = self.distance.shape
        v = self.vector.reshape(-1, 3)
        p_idx, m_idx = self.robot_index.ravel(), self.human_index.ravel()
        rp = P[p_idx] - r_robot[:, None] * v
        hp = H[m_idx] + r_human[:, None] * v
        rp[p_idx < 0] = np.nan
        hp[p_idx < 0] = np.nan
        return rp.reshape(*shape, 3), hp.reshape(*shape, 3)

    @classmethod
    def of_capsules(
        cls,
        names: tuple[tuple[str, ...], tuple[str, ...]],
        distance: np.ndarray,
        vector: np.ndarray,
        robot_s: np.ndarray,
        robot_point: np.ndarray,
        human_point: np.ndarray,
    ) -> DistanceTable:
        """A capsule table from its rows ``r = i K + j`` (``names``: the sets', the parts')."""
        shape = (len(names[0]), len(names[1]))
        none = _no_index(shape)  # one read-only array per shape, not one per tick
        return cls(
            "capsules",
            distance.reshape(shape),
            vector.reshape(*shape, 3),
            none,
            robot_s.reshape(shape),
            none,
            *names,
            (robot_point.reshape(*shape, 3), human_point.reshape(*shape, 3)),
        )

    def min_per_set(self) -> np.ndarray:
        """(S,) minimum distance of each robot set over all parts, m."""
        return self.distance.min(axis=1)

    def closest_part(self, set_index: int) -> int:
        """Column of the part closest to robot set ``set_index``."""
        return int(np.argmin(self.distance[set_index]))

    def robot_jacobian(self, kin: Kinematics, set_index: int, part: int) -> np.ndarray:
        """(3, nv) Jacobian of the robot point of pair (set, part) at ``kin``.

        For spheres, the Jacobian of the control point that realised the minimum (the
        sphere centre, as in eq. 6: a Pinocchio frame on the body that carries it); for
        capsules, that of the witness point's projection on the axis, at ``robot_s``:
        the interpolation of the ends' Jacobians, exact because one rigid body carries
        the axis (checked when the description is read). Either is the velocity of that
        point on its body. The witness point on the surface, ``c − r n`` with c that
        point, moves at ``J_c q̇ − ω × r n``: the difference is normal to ``n``, so
        ``nᵀ J`` is the exact rate of the distance, ``ḋ = nᵀ J q̇`` (the velocity
        dampers' and speed and separation's rows; tests/test_witness_jacobians.py checks
        both against finite differences on every arm).
        """
        return self.robot_jacobians(kin, np.array([set_index]), np.array([part]))[0]

    def robot_jacobians(self, kin: Kinematics, sets: np.ndarray, parts: np.ndarray) -> np.ndarray:
        """(A, 3, nv) Jacobians of the robot points of the pairs ``(sets[a], parts[a])``.

        The vectorised :meth:`robot_jacobian` (the velocity dampers need every close pair).
        """
        if self.method == "spheres":
            assert kin.point_jacobians is not None
            return kin.point_jacobians[self.robot_index[sets, parts]]
        return kin.segment_point_jacobian(sets, self.robot_s[sets, parts])


@cache
def _no_index(shape: tuple[int, int]) -> np.ndarray:
    """(S, K) of −1, read-only: the capsule tables' robot and human indices."""
    out = np.full(shape, -1)
    out.setflags(write=False)
    return out


def require_people(geos: Sequence[object]) -> None:
    """Refuse an empty list of people: nobody is :data:`~qpavoid.human.people.NOBODY`'s
    one geometry with no part seen, never no geometry (an ``InputError``)."""
    if not geos:
        raise InputError("closest: no person's geometry (nobody: NOBODY's)", name="geos")


def closest_of(tables: Sequence[DistanceTable]) -> tuple[DistanceTable, np.ndarray]:
    """Per robot set and body part, the entry of the closest person.

    Returns the combined table (its witness points picked when first asked) and ``who``
    (S, K): the index of the person each entry comes from.
    """
    if not tables:
        raise InputError("closest_of: no person's table (nobody: NOBODY's)", name="tables")
    if len(tables) == 1:
        return tables[0], np.zeros(tables[0].distance.shape, dtype=np.intp)
    D = np.stack([t.distance for t in tables])
    who = np.argmin(D, axis=0)

    pick = partial(_pick, tables, who)
    first = tables[0]
    return (
        DistanceTable(
            first.method,
            pick("distance"),
            pick("vector"),
            pick("robot_index"),
            pick("robot_s"),
            pick("human_index"),
            first.set_names,
            first.part_names,
            partial(_pick_witnesses, pick),  # only if asked: a pick per person
        ),
        who,
    )


def _pick(tables: Sequence[DistanceTable], who: np.ndarray, name: str) -> np.ndarray:
    """Attribute ``name`` of each entry's closest person's table (``who`` (S, K))."""
    a = np.stack([getattr(t, name) for t in tables])
    idx = who.reshape(1, *who.shape, *([1] * (a.ndim - 3)))
    return np.take_along_axis(a, idx, axis=0)[0]


def _pick_witnesses(pick: Callable[[str], np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    return pick("robot_point"), pick("human_point")
