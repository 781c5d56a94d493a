"""Sensor calibration files and per-sensor recordings: every malformed input a clear error."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from qpavoid.core.errors import CalibrationError, RecordingError
from qpavoid.human.posture import Operator
from qpavoid.sensing.calibration import SensorCalibration
from qpavoid.sensing.calibration_file import calibration_from_dict, load_calibration
from qpavoid.sensing.per_sensor import (
    BodyFrame,
    SensorRecording,
    is_sensor_recording,
    load_sensor_recording,
    save_sensor_csv,
    save_sensor_npz,
)
from qpavoid.sensing.synthetic_pair import look_at


def toml_matrix(T: np.ndarray) -> str:
    return "[" + ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in T) + "]"


def write(tmp_path, text: str):
    p = tmp_path / "calib.toml"
    p.write_text(text)
    return p


def test_a_calibration_moves_camera_points_into_the_base_frame(tmp_path):
    T = look_at(np.array([1.0, 2.0, 1.3]), np.array([0.0, 1.0, 0.5]))
    p = write(
        tmp_path,
        f"[sensors.a]\nbase_from_camera = {toml_matrix(T)}\ntime_offset_s = 0.25\n"
        f"[sensors.b]\nbase_from_camera = {toml_matrix(np.eye(4))}\nweight = 2\n",
    )
    cal = load_calibration(p)
    assert cal.names == ("a", "b")
    assert cal["a"].time_offset_s == 0.25 and cal["b"].weight == 2.0
    # the camera's optical axis (z) points from the camera to the target
    target_in_camera = np.array([0.0, 0.0, np.linalg.norm([1.0, 1.0, 0.8])])
    np.testing.assert_allclose(cal["a"].to_base(target_in_camera), [0.0, 1.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(cal["a"].to_base(np.zeros(3)), [1.0, 2.0, 1.3])


def test_six_decimals_pass_and_come_back_orthonormal(tmp_path):
    R = Rotation.from_euler("xyz", [0.3, -0.2, 1.1]).as_matrix()
    T = np.eye(4)
    T[:3, :3] = np.round(R, 6)
    cal = load_calibration(write(tmp_path, f"[sensors.a]\nbase_from_camera = {toml_matrix(T)}"))
    Rf = cal["a"].base_from_camera[:3, :3]
    np.testing.assert_allclose(Rf.T @ Rf, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(Rf, R, atol=2e-6)


@pytest.mark.parametrize(
    ("body", "words"),
    [
        ("base_from_camera = [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]", "not rigid"),
        ("base_from_camera = [[1,0.1,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]", "not rigid"),
        ("base_from_camera = [[-1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]", "det R = -1"),
        ("base_from_camera = [[1,0,0,0],[0,1,0,0],[0,0,1,0]]", "shape (4, 4)"),
        ("base_from_camera = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]]", "last row"),
        ("base_from_camera = [[1,0,0,0],[0,1,0,0],[0,0,1,0],['a',0,0,1]]", "4 rows of 4"),
        ("base_from_camera = [[1,0,0,nan],[0,1,0,0],[0,0,1,0],[0,0,0,1]]", "non-finite"),
        ("translation = [0, 0, 0]", "sensors.a has unknown key(s) ['translation']"),
        # found by an adversarial tester
        ("base_from_camera = [[true,false,false,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]", "4 rows"),
        ("base_from_camera = [[[[1]]],[0,1,0,0],[0,0,1,0],[0,0,0,1]]", "4 rows"),
        ("base_from_camera = [[1,0,0,1e300],[0,1,0,0],[0,0,1,0],[0,0,0,1]]", "beyond 100 m"),
        ("base_from_camera = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\nweight = 1e308", "weight"),
        (
            "base_from_camera = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\ntime_offset_s = 1e17",
            "time_offset_s",
        ),
        ("weight = 1", "sensors.a is missing key(s) base_from_camera"),
        ("base_from_camera = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\nweight = 0", "weight"),
        (
            "base_from_camera = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\ntime_offset_s = 'x'",
            "time_offset_s",
        ),
    ],
)
def test_malformed_transforms_and_keys_are_refused_by_name(tmp_path, body, words):
    with pytest.raises(CalibrationError, match=r"sensors\.a[.: ]") as err:
        load_calibration(write(tmp_path, f"[sensors.a]\n{body}\n"))
    assert words in str(err.value)
    assert err.value.sensor == "a" and str(err.value.path).endswith("calib.toml")


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("", "no sensor"),
        ("x = 1", r"the top level has unknown key\(s\) \['x'\]"),
        ("[sensors", "not valid TOML"),
        ("x = " + "[" * 5000 + "]" * 5000, "not valid TOML"),  # nested past Python's stack
    ],
)
def test_files_without_sensors_are_refused(tmp_path, text, words):
    with pytest.raises(CalibrationError, match=words):
        load_calibration(write(tmp_path, text))


def test_a_missing_file_and_an_unknown_sensor_are_clear_errors(tmp_path):
    with pytest.raises(CalibrationError, match="cannot read calibration"):
        load_calibration(tmp_path / "nope.toml")
    cal = calibration_from_dict({"sensors": {"a": {"base_from_camera": np.eye(4).tolist()}}})
    with pytest.raises(CalibrationError, match="no sensor 'kinect_9'") as err:
        cal.check_names(["a", "kinect_9"])
    assert err.value.sensor == "kinect_9"


def recording(n: int = 4) -> SensorRecording:
    rest = Operator().rest()
    rows = [
        BodyFrame(sensor, body, 0.1 * k, rest + 0.01 * k + body, np.full(25, 2))
        for k in range(n)
        for sensor in ("a", "b")
        for body in (0, 3)
    ]
    return SensorRecording.from_frames(rows)


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_per_sensor_recordings_round_trip_exactly(tmp_path, suffix):
    rec = recording()
    path = tmp_path / f"rec{suffix}"
    (save_sensor_npz if suffix == ".npz" else save_sensor_csv)(path, rec)
    assert is_sensor_recording(path)
    back = load_sensor_recording(path)
    for name in ("sensor", "t", "body", "joints", "state"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rec, name))
    assert back.sensors == ("a", "b")


def test_a_scalar_sensor_name_and_no_body_mean_one_sensor_body_zero(tmp_path):
    rest = Operator().rest()
    path = tmp_path / "one.npz"
    np.savez(
        path,
        t=[0.0, 0.1],
        joints=np.stack([rest, rest]),
        state=np.full((2, 25), 2),
        sensor="kinect_left",
    )
    rec = load_sensor_recording(path)
    assert rec.sensors == ("kinect_left",) and rec.body.tolist() == [0, 0]


def test_bad_per_sensor_recordings_are_one_line_errors(tmp_path):
    rest = Operator().rest()
    base = tmp_path / "base.npz"
    np.savez(base, t=[0.0], joints=rest[None], state=np.full((1, 25), 2))
    assert not is_sensor_recording(base)
    with pytest.raises(RecordingError, match=r"no array 'sensor'.*needs no calibration"):
        load_sensor_recording(base)
    with pytest.raises(Exception, match="must increase strictly"):
        SensorRecording(["a", "a"], [0.1, 0.1], [0, 0], np.stack([rest, rest]), np.full((2, 25), 2))
    with pytest.raises(Exception, match="body ids of Kinect v2 are 0 to 5"):
        SensorRecording(["a"], [0.0], [6], rest[None], np.full((1, 25), 2))
    with pytest.raises(Exception, match="non-empty name"):
        SensorRecording([""], [0.0], [0], rest[None], np.full((1, 25), 2))
    # two bodies, or two sensors, may share a time
    SensorRecording(
        ["a", "a", "b"], [0.1] * 3, [0, 1, 0], np.stack([rest] * 3), np.full((3, 25), 2)
    )


@pytest.mark.parametrize(
    "kwargs, key",
    [
        ({"weight": 0.0}, "weight"),
        ({"weight": np.float64(-1.0)}, "weight"),
        ({"time_offset_s": float("nan")}, "time_offset_s"),
        ({"base_from_camera": np.eye(3)}, "base_from_camera"),
    ],
)
def test_a_sensor_made_in_code_has_the_file_s_limits(kwargs, key):
    """SensorCalibration(weight=0) was accepted (only the file refused it): seen joints
    then came out missing with a positive confidence (adversarial tester)."""
    args = {"name": "k", "base_from_camera": np.eye(4), **kwargs}
    with pytest.raises(CalibrationError) as err:
        SensorCalibration(**args)
    assert err.value.name == key and "np." not in str(err.value)
