"""Every input path takes every skeleton format (issue 28, items 4 and 5): the calibration
file, per-sensor and base-frame recordings (NPZ, CSV), the wire (versions 1 and 2), the
receiver's slots and the fusion of mixed cells; and refuses, in one line, a frame of the
wrong size, an unknown format, millimetres given as metres and a format its sensor is not
calibrated for."""

from __future__ import annotations

import json
import multiprocessing

import numpy as np
import pytest

from qpavoid.cli.commands import main
from qpavoid.core.errors import CalibrationError, InputError, RecordingError
from qpavoid.fusion.fuser import Fuser, FusionConfig
from qpavoid.human.landmarks import landmark_map
from qpavoid.scenarios.generated import make_scenario
from qpavoid.sensing.calibration import (
    Calibration,
    SensorCalibration,
    known_formats,
)
from qpavoid.sensing.calibration_file import calibration_from_dict, load_calibration
from qpavoid.sensing.keys import SensorKeys
from qpavoid.sensing.per_sensor import (
    BodyFrame,
    SensorRecording,
    load_sensor_recording,
    save_sensor_csv,
    save_sensor_npz,
)
from qpavoid.sensing.receiver import COUNTERS, SlotTable
from qpavoid.sensing.recording import Recording, load_recording, save_npz
from qpavoid.sensing.recording_files import csv_header
from qpavoid.sensing.signing import Signer, Verifier
from qpavoid.sensing.synthetic_pair import TwoSensorConfig, look_at, two_sensor_data
from qpavoid.sensing.wire import REASONS, WireError, Workspace, decode, encode

FORMATS = tuple(known_formats())
RAW = FusionConfig(smooth=False)
#: A camera 2 m in front of the operator, looking at them.
POSE = look_at(np.array([0.0, 2.0, 1.2]), np.array([0.0, 0.5, 0.9]))


def frame_of(name: str, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A camera frame of format ``name``: a person 2 m in front, m, some joints inferred,
    one lost (NaN, state 0)."""
    fmt = known_formats()[name]
    rng = np.random.default_rng(seed)
    joints = np.array([0.0, 0.2, 2.0]) + rng.uniform(-0.4, 0.4, (fmt.n_joints, 3))
    state = rng.choice(np.array([1, 2], dtype=np.int8), fmt.n_joints)
    joints[3], state[3] = np.nan, 0
    return joints, state


def cell(*formats: str, keys: bool = False) -> Calibration:
    """A cell with one sensor per format (``s0``, ``s1``, ...), each at :data:`POSE`."""
    sensors = {
        f"s{k}": SensorCalibration(f"s{k}", POSE, format=name) for k, name in enumerate(formats)
    }
    if not keys:
        return Calibration(sensors)
    return Calibration(sensors, cell="c", keys={n: SensorKeys.generate(n) for n in sensors})


def recording_of(name: str, sensor: str = "s0", n: int = 3) -> SensorRecording:
    frames = []
    for i in range(n):
        joints, state = frame_of(name, i)
        frames.append(BodyFrame(sensor, 0, 0.1 * i, joints, state, name))
    return SensorRecording.from_frames(frames)


# --- the calibration file ----------------------------------------------------------------


@pytest.mark.parametrize("name", FORMATS)
def test_a_sensor_names_its_format_in_the_calibration_file(name):
    table = {"base_from_camera": POSE.tolist(), "field_of_view_deg": [50.0, 40.0]}
    if name != "kinect_v2":
        table["format"] = name
    cal = calibration_from_dict({"sensors": {"a": table}})
    assert cal["a"].format == name and cal.formats == (name,)
    assert cal["a"].field_of_view_deg == (50.0, 40.0)  # as given, not the format's
    again = calibration_from_dict(__import__("tomllib").loads(cal.to_toml()))
    assert again["a"].format == name
    assert ("format =" in cal.to_toml()) == (name != "kinect_v2")  # Kinect v2 files as before


def test_an_unknown_format_in_the_calibration_is_refused_naming_the_sensor(tmp_path):
    path = tmp_path / "cal.toml"
    path.write_text(f'[sensors.left]\nbase_from_camera = {POSE.tolist()}\nformat = "kinect_v3"\n')
    with pytest.raises(CalibrationError) as err:
        load_calibration(path)
    assert err.value.sensor == "left" and err.value.value == "kinect_v3"
    assert "sensors.left.format" in str(err.value) and "kinect_v3" in str(err.value)
    assert "k4abt" in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(CalibrationError):
        SensorCalibration("a", POSE, format="nope")


# --- per-sensor recordings ---------------------------------------------------------------


@pytest.mark.parametrize("name", FORMATS)
@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_per_sensor_recordings_of_every_format_round_trip(tmp_path, name, suffix):
    rec = recording_of(name)
    path = tmp_path / f"rec{suffix}"
    (save_sensor_npz if suffix == ".npz" else save_sensor_csv)(path, rec)
    back = load_sensor_recording(path)
    assert back.format == name and back.joints.shape == rec.joints.shape
    np.testing.assert_array_equal(back.joints, rec.joints)
    np.testing.assert_array_equal(back.state, rec.state)
    assert all(f.format == name for f in back.frames())
    if suffix == ".npz":  # a Kinect v2 file is as it was: no format array
        assert ("format" in np.load(path)) == (name != "kinect_v2")


def test_a_per_sensor_recording_of_the_wrong_size_for_its_format_is_refused(tmp_path):
    rec = recording_of("kinect_v2")
    path = tmp_path / "rec.npz"
    np.savez(path, t=rec.t, sensor=rec.sensor, joints=rec.joints, state=rec.state, format="k4abt")
    with pytest.raises(RecordingError, match=r"joints .*\(3, 32, 3\)") as err:
        load_sensor_recording(path)
    assert "\n" not in str(err.value)
    np.savez(path, t=rec.t, sensor=rec.sensor, joints=rec.joints, state=rec.state, format="x")
    with pytest.raises(RecordingError, match="array 'format' must be one string naming"):
        load_sensor_recording(path)
    with pytest.raises(InputError, match="format must be one of"):
        SensorRecording(rec.sensor, rec.t, rec.body, rec.joints, rec.state, "kinect_v3")
    with pytest.raises(InputError, match="several skeleton formats"):
        SensorRecording.from_frames([*recording_of("k4abt").frames(), *rec.frames()])


def test_a_csv_header_naming_no_format_is_refused_naming_the_formats(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text("t,sensor,body,Foo_x,Foo_y,Foo_z,Foo_state\n0,s0,0,1,2,3,2\n")
    with pytest.raises(RecordingError) as err:
        load_sensor_recording(path)
    message = str(err.value)
    assert "no skeleton format" in message and "\n" not in message
    assert all(name in message for name in FORMATS)


# --- base-frame recordings ---------------------------------------------------------------


@pytest.mark.parametrize("name", FORMATS)
@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_base_frame_recordings_of_every_format_hold_the_bodys_landmarks(tmp_path, name, suffix):
    fmt = known_formats()[name]
    frames = [frame_of(name, i) for i in range(3)]
    t = np.array([0.0, 0.1, 0.2])
    joints, state = np.array([f[0] for f in frames]), np.array([f[1] for f in frames])
    path = tmp_path / f"human{suffix}"
    if suffix == ".npz":
        extra = {"format": np.array(name)} if name != "kinect_v2" else {}
        np.savez(path, t=t, joints=joints, state=state, **extra)
    else:
        lines = [",".join(csv_header(fmt))]
        for k in range(3):
            cells = [repr(float(t[k]))]
            for xyz, s in zip(joints[k], state[k], strict=True):
                cells += [repr(float(v)) for v in xyz] + [str(int(s))]
            lines.append(",".join(cells))
        path.write_text("\n".join(lines) + "\n")
    rec = load_recording(path)
    expected = landmark_map(fmt).map(joints, state)
    assert rec.format == name and rec.joints.shape == (3, 25, 3)
    np.testing.assert_array_equal(rec.joints, expected.joints)
    np.testing.assert_array_equal(rec.state, expected.state)
    if name == "kinect_v2":  # bit-identical
        np.testing.assert_array_equal(rec.joints, joints)
    out = tmp_path / "landmarks.npz"  # written back: the landmarks, a Kinect v2 file
    save_npz(out, rec)
    np.testing.assert_array_equal(load_recording(out).joints, rec.joints)


def test_millimetres_given_as_metres_are_refused_in_the_formats_joints(tmp_path):
    joints, state = frame_of("k4abt")
    path = tmp_path / "human.npz"
    np.savez(path, t=[0.0], joints=[joints * 1000.0], state=[state], format="k4abt")
    with pytest.raises(RecordingError, match=r"beyond 100 m .*joint PELVIS.*not metres") as err:
        load_recording(path)
    assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="format must be one of"):
        Recording(np.zeros(1), np.zeros((1, 25, 3)), np.zeros((1, 25)), "kinect_v3")


# --- the wire ----------------------------------------------------------------------------


@pytest.mark.parametrize("name", FORMATS)
def test_datagrams_of_every_format_round_trip_signed_and_unsigned(name):
    cal = cell(name, keys=True)
    joints, state = frame_of(name)
    frame = BodyFrame("s0", 0, 12.5, joints, state, name)
    v1 = encode(frame)
    assert ('"format"' in v1.decode()) == (name != "kinect_v2")  # Kinect v2's as before
    signed = Signer("c", cal.keys["s0"], first_sequence=1).encode(frame)
    for got in (decode(v1, cell(name)), Verifier(cal).decode(signed)):
        assert got.format == name and got.joints.shape == joints.shape
        np.testing.assert_allclose(got.joints, joints, atol=1e-6)
        np.testing.assert_array_equal(got.state, state)
        assert got.body == 0 and got.t == 12.5


def v1_datagram(name: str | None, n_rows: int, scale: float = 1.0) -> bytes:
    joints, _ = frame_of("k4abt")
    rows = [[*(scale * joints[k % 32]).tolist(), 2] for k in range(n_rows)]
    message: dict = {"v": 1, "sensor": "s0", "body": 0, "t": 1.0, "joints": rows}
    if name is not None:
        message["format"] = name
    return json.dumps(message).replace("NaN", "0.0").encode()


@pytest.mark.parametrize(
    ("format_key", "rows", "reason"),
    [
        ("k4abt", 32, None),
        ("kinect_v3", 32, "wrong_format"),  # unknown
        (None, 32, "wrong_format"),  # missing: Kinect v2, not the sensor's k4abt
        ("zed_body_34", 34, "wrong_format"),  # known, not the sensor's
        ("k4abt", 25, "bad_field"),  # not its format's rows
        (7, 32, "wrong_format"),
    ],
)
def test_a_datagram_of_the_wrong_format_is_dropped_with_a_reason(format_key, rows, reason):
    cal = cell("k4abt")
    data = v1_datagram(format_key, rows)
    if reason is None:
        assert decode(data, cal).format == "k4abt"
        return
    with pytest.raises(WireError) as err:
        decode(data, cal)
    assert err.value.reason == reason and reason in REASONS
    assert f"dropped_{reason}" in COUNTERS


def test_the_new_reason_keeps_the_old_ones_in_their_order():
    assert REASONS[REASONS.index("bad_version") + 1 : REASONS.index("bad_field")] == (
        "wrong_format",
    )
    old = [r for r in REASONS if r not in ("wrong_format", "bad_manifest")]  # issues 28, 40
    assert old[:3] == ["too_long", "unauthenticated", "bad_header"]
    assert old[-4:] == ["bad_version", "bad_field", "non_finite", "outside_workspace"]


def test_millimetres_on_the_wire_are_outside_the_workspace():
    with pytest.raises(WireError) as err:
        decode(v1_datagram("k4abt", 32, scale=1000.0), cell("k4abt"), Workspace())
    assert err.value.reason == "outside_workspace"


def test_a_signed_datagram_of_another_format_than_its_sensors_is_dropped():
    cal = cell("k4abt", keys=True)
    joints, state = frame_of("kinect_v2")
    signed = Signer("c", cal.keys["s0"], first_sequence=1).encode(
        BodyFrame("s0", 0, 1.0, joints, state)
    )
    with pytest.raises(WireError) as err:
        Verifier(cal).decode(signed)
    assert err.value.reason == "wrong_format"


def test_the_receivers_slots_fit_each_sensors_format():
    cal = cell("kinect_v2", "k4abt", "mediapipe_pose")
    table = SlotTable.create(multiprocessing.get_context("spawn"), cal)
    assert table.formats == ("kinect_v2", "k4abt", "mediapipe_pose")
    assert table.n_joints == 33 and table.max_bodies == 10  # the widest, the most bodies
    width = 3 + 4 * table.n_joints
    rows = np.frombuffer(table.values, dtype=np.float64).reshape(-1, width)
    joints, state = frame_of("k4abt")
    slot = rows[1 * table.max_bodies + 2]  # sensor s1, body 2
    slot[0], slot[2] = 1.0, 4.0
    slot[3 : 3 + 96] = np.nan_to_num(joints).ravel()
    slot[3 + 3 * 33 : 3 + 3 * 33 + 32] = state
    (frame,) = table.take()
    assert (frame.sensor, frame.body, frame.format) == ("s1", 2, "k4abt")
    np.testing.assert_array_equal(frame.joints, np.nan_to_num(joints))
    np.testing.assert_array_equal(frame.state, state)
    plain = SlotTable.create(multiprocessing.get_context("spawn"), ["a"])
    assert (plain.n_joints, plain.max_bodies, plain.formats) == (25, 6, ("kinect_v2",))


# --- the fusion --------------------------------------------------------------------------


def mean_error(data, names, motion) -> float:
    """Mean landmark error of the fusion of ``names`` (the sensors' weighted mean) against
    the truth, m; one person throughout."""
    cal = Calibration({n: data.calibration[n] for n in names})
    rows = sorted(
        (
            (f.t + cal[f.sensor].time_offset_s, k, f)
            for n in names
            for k, f in enumerate(data.recordings[n].frames())
        ),
        key=lambda r: r[:2],
    )
    fuser, errors = Fuser(cal, RAW), []
    for t, _, f in rows:
        fuser.add(f)
        people = fuser.fuse(t).people
        assert len(people) == 1
        joints, truth = people[0].frame.joints, motion.frame_at(t)[0]
        seen = np.isfinite(joints).all(axis=1)
        assert (people[0].frame.state[~seen] == 0).all()  # no NaN passed as seen
        errors.extend(np.linalg.norm(joints[seen] - truth[seen], axis=1))
    return float(np.mean(errors))


@pytest.mark.parametrize(
    "formats", [("kinect_v2", "k4abt"), ("zed_body_34", "k4abt"), ("kinect_v2", "mediapipe_pose")]
)
def test_a_mixed_cell_fused_beats_either_sensor_alone(robot, formats):
    motion = make_scenario("test1", robot)
    data = two_sensor_data([motion], 3.0, TwoSensorConfig(seed=1, formats=formats))
    a, b = data.calibration.names
    assert data.calibration.formats == formats
    assert data.recordings[b].format == formats[1]
    assert data.recordings[b].joints.shape[1] == known_formats()[formats[1]].n_joints
    alone = [mean_error(data, [n], motion) for n in (a, b)]
    fused = mean_error(data, [a, b], motion)
    assert fused < min(alone), (fused, alone)
    fuser = Fuser(data.calibration)
    expected = np.maximum.reduce([landmark_map(known_formats()[f]).uncertainty_m for f in formats])
    np.testing.assert_array_equal(fuser.landmark_uncertainty_m, expected)


def test_a_kinect_v2_cell_has_no_landmark_uncertainty_and_its_pair_is_unchanged(robot):
    data = two_sensor_data([make_scenario("test1", robot)], 0.5, TwoSensorConfig(seed=3))
    assert not Fuser(data.calibration).landmark_uncertainty_m.any()
    assert data.calibration.formats == ("kinect_v2", "kinect_v2")
    assert all(data.calibration[n].weight == 1.0 for n in data.calibration.names)


def test_the_fusion_refuses_a_frame_of_another_format_than_its_sensors():
    cal = cell("k4abt")
    fuser = Fuser(cal)
    joints, state = frame_of("kinect_v2")
    with pytest.raises(CalibrationError, match=r"holds kinect_v2 frames.*calibrated as k4abt"):
        fuser.add(BodyFrame("s0", 0, 0.0, joints, state))
    with pytest.raises(InputError, match=r"\(32, 3\)"):  # k4abt said, 25 rows given
        fuser.add(BodyFrame("s0", 0, 0.0, joints, state, "k4abt"))
    k4, s4 = frame_of("k4abt")
    assert fuser.add(BodyFrame("s0", 0, 0.0, k4, s4, "k4abt"))


def test_a_recording_whose_format_is_not_its_sensors_is_refused_on_the_command_line(
    tmp_path, capsys
):
    cal = tmp_path / "cal.toml"
    cal.write_text(cell("kinect_v2").to_toml())
    rec = tmp_path / "s0.npz"
    save_sensor_npz(rec, recording_of("k4abt"))
    out = tmp_path / "fused.npz"
    assert main(["fuse", str(rec), "--sensors", str(cal), "--out", str(out)]) == 2
    message = capsys.readouterr().err.strip()
    assert "holds k4abt frames" in message and "calibrated as kinect_v2" in message
    assert "\n" not in message and not out.exists()
    assert main(["replay", str(rec), "--to", "127.0.0.1:9", "--sensors", str(cal)]) == 2
    assert "calibrated as kinect_v2" in capsys.readouterr().err


def test_a_live_mixed_cell_takes_each_sensors_own_format_and_drops_the_rest():
    """A Kinect v2 and an Azure Kinect signing into one listener: each one's frames come
    out in its own format; a Femto frame claiming the Kinect's format, or the Kinect's
    sensor sending k4abt, is dropped and counted (wrong_format)."""
    import socket
    import time

    from qpavoid.human.landmarks import LandmarkMap, skeleton_format
    from qpavoid.human.posture import Operator
    from qpavoid.loop.live_input import Listener
    from qpavoid.sensing.keys import SensorKeys
    from qpavoid.sensing.signing import Signer

    keys = {name: SensorKeys.generate(name) for name in ("kinect", "femto")}
    cal = Calibration(
        {
            "kinect": SensorCalibration("kinect", np.eye(4)),
            "femto": SensorCalibration("femto", np.eye(4), format="k4abt"),
        },
        cell="mixed",
        keys=keys,
    )
    body = Operator().rest()
    k4abt = skeleton_format("k4abt")
    femto = LandmarkMap.simulated(k4abt).map(body, np.full(25, 2, dtype=np.int8))
    good = {
        "kinect": BodyFrame("kinect", 0, 0.0, body, np.full(25, 2, dtype=np.int8)),
        "femto": BodyFrame("femto", 3, 0.0, femto.joints, femto.state, format="k4abt"),
    }
    bad = [
        BodyFrame("femto", 1, 0.0, body, np.full(25, 2, dtype=np.int8)),  # a Kinect frame
        BodyFrame("kinect", 1, 0.0, femto.joints, femto.state, format="k4abt"),
    ]
    signers = {name: Signer(cal.cell, keys[name]) for name in keys}
    frames: list[BodyFrame] = []
    with Listener(("127.0.0.1", 0), cal) as listener:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            deadline = time.time() + 30.0  # as sensors stream: until the loop took both
            while {f.sensor for f in frames} != {"kinect", "femto"} and time.time() < deadline:
                for f in [*bad, *good.values()]:  # fresh stamps: a loaded machine's
                    sock.sendto(
                        signers[f.sensor].encode(f._replace(t=time.time())), listener.address
                    )
                time.sleep(0.05)
                frames += listener.drain()
        counts = dict(listener.counters)
    assert {(f.sensor, f.format, f.body) for f in frames} == {
        ("femto", "k4abt", 3),
        ("kinect", "kinect_v2", 0),
    }
    assert counts["dropped_wrong_format"] >= 2  # (a late one is dropped as late first)
    np.testing.assert_allclose(
        next(f for f in frames if f.sensor == "femto").joints, femto.joints, atol=1e-6
    )
