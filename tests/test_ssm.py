"""Speed and separation monitoring terms (ISO/TS 15066): hand-computed values and invariants."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from qpavoid.arm.dynamics import ArmDynamics, StoppingData
from qpavoid.core.errors import InputError
from qpavoid.laws.ssm import (
    SSMConfig,
    StopTimeBudget,
    accelerated_reach,
    human_speed,
    joint_speed_limits,
    max_approach_speed,
    protective_distance,
    speed_scale,
    stopping_distance,
)

# T_r = 0.01 s, T_s = 0.1 s, C + Z_d + Z_r = 0.02 + 0.03 + 0.005 = 0.055 m
CFG = SSMConfig(
    reaction_time_s=0.01, stop_time_s=0.1, max_acceleration_radps2=(("A1", 8.0), ("A2", 4.0))
)


def test_human_speed_zones_of_iso_13855():
    np.testing.assert_array_equal(human_speed([0.1, 0.5, 0.5001, 2.0], CFG), [2, 2, 1.6, 1.6])


def test_protective_distance_by_hand():
    # d = 0.5 m (v_h = 2.0), frame 0.07 s old, v_r = 0.2 m/s:
    # S_h = 2.0 (0.07 + 0.01 + 0.1) = 0.36, S_r = 0.002, S_s = 0.2 · 0.1 / 2 = 0.01
    assert protective_distance(0.2, 0.5, 0.07, CFG) == pytest.approx(0.36 + 0.002 + 0.01 + 0.055)
    assert stopping_distance(0.4, CFG) == pytest.approx(0.02)
    # beyond 0.5 m the person is taken at 1.6 m/s
    assert protective_distance(0.0, 0.6, 0.07, CFG) == pytest.approx(1.6 * 0.18 + 0.055)


@pytest.mark.parametrize("d, age, v", [(0.5, 0.07, 0.085 / 0.06), (0.3, 0.07, -0.115 / 0.06)])
def test_max_approach_speed_by_hand(d, age, v):
    # (d − 2.0 · 0.18 − 0.055) / (0.01 + 0.05)
    assert max_approach_speed(d, age, CFG) == pytest.approx(v, abs=1e-9)


def test_max_approach_speed_is_the_root_of_s_p_equals_d():
    rng = np.random.default_rng(0)
    d = rng.uniform(0.0, 2.0, 1000)
    age = rng.uniform(0.0, 0.1, 1000)
    v = max_approach_speed(d, age, CFG)
    assert (v >= 0).sum() > 500 and (v < 0).sum() > 100
    np.testing.assert_allclose(protective_distance(v, d, age, CFG), d, atol=1e-12)
    # an older frame never allows a faster approach
    assert np.all(max_approach_speed(d, age + 0.05, CFG) < v)
    assert max_approach_speed(np.inf, 0.0, CFG) == np.inf  # a part not seen: no bound


def test_joint_speed_limits_keep_the_stop_within_its_budget():
    np.testing.assert_allclose(joint_speed_limits(CFG, ("A2", "A1")), [0.4, 0.8])


def test_speed_scale_by_hand_and_against_a_grid():
    assert speed_scale(np.array([0.5, -0.2]), np.array([0.25, 1.0])) == pytest.approx(0.5)
    assert speed_scale(np.array([0.5]), np.array([-0.1])) is None  # a retreat is needed
    assert speed_scale(np.array([-0.5]), np.array([-0.1])) == 1.0  # already retreating fast
    assert speed_scale(np.array([-0.5]), np.array([-0.4])) == 1.0
    assert speed_scale(np.array([-0.5]), np.array([-0.6])) is None  # not fast enough
    assert speed_scale(np.array([0.0]), np.array([-0.1])) is None
    rng = np.random.default_rng(1)
    grid = np.linspace(0.0, 1.0, 2001)
    for _ in range(300):
        v, b = rng.normal(0, 1, 4), rng.normal(0.3, 0.5, 4)
        ok = np.all(grid[:, None] * v[None] <= b[None] + 1e-12, axis=1)
        s = speed_scale(v, b)
        if s is None:
            assert not ok.any()
        else:
            assert np.all(s * v <= b + 1e-12) and s >= grid[ok].max() - 1e-3


def test_stop_time_budget_grows_one_period_a_tick_and_remembers_the_arm_s_lag():
    budget = StopTimeBudget(
        CFG, ("A1", "A2"), 0.01
    )  # a = (8, 4) rad/s², T_s,max = 0.1 s, T_r = 0.01 s
    assert budget.budget() == pytest.approx(0.01)  # at rest: one period to speed up in
    budget.record(np.array([0.16, 0.04]))  # stop times 0.02 and 0.01 s
    assert budget.budget() == pytest.approx(0.03)
    budget.record(np.array([2.0, 0.0]))
    assert budget.budget() == pytest.approx(0.1)  # capped at T_s,max
    for _ in range(budget.history.maxlen - 1):  # (0.01 + 2 · 0.1) / 0.01 + 2 = 23 ticks
        budget.record(np.zeros(2))
    assert budget.history.maxlen == 23 and budget.budget() == pytest.approx(0.1)  # remembered
    budget.record(np.zeros(2))
    assert budget.budget() == pytest.approx(0.01)  # forgotten once the arm must have followed


def test_the_maker_s_stopping_time_is_used_where_it_is_longer():
    """A1 may brake at 8 rad/s² but its maker measured a stop of 0.5 s from 2 rad/s (over
    0.4 rad: 2²/0.8 = 5 rad/s² by distance, 2/0.5 = 4 by time): SSM brakes A1 at 4, so a
    stop from 0.2 rad/s takes 0.05 s, not 0.025, and A1 is held to 4 T_s. A2's maker stop
    (1 rad/s in 0.1 s over 0.05 rad: 10 rad/s²) is faster than its 4 rad/s²: A2 keeps 4."""
    arm = ArmDynamics(
        reaction_time_s=0.01,
        max_acceleration_radps2=(("A1", 8.0), ("A2", 4.0)),
        max_point_speed_mps=3.0,
        stopping=(
            StoppingData(("A1",), 0, 2.0, 0.4, 0.5, 1.0, 5.0),
            StoppingData(("A2",), 1, 1.0, 0.05, 0.1, 1.0, 5.0),
        ),
    )
    cfg = SSMConfig(stop_time_s=0.1).resolve(arm)
    assert cfg.max_acceleration_radps2 == (("A1", 4.0), ("A2", 4.0))
    assert cfg.reaction_time_s == 0.01  # no jerk limits: no lag
    np.testing.assert_allclose(joint_speed_limits(cfg, ("A1", "A2")), [0.4, 0.4])
    budget = StopTimeBudget(cfg, ("A1", "A2"), 0.01)
    budget.record(np.array([0.2, 0.0]))
    assert budget.budget() == pytest.approx(0.05 + 0.01)  # 0.025 + 0.01 by the limit alone
    # the same arm without its maker's data: as computed from the accelerations
    plain = SSMConfig(stop_time_s=0.1).resolve(replace(arm, stopping=()))
    assert plain.max_acceleration_radps2 is arm.max_acceleration_radps2


def test_an_arm_with_jerk_limits_adds_their_lag_to_the_reaction_time():
    # τ = 2 max_j a_j / j_j = 2 · max(8/4000, 4/1000) = 0.008 s
    arm = ArmDynamics(
        reaction_time_s=0.001,
        max_acceleration_radps2=(("A1", 8.0), ("A2", 4.0)),
        max_point_speed_mps=3.0,
        max_jerk_radps3=(("A1", 4000.0), ("A2", 1000.0)),
    )
    assert SSMConfig().resolve(arm).reaction_time_s == pytest.approx(0.009)
    assert SSMConfig(reaction_time_s=0.02).resolve(arm).reaction_time_s == 0.02  # as given


# --- the body's reachable occupancy under an acceleration bound (issue 41, off by default) ---


def test_accelerated_reach_by_hand():
    # from rest, a = 25 m/s², v_max = 1.6 m/s: t1 = 0.064 s, D(0.2) = 0.0512 + 1.6 · 0.136
    assert accelerated_reach(0.2, 0.0, 1.6, 25.0) == pytest.approx(0.2688)
    assert accelerated_reach(0.05, 0.0, 1.6, 25.0) == pytest.approx(0.5 * 25.0 * 0.05**2)
    # at 0.5 m/s: t1 = 0.044 s, D(0.1) = 0.022 + 0.0242 + 1.6 · 0.056
    assert accelerated_reach(0.1, 0.5, 1.6, 25.0) == pytest.approx(0.022 + 0.0242 + 0.0896)
    # at or above v_max it is ISO's v_max T
    assert accelerated_reach(0.2, 3.0, 1.6, 25.0) == pytest.approx(0.32)


def test_accelerated_reach_never_exceeds_iso_and_its_rate_is_the_capped_speed():
    rng = np.random.default_rng(0)
    t, v0 = rng.uniform(0.0, 0.5, 500), rng.uniform(0.0, 2.5, 500)
    a = rng.uniform(1.0, 60.0, 500)
    reach = accelerated_reach(t, v0, 1.6, a)
    assert np.all(reach <= 1.6 * t + 1e-12) and np.all(reach >= np.minimum(v0, 1.6) * t - 1e-12)
    h = 1e-7  # dD/dT = min(v_max, v0 + a T), by central differences
    rate = (accelerated_reach(t + h, v0, 1.6, a) - accelerated_reach(t - h, v0, 1.6, a)) / (2 * h)
    np.testing.assert_allclose(rate, np.minimum(1.6, np.minimum(v0, 1.6) + a * t), atol=1e-5)


def test_the_acceleration_model_loosens_only_the_body_and_only_when_asked():
    d = np.array([[0.4, 0.4], [0.8, 0.8]])
    body = np.array([[True, False]])
    speed = np.zeros_like(d)
    iso = max_approach_speed(d, 0.1, CFG, body)
    np.testing.assert_array_equal(max_approach_speed(d, 0.1, CFG, body, speed), iso)  # off
    on = replace(CFG, body_acceleration_mps2=25.0, speed_error_mps=0.0)
    loose = max_approach_speed(d, 0.1, on, body, speed)
    np.testing.assert_array_equal(loose[:, 1], iso[:, 1])  # an arm: ISO's speed as before
    gain = accelerated_reach(0.21, 0.0, 1.6, 25.0) - 1.6 * 0.21  # S_h less by v_max² / 2a
    np.testing.assert_allclose((loose - iso)[:, 0], -gain / (0.01 + 0.05))
    # a body part already at the body's speed gains nothing
    np.testing.assert_allclose(max_approach_speed(d, 0.1, on, body, speed + 1.6), iso)
    with pytest.raises(InputError, match="body_acceleration_mps2"):
        SSMConfig(body_acceleration_mps2=0.0)
