"""Speed and separation monitoring terms (ISO/TS 15066): hand-computed values and invariants."""

from __future__ import annotations

import numpy as np
import pytest

from qpavoid.ssm import (
    SSMConfig,
    human_speed,
    max_approach_speed,
    protective_distance,
    stopping_distance,
)

CFG = SSMConfig()  # a = 2 m/s², T_r = 0.15 s, C + Z_d + Z_r = 0.075 m


def test_human_speed_zones_of_iso_13855():
    np.testing.assert_array_equal(human_speed([0.1, 0.5, 0.5001, 2.0], CFG), [2, 2, 1.6, 1.6])


def test_protective_distance_by_hand():
    # d = 0.5 m (v_h = 2.0): S_p(v) = 2 (0.15 + v/2) + 0.15 v + v²/4 + 0.075
    v = 0.2
    assert protective_distance(v, 0.5, CFG) == pytest.approx(0.3 + 0.2 + 0.03 + 0.01 + 0.075)
    assert stopping_distance(0.4, CFG) == pytest.approx(0.04)
    assert stopping_distance(-0.4, CFG) == 0.0  # moving away: no stopping distance


@pytest.mark.parametrize("d, v", [(0.5, 0.106242), (1.0, 0.619921)])
def test_max_approach_speed_by_hand(d, v):
    # 0.25 v² + 1.15 v − 0.125 = 0 at 0.5 m; 0.25 v² + 0.95 v − 0.685 = 0 at 1.0 m
    assert max_approach_speed(d, CFG) == pytest.approx(v, abs=1e-6)


def test_max_approach_speed_is_the_root_of_s_p_equals_d():
    rng = np.random.default_rng(0)
    d = rng.uniform(0.0, 2.0, 1000)
    v = max_approach_speed(d, CFG)
    ok = v >= 0
    assert ok.sum() > 500 and (~ok).sum() > 50
    np.testing.assert_allclose(protective_distance(v[ok], d[ok], CFG), d[ok], atol=1e-12)
    # where negative, even a robot at rest is too close: S_p(0) > d
    assert np.all(protective_distance(0.0, d[~ok], CFG) > d[~ok])
    # more uncertainty never allows a faster approach
    assert np.all(max_approach_speed(d, CFG, 0.05) <= v + 1e-15)
