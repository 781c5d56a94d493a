"""The compiled tracker and capsules against their former numpy code, over random frames."""

import numpy as np
import pytest

from qpavoid.human._kernels import fastest_joint, largest_per_part
from qpavoid.human.body import KinectHuman
from qpavoid.human.frames import HumanFrame
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.perception.tracker import PerceptionConfig, Tracker

PARENT, MAX_BONE_M = KINECT_V2.parent, KINECT_V2.max_bone_m


def numpy_track(mem, z, state, t, cfg):
    """The tracker's update as plain numpy (the code the kernel replaced, commit 6f201b9)."""
    pos, vel, last_seen, last_tracked, bone = mem
    seen = np.isfinite(z).all(axis=1) & (state != 0)
    tracked = seen & (state == 2)
    dt = t - last_seen
    both = seen & np.isfinite(dt)
    d = dt[both, None]
    pred = pos[both] + vel[both] * d
    r = z[both] - pred
    pos[both] = pred + cfg.velocity_alpha * r
    vel[both] = vel[both] + cfg.velocity_beta * r / d
    fresh = seen & ~both
    pos[fresh], vel[fresh] = z[fresh], 0.0
    vel[~seen] = 0.0
    last_seen[seen] = t
    last_tracked[tracked] = t
    pair = seen & (PARENT >= 0) & seen[np.maximum(PARENT, 0)]
    bone[pair] = np.maximum(bone[pair], np.linalg.norm(z[pair] - z[PARENT[pair]], axis=1))
    joints = np.where(seen[:, None], z, pos)
    radius = np.zeros(25)
    inferred = seen & ~tracked
    radius[inferred] = cfg.inferred_uncertainty_m + cfg.max_human_speed_mps * np.maximum(
        t - last_tracked[inferred], 0.0
    )
    lost = ~seen & np.isfinite(last_seen)
    radius[lost] = cfg.max_human_speed_mps * (t - last_seen[lost])
    radius[~seen & ~np.isfinite(last_seen)] = np.inf
    # the tree's path lengths, by Floyd-Warshall on its edges (a second method)
    n = len(PARENT)
    D = np.full((n, n), np.inf)
    np.fill_diagonal(D, 0.0)
    for j in np.flatnonzero(PARENT >= 0):
        D[j, PARENT[j]] = D[PARENT[j], j] = bone[j]
    for m in range(n):
        D = np.minimum(D, D[:, m : m + 1] + D[m : m + 1, :])
    for j in np.flatnonzero(~tracked):
        reach, a = bone[j], PARENT[j]
        while a >= 0 and not tracked[a]:
            reach, a = reach + bone[a], PARENT[a]
        if a < 0:  # no tracked ancestor: the nearest tracked joint along the tree
            near = np.where(tracked, D[j], np.inf)
            a, reach = int(np.argmin(near)), float(near.min())
            if not np.isfinite(reach):
                continue
        if reach < radius[j]:
            joints[j], radius[j] = z[a], reach
    known = np.isfinite(joints).all(axis=1)
    out_state = state.copy()
    out_state[~seen & known] = 1
    radius[~known] = 0.0
    return joints, out_state, radius, np.where(seen[:, None], vel, 0.0)


def random_frames(rng, n):
    base = rng.normal(0.0, 0.3, (25, 3)) + np.array([0.6, -0.6, 0.3])
    for _ in range(n):
        z = base + rng.normal(0.0, 0.02, (25, 3))
        state = rng.choice(np.array([0, 1, 2], dtype=np.int8), 25, p=[0.15, 0.15, 0.7])
        z[rng.uniform(size=25) < 0.1] = np.nan
        yield z, state


@pytest.mark.parametrize("seed", range(5))
def test_the_tracker_is_its_numpy_code(seed):
    rng = np.random.default_rng(seed)
    cfg = PerceptionConfig()
    tracker = Tracker(cfg)
    mem = [
        np.full((25, 3), np.nan),
        np.zeros((25, 3)),
        np.full(25, -np.inf),
        np.full(25, -np.inf),
        MAX_BONE_M.copy(),
    ]
    for k, (z, state) in enumerate(random_frames(rng, 60)):
        t = k / 30 + (0.5 if k > 40 else 0.0)  # and a gap
        p = tracker.update(HumanFrame(z, state), t)
        want = numpy_track(mem, z, state, t, cfg)
        np.testing.assert_allclose(p.frame.joints, want[0], atol=1e-12)
        np.testing.assert_array_equal(p.frame.state, want[1])
        np.testing.assert_allclose(p.joint_radius, want[2], atol=1e-12)
        np.testing.assert_allclose(p.joint_velocity, want[3], atol=1e-9)
    np.testing.assert_allclose(tracker.bone, mem[4], atol=1e-12)


def test_capsules_are_first_and_last_usable_joints_and_fingers_stick_out():
    rng = np.random.default_rng(7)
    human = KinectHuman()
    for z, state in random_frames(rng, 50):
        geo = human.geometry(z, state)
        usable = np.isfinite(z).all(axis=1) & (state != 0)
        for k, part in enumerate(human.parts):
            ids = [human.skeleton.index(j) for j in part.chain]
            chain = [j for j in ids if usable[j]]
            assert geo.segment_valid[k] == bool(chain)
            if chain:
                np.testing.assert_array_equal(geo.segments[k], z[[chain[0], chain[-1]]])
                a, b = geo.segments[k]
                out = 0.0
                for j in (human.skeleton.index(j) for j in part.reach):
                    if not usable[j]:
                        continue
                    s = np.clip(np.dot(z[j] - a, b - a) / max(np.dot(b - a, b - a), 1e-12), 0, 1)
                    gap = np.linalg.norm(z[j] - (a + s * (b - a))) - part.capsule_radius_m
                    out = max(out, gap)
                assert geo.reach_margin[k] == pytest.approx(out, abs=1e-12)
        for i, j in enumerate(human.joint_ids):
            assert geo.point_valid[i] == usable[j]


@pytest.mark.parametrize("seed", range(10))
def test_part_maxima_are_their_numpy_code(seed):
    """Largest radius and fastest joint per part against the numpy they replaced, on random
    memberships (parts with no joint included) and speeds with ties."""
    rng = np.random.default_rng(seed)
    members = rng.uniform(size=(8, 25)) < 0.2
    members[0] = False
    radius = rng.uniform(0, 0.3, size=25) * (rng.uniform(size=25) < 0.5)
    velocity = rng.choice([-1.0, 0.0, 1.0], size=(25, 3))  # many equal speeds
    np.testing.assert_array_equal(
        largest_per_part(members, radius), np.where(members, radius[None, :], 0.0).max(axis=1)
    )
    speed = np.where(members, (velocity * velocity).sum(axis=1)[None, :], -1.0)
    np.testing.assert_array_equal(fastest_joint(members, velocity), velocity[speed.argmax(axis=1)])
