"""The compiled capsule distances, judged by coal and by hand.

* :func:`segment_closest` on cases worked by hand (crossing, parallel, collinear, touching,
  zero length) and, over random segments, never farther than any pair of points of the
  two segments (a fine grid of them);
* :class:`CapsuleDistance` (one compiled pass) against :class:`CoalCapsuleDistance` (coal's
  capsule distance) on every shipped arm: random postures and people, several people at
  once, parts not seen, widened radii, near-parallel and crossing axes; distances to
  1e-9 m, the same closest person, witness points, directions and axis parameters where
  the closest pair is unique.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_q

import qpavoid
from qpavoid.arm.model import Kinematics
from qpavoid.distance._kernels import capsule_table, segment_closest
from qpavoid.distance.methods import CapsuleDistance, CoalCapsuleDistance, distance_method
from qpavoid.distance.table import FALLBACK_DIRECTION
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.runs import simulate_one
from qpavoid.human.body import HumanGeometry, KinectHuman
from qpavoid.human.posture import random_posture


def _closest(p1, q1, p2, q2):
    s, t = segment_closest(*(np.asarray(x, dtype=float) for x in (p1, q1, p2, q2)))
    c1 = np.asarray(p1, float) + s * (np.asarray(q1, float) - p1)
    c2 = np.asarray(p2, float) + t * (np.asarray(q2, float) - p2)
    return s, t, float(np.linalg.norm(c1 - c2))


@pytest.mark.parametrize(
    "segments, s, t, gap",
    [
        # perpendicular, crossing at mid-length, 0.3 apart in z
        (([-1, 0, 0], [1, 0, 0], [0, -1, 0.3], [0, 1, 0.3]), 0.5, 0.5, 0.3),
        # perpendicular, the second's end nearest: (2, 0, 0) to x = 1 along y
        (([0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 1, 0]), 1.0, 0.0, 1.0),
        # parallel, overlapping along x from 0.5 to 1, 0.2 apart: every pair across the
        # overlap is closest; the first end found on it, q1 (s = 1), and its foot t = 0.25
        (([0, 0, 0], [1, 0, 0], [0.5, 0.2, 0], [2.5, 0.2, 0]), 1.0, 0.25, 0.2),
        # collinear and apart: the ends 0.4 apart
        (([0, 0, 0], [0, 0, 1], [0, 0, 1.4], [0, 0, 2]), 1.0, 0.0, 0.4),
        # antiparallel, the second reversed: q2 meets p1's end
        (([0, 0, 0], [1, 0, 0], [3, 0.1, 0], [1.5, 0.1, 0]), 1.0, 1.0, np.hypot(0.5, 0.1)),
        # touching: the second starts on the first
        (([0, 0, 0], [1, 0, 0], [0.25, 0, 0], [0.25, 0, 1]), 0.25, 0.0, 0.0),
        # two points
        (([1, 2, 3], [1, 2, 3], [1, 2, 4], [1, 2, 4]), 0.0, 0.0, 1.0),
        # a point and a segment: its foot at t = 0.75
        (([0.75, 0.5, 0], [0.75, 0.5, 0], [0, 0, 0], [1, 0, 0]), 0.0, 0.75, 0.5),
        # a segment and a point beyond its start
        (([0, 0, 0], [1, 0, 0], [-1, 1, 0], [-1, 1, 0]), 0.0, 0.0, np.sqrt(2.0)),
    ],
)
def test_segment_closest_by_hand(segments, s, t, gap):
    got = _closest(*segments)
    assert got == pytest.approx((s, t, gap), abs=1e-12)


def test_segment_closest_is_never_beaten_by_a_grid_of_pairs():
    """Over random segments, nearly parallel ones among them, no pair of points of a
    129 × 129 grid along the two segments is closer than the pair returned; and that pair
    is within the grid's spacing of the grid's best (it is a closest pair)."""
    rng = np.random.default_rng(11)
    grid = np.linspace(0.0, 1.0, 129)
    for k in range(300):
        p1, q1, p2 = rng.uniform(-1, 1, (3, 3))
        if k % 3 == 0:  # nearly parallel: the second along the first, tilted by ~1e-7..1e-2
            tilt = rng.normal(size=3) * 10 ** rng.uniform(-7, -2)
            q2 = p2 + (q1 - p1) * rng.uniform(-2, 2) + tilt
        elif k % 3 == 1:  # short: down to 1e-9 m
            q2 = p2 + rng.normal(size=3) * 10 ** rng.uniform(-9, -3)
        else:
            q2 = rng.uniform(-1, 1, 3)
        s, t, gap = _closest(p1, q1, p2, q2)
        assert 0.0 <= s <= 1.0 and 0.0 <= t <= 1.0
        a = p1 + grid[:, None] * (q1 - p1)
        b = p2 + grid[:, None] * (q2 - p2)
        best = np.sqrt(((a[:, None] - b[None]) ** 2).sum(axis=2)).min()
        assert gap <= best + 1e-12
        spacing = (np.linalg.norm(q1 - p1) + np.linalg.norm(q2 - p2)) / 128
        assert gap >= best - spacing


def _people(rng, kin, n_people):
    human = KinectHuman()
    geos = []
    for _ in range(n_people):
        spread = float(rng.uniform(0.0, 1.2))
        state = np.where(rng.random(25) < 0.1, 0, 2)  # a tenth not tracked
        state[0] = 2
        geos.append(human.geometry(random_posture(rng, kin.points, spread_m=spread), state))
    return human, geos


def _assert_same(compiled, coal, who_c, who_k):
    dc, dk = compiled.distance, coal.distance
    np.testing.assert_array_equal(np.isinf(dc), np.isinf(dk))
    finite = np.isfinite(dk)
    np.testing.assert_allclose(dc[finite], dk[finite], atol=1e-9, rtol=0)
    # the same person, unless two are within 1e-9 m of each other
    assert np.all((who_c == who_k)[finite] | (np.abs(dc[finite] - dk[finite]) < 1e-9))
    # where the closest pair is unique (apart, not both axes nearly parallel), the same
    # pair, direction and axis parameter
    apart = finite & (dk > 1e-4)
    for i, j in zip(*np.nonzero(apart), strict=True):
        if who_c[i, j] != who_k[i, j]:
            continue
        np.testing.assert_allclose(compiled.vector[i, j], coal.vector[i, j], atol=1e-6)
        np.testing.assert_allclose(compiled.robot_point[i, j], coal.robot_point[i, j], atol=1e-6)
        np.testing.assert_allclose(compiled.human_point[i, j], coal.human_point[i, j], atol=1e-6)
    np.testing.assert_array_equal(compiled.vector[~finite], 0.0)
    assert np.all(np.isnan(compiled.robot_point[~finite]))


@pytest.mark.parametrize(
    "n, seed",
    [(50, 5), pytest.param(400, 6, marks=pytest.mark.slow)],  # 400 more with the slow ones
)
@pytest.mark.parametrize("arm", ["iiwa14", "panda", "fr3", "ur5"])
def test_the_compiled_table_is_coals_on_every_arm(arm, n, seed):
    """``n`` random postures of each arm beside one to six people (a tenth of their joints
    not tracked, so some parts unseen and others widened): coal's table, entry by entry."""
    robot = qpavoid.load_robot(arm)
    rng = np.random.default_rng(seed)
    human = KinectHuman()
    compiled, coal = CapsuleDistance(robot, human), CoalCapsuleDistance(robot, human)
    for k in range(n):
        kin = robot.kinematics(random_q(rng, robot), jacobians=False)
        _, geos = _people(rng, kin, 1 + k % 6)
        table_c, who_c = compiled.closest(kin, geos)
        table_k, who_k = coal.closest(kin, geos)
        _assert_same(table_c, table_k, who_c, who_k)
        np.testing.assert_allclose(
            table_c.robot_s[np.isfinite(table_c.distance)],
            table_k.robot_s[np.isfinite(table_k.distance)],
            atol=1e-6,
        )


def _kin(segments):
    return Kinematics(np.zeros(6), np.zeros((9, 3)), None, segments, None, np.eye(4), None)


def _geo(segments):
    n = len(segments)
    return HumanGeometry(np.zeros((25, 3)), np.ones(25, dtype=bool), segments, np.ones(n, bool))


@pytest.mark.parametrize("tilt", [0.0, 1e-9, 1e-6, 1e-3])
def test_nearly_parallel_and_crossing_axes_agree_with_coal(robot, tilt):
    """Every human part laid along or across the robot's capsules, parallel to within
    ``tilt`` rad, at gaps from deep penetration to apart: coal's distance to 1e-9 m."""
    human = KinectHuman()
    rng = np.random.default_rng(int(tilt * 1e9) + 1)
    compiled, coal = CapsuleDistance(robot, human), CoalCapsuleDistance(robot, human)
    kin0 = robot.kinematics(random_q(rng, robot), jacobians=False)
    n_parts = len(human.parts)
    for _ in range(30):
        seg = kin0.segments.copy()
        i = int(rng.integers(len(seg)))
        a, b = seg[i]
        axis = b - a
        length = np.linalg.norm(axis)
        if length < 1e-6:
            continue
        u = axis / length
        normal = np.cross(u, rng.normal(size=3))
        normal /= np.linalg.norm(normal)
        hseg = np.empty((n_parts, 2, 3))
        for j in range(n_parts):
            gap = rng.uniform(-0.1, 0.3)
            along = rng.uniform(-0.5, 1.5) * length
            direction = u + tilt * np.cross(u, normal) if j % 2 else normal  # along or across
            start = a + along * u + gap * normal
            hseg[j] = [start, start + rng.uniform(0.0, 0.4) * direction]
        geo = _geo(hseg)
        geo_k = _geo(hseg.copy())
        table_c = compiled(_kin(seg), geo)
        table_k = coal(_kin(seg), geo_k)
        np.testing.assert_allclose(table_c.distance, table_k.distance, atol=1e-9, rtol=0)
        np.testing.assert_allclose(np.linalg.norm(table_c.vector, axis=2), 1.0, atol=1e-12)


def test_axes_that_meet_give_a_unit_direction_normal_to_both():
    """Two capsules whose axes cross: penetration by both radii, and a direction normal
    to both axes (the witnesses give none); a sphere on a sphere: the fallback."""
    robot_seg = np.array([[[0, 0, 0], [1, 0, 0]], [[2, 2, 2], [2, 2, 2]]], dtype=float)
    human_seg = np.array([[[0.5, -1, 0], [0.5, 1, 0]], [[2, 2, 2], [2, 2, 2]]], dtype=float)
    d, vector, s, robot_point, human_point, who = capsule_table(
        robot_seg,
        np.array([0.05, 0.05]),
        human_seg,
        np.array([0.1, 0.1]),
        np.ones(2, dtype=np.bool_),
        2,
        FALLBACK_DIRECTION,
    )
    assert d[0] == pytest.approx(-0.15, abs=1e-15)
    np.testing.assert_allclose(np.abs(vector[0]), [0, 0, 1], atol=1e-15)  # x × y
    assert s[0] == pytest.approx(0.5)
    np.testing.assert_allclose(robot_point[0] - human_point[0], -0.15 * vector[0], atol=1e-15)
    assert d[3] == pytest.approx(-0.15) and np.all(vector[3] == FALLBACK_DIRECTION)
    np.testing.assert_array_equal(who, 0)


def test_the_methods_by_name_and_their_geometry(robot):
    human = KinectHuman()
    for name, kind in [("capsules", CapsuleDistance), ("capsules-coal", CoalCapsuleDistance)]:
        method = distance_method(name, robot, human)
        assert type(method) is kind and method.name == name and method.method == "capsules"


@pytest.mark.parametrize("controller, tol", [("analytic", 1e-9), ("qp", 1e-6)])
def test_a_run_on_the_compiled_capsules_commands_what_coal_s_commands(controller, tol):
    """Test 1 with speed and separation, 4 s on the Panda: the commands on the compiled
    capsules are those on coal's, to 1e-9 rad/s for the paper's controller (a closed
    form) and 1e-6 for the QP (OSQP stops within eps = 1e-7 of its optimum: distances equal
    to ~1e-12 m move its stopping point by up to 2e-7 here); the metrics name the method
    used and keep the geometries' minimum distances under their usual keys."""
    runs = {
        d: simulate_one(
            RunSpec(
                scenario="test1",
                robot="panda",
                controller=controller,
                safety="ssm",
                distance=d,
                max_time_s=4.0,
                rate_hz=100,
            )
        )
        for d in ("capsules", "capsules-coal")
    }
    compiled, coal = (runs[d].sim.log["dq_command"] for d in ("capsules", "capsules-coal"))
    assert np.abs(coal).max() > 0.01  # it moved
    np.testing.assert_allclose(compiled, coal, atol=tol, rtol=0)
    metrics = runs["capsules-coal"].metrics
    assert metrics["distance_method"] == "capsules-coal"
    assert metrics["min_distance_m"]["capsules"] == pytest.approx(
        runs["capsules"].metrics["min_distance_m"]["capsules"], abs=1e-9
    )
