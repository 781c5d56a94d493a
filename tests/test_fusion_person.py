"""One person's compiled fusion step against a plain-numpy second implementation of it, the
frame intake against the calibration's own transform, over many random cases."""

import numpy as np
import pytest

from qpavoid.fusion._kernels import believed, disagreement, ingest
from qpavoid.fusion.person import MIRROR_CHECK_M, fuse_person, mirror_costs
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.sensing.calibration import SensorCalibration

#: Writeable copies, as the fusion passes them (a read-only array is another compile).
PARENT, MIRROR, SIDED = (np.array(a) for a in (KINECT_V2.parent, KINECT_V2.mirror, KINECT_V2.sided))
STATE_WEIGHT = np.array([0.0, 0.2, 1.0])
STATE_CONFIDENCE = np.array([0.0, 0.15, 0.5])


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.mark.parametrize("seed", range(10))
def test_ingest_is_the_calibration_transform_with_unusable_joints_masked(seed):
    rng = np.random.default_rng(seed)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = random_rotation(rng), rng.normal(size=3)
    cal = SensorCalibration("s", T)
    joints = rng.normal(size=(25, 3))
    state = rng.integers(0, 3, size=25).astype(np.int8)
    joints[rng.uniform(size=(25, 3)) < 0.05] = np.nan  # one coordinate alone may be NaN
    out, usable = ingest(joints, state, T[:3, :3].copy(), T[:3, 3].copy())
    ok = (state > 0) & np.isfinite(joints).all(axis=1)
    np.testing.assert_allclose(out[ok], cal.to_base(joints)[ok], atol=1e-12)
    assert np.isnan(out[~ok]).all()
    np.testing.assert_array_equal(usable, np.where(ok, state, 0))


def mirror_costs_numpy(joints, reference):
    ref_ok = np.isfinite(reference).all(axis=1)
    usable = ~np.isnan(joints[:, 0])
    keep = SIDED[usable[SIDED] & ref_ok[SIDED]]
    keep_m = SIDED[usable[MIRROR[SIDED]] & ref_ok[SIDED]]
    if keep.size == 0 or keep_m.size == 0:
        return np.inf, np.inf
    return (
        np.median(np.linalg.norm(joints[keep] - reference[keep], axis=1)),
        np.median(np.linalg.norm(joints[MIRROR[keep_m]] - reference[keep_m], axis=1)),
    )


@pytest.mark.parametrize("seed", range(20))
def test_mirror_costs_are_the_medians_as_labelled_and_swapped(seed):
    rng = np.random.default_rng(seed)
    joints, reference = rng.normal(size=(25, 3)), rng.normal(size=(25, 3))
    joints[rng.uniform(size=25) < rng.uniform(0, 1)] = np.nan
    reference[rng.uniform(size=25) < 0.3] = np.nan
    np.testing.assert_allclose(
        mirror_costs(joints, reference, SIDED, MIRROR), mirror_costs_numpy(joints, reference)
    )
    # a body that is the reference with left and right swapped: swapped cost 0
    swapped = reference[MIRROR]
    as_is, mirrored = mirror_costs(swapped, reference, SIDED, MIRROR)
    assert mirrored == 0.0 and as_is > 0.0


def person_step_numpy(P, S, age, sensor_weight, recent, track, t, cfg):
    """The step as the fusion did it before it was compiled: numpy on whole arrays."""
    positions, velocity, last_seen, bone = track
    dt = np.maximum(np.minimum(t - last_seen, 0.1), 0.0)
    prediction = positions + velocity * dt[:, None] if recent else None
    reference = prediction if recent else P[0].copy()
    P, S = P.copy(), S.copy()
    ref_ok = np.isfinite(reference).all(axis=1)
    gaps = []
    for body in P:
        g = np.linalg.norm(body[SIDED] - reference[SIDED], axis=1)
        gaps.append(g[np.isfinite(g)].mean() if np.isfinite(g).any() else np.nan)
    mirrored = np.zeros(len(P), dtype=bool)
    for s in np.flatnonzero(np.array(gaps) > MIRROR_CHECK_M):
        as_is, swapped = mirror_costs_numpy(P[s], np.where(ref_ok[:, None], reference, np.nan))
        if swapped + cfg["mirror_margin_m"] < as_is:
            P[s], S[s], mirrored[s] = P[s][MIRROR], S[s][MIRROR], True
    if cfg["max_extrapolation_s"] > 0:
        P = P + velocity[None] * np.minimum(age, cfg["max_extrapolation_s"])[:, None, None]
    fresh = np.clip(1.0 - 0.5 * age / cfg["max_age_s"], 0.0, 1.0)
    W = STATE_WEIGHT[S] * (fresh * sensor_weight)[:, None]
    conf = STATE_CONFIDENCE[S] * fresh[:, None]
    disputed = np.flatnonzero(disagreement(P) > cfg["threshold"])
    expected = prediction if recent else np.full((25, 3), np.nan)
    keep = believed(P, S, disputed, expected, bone, PARENT, cfg["threshold"])
    W[:, disputed] *= keep
    conf[:, disputed] *= keep
    total = W.sum(axis=0)
    seen = total > 0
    joints = np.full((25, 3), np.nan)
    joints[seen] = np.einsum("sj,sjx->jx", W, np.nan_to_num(P))[seen] / total[seen, None]
    tracked = ((S == 2) & (W > 0)).any(axis=0)
    is_disputed = np.isin(np.arange(25), disputed)
    state = np.where(seen, np.where(tracked & ~is_disputed, 2, 1), 0)
    confidence = np.minimum(conf.sum(axis=0), 1.0)
    return joints, state, confidence, mirrored, disputed, keep, P, S


@pytest.mark.parametrize("seed", range(40))
def test_the_compiled_person_step_is_the_numpy_one(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 4))
    person = rng.normal(scale=0.3, size=(25, 3))
    P = person + rng.normal(scale=rng.choice([0.01, 0.1, 0.3]), size=(n, 25, 3))
    S = rng.choice(np.array([0, 1, 2], dtype=np.int8), p=[0.1, 0.2, 0.7], size=(n, 25))
    for s in range(n):
        if rng.uniform() < 0.3:  # a body labelled left for right
            P[s], S[s] = P[s][MIRROR], S[s][MIRROR]
    P[S == 0] = np.nan
    age = rng.uniform(0, 0.12, size=n)
    sensor_weight = rng.uniform(0.5, 1.5, size=n)
    recent = bool(rng.uniform() < 0.7)
    track = [
        person + rng.normal(scale=0.02, size=(25, 3)),
        rng.normal(scale=0.5, size=(25, 3)),
        0.9 - rng.uniform(0, 0.3, size=25),
        np.where(rng.uniform(size=25) < 0.5, rng.uniform(0.1, 0.4, size=25), 0.0),
    ]
    track[2][rng.uniform(size=25) < 0.1] = -np.inf
    cfg = {
        "max_age_s": 0.1,
        "max_extrapolation_s": float(rng.choice([0.0, 0.03])),
        "threshold": 0.2,
        "mirror_margin_m": 0.05,
    }
    smooth = bool(rng.uniform() < 0.5)
    want = person_step_numpy(P, S, age, sensor_weight, recent, track, 1.0, cfg)
    mine = [a.copy() for a in track]
    got = fuse_person(
        P.copy(),
        S.copy(),
        age,
        sensor_weight,
        recent,
        *mine,
        PARENT,
        MIRROR,
        SIDED,
        1.0,
        STATE_WEIGHT,
        STATE_CONFIDENCE,
        cfg["max_age_s"],
        cfg["max_extrapolation_s"],
        cfg["threshold"],
        cfg["mirror_margin_m"],
        0.3,
        0.05,
        smooth,
    )
    joints, state, confidence, mirrored, disputed, keep = got
    np.testing.assert_array_equal(state, want[1])
    np.testing.assert_allclose(confidence, want[2], atol=1e-12)
    np.testing.assert_array_equal(mirrored, want[3])
    np.testing.assert_array_equal(disputed, want[4])
    np.testing.assert_array_equal(keep, want[5])
    seen = state > 0
    if smooth:  # the filtered joints, where fused now
        np.testing.assert_allclose(joints[seen], mine[0][seen], atol=1e-12)
    else:
        np.testing.assert_allclose(joints[seen], want[0][seen], atol=1e-12)
    assert np.isnan(joints[~seen]).all()
    assert (mine[2][seen] == 1.0).all()  # the track saw what was fused
