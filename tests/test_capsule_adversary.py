"""The compiled capsule distances under attack, judged by exact rational arithmetic.

The reference (:func:`_exact_gap`) is the minimum of the segment–segment squared distance,
a convex quadratic in (s, t) on the unit square, over its interior critical point and its
four clamped edges, in :class:`fractions.Fraction` arithmetic on the very floats given:
no rounding at all, then one square root to 40 digits.

* where the controller acts (the axes ≥ 8 cm apart: the radii of the shipped arms and
  body sum to more), nearly parallel and crossing axes are never overestimated by more
  than 1e-11 m and the direction is the exact normal's;
* far from the origin (to 1e5 m), tiny and collinear segments: within a few ulps;
* the distance does not depend on the order of the segments, of their ends, or of the
  people; ``who`` is the first of equals;
* the arms in contact (parts along, across and inside the links): the exact distance;
* axes nearly parallel (within 1e-6 rad) and crossing within a few µm: the exact distance
  (to 1e-9 m) and the common normal (measured between the segments' ends instead, it
  would be up to ``min(L₁, L₂) θ / 2`` too far and 90° off); a part marked valid with a
  NaN coordinate reads −inf, in contact, never +inf (not seen).
"""

from __future__ import annotations

from decimal import Decimal, localcontext
from fractions import Fraction

import numpy as np
import pytest

import qpavoid
from qpavoid.arm.model import Kinematics
from qpavoid.distance._kernels import capsule_table, segment_closest
from qpavoid.distance.methods import CapsuleDistance, CoalCapsuleDistance
from qpavoid.distance.table import FALLBACK_DIRECTION
from qpavoid.human.body import HumanGeometry, KinectHuman
from qpavoid.human.posture import random_posture


def _exact(p1, q1, p2, q2) -> tuple[Fraction, Fraction, Fraction]:
    """The exact minimum squared distance of the segments and its (s, t)."""
    P1, Q1, P2, Q2 = ([Fraction(float(x)) for x in v] for v in (p1, q1, p2, q2))
    d1 = [Q1[k] - P1[k] for k in range(3)]
    d2 = [Q2[k] - P2[k] for k in range(3)]
    r = [P1[k] - P2[k] for k in range(3)]

    def dot(u, v):
        return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]

    def clamp(x):
        return min(max(x, Fraction(0)), Fraction(1))

    a, e, b, c, f = dot(d1, d1), dot(d2, d2), dot(d1, d2), dot(d1, r), dot(d2, r)
    zero, one = Fraction(0), Fraction(1)
    candidates = [(s, t) for s in (zero, one) for t in (zero, one)]
    if e > 0:
        candidates += [(zero, clamp(f / e)), (one, clamp((b + f) / e))]
    if a > 0:
        candidates += [(clamp(-c / a), zero), (clamp((b - c) / a), one)]
    det = a * e - b * b
    if det > 0:
        s, t = (b * f - c * e) / det, (a * f - b * c) / det
        if 0 <= s <= 1 and 0 <= t <= 1:
            candidates.append((s, t))

    def q(st):
        s, t = st
        return dot(r, r) + a * s * s + e * t * t + 2 * c * s - 2 * f * t - 2 * b * s * t

    s, t = min(candidates, key=q)
    return q((s, t)), s, t


def _sqrt(x: Fraction) -> Decimal:
    with localcontext() as ctx:
        ctx.prec = 40
        return Decimal(x.numerator).sqrt() / Decimal(x.denominator).sqrt()


def _exact_gap(p1, q1, p2, q2) -> Decimal:
    return _sqrt(_exact(p1, q1, p2, q2)[0])


def _exact_normal(p1, q1, p2, q2) -> np.ndarray:
    """The unit vector from the second segment's closest point to the first's (apart)."""
    _, s, t = _exact(p1, q1, p2, q2)
    P1, Q1, P2, Q2 = ([Fraction(float(x)) for x in v] for v in (p1, q1, p2, q2))
    v = np.array(
        [float(P1[k] + s * (Q1[k] - P1[k]) - P2[k] - t * (Q2[k] - P2[k])) for k in range(3)]
    )
    return v / np.linalg.norm(v)


def _table(robot_seg, human_seg, robot_r=0.0, human_r=0.0):
    """The compiled table's (distance, vector) of one robot capsule and one human capsule."""
    d, vector, *_ = capsule_table(
        np.array([robot_seg], dtype=float),
        np.array([robot_r]),
        np.array([human_seg], dtype=float),
        np.array([human_r]),
        np.ones(1, dtype=np.bool_),
        1,
        FALLBACK_DIRECTION,
    )
    return float(d[0]), vector[0]


def _over(p1, q1, p2, q2) -> float:
    """How much farther the compiled gap (radii 0) is than the exact one, m."""
    return float(Decimal(_table((p1, q1), (p2, q2))[0]) - _exact_gap(p1, q1, p2, q2))


def _crossing(rng, theta, gap, lengths=(0.4, 0.3), centre=None, middle=False):
    """Two segments at angle ``theta`` whose lines pass ``gap`` apart inside both (at
    their middles if ``middle``), and the unit normal from the first to the second."""
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    w = np.cross(u, rng.normal(size=3))
    w /= np.linalg.norm(w)
    normal = np.cross(u, w)
    v = np.cos(theta) * u + np.sin(theta) * w
    c = rng.uniform(-1, 1, 3) if centre is None else centre
    s0, t0 = (0.5, 0.5) if middle else rng.uniform(0.05, 0.95, 2)
    p1 = c - s0 * lengths[0] * u
    p2 = c + gap * normal - t0 * lengths[1] * v
    return (p1, p1 + lengths[0] * u, p2, p2 + lengths[1] * v), normal


def test_near_parallel_crossing_axes_where_the_controller_acts():
    """Axes 8 to 30 cm apart (contact for every shipped arm and body part), parallel to
    within 1e-10..1e-4 rad, lengths up to 1.5 m: never more than 1e-11 m too far (1.4e-12
    at worst over 20 000 of them), and the direction within 1e-4 rad of the exact normal,
    never towards the person."""
    rng = np.random.default_rng(12)
    for k in range(150):
        theta = 10 ** rng.uniform(-10, -4) if k % 2 else 10 ** rng.uniform(-7, -5.9)
        lengths = rng.uniform(0.05, 1.5, 2)
        seg, _ = _crossing(rng, theta, rng.uniform(0.08, 0.3), lengths, rng.uniform(-3, 3, 3))
        assert _over(*seg) <= 1e-11
        _, vector = _table(seg[:2], seg[2:])
        exact = _exact_normal(*seg)
        assert vector @ exact > np.cos(1e-4)


@pytest.mark.parametrize("kind", ["generic", "far", "tiny", "collinear"])
def test_segments_against_exact_arithmetic(kind):
    """Random segments of each kind: the compiled gap within a few ulps of the largest
    coordinate of the exact one (2e-16 m near the origin, 8e-11 m at 8e5 m), never NaN."""
    rng = np.random.default_rng(["generic", "far", "tiny", "collinear"].index(kind))
    for _ in range(60):
        if kind == "generic":
            seg = rng.uniform(-1, 1, (4, 3))
        elif kind == "far":  # cancellation: the segments 1e3..1e5 m from the origin
            seg = rng.uniform(-1, 1, (4, 3)) + rng.normal(size=3) * 10 ** rng.uniform(3, 5)
        elif kind == "tiny":  # 1e-14..1e-5 m long, sometimes on the other segment
            seg = rng.uniform(-1, 1, (4, 3))
            if rng.random() < 0.4:
                seg[2] = seg[0] + rng.uniform() * (seg[1] - seg[0])
            seg[3] = seg[2] + rng.normal(size=3) * 10 ** rng.uniform(-14, -5)
        else:  # on one line: apart, overlapping, coincident, reversed
            u = rng.normal(size=3)
            seg = rng.uniform(-1, 1, 3) + rng.uniform(-1, 1, (4, 1)) * u
            if rng.random() < 0.3:
                seg[2:] = seg[rng.permutation(2)]
        s, t = segment_closest(*seg)
        assert 0.0 <= s <= 1.0 and 0.0 <= t <= 1.0
        tol = 4 * np.spacing(np.abs(seg).max()) + 1e-15
        assert abs(_over(*seg)) <= tol + (1e-12 if kind == "tiny" else 0.0)


def test_the_order_of_segments_and_of_their_ends_changes_nothing():
    """Swapping the two segments or reversing either: the same gap to 1e-12 m where the
    controller acts (random and nearly parallel crossing axes, 8 cm and more apart)."""
    rng = np.random.default_rng(3)
    for k in range(200):
        if k % 2:
            seg, _ = _crossing(rng, 10 ** rng.uniform(-9, -3), rng.uniform(0.08, 0.3))
        else:
            seg = rng.uniform(-1, 1, (4, 3))
        p1, q1, p2, q2 = seg
        gaps = [
            _table((a, b), (c, d))[0]
            for a, b, c, d in [
                (p1, q1, p2, q2),
                (p2, q2, p1, q1),
                (q1, p1, p2, q2),
                (p1, q1, q2, p2),
                (q2, p2, q1, p1),
            ]
        ]
        assert max(gaps) - min(gaps) <= 1e-12


def _geometry(segments, margin=None):
    n = len(segments)
    return HumanGeometry(
        np.zeros((25, 3)),
        np.ones(25, dtype=bool),
        np.asarray(segments, dtype=float),
        np.ones(n, dtype=bool),
        np.zeros(n) if margin is None else margin,
        np.zeros(n),
    )


def _kin(segments):
    return Kinematics(np.zeros(6), np.zeros((9, 3)), None, segments, None, np.eye(4), None)


def test_people_in_any_order_and_equal_people():
    """Up to seven people, one of them twice and one reversed end for end (ties): in any
    order, the same distances bit for bit, and ``who`` the first of the closest."""
    robot, human = qpavoid.load_robot("panda"), KinectHuman()
    rng = np.random.default_rng(9)
    method = CapsuleDistance(robot, human)
    for _ in range(10):
        kin = robot.kinematics(rng.uniform(robot.q_min, robot.q_max), jacobians=False)
        geos = [
            human.geometry(random_posture(rng, kin.points, spread_m=0.1))
            for _ in range(int(rng.integers(2, 6)))
        ]
        g = geos[1]
        geos += [geos[0], _geometry(g.segments[:, ::-1].copy(), g.part_margin)]
        each = np.stack([method(kin, x).distance for x in geos])
        table, who = method.closest(kin, geos)
        np.testing.assert_array_equal(table.distance, each.min(axis=0))
        np.testing.assert_array_equal(who, np.argmax(each == each.min(axis=0), axis=0))
        perm = rng.permutation(len(geos))
        table_p, who_p = method.closest(kin, [geos[p] for p in perm])
        np.testing.assert_array_equal(table_p.distance, table.distance)
        np.testing.assert_array_equal(
            np.take_along_axis(each, perm[who_p][None], 0)[0], table.distance
        )


def _against_the_links(rng, seg, robot_r, human_r):
    """Each body part laid against a random link: along it at contact, across its axis,
    inside it on its axis, an end on its surface, or a zero-length part touching it."""
    parts = np.empty((len(human_r), 2, 3))
    for j in range(len(human_r)):
        i = int(rng.integers(len(seg)))
        a, b = seg[i]
        axis = b - a
        u = axis / max(np.linalg.norm(axis), 1e-12)
        w = np.cross(u, rng.normal(size=3))
        w /= np.linalg.norm(w)
        contact = robot_r[i] + human_r[j] + rng.choice([0.0, 1e-12, -1e-12, 1e-9])
        on = a + rng.uniform() * axis
        length = rng.uniform(0.0, 0.45)
        kind = j % 5
        if kind == 0:
            p = on + contact * w
            parts[j] = [p, p + length * u]
        elif kind == 1:
            c = on + contact * np.cross(u, w)
            parts[j] = [c - length * w / 2, c + length * w / 2]
        elif kind == 2:
            parts[j] = [on, a + rng.uniform() * axis]
        elif kind == 3:
            p = on + contact * w
            parts[j] = [p, p + length * rng.normal(size=3)]
        else:
            parts[j] = [on + contact * w] * 2
    return parts


@pytest.mark.parametrize("arm", ["iiwa14", "ur5"])
def test_body_parts_against_the_links_are_exact(arm):
    """Parts at contact along, across and inside the links of random postures: the exact
    distance to 1e-12 m (coal's is 2e-12 off), coal's to 1e-9, every direction a unit
    vector, every distance finite."""
    robot, human = qpavoid.load_robot(arm), KinectHuman()
    rng = np.random.default_rng(21)
    compiled, coal = CapsuleDistance(robot, human), CoalCapsuleDistance(robot, human)
    robot_r = np.asarray(robot.capsule_radii)
    for _ in range(6):
        seg = robot.kinematics(rng.uniform(robot.q_min, robot.q_max), jacobians=False).segments
        margin = rng.uniform(0.0, 0.05, len(human.parts))
        human_r = human.capsule_radii + margin
        parts = _against_the_links(rng, seg, robot_r, human_r)
        table = compiled(_kin(seg), _geometry(parts, margin))
        judge = coal(_kin(seg), _geometry(parts.copy(), margin))
        assert np.isfinite(table.distance).all()
        np.testing.assert_allclose(table.distance, judge.distance, atol=1e-9, rtol=0)
        np.testing.assert_allclose(np.linalg.norm(table.vector, axis=-1), 1.0, atol=1e-12)
        for i in range(len(seg)):
            for j in range(len(parts)):
                exact = float(_exact_gap(*seg[i], *parts[j])) - robot_r[i] - human_r[j]
                assert table.distance[i, j] == pytest.approx(exact, abs=1e-12)


@pytest.mark.parametrize("gap", [0.0, 1e-8, 1e-7])
def test_nearly_parallel_axes_that_cross_are_not_measured_too_far(gap):
    rng = np.random.default_rng(1)
    seg, normal = _crossing(rng, 9.9e-7, gap, middle=True)
    assert _over(*seg) <= 1e-9  # 1.5e-7 m too far between the ends
    if gap > 0:  # the exact direction: the common normal, from the second to the first
        _, vector = _table(seg[:2], seg[2:])
        assert vector @ -normal > np.cos(np.radians(1.0))  # 56° and 86° off between the ends


def test_a_valid_part_with_a_nan_coordinate_is_not_read_as_absent():
    human = np.array([[[0.5, 0.3, 0.0], [0.5, 1.0, 0.0]]])
    human[0, 1, 1] = np.nan
    d, vector, *_ = capsule_table(
        np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]]),
        np.array([0.05]),
        human,
        np.array([0.05]),
        np.ones(1, dtype=np.bool_),
        1,
        FALLBACK_DIRECTION,
    )
    assert d[0] == -np.inf  # in doubt, in contact: never "not seen"
    np.testing.assert_array_equal(vector[0], FALLBACK_DIRECTION)
