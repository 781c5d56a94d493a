"""The fusion's compiled kernels against plain numpy over many random cases."""

import os
import signal

import numpy as np
import pytest

from qpavoid.core.compiling import ctrl_c_deferred
from qpavoid.fusion._kernels import disagreement, mean_gaps, merge, subset_mean
from qpavoid.fusion.person import BONE_GAIN
from qpavoid.human.alpha_beta import alpha_beta_step
from qpavoid.human.kinect_v2 import KINECT_V2

#: Writeable copies, as the fusion passes them (a read-only array is another compile).
PARENT = np.array(KINECT_V2.parent)


def update_track(positions, velocity, last_seen, bone, parent, z, state, t, alpha, beta, gap):
    """One step of a fusion track: the α-β filter with the fusion's parameters."""
    alpha_beta_step(
        positions,
        velocity,
        last_seen,
        bone,
        parent,
        z,
        state,
        t,
        alpha,
        beta,
        gap,
        2,
        BONE_GAIN,
        BONE_GAIN,
    )


def bodies(rng, S):
    P = rng.normal(size=(S, 25, 3))
    states = rng.integers(0, 3, size=(S, 25)).astype(np.int8)
    P[states == 0] = np.nan
    return P, states


@pytest.mark.parametrize("seed", range(20))
def test_merge_is_the_weighted_mean(seed):
    rng = np.random.default_rng(seed)
    P, states = bodies(rng, int(rng.integers(1, 5)))
    W = rng.uniform(0, 1, size=states.shape) * (states > 0) * (rng.uniform(size=states.shape) > 0.2)
    disputed = rng.uniform(size=25) < 0.2
    joints, state = merge(P, states, W, disputed)
    total = W.sum(axis=0)
    seen = total > 0
    want = np.einsum("sj,sjx->jx", W, np.nan_to_num(P))[seen] / total[seen, None]
    np.testing.assert_allclose(joints[seen], want, atol=1e-12)
    assert np.isnan(joints[~seen]).all()
    tracked = ((states == 2) & (W > 0)).any(axis=0)
    np.testing.assert_array_equal(state, np.where(seen, np.where(tracked & ~disputed, 2, 1), 0))


@pytest.mark.parametrize("seed", range(20))
def test_disagreement_and_gaps_are_brute_force_distances(seed):
    rng = np.random.default_rng(seed)
    P, _ = bodies(rng, int(rng.integers(1, 5)))
    want = np.full(25, -1.0)
    for j in range(25):
        for a in range(len(P)):
            for b in range(a + 1, len(P)):
                d = np.linalg.norm(P[a, j] - P[b, j])
                if np.isfinite(d):
                    want[j] = max(want[j], d)
    np.testing.assert_allclose(disagreement(P), want)
    ref, pick = rng.normal(size=(25, 3)), np.arange(3, 20)
    gaps = np.linalg.norm(P[:, pick] - ref[pick], axis=2)
    want_mean = [g[np.isfinite(g)].mean() if np.isfinite(g).any() else np.nan for g in gaps]
    np.testing.assert_allclose(mean_gaps(P, ref, pick), want_mean)
    centre = subset_mean(P[0], pick)
    ok = pick[np.isfinite(P[0, pick]).all(axis=1)]
    if ok.size:
        np.testing.assert_allclose(centre, P[0, ok].mean(axis=0))


def test_a_fusion_track_filters_and_learns_bones_by_hand():
    positions, velocity = np.zeros((25, 3)), np.zeros((25, 3))
    last_seen, bone = np.full(25, -np.inf), np.zeros(25)
    z = np.arange(75.0).reshape(25, 3) * 0.01
    state = np.full(25, 2, dtype=np.int8)
    update_track(positions, velocity, last_seen, bone, PARENT, z, state, 1.0, 0.3, 0.05, 0.6)
    np.testing.assert_array_equal(positions, z)  # first sight: taken as is, at rest
    assert not velocity.any() and (last_seen == 1.0).all()
    child = np.flatnonzero(PARENT >= 0)
    np.testing.assert_allclose(bone[child], np.linalg.norm(z[child] - z[PARENT[child]], axis=1))
    z2 = z + 0.1
    update_track(positions, velocity, last_seen, bone, PARENT, z2, state, 1.5, 0.3, 0.05, 0.6)
    np.testing.assert_allclose(positions, z + 0.3 * 0.1)  # α r, r = 0.1
    np.testing.assert_allclose(velocity, np.full((25, 3), 0.05 * 0.1 / 0.5))  # β r / Δt
    z3 = z + 1.0  # after a gap over max_gap_s: no extrapolation across it
    update_track(positions, velocity, last_seen, bone, PARENT, z3, state, 2.5, 0.3, 0.05, 0.6)
    np.testing.assert_array_equal(positions, z3)
    assert not velocity.any()


def test_a_ctrl_c_while_the_kernels_compile_comes_right_after():
    """Numba drops a KeyboardInterrupt raised in its compiler's callbacks: held back."""
    reached = False
    with pytest.raises(KeyboardInterrupt), ctrl_c_deferred():
        os.kill(os.getpid(), signal.SIGINT)
        reached = True  # not interrupted inside
    assert reached
