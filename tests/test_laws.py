"""The laws of eqs. (2)-(9) against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from qpavoid.arm.roles import Roles
from qpavoid.core.errors import InputError
from qpavoid.laws._kernels import NOT_FINITE, limit_crossed
from qpavoid.laws.avoidance import (
    AvoidanceConfig,
    avoidance_terms,
    damped_pinv,
    distance_at_factor,
    ee_repulsive_velocity,
    l1_factor,
    law_constants,
    modified_ik,
    repelled_joint_velocity,
    repulsive_speed,
    repulsive_velocity,
    scaled_velocity_limits,
    set_stop_distances,
    stop_distances,
    stop_reason,
)

CFG = AvoidanceConfig()


def test_f_at_hand_computed_distances():
    # f = 1 / (1 + exp((2d/rho - 1) alpha)), rho = 0.1, alpha = 9 (paper Fig. 6)
    assert l1_factor(0.0, CFG) == pytest.approx(1 / (1 + math.exp(-9)))  # 0.99988
    assert l1_factor(0.05, CFG) == pytest.approx(0.5)
    assert l1_factor(0.1, CFG) == pytest.approx(1 / (1 + math.exp(9)))  # 1.234e-4
    assert l1_factor(np.inf, CFG) == 0.0
    assert l1_factor(-np.inf, CFG) == 1.0
    assert not np.isnan(l1_factor(np.array([np.inf, -np.inf, 1e6]), CFG)).any()
    # The reading notes: f > 0.8 below about 0.042 m.
    d08 = CFG.d_stop_L1_m()
    assert d08 == pytest.approx(0.05 * (1 - math.log(4) / 9))
    assert d08 == pytest.approx(0.0423, abs=1e-4)
    assert l1_factor(d08, CFG) == pytest.approx(0.8)
    assert distance_at_factor(0.5, 0.1, 9) == pytest.approx(0.05)


def test_f_is_monotone_decreasing():
    d = np.linspace(-0.05, 0.2, 1000)  # beyond, it saturates at exactly 1 or 0
    assert np.all(np.diff(l1_factor(d, CFG)) < 0)
    d = np.linspace(-1, 1, 1000)
    assert np.all(np.diff(l1_factor(d, CFG)) <= 0)


def test_scaled_limits_eq3():
    dq = np.array([1.4835, 1.4835])
    np.testing.assert_allclose(scaled_velocity_limits(dq, 0.25), 0.75 * dq)
    np.testing.assert_allclose(scaled_velocity_limits(dq, 1.0), 0.0)


def test_repulsive_speed_eq4_and_velocity_eq5():
    cfg = AvoidanceConfig(v_max_mps=0.3, rho_rep_m=0.2, alpha_rep=9)
    assert repulsive_speed(0.1, cfg) == pytest.approx(0.15)  # V_max / 2 at rho/2
    assert repulsive_speed(0.2, cfg) == pytest.approx(0.3 / (1 + math.exp(9)))
    v = repulsive_velocity(0.1, np.array([0, 0.6, 0.8]), *law_constants(cfg))
    np.testing.assert_allclose(v, [0, 0.09, 0.12])
    unseen = repulsive_velocity(np.inf, np.array([1.0, 0, 0]), *law_constants(cfg))
    np.testing.assert_array_equal(unseen, 0.0)


def test_ee_sum_eq7_ignores_unseen_parts():
    d = np.array([0.1, 0.1, np.inf, 0.5])
    dirs = np.array([[1.0, 0, 0], [0, 1.0, 0], [np.nan, np.nan, np.nan], [0, 0, 1.0]])
    v = ee_repulsive_velocity(d, dirs, *law_constants(CFG))
    half = CFG.v_max_mps / 2
    np.testing.assert_allclose(v, [half, half, repulsive_speed(0.5, CFG)])


def test_damped_pinv_is_the_inverse_away_from_singularities():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(6, 6)) + 3 * np.eye(6)
    np.testing.assert_allclose(damped_pinv(J, 0.02, 0.05), np.linalg.inv(J), atol=1e-10)


def test_damped_pinv_stays_bounded_at_a_singularity():
    J = np.diag([1.0, 1.0, 1e-9])
    Jp = damped_pinv(J, 0.02, 0.05)
    assert np.abs(Jp).max() < 1.0 / 0.05  # sigma / (sigma^2 + lambda^2) <= 1 / (2 lambda)
    np.testing.assert_allclose(Jp[:2, :2], np.eye(2), atol=1e-2)


def test_l2_velocity_eq6_moves_the_point_as_asked():
    J = np.array([[0.2, 0.0, 0.1], [0.0, 0.3, 0.0], [0.1, 0.0, 0.4]])
    v = np.array([0.01, -0.02, 0.03])
    np.testing.assert_allclose(J @ repelled_joint_velocity(J, v, 0.02, 0.05), v, atol=1e-12)


def test_modified_ik_eq8():
    rng = np.random.default_rng(1)
    J = rng.normal(size=(6, 6)) + 3 * np.eye(6)
    v_pl, e = rng.normal(size=6), rng.normal(size=6)
    K = np.full(6, 5.0)
    v_ee = np.array([0.1, 0.0, -0.1])
    dq = modified_ik(J, v_pl, K, e, v_ee, 0.02, 0.05)
    np.testing.assert_allclose(J @ dq, v_pl + K * e + np.r_[v_ee, 0, 0, 0], atol=1e-10)


@pytest.mark.parametrize(
    "f, d_l2, d_ee, expect",
    [
        (0.8, 1.0, 1.0, None),  # f must exceed 0.8
        (0.8000001, 1.0, 1.0, "f = "),
        (0.0, 0.05, 1.0, "d_forearm = 0.050 m"),  # <= 0.05 m stops
        (0.0, 0.0500001, 1.0, None),
        (0.0, 1.0, 0.05, "d_tool = 0.050 m"),
        (0.0, np.inf, np.inf, None),
    ],
)
def test_stop_rules_quote_the_sets_by_the_part_they_play(f, d_l2, d_ee, expect):
    reason = stop_reason(f, d_l2, d_ee, CFG, ("upper_arm", "forearm", "tool"))
    if expect is None:
        assert reason is None
    else:
        assert reason.startswith(expect)
        assert expect != "f = " or reason.endswith("(upper_arm)")


def test_stop_distances_go_to_the_sets_playing_each_part():
    """Each set's stop distance is its part's (Roles), 0 for a set that plays none, the
    largest for a set that plays two."""
    by_role = stop_distances(CFG)  # scaled, repelled, end effector
    assert by_role[0] == pytest.approx(CFG.d_stop_L1_m()) and by_role[0] < 0.05
    roles = Roles(scaled=2, scaled_joints=(), repelled=0, repelled_joints=(), end_effector=3)
    np.testing.assert_array_equal(
        set_stop_distances(CFG, roles, 5), [CFG.d_stop_L2_m, 0.0, by_role[0], 0.05, 0.0]
    )
    shared = Roles(scaled=0, scaled_joints=(), repelled=0, repelled_joints=(), end_effector=1)
    np.testing.assert_array_equal(set_stop_distances(CFG, shared, 2), [0.05, 0.05])


def test_the_compiled_avoidance_terms_are_the_laws():
    """avoidance_terms against eq. (4) in numpy (repulsive_speed, the logistic numba does
    not compile), eqs. (5) and (7) written out, and the table's minima, on random tables
    with unseen parts (+inf, NaN directions), ties, contact and NaN; the repelled and
    end-effector rows anywhere in the table."""
    rng = np.random.default_rng(3)
    for n in range(500):
        cfg = AvoidanceConfig(
            rho_L1_m=rng.uniform(0.05, 0.3),
            alpha_L1=rng.uniform(3.0, 12.0),
            rho_rep_m=rng.uniform(0.05, 0.4),
            alpha_rep=rng.uniform(3.0, 12.0),
            v_max_mps=rng.uniform(0.1, 1.0),
        )
        n_sets = 3 + n % 3
        rep, ee = rng.choice(n_sets, 2, replace=False)
        d = rng.uniform(-0.02, 0.4, (n_sets, 8))
        v = rng.normal(size=(n_sets, 8, 3))
        v /= np.linalg.norm(v, axis=2, keepdims=True)
        unseen = rng.random((n_sets, 8)) < 0.3
        d[unseen], v[unseen] = np.inf, np.nan
        if n % 50 == 0:
            d[rep] = np.inf  # the repelled set sees nobody
        if n % 50 == 2:  # a NaN distance (never from our tables): NaN spoils the sum
            d[rng.integers(n_sets), rng.integers(8)] = np.nan
        if n % 50 == 1:  # a tie: the first, as argmin
            d[rep, 2:4], v[rep, 2:4] = d[rep].min(), [0.0, 0.0, 1.0]
        dmin, j, v_rep, v_ee = avoidance_terms(d, v, rep, ee, *law_constants(cfg))
        np.testing.assert_array_equal(dmin, d.min(axis=1))  # exact: the stop rules read it
        assert j == int(np.argmin(d[rep]))
        expect_rep = repulsive_speed(d[rep, j], cfg) * v[rep, j] if np.isfinite(d[rep, j]) else 0
        np.testing.assert_allclose(v_rep, expect_rep, atol=1e-15)
        speed = repulsive_speed(d[ee], cfg)  # eq. (7): 0 for a part not seen, NaN spoils
        expect_ee = speed @ np.where((speed > 0.0)[:, None] | np.isnan(speed)[:, None], v[ee], 0.0)
        np.testing.assert_allclose(v_ee, expect_ee, atol=1e-15)
        if not np.isnan(d).any():
            assert np.isfinite(v_rep).all() and np.isfinite(v_ee).all()


@pytest.mark.parametrize(
    "field, value",
    [("rho_L1_m", 0.0), ("rho_rep_m", np.float64(0.0)), ("alpha_L1", -9.0),
     ("alpha_rep", math.inf), ("v_max_mps", -0.25), ("d_stop_L2_m", math.nan),
     ("d_stop_EE_m", -0.05), ("f_stop", 1.0), ("f_stop", 0.0), ("rho_L1_m", "0.1")],
)  # fmt: skip
def test_a_degenerate_avoidance_config_is_refused(field, value):
    """ρ = 0 divides by zero in eqs. (2) and (4); f_stop outside (0, 1) has no distance."""
    with pytest.raises(InputError) as err:
        AvoidanceConfig(**{field: value})
    assert err.value.name == field


def _limit_crossed_numpy(q, dq, dt, q_min, q_max):
    """The last-resort check as numpy said it before it was compiled."""
    with np.errstate(over="ignore"):  # the test's 1e308 entries overflow on purpose
        total = dq.sum()
    if not math.isfinite(total):
        return NOT_FINITE
    q_next = q + dq * dt
    out = (q_next > q_max) | (q_next < q_min)
    return int(np.flatnonzero(out)[0]) if out.any() else -1


def test_limit_crossed_equals_the_numpy_check():
    """Random commands near and past the limits, exactly on them, NaN, ±inf, overflow."""
    rng = np.random.default_rng(11)
    q_min, q_max = -np.linspace(1.0, 3.0, 6), np.linspace(1.0, 3.0, 6)
    seen = set()
    for trial in range(3000):
        q = rng.uniform(q_min, q_max)
        dq = rng.normal(0.0, 2.0, 6)
        dt = float(rng.choice([0.01, 0.002, 1.0]))
        if trial % 7 == 0:  # land exactly on a limit: not a crossing
            k = rng.integers(6)
            dq[k], q[k] = 0.0, q_max[k]
        if trial % 11 == 0:
            dq[rng.integers(6)] = rng.choice([np.nan, np.inf, -np.inf])
        if trial % 13 == 0:
            dq[:] = 1e308  # finite entries whose sum overflows
        got = limit_crossed(q, dq, dt, q_min, q_max)
        assert got == _limit_crossed_numpy(q, dq, dt, q_min, q_max), (q, dq, dt)
        seen.add(got if got < 0 else "joint")
    assert seen == {NOT_FINITE, -1, "joint"}


def test_a_command_past_a_limit_or_not_finite_is_a_stop(robot):
    """The last-resort layer: the joint that would cross is named; NaN is never sent."""
    from qpavoid.arm.ik import inverse_kinematics
    from qpavoid.control.analytic import AnalyticController
    from qpavoid.control.path import ArcPath
    from qpavoid.human.posture import Operator

    path = ArcPath()
    ctrl = AnalyticController(robot, path=path)
    q = inverse_kinematics(robot, path.reference(1.0)[0])
    tick = ctrl.measure(q, Operator().rest(), None, 1.0)
    assert not tick.reason
    fine = ctrl.command(tick, np.full(robot.nv, 0.01))
    assert not fine.stopped
    k = 3
    step = (robot.q_max[k] - q[k]) / ctrl.config.control_period_s
    past = np.zeros(robot.nv)
    past[k] = step * 1.001
    cmd = ctrl.command(tick, past)
    assert cmd.stopped and f"joint {robot.joint_names[k]} would cross" in cmd.reason
    np.testing.assert_array_equal(cmd.dq, 0.0)
    past[k] = step * 0.999  # just short of it
    assert not ctrl.command(tick, past).stopped
    bad = np.full(robot.nv, 0.01)
    bad[1] = np.nan
    cmd = ctrl.command(tick, bad)
    assert cmd.stopped and cmd.reason == "non-finite joint velocity computed"
    np.testing.assert_array_equal(cmd.dq, 0.0)
    # a command of another shape is never sent nor read past its end
    buf = np.r_[np.zeros(robot.nv - 1), 1e6]
    for wrong in (buf[:-1], np.r_[np.zeros(robot.nv), 1e6], np.zeros((1, robot.nv)), 0.0):
        cmd = ctrl.command(tick, wrong)
        assert cmd.stopped and "joint velocity of shape" in cmd.reason, cmd.reason
        assert cmd.dq.shape == (robot.nv,)
        np.testing.assert_array_equal(cmd.dq, 0.0)
