"""Speed and separation's compiled rows against the numpy functions they compile.

:func:`~qpavoid.laws.ssm.approach_bounds` (the limits stage's one call) must give what
:func:`~qpavoid.laws.ssm.separation_bounds` (numpy, term by term: ``human_speed``,
``human_distance``, ``accelerated_reach``, ``max_approach_speed``) gives for the same
pairs, over random tables of several people with parts unseen, at every age (stale,
unknown), with SaRA's acceleration model on and off; and one value by hand.
"""

from __future__ import annotations

import numpy as np
import pytest

from qpavoid.distance.table import DistanceTable
from qpavoid.laws.ssm import (
    SSMConfig,
    approach_bounds,
    body_mask,
    separation_bounds,
    separation_constants,
)

PARTS = ("head", "trunk", "left_hand", "right_hand", "left_forearm")


def _table(distance, vector):
    n_sets, n_parts = distance.shape
    none = np.full(distance.shape, -1)
    names = tuple(f"L{i}" for i in range(n_sets))
    return DistanceTable(
        "capsules", distance, vector, none, np.zeros(distance.shape), none, names, PARTS[:n_parts]
    )


def _rows(table, who, velocity, age, cfg):
    return approach_bounds(
        table.distance,
        table.vector,
        who,
        velocity,
        body_mask(table.part_names, cfg),
        age,
        *separation_constants(cfg),
    )


@pytest.mark.parametrize("acceleration", [None, 3.0])
def test_the_compiled_rows_are_numpys_over_random_tables(acceleration):
    rng = np.random.default_rng(17)
    cfg = SSMConfig(
        reaction_time_s=0.02,
        stop_time_s=0.15,
        max_acceleration_radps2=(("A1", 5.0),),
        body_acceleration_mps2=acceleration,
    )
    for k in range(300):
        n_sets, n_people = int(rng.integers(1, 9)), int(rng.integers(1, 7))
        shape = (n_sets, len(PARTS))
        distance = rng.uniform(-0.2, 1.5, shape)
        distance[rng.random(shape) < 0.15] = np.inf  # parts not seen
        vector = rng.normal(size=(*shape, 3))
        vector /= np.linalg.norm(vector, axis=2, keepdims=True)
        vector[np.isinf(distance)] = 0.0
        who = rng.integers(0, n_people, shape)
        velocity = rng.normal(scale=1.0, size=(n_people, len(PARTS), 3))
        age = [0.0, 0.05, 0.2, np.inf, np.nan][k % 5] if k % 7 == 0 else rng.uniform(0, 0.3)
        table = _table(distance, vector)
        limit, towards = _rows(table, who, velocity, float(age), cfg)
        v_pairs = velocity[who, np.arange(len(PARTS))[None, :]]  # as the stage picked them
        limit_np, towards_np = separation_bounds(table, v_pairs, age, cfg)
        np.testing.assert_allclose(limit, limit_np, rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(towards, towards_np, rtol=1e-13, atol=1e-15)


def test_one_pair_by_hand():
    """A hand 0.4 m away (2.0 m/s within 0.5 m), a frame 0.05 s old, T_r 0.02 s, T_s
    0.15 s: (0.4 − 2.0 · 0.22 − 0.055) / (0.02 + 0.075) = −1.0 m/s (the robot must
    retreat); the hand moving at 0.3 m/s towards the set and 0.4 across it: 0.3."""
    cfg = SSMConfig(reaction_time_s=0.02, stop_time_s=0.15, max_acceleration_radps2=(("A1", 5.0),))
    distance = np.array([[np.inf, np.inf, 0.4]])
    vector = np.zeros((1, 3, 3))
    vector[0, 2] = [1.0, 0.0, 0.0]
    velocity = np.zeros((1, 3, 3))
    velocity[0, 2] = [0.3, 0.4, 0.0]
    who = np.zeros((1, 3), np.int64)
    limit, towards = _rows(_table(distance, vector), who, velocity, 0.05, cfg)
    assert limit[0, 2] == pytest.approx((0.4 - 2.0 * 0.22 - 0.055) / 0.095)
    assert limit[0, 2] == pytest.approx(-1.0)
    assert towards[0, 2] == pytest.approx(0.3)
    assert limit[0, 0] == np.inf and towards[0, 0] == 0.0
