"""A sender for every format (issue 46, item 2): ``qpavoid send`` and
:mod:`qpavoid.loop.sender` play a calibrated sensor of any format on the wire; the worked
calibrations of docs/sensors.md §11 (``docs/calibrations/``) put the operator where their
hand-worked numbers say; a listener says which format arrived and which it expected.

The worked calibrations' camera is 0.6 m behind the robot's base and 1.5 m above the
table, tilted down by asin(0.6) (36.87°), so that its optical axis meets (0, 1.0, 0.3)
in the base frame 2.0 m away. The numbers below are worked by hand from that place (not
by the library): a base point p is, in the optical frame (x right, y down, z forward),
``(r·(p − c), −u·(p − c), f·(p − c))`` with c = (0, −0.6, 1.5), r = (1, 0, 0),
u = (0, 0.6, 0.8), f = (0, 0.8, −0.6); the Kinect v2's frame (x left, y up) negates x and y.
"""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import PYTHON
from test_cli_errors import test_bad_input_is_one_line_and_exit_2 as refused_as_every_command

from qpavoid.arm.model import load_robot
from qpavoid.cli.commands import main
from qpavoid.control.task import default_task
from qpavoid.human.landmarks import FORMAT_NAMES, camera_frame, skeleton_format
from qpavoid.human.posture import Operator
from qpavoid.loop.live_input import Listener
from qpavoid.loop.sender import AtRest, send, sensor_frames, sensor_latency_s
from qpavoid.sensing.calibration import Calibration, SensorCalibration
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.keys import SensorKeys, new_key_file
from qpavoid.sensing.per_sensor import BodyFrame, SensorRecording, save_sensor_npz
from qpavoid.sensing.recording import Recording, save_npz
from qpavoid.sensing.signing import Signer, Verifier
from qpavoid.sensing.synthetic_pair import look_at

WORKED = Path(__file__).parents[1] / "docs" / "calibrations"
#: Each format's worked calibration file and its sensor's name in it.
SENSORS = {
    "kinect_v2": "kinect",
    "k4abt": "femto",
    "zed_body_34": "zed",
    "zed_body_38": "zed",
    "mediapipe_pose": "rgbd",
}
#: Base-frame points (m) and where each format's SDK puts them, worked by hand (module
#: docstring): the chest on the optical axis, a point 0.5 m above it, one 0.15 m to the
#: operator's left (+x).
POINTS = np.array([[0.0, 1.0, 0.3], [0.0, 1.0, 0.8], [0.15, 1.0, 0.3]])
OPTICAL = np.array([[0.0, 0.0, 2.0], [0.0, -0.4, 1.7], [0.15, 0.0, 2.0]])
KINECT = np.array([[0.0, 0.0, 2.0], [0.0, 0.4, 1.7], [-0.15, 0.0, 2.0]])
#: The Panda's seat (robots/panda/task.toml, [operator]: x_m, distance_m), m.
PANDA_SEAT = (0.1360, 1.0882)


def worked(folder: Path, fmt: str) -> str:
    """The worked calibration of ``fmt`` copied into ``folder`` with its key made, as a
    user does (``qpavoid keygen``); the copy's path."""
    path = folder / f"{fmt}.toml"
    shutil.copy(WORKED / f"{fmt}.toml", path)
    key = folder / f"{SENSORS[fmt]}.key"
    if not key.exists():
        new_key_file(key, SENSORS[fmt])
    return str(path)


def panda_seat_operator() -> Operator:
    return default_task(load_robot("panda")).operator


def wait_for(listener: Listener, received: int, within_s: float = 20.0) -> None:
    deadline = time.time() + within_s
    while listener.counters["received"] < received and time.time() < deadline:
        time.sleep(0.02)


def torso_centre(frame: BodyFrame, calibration: Calibration) -> np.ndarray:
    """The mean of the frame's torso joints in the base frame, m."""
    fmt = skeleton_format(frame.format)
    torso = [fmt.joints.index(j) for j in fmt.torso]
    return calibration[frame.sensor].to_base(frame.joints[torso]).mean(axis=0)


# --- the worked calibrations ---------------------------------------------------------------


@pytest.mark.parametrize("fmt", FORMAT_NAMES)
def test_each_worked_calibration_is_rigid_and_names_its_format(tmp_path, fmt):
    cal = load_calibration(worked(tmp_path, fmt))[SENSORS[fmt]]
    T = cal.base_from_camera
    R = T[:3, :3]
    assert cal.format == fmt
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])
    np.testing.assert_allclose(T[:3, 3], [0.0, -0.6, 1.5])  # the camera's place
    np.testing.assert_allclose(R[:, 2], [0.0, 0.8, -0.6])  # it looks along +z, 36.87° down


@pytest.mark.parametrize("fmt", FORMAT_NAMES)
def test_the_recipe_for_your_own_place_gives_the_worked_matrices(tmp_path, fmt):
    """docs/sensors.md §11: ``look_at`` (a Kinect v2 at the camera's place, looking at the
    chest), its rotation times diag(-1, -1, 1) for a right-down-forward camera."""
    T = look_at(np.array([0.0, -0.6, 1.5]), np.array([0.0, 1.0, 0.3]))
    if fmt != "kinect_v2":
        T[:3, :3] = T[:3, :3] @ np.diag([-1.0, -1.0, 1.0])
    cal = load_calibration(worked(tmp_path, fmt))[SENSORS[fmt]]
    np.testing.assert_allclose(cal.base_from_camera, T, atol=1e-12)


@pytest.mark.parametrize("fmt", FORMAT_NAMES)
def test_the_sdks_numbers_land_where_the_hand_worked_points_are(tmp_path, fmt):
    """Each format's own units and axes (the SDK's millimetres of the k4abt and the ZED,
    the Kinect v2's x left and y up) through the format's conversion
    (:func:`camera_frame`) and the worked calibration: the hand-worked base points."""
    spec = skeleton_format(fmt)
    cal = load_calibration(worked(tmp_path, fmt))[SENSORS[fmt]]
    in_sdk = (KINECT if fmt == "kinect_v2" else OPTICAL) / spec.unit_m  # mm where mm
    sdk = np.repeat(in_sdk[:1], spec.n_joints, axis=0)
    sdk[:3] = in_sdk
    joints, states = camera_frame(fmt, sdk)
    np.testing.assert_allclose(cal.to_base(joints[:3]), POINTS, atol=1e-9)
    assert (states == 2).all()


@pytest.mark.parametrize("fmt", FORMAT_NAMES)
def test_the_seated_operator_lands_at_the_seat_through_each_formats_camera(tmp_path, fmt):
    """The operator at rest at the Panda's seat, filmed by the worked camera (its frame,
    its format's joints and noise): back in the base frame, the torso is at the seat."""
    calibration = load_calibration(worked(tmp_path, fmt))
    sensor = SENSORS[fmt]
    frames = list(sensor_frames(AtRest(panda_seat_operator()), calibration, sensor, 0.5))
    assert len(frames) == 15 and {(f.sensor, f.format, f.body) for f in frames} == {
        (sensor, fmt, 0)
    }
    centre = np.mean([torso_centre(f, calibration) for f in frames], axis=0)
    # the torso's joints are symmetric about the seat's x; the hips sit 0.05 m behind it
    assert centre[0] == pytest.approx(PANDA_SEAT[0], abs=0.03)
    assert centre[1] == pytest.approx(PANDA_SEAT[1], abs=0.06)
    assert -0.3 < centre[2] < 0.35  # between the hips and the shoulders


# --- the sender on the wire ----------------------------------------------------------------


@pytest.mark.parametrize("fmt, noise_m", [("kinect_v2", 0.002), ("k4abt", 0.005)])
def test_frames_are_stamped_send_time_less_the_latency_and_carry_the_cameras_noise(
    tmp_path, fmt, noise_m
):
    """A fake clock: frame k goes 1/30 s after frame k−1 and is stamped its send time
    less the latency and the sensor's clock offset; a still operator's joints move from
    frame to frame by the format file's noise (their difference's spread sqrt(2) σ)."""
    calibration = load_calibration(worked(tmp_path, fmt))
    sensor = SENSORS[fmt]
    offset = 0.25
    cal = SensorCalibration(
        sensor, calibration[sensor].base_from_camera, time_offset_s=offset, format=fmt
    )
    calibration = Calibration({sensor: cal}, cell=calibration.cell, keys=calibration.keys)
    now = [1000.0]

    def clock() -> float:
        return now[0]

    def sleep(s: float) -> None:
        now[0] += s

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sink:
        sink.bind(("127.0.0.1", 0))
        sink.settimeout(5.0)
        frames = sensor_frames(AtRest(Operator()), calibration, sensor, 1.0)
        summary = send(frames, calibration, sensor, sink.getsockname(), clock=clock, sleep=sleep)
        got = [sink.recv(65536) for _ in range(summary.datagrams)]
    latency = skeleton_format(fmt).sensor.latency_s  # the format file's, by default
    assert summary.latency_s == latency and summary.frames == summary.datagrams == 30
    verifier = Verifier(calibration)
    decoded = [verifier.decode(d) for d in got]
    # frame k sent k / 30 s after the first, stamped that less the latency and the offset
    stamps = np.array([f.t for f in decoded])
    np.testing.assert_allclose(stamps, 1000.0 + np.arange(30) / 30 - latency - offset, atol=1e-9)
    joints = np.array([f.joints for f in decoded])
    spread = np.diff(joints, axis=0).std() / np.sqrt(2)
    assert spread == pytest.approx(noise_m, rel=0.15)


def test_the_default_latency_is_the_calibrations_measured_one_else_the_formats(tmp_path):
    calibration = load_calibration(worked(tmp_path, "zed_body_38"))
    assert sensor_latency_s(calibration, "zed") == 0.12  # zed_body_38.toml's [sensor]
    text = Path(worked(tmp_path, "k4abt")).read_text() + "latency_s = 0.21\n"
    (tmp_path / "measured.toml").write_text(text)  # a measured one, under [sensors.femto]
    assert sensor_latency_s(load_calibration(tmp_path / "measured.toml"), "femto") == 0.21


def test_each_formats_sender_gets_its_frames_taken_by_a_listener(tmp_path):
    """Every format's worked camera, each sending the operator at rest for 1 s into one
    listener (its sensors the five worked ones): every frame taken, none dropped, each in
    its format, at the Panda's seat. (Frames 5 s old are taken: a loaded machine may take
    tenths of a second to deliver; the stamps are checked on a fake clock above.)"""
    sensors = {}
    for fmt in FORMAT_NAMES:
        cal = load_calibration(worked(tmp_path, fmt))[SENSORS[fmt]]
        name = f"{SENSORS[fmt]}_{fmt}"
        sensors[name] = SensorCalibration(name, cal.base_from_camera, format=fmt)
    keys = {name: SensorKeys.generate(name) for name in sensors}
    calibration = Calibration(sensors, cell="worked-example", keys=keys)
    operator = panda_seat_operator()
    with Listener(("127.0.0.1", 0), calibration, max_age_s=5.0) as listener:
        summaries = {}

        def play(name: str) -> None:
            frames = sensor_frames(AtRest(operator), calibration, name, 1.0, seed=7)
            summaries[name] = send(frames, calibration, name, listener.address)

        players = [threading.Thread(target=play, args=(name,)) for name in sensors]
        for p in players:
            p.start()
        for p in players:
            p.join()
        wait_for(listener, sum(s.datagrams for s in summaries.values()))
        counts = dict(listener.counters)
        taken = listener.drain()
    assert all(s.datagrams == 30 for s in summaries.values()), summaries
    assert counts["received"] == counts["accepted"] == 150, counts
    assert not [k for k in counts if k.startswith("dropped") or k in ("late", "from_the_future")]
    assert {(f.sensor, f.format) for f in taken} == {(n, c.format) for n, c in sensors.items()}
    for frame in taken:
        centre = torso_centre(frame, calibration)
        assert np.hypot(*(centre[:2] - PANDA_SEAT)) < 0.08, (frame.sensor, centre)


def test_qpavoid_send_plays_the_issues_femto_for_a_listener(tmp_path, capsys):
    """The case of issue 46: a Femto Bolt (k4abt) calibration; ``qpavoid send`` says where
    it sends what, and the listener takes every frame."""
    calib = worked(tmp_path, "k4abt")
    with Listener(("127.0.0.1", 0), load_calibration(calib), max_age_s=5.0) as listener:
        port = listener.address[1]
        argv = ["send", "femto", "--to", f"127.0.0.1:{port}", "--sensors", calib]
        status = main([*argv, "--robot", "panda", "--seconds", "0.5", "--camera", "k4abt"])
        out = capsys.readouterr()
        wait_for(listener, 15)
        counts = dict(listener.counters)
        frames = listener.drain()
    assert status == 0, out.err
    first, last = out.out.strip().splitlines()
    assert first.startswith("sending femto (k4abt, 30 Hz, latency 0.100 s") and "panda" in first
    assert f"to 127.0.0.1:{port} for 0.5 s" in first
    assert last.startswith(f"sent 15 frames of femto (k4abt) to 127.0.0.1:{port}: 15 signed")
    assert counts["received"] == counts["accepted"] == 15, counts
    assert {f.format for f in frames} == {"k4abt"}


def test_a_per_sensor_recording_is_sent_as_recorded_with_its_latency(tmp_path, capsys):
    """Recorded frames go as ``qpavoid replay`` sends them (its streamer), each stamped
    its send time less the latency; another sensor's frames in the file stay home."""
    calib = worked(tmp_path, "k4abt")
    calibration = load_calibration(calib)
    frames = list(sensor_frames(AtRest(Operator()), calibration, "femto", 0.3))
    other = [f._replace(sensor="other") for f in frames]
    save_sensor_npz(tmp_path / "rec.npz", SensorRecording.from_frames(frames + other))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sink:
        sink.bind(("127.0.0.1", 0))
        sink.settimeout(5.0)
        to = f"127.0.0.1:{sink.getsockname()[1]}"
        argv = ["send", "femto", "--to", to, "--sensors", calib, "--human"]
        before = time.time()
        assert main([*argv, str(tmp_path / "rec.npz"), "--latency", "0.2"]) == 0
        got = [sink.recv(65536) for _ in range(9)]
        after = time.time()
    assert "femto's frames recorded in" in capsys.readouterr().out
    decoded = [Verifier(calibration).decode(d) for d in got]
    for frame, recorded in zip(decoded, frames, strict=True):
        np.testing.assert_allclose(frame.joints, recorded.joints, atol=1e-6)  # µm on the wire
        assert before - 0.2 <= frame.t <= after - 0.2


# --- what the listener says of a datagram of another format --------------------------------


def test_a_datagram_of_another_format_is_reported_once_per_sensor_with_both_names(tmp_path):
    """A k4abt datagram to a sensor calibrated kinect_v2, a kinect_v2 one to a k4abt
    sensor, an unknown format to a ZED: each dropped (dropped_wrong_format) and reported
    by the listener as (arrived, expected), the first one per sensor."""
    kinect = load_calibration(worked(tmp_path, "kinect_v2"))["kinect"]
    femto = load_calibration(worked(tmp_path, "k4abt"))["femto"]
    zed = load_calibration(worked(tmp_path, "zed_body_34"))["zed"]
    keys = {n: SensorKeys.generate(n) for n in ("kinect", "femto", "zed", "quiet")}
    calibration = Calibration(
        {
            "kinect": kinect,
            "femto": femto,
            "zed": zed,
            "quiet": SensorCalibration("quiet", kinect.base_from_camera),
        },
        cell="c",
        keys=keys,
    )
    rest = AtRest(Operator())
    a_femto = next(sensor_frames(rest, calibration, "femto", 0.1))
    a_kinect = next(sensor_frames(rest, calibration, "kinect", 0.1))
    a_zed = next(sensor_frames(rest, calibration, "zed", 0.1))
    wrong = [
        a_femto._replace(sensor="kinect"),  # k4abt to kinect_v2
        a_zed._replace(sensor="kinect"),  # a second wrong one: the first is reported
        a_kinect._replace(sensor="femto"),  # kinect_v2 to k4abt
        a_femto._replace(sensor="femto", format="kinect_v3"),  # no such format
        a_femto._replace(sensor="zed", format="kinect_v3"),
    ]
    signers = {n: Signer("c", k) for n, k in keys.items()}
    with Listener(("127.0.0.1", 0), calibration, max_age_s=5.0) as listener:
        assert listener.format_mismatches() == {}
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            for frame in wrong:
                data = signers[frame.sensor].encode(frame._replace(t=time.time()))
                sock.sendto(data, listener.address)
        wait_for(listener, len(wrong))
        counts = dict(listener.counters)
        mismatches = listener.format_mismatches()
    assert counts["dropped_wrong_format"] == counts["received"] == 5, counts
    assert mismatches == {
        "kinect": ("k4abt", "kinect_v2"),
        "femto": ("kinect_v2", "k4abt"),
        "zed": ("kinect_v3", "zed_body_34"),
    }


# --- refusals ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sendir(tmp_path_factory):
    d = tmp_path_factory.mktemp("send")
    for fmt in ("kinect_v2", "k4abt"):
        worked(d, fmt)
    (d / "open.toml").write_text(  # no keys
        '[sensors.cam]\nformat = "k4abt"\n'
        "base_from_camera = [[1,0,0,0],[0,-0.6,0.8,-0.6],[0,-0.8,-0.6,1.5],[0,0,0,1]]\n"
    )
    calibration = load_calibration(d / "k4abt.toml")
    frames = list(sensor_frames(AtRest(Operator()), calibration, "femto", 0.1))
    others = [f._replace(sensor="other") for f in frames]
    save_sensor_npz(d / "others.npz", SensorRecording.from_frames(others))
    kinect = [
        f._replace(sensor="femto")
        for f in sensor_frames(
            AtRest(Operator()), load_calibration(d / "kinect_v2.toml"), "kinect", 0.1
        )
    ]
    save_sensor_npz(d / "kinect.npz", SensorRecording.from_frames(kinect))
    rest = Operator().rest()
    save_npz(d / "rest.npz", Recording([0.0, 0.1], np.stack([rest, rest]), np.full((2, 25), 2)))
    return d


TO = ["--to", "127.0.0.1:9"]
#: Refused, one line each, exit 2, before anything is sent: args and a word of the line.
SEND_REFUSALS = [
    (["send", "zz", *TO, "--sensors", "k4abt.toml"], "no sensor 'zz' (sensors: femto)"),
    (["send", "femto", *TO, "--sensors", "k4abt.toml", "--camera", "kinect_v2"], "k4abt"),
    (["send", "kinect", *TO, "--sensors", "kinect_v2.toml", "--camera", "k4abt"], "kinect_v2"),
    (["send", "femto", *TO, "--sensors", "k4abt.toml", "--camera", "femto"], "--camera"),
    (["send", "femto", "--to", "127.0.0.1", "--sensors", "k4abt.toml"], "HOST:PORT"),
    (["send", "femto", "--to", "nohost.invalid:5005", "--sensors", "k4abt.toml"], "resolve"),
    (["send", "femto", *TO, "--sensors", "k4abt.toml", "--unsigned"], "have keys"),
    (["send", "cam", *TO, "--sensors", "open.toml"], "no key"),
    (["send", "cam", "--to", "192.0.2.1:5005", "--sensors", "open.toml", "--unsigned"], "loopback"),
    (["send", "femto", *TO, "--sensors", "k4abt.toml", "--latency", "2"], "--latency"),
    (["send", "femto", *TO, "--sensors", "k4abt.toml", "--seconds", "0"], "--seconds"),
    (["send", "femto", *TO, "--sensors", "k4abt.toml", "--scenario", "nosuch"], "nosuch"),
    (["send", "femto", *TO, "--sensors", "k4abt.toml", "--robot", "nosuch"], "nosuch"),
    (
        ["send", "femto", *TO, "--sensors", "k4abt.toml", "--scenario", "test1", "--human", "x"],
        "not allowed with",
    ),
    (["send", "femto", *TO, "--sensors", "k4abt.toml", "--human", "others.npz"], "no frame"),
    (["send", "femto", *TO, "--sensors", "k4abt.toml", "--human", "kinect.npz"], "calibrated"),
    (["send", "femto", *TO, "--sensors", "nosuch.toml"], "nosuch.toml"),
    (["send", "femto", *TO], "--sensors"),
]


@pytest.mark.parametrize("args, word", SEND_REFUSALS, ids=[" ".join(a) for a, _ in SEND_REFUSALS])
def test_a_bad_send_is_one_line_and_exit_2(sendir, args, word, monkeypatch, capsys):
    """Checked as every command's refusals are (tests/test_cli_errors.py): exit 2, one line
    naming the problem, no traceback, nothing written."""
    refused_as_every_command(sendir, args, word, monkeypatch, capsys)


@pytest.mark.slow  # a live run in real time, about 15 s
def test_send_and_a_live_run_on_loopback_move_the_panda(tmp_path):
    """The check docs/sensors.md §11 gives a newcomer: the worked Femto calibration,
    ``qpavoid run --listen`` on the Panda and ``qpavoid send`` on loopback: the frames
    are taken and the robot moves along its path."""
    calib = worked(tmp_path, "k4abt")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "live"
    run = [*PYTHON, "-m", "qpavoid", "run", "--listen", f"127.0.0.1:{port}", "--sensors", calib]
    run += ["--robot", "panda", "--controller", "qp", "--max-time", "10", "--rate", "100"]
    run += ["--no-plots", "-q", "--out", str(out)]
    listener = subprocess.Popen(run, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(4.0)  # the run loads and listens
    send_cmd = [*PYTHON, "-m", "qpavoid", "send", "femto", "--to", f"127.0.0.1:{port}"]
    send_cmd += ["--sensors", calib, "--robot", "panda", "--seconds", "8"]
    sender = subprocess.run(send_cmd, capture_output=True, text=True, timeout=60)
    _, stderr = listener.communicate(timeout=60)
    assert sender.returncode == 0 and listener.returncode == 0, sender.stderr + stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["input"]["accepted"] >= 150, metrics["input"]
    assert not [k for k in metrics["input"] if k.startswith("dropped")], metrics["input"]
    assert metrics["final_position_error_m"] < 0.30  # it started 0.374 m from its goal
