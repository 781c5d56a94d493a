"""The one α-β filter of a skeleton's joints: steps and bones by hand, and each of its two
users' parameters against the code they had before (the tracker's longest bone, the
fusion's 0.9/0.1 average), bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from qpavoid.fusion.person import BONE_GAIN
from qpavoid.human.alpha_beta import alpha_beta_step
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.perception._kernels import BONE_GROW, BONE_SHRINK

#: Writeable copies, as the fusion passes them (a read-only array is another compile).
PARENT = np.array(KINECT_V2.parent)
N = KINECT_V2.n_joints


def memory(bone: np.ndarray | None = None) -> list[np.ndarray]:
    """A person never seen: positions, velocities, last seen, bones."""
    return [
        np.full((N, 3), np.nan),
        np.zeros((N, 3)),
        np.full(N, -np.inf),
        np.zeros(N) if bone is None else bone.copy(),
    ]


def step(mem, z, state, t, *, gap=np.inf, bone_state=1, grow=1.0, shrink=0.0):
    return alpha_beta_step(
        *mem, PARENT, z, state, t, 0.5, 0.25, gap, np.int64(bone_state), grow, shrink
    )


def test_a_joint_starts_at_rest_then_steps_by_hand():
    mem = memory()
    z = np.zeros((N, 3))
    state = np.full(N, 2, dtype=np.int8)
    seen = step(mem, z, state, 0.0)
    assert seen.all() and not mem[1].any() and (mem[2] == 0.0).all()
    # Δt = 0.1 s, r = 0.2: p = α r = 0.1, v = β r / Δt = 0.5 m/s
    seen = step(mem, z + np.array([0.2, 0.0, 0.0]), state, 0.1)
    np.testing.assert_allclose(mem[0][:, 0], 0.1)
    np.testing.assert_allclose(mem[1][:, 0], 0.5)
    # Δt = 0.2 s: p̂ = 0.1 + 0.5 × 0.2 = 0.2, r = 0.4 − 0.2 = 0.2: p = 0.3, v = 0.5 + 0.25
    step(mem, z + np.array([0.4, 0.0, 0.0]), state, 0.3)
    np.testing.assert_allclose(mem[0][:, 0], 0.3)
    np.testing.assert_allclose(mem[1][:, 0], 0.75)
    assert (mem[2] == 0.3).all() and not mem[0][:, 1:].any()


def test_unseen_joints_keep_their_memory_and_a_repeated_time_is_no_step():
    mem = memory()
    z, state = np.zeros((N, 3)), np.full(N, 2, dtype=np.int8)
    step(mem, z, state, 0.0)
    step(mem, z + 0.1, state, 0.1)
    before = [a.copy() for a in mem]
    lost = z + 5.0
    lost[:3] = np.nan  # NaN: not seen
    state_lost = state.copy()
    state_lost[3:6] = 0  # NotTracked: not seen either
    seen = step(mem, lost, state_lost, 0.2)
    assert not seen[:6].any() and seen[6:].all()
    for a, b in zip(mem, before):
        np.testing.assert_array_equal(a[:6], b[:6])
    again = [a.copy() for a in mem]
    step(mem, z + 7.0, state, 0.2)  # the same time again: taken as seen, nothing moves
    np.testing.assert_array_equal(mem[0][6:], again[0][6:])


def test_a_gap_longer_than_max_gap_restarts_the_joint_at_rest():
    z, state = np.zeros((N, 3)), np.full(N, 2, dtype=np.int8)
    for gap, restarted in ((0.1, True), (np.inf, False)):
        mem = memory()
        step(mem, z, state, 0.0, gap=gap)
        step(mem, z + 0.1, state, 0.05, gap=gap)
        step(mem, z + 1.0, state, 0.5, gap=gap)  # 0.45 s later
        if restarted:  # the fusion's: no extrapolation across the gap
            np.testing.assert_array_equal(mem[0], z + 1.0)
            assert not mem[1].any()
        else:  # the tracker's: the step from where the joint was
            assert (mem[0] < 1.0).all() and (mem[1] > 0).all()


def bone_measures(mem, lengths, states, *, bone_state, grow, shrink):
    """Put HandRight at ``lengths`` from WristRight, frame after frame; its bone after each."""
    out = []
    for k, (length, s) in enumerate(zip(lengths, states)):
        z = np.zeros((N, 3))
        z[KINECT_V2.index("HandRight")] = [length, 0.0, 0.0]
        state = np.full(N, 2, dtype=np.int8)
        state[KINECT_V2.index("HandRight")] = s
        step(mem, z, state, 0.1 * k, bone_state=bone_state, grow=grow, shrink=shrink)
        out.append(mem[3][KINECT_V2.index("HandRight")])
    return out


def test_the_trackers_bones_are_the_longest_seen_and_the_fusions_an_average():
    # the tracker: starts at the format's bound (0.12 m), keeps the longest, Inferred counts
    mem = memory(np.array(KINECT_V2.max_bone_m))
    got = bone_measures(
        mem, [0.10, 0.15, 0.05, 0.2], [2, 2, 2, 1], bone_state=1, grow=BONE_GROW, shrink=BONE_SHRINK
    )
    assert got == [0.12, 0.15, 0.15, 0.2]
    # the fusion: the first measure as is, then 0.9 bone + 0.1 length, Tracked ends only
    mem = memory()
    got = bone_measures(
        mem, [0.10, 0.20, 0.9, 0.05], [2, 2, 1, 2], bone_state=2, grow=BONE_GAIN, shrink=BONE_GAIN
    )
    assert got == pytest.approx([0.10, 0.11, 0.11, 0.104], abs=1e-15)


def former_fusion_update(positions, velocity, last_seen, bone, parent, z, state, t, a, b, gap):
    """The fusion's own filter before there was one (fusion_kernels.update_track), in numpy."""
    for j in range(len(z)):
        if np.isnan(z[j, 0]):
            continue
        dt = t - last_seen[j]
        if dt > gap:
            positions[j], velocity[j] = z[j], 0.0
        elif dt > 0.0:
            pred = positions[j] + velocity[j] * dt
            r = z[j] - pred
            positions[j] = pred + a * r
            velocity[j] = velocity[j] + b * r / dt
        last_seen[j] = t
    for j in range(len(z)):
        p = parent[j]
        if p < 0 or state[j] != 2 or state[p] != 2:
            continue
        length = np.sqrt(((z[j] - z[p]) ** 2).sum())
        bone[j] = 0.9 * bone[j] + 0.1 * length if bone[j] > 0.0 else length


def former_tracker_update(position, velocity, last_seen, bone, parent, z, state, t, a, b):
    """The tracker's α-β and bones before (perception_kernels.track), in numpy."""
    seen = (state != 0) & np.isfinite(z).all(axis=1)
    for j in np.flatnonzero(seen):
        dt = t - last_seen[j]
        if np.isfinite(dt):
            pred = position[j] + velocity[j] * dt
            r = z[j] - pred
            position[j] = pred + a * r
            velocity[j] = velocity[j] + b * r / dt
        else:
            position[j], velocity[j] = z[j], 0.0
        last_seen[j] = t
    for j in range(len(z)):
        p = parent[j]
        if p >= 0 and seen[j] and seen[p]:
            bone[j] = max(bone[j], np.sqrt(((z[j] - z[p]) ** 2).sum()))


def random_frames(rng, n):
    base = rng.normal(0.0, 0.3, (N, 3))
    t = 0.0
    for _ in range(n):
        t += rng.choice([1 / 30, 0.08, 0.3])  # and gaps longer than the fusion's 0.1 s
        z = base + rng.normal(0.0, 0.03, (N, 3))
        state = rng.choice(np.array([0, 1, 2], dtype=np.int8), N, p=[0.15, 0.2, 0.65])
        z[state == 0] = np.nan
        yield z, state, t


@pytest.mark.parametrize("seed", range(8))
def test_with_the_fusions_parameters_it_is_the_fusions_former_filter(seed):
    rng = np.random.default_rng(seed)
    mine, former = memory(), memory()
    for z, state, t in random_frames(rng, 80):
        alpha_beta_step(
            *mine, PARENT, z, state, t, 0.3, 0.05, 0.1, np.int64(2), BONE_GAIN, BONE_GAIN
        )
        former_fusion_update(*former, PARENT, z, state, t, 0.3, 0.05, 0.1)
        for a, b in zip(mine, former):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("seed", range(8))
def test_with_the_trackers_parameters_it_is_the_trackers_former_filter(seed):
    rng = np.random.default_rng(seed)
    mine, former = memory(np.array(KINECT_V2.max_bone_m)), memory(np.array(KINECT_V2.max_bone_m))
    for z, state, t in random_frames(rng, 80):
        alpha_beta_step(
            *mine, PARENT, z, state, t, 0.5, 0.3, np.inf, np.int64(1), BONE_GROW, BONE_SHRINK
        )
        former_tracker_update(*former, PARENT, z, state, t, 0.5, 0.3)
        for a, b in zip(mine, former):
            np.testing.assert_array_equal(a, b)
