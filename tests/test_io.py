"""Human-motion recordings: NPZ and CSV formats, validation and sample-and-hold."""

from __future__ import annotations

import csv
import re

import numpy as np
import pytest

from qpavoid.core.errors import InputError
from qpavoid.human.kinect_v2 import JointType
from qpavoid.sensing.recording import Recording, csv_header, load_recording, save_csv, save_npz

N_FRAMES = 5


def make_arrays(n: int = N_FRAMES, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """t (irregular, strictly increasing), joints with NaN, mixed states."""
    rng = np.random.default_rng(seed)
    t = 10.0 + np.cumsum(rng.uniform(0.02, 0.05, n))
    joints = rng.normal(0.0, 0.7, (n, 25, 3)) + np.array([0.6, 0.0, 0.4])
    joints[1, JointType.HandLeft] = np.nan  # lost joint
    joints[3, JointType.Head, 2] = np.nan  # one NaN coordinate
    state = rng.integers(0, 3, (n, 25))
    state[0] = [0, 1, 2] * 8 + [2]  # all three states present
    return t, joints, state


@pytest.fixture
def rec() -> Recording:
    return Recording(*make_arrays())


def assert_same(a: Recording, b: Recording) -> None:
    np.testing.assert_allclose(a.t, b.t, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.joints, b.joints, rtol=0, atol=1e-9, equal_nan=True)
    np.testing.assert_array_equal(np.isnan(a.joints), np.isnan(b.joints))
    np.testing.assert_array_equal(a.state, b.state)


# ----------------------------------------------------------------------------- round trips


def test_recording_converts_and_freezes(rec):
    t, joints, state = make_arrays()
    assert rec.n_frames == N_FRAMES
    assert rec.t.dtype == np.float64 and rec.joints.dtype == np.float64
    assert rec.state.dtype == np.int8
    np.testing.assert_array_equal(rec.state, state)
    assert rec.duration_s == pytest.approx(t[-1] - t[0])
    with pytest.raises(ValueError):
        rec.joints[0, 0, 0] = 1.0  # read-only
    joints[0, 0, 0] = 123.0  # the recording holds a copy
    assert rec.joints[0, 0, 0] != 123.0


def test_npz_round_trip(tmp_path, rec):
    path = tmp_path / "motion.npz"
    save_npz(path, rec)
    assert path.exists()
    back = load_recording(path)
    assert_same(rec, back)
    with np.load(path) as data:
        assert set(data.files) == {"t", "joints", "state"}
        assert data["joints"].shape == (N_FRAMES, 25, 3)
        assert data["state"].shape == (N_FRAMES, 25)


def test_csv_round_trip(tmp_path, rec):
    path = tmp_path / "motion.csv"
    save_csv(path, rec)
    back = load_recording(path)
    assert_same(rec, back)
    # exact, not only to 1e-9
    np.testing.assert_array_equal(rec.joints, back.joints)
    np.testing.assert_array_equal(rec.t, back.t)


def test_csv_text_nan_and_integer_states(tmp_path, rec):
    path = tmp_path / "motion.csv"
    save_csv(path, rec)
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    assert len(rows) == 1 + N_FRAMES
    header = rows[0]
    row1 = dict(zip(header, rows[2]))  # frame 1: HandLeft is NaN
    assert [row1[f"HandLeft_{a}"] for a in "xyz"] == ["nan", "nan", "nan"]
    row0 = dict(zip(header, rows[1]))
    assert [row0[f"{j.name}_state"] for j in JointType][:4] == ["0", "1", "2", "0"]
    assert float(row0["t"]) == rec.t[0]


def test_suffix_is_case_insensitive(tmp_path, rec):
    save_npz(tmp_path / "A.NPZ", rec)
    save_csv(tmp_path / "B.Csv", rec)
    assert_same(rec, load_recording(tmp_path / "A.NPZ"))
    assert_same(rec, load_recording(str(tmp_path / "B.Csv")))


def test_csv_written_by_hand_with_numpy(tmp_path):
    t, joints, state = make_arrays(4, seed=4)
    table = np.column_stack([t, np.concatenate([joints, state[:, :, None]], axis=2).reshape(4, -1)])
    path = tmp_path / "hand.csv"
    np.savetxt(path, table, delimiter=",", header=",".join(csv_header()), comments="", fmt="%.17g")
    back = load_recording(path)
    assert_same(Recording(t, joints, state), back)


# ----------------------------------------------------------------------------- header


def test_csv_header_exact():
    header = csv_header()
    assert len(header) == 101
    assert header[:6] == [
        "t",
        "SpineBase_x",
        "SpineBase_y",
        "SpineBase_z",
        "SpineBase_state",
        "SpineMid_x",
    ]
    assert header[-4:] == ["ThumbRight_x", "ThumbRight_y", "ThumbRight_z", "ThumbRight_state"]
    assert header[-1] == "ThumbRight_state"
    assert header[1 + 4 * JointType.SpineShoulder] == "SpineShoulder_x"
    assert len(set(header)) == 101


def test_csv_file_header_line(tmp_path, rec):
    path = tmp_path / "motion.csv"
    save_csv(path, rec)
    first = path.read_text().splitlines()[0]
    assert first.startswith("t,SpineBase_x,SpineBase_y,SpineBase_z,SpineBase_state,SpineMid_x,")
    assert first.endswith(",ThumbRight_state")
    assert first.count(",") == 100


# ----------------------------------------------------------------------------- sampling


@pytest.fixture
def steps() -> Recording:
    """Frame k at t = 1.0 + 0.5 k with every coordinate equal to k, for 4 frames."""
    t = np.array([1.0, 1.5, 2.0, 2.5])
    joints = np.broadcast_to(np.arange(4.0)[:, None, None], (4, 25, 3))
    state = np.broadcast_to(np.array([2, 1, 0, 2])[:, None], (4, 25))
    return Recording(t, joints, state)


def test_between_frames_returns_earlier_frame(steps):
    joints, state = steps.frame_at(1.7)
    assert joints.shape == (25, 3) and state.shape == (25,)
    assert np.all(joints == 1.0) and np.all(state == 1)
    assert steps.index_at(1.499999) == 0
    assert steps.index_at(2.4999) == 2


def test_exactly_at_frame_time_returns_that_frame(steps):
    for k, tk in enumerate(steps.t):
        joints, _ = steps.frame_at(float(tk))
        assert steps.index_at(float(tk)) == k
        assert np.all(joints == k)
    assert np.all(steps.frame_at(2.0)[1] == 0)


def test_after_end_holds_last_frame(steps):
    joints, state = steps.frame_at(100.0)
    assert steps.index_at(100.0) == 3
    assert np.all(joints == 3.0) and np.all(state == 2)


def test_before_start_raises(steps):
    with pytest.raises(InputError, match=r"no frame yet at t=0\.99.*t\[0\]=1\.0"):
        steps.frame_at(0.99)
    with pytest.raises(InputError, match="no frame yet"):
        steps.index_at(-5.0)
    with pytest.raises(InputError, match="finite"):
        steps.frame_at(float("nan"))


def test_frame_at_returns_copies(steps):
    joints, _ = steps.frame_at(1.0)
    joints[:] = -1.0
    assert np.all(steps.frame_at(1.0)[0] == 0.0)


# ----------------------------------------------------------------------------- errors


def test_wrong_joints_shape():
    t, joints, state = make_arrays()
    with pytest.raises(InputError, match=r"joints.*shape \(5, 25, 3\), got \(5, 24, 3\)"):
        Recording(t, joints[:, :24], state)
    with pytest.raises(InputError, match=r"joints.*got \(4, 25, 3\)"):
        Recording(t, joints[:4], state)


def test_wrong_state_shape():
    t, joints, state = make_arrays()
    with pytest.raises(InputError, match=r"state.*shape \(5, 25\), got \(5, 25, 1\)"):
        Recording(t, joints, state[:, :, None])


def test_no_frame():
    with pytest.raises(InputError, match="no frame"):
        Recording(np.zeros(0), np.zeros((0, 25, 3)), np.zeros((0, 25), int))


def test_decreasing_t():
    t, joints, state = make_arrays()
    t[3] = t[1] - 0.01
    with pytest.raises(InputError, match=r"strictly increasing \(frames out of order\): t\[3\]="):
        Recording(t, joints, state)


def test_duplicate_t():
    t, joints, state = make_arrays()
    t[2] = t[1]
    expected = f"t[2]={float(t[2])!r} s is not after t[1]={float(t[1])!r} s"
    with pytest.raises(InputError, match=r"duplicate frame time.*" + re.escape(expected)):
        Recording(t, joints, state)


def test_non_finite_t():
    t, joints, state = make_arrays()
    t[4] = np.inf
    with pytest.raises(InputError, match=r"non-finite value at index 4: inf"):
        Recording(t, joints, state)


def test_state_3():
    t, joints, state = make_arrays()
    state[2, JointType.ElbowRight] = 3
    with pytest.raises(InputError, match=r"state\[2, 9\] \(ElbowRight.*is 3, expected 0"):
        Recording(t, joints, state)


def test_infinite_coordinate_rejected_nan_allowed():
    t, joints, state = make_arrays()
    joints[4, JointType.WristLeft, 1] = -np.inf
    with pytest.raises(InputError, match=r"infinite coordinate at frame 4.*WristLeft, axis y"):
        Recording(t, joints, state)
    joints[4, JointType.WristLeft, 1] = np.nan
    assert np.isnan(Recording(t, joints, state).joints[4, JointType.WristLeft, 1])


def test_missing_state_array_in_npz(tmp_path):
    t, joints, _ = make_arrays()
    path = tmp_path / "nostate.npz"
    np.savez(path, t=t, joints=joints)
    with pytest.raises(InputError, match=r"nostate\.npz.*no array 'state'"):
        load_recording(path)


def test_npz_with_bad_data_names_the_path(tmp_path):
    t, joints, state = make_arrays()
    state[0, 0] = 7
    path = tmp_path / "bad.npz"
    np.savez(path, t=t, joints=joints, state=state)
    with pytest.raises(InputError, match=r"bad\.npz.*state\[0, 0\] \(SpineBase"):
        load_recording(path)


def test_wrong_csv_header_order(tmp_path, rec):
    path = tmp_path / "swapped.csv"
    save_csv(path, rec)
    lines = path.read_text().splitlines()
    lines[0] = lines[0].replace("SpineBase_x,SpineBase_y", "SpineBase_y,SpineBase_x")
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(
        InputError,
        match=r"swapped\.csv.*column 1 is 'SpineBase_y', "
        r"expected 'SpineBase_x'",
    ):
        load_recording(path)


def test_csv_missing_column(tmp_path, rec):
    path = tmp_path / "short.csv"
    save_csv(path, rec)
    rows = [line.split(",") for line in path.read_text().splitlines()]
    drop = rows[0].index("Head_state")
    path.write_text("\n".join(",".join(r[:drop] + r[drop + 1 :]) for r in rows) + "\n")
    with pytest.raises(InputError, match=r"missing column\(s\) Head_state"):
        load_recording(path)


def test_csv_bad_cell_names_line_and_column(tmp_path, rec):
    path = tmp_path / "cell.csv"
    save_csv(path, rec)
    lines = path.read_text().splitlines()
    cells = lines[3].split(",")
    cells[2] = "abc"
    lines[3] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"line 4, column 'SpineBase_y': 'abc' is not a number"):
        load_recording(path)


def test_unknown_suffix(tmp_path, rec):
    path = tmp_path / "motion.json"
    path.write_text("{}")
    with pytest.raises(InputError, match=r"unknown recording format '\.json'.*\.npz or \.csv"):
        load_recording(path)


def test_missing_file(tmp_path):
    path = tmp_path / "absent.npz"
    with pytest.raises(InputError, match=r"not found.*absent\.npz"):
        load_recording(path)


def test_corrupt_npz(tmp_path):
    path = tmp_path / "junk.npz"
    path.write_bytes(b"not a zip file")
    with pytest.raises(InputError, match=r"junk\.npz.*not a readable NPZ"):
        load_recording(path)
