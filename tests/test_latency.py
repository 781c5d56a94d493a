"""A camera's latency measured from a recording of the robot's own flange (issue 41):
the estimator on simulated measurements of known latency, its refusals, its files, the
excitation that makes them.

**The tolerance.** The simulated recorder stamps each frame with its exact delivery time
(capture + latency), so the frame period (33 ms) adds no error of its own: the fit
interpolates the arm's 500 Hz log at the camera's stamps, never rounds the lag to a frame
(which would be off by up to half a period, 17 ms). What is left is the camera's noise.
Least squares on ``h_k = p(t_k − τ) + b + e_k`` with independent noise of σ_k per axis
has the standard error

    σ_τ = sqrt(Σ_k σ_k² |v_k|²) / Σ_k |v_k|²

(``v_k`` the flange's velocity at frame k: a lag δ moves the flange by v_k δ): about
0.5 ms for a Kinect v2 (2 mm) over the 30 s excitation's 900 frames at a flange speed of
0.1 m/s RMS, 1-3 ms for the other cameras. σ_k is the format's ``noise_m`` through its
landmark rule (a mean of three joints divides it by √3) and, for a stereo camera, times
the square of the hand's range over the reference range. The estimate must be within
5 σ_τ of the truth (a chance of 6e-7 for Gaussian noise), and the reported uncertainty
(the jackknife's) within a factor of 2 of σ_τ.
"""

from __future__ import annotations

import math
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import PYTHON

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import load_robot
from qpavoid.cli.commands import main
from qpavoid.control.task import default_task
from qpavoid.core.errors import InputError, RecordingError
from qpavoid.drive.simulated import SimulatedArm
from qpavoid.human.landmarks import landmark_map, skeleton_format
from qpavoid.loop.camera import CameraConfig
from qpavoid.loop.excitation import Excitation, drive_excitation, film_excitation
from qpavoid.sensing.arm_log import ArmLog, flange_positions, read_arm_log, save_arm_log
from qpavoid.sensing.calibration import Calibration, SensorCalibration
from qpavoid.sensing.hand_track import camera_track, landmark_index
from qpavoid.sensing.latency import measure_latency
from qpavoid.sensing.latency_fit import LatencyConfig, estimate_latency
from qpavoid.sensing.per_sensor import SensorRecording, save_sensor_npz
from qpavoid.sensing.recording import save_csv, save_npz

#: A short excitation for the refusals (their numbers do not matter, only that they refuse).
SHORT = Excitation(duration_s=12.0)


def measured(robot, camera, **film):
    """(camera times, landmark, arm times, flange) of a simulated measurement."""
    recording, log = film_excitation(robot, camera, **film)
    t, hand = camera_track(recording)
    return t, hand, log.t, flange_positions(robot, log.q)


def standard_error(robot, camera, t, hand, arm_t, flange, lag):
    """σ_τ of the module docstring for these frames (the tracked ones the fit can use)."""
    seen = np.isfinite(hand).all(axis=1) & (t - 0.5 >= arm_t[0]) & (t + 0.1 <= arm_t[-1])
    velocity = np.stack(
        [np.interp(t[seen] - lag, arm_t, np.gradient(flange[:, a], arm_t)) for a in range(3)],
        axis=1,
    )
    fmt = skeleton_format(camera.format)
    rule = np.linalg.norm(landmark_map(fmt).weights[landmark_index("right_hand")])
    sigma = np.full(int(seen.sum()), camera.noise_m * rule)
    reference = fmt.sensor.noise_reference_range_m
    if reference > 0:  # a stereo camera: noise grows with the square of the range
        far = np.linalg.norm(hand[seen] - np.asarray(camera.sensor_position_m), axis=1)
        sigma *= (far / reference) ** 2
    speed2 = np.sum(velocity**2, axis=1)
    return math.sqrt(np.sum(sigma**2 * speed2)) / np.sum(speed2)


@pytest.fixture(scope="module")
def kinect(robot):
    """A Kinect v2 at 80 ms over the default 30 s excitation."""
    return measured(robot, CameraConfig.of("kinect_v2", latency_s=0.08, seed=3))


# --------------------------------------------------------------------------- accuracy


@pytest.mark.parametrize(
    "fmt, latency, seed",
    [
        # one with the default suite, every format with the slow one (its time budget)
        pytest.param("kinect_v2", 0.03, 1, marks=pytest.mark.slow),
        pytest.param("kinect_v2", 0.15, 2, marks=pytest.mark.slow),
        ("k4abt", 0.10, 3),
        pytest.param("zed_body_34", 0.12, 4, marks=pytest.mark.slow),
        pytest.param("zed_body_38", 0.045, 5, marks=pytest.mark.slow),
        pytest.param("mediapipe_pose", 0.07, 6, marks=pytest.mark.slow),
    ],
)
def test_the_estimate_is_within_its_noise_of_the_true_latency(robot, fmt, latency, seed):
    camera = CameraConfig.of(fmt, latency_s=latency, seed=seed)
    t, hand, arm_t, flange = measured(robot, camera)
    estimate = estimate_latency(t, hand, arm_t, flange)
    sigma = standard_error(robot, camera, t, hand, arm_t, flange, latency)
    assert sigma < 0.004  # a tight tolerance: 5 σ_τ is under a frame period's 33 ms
    assert abs(estimate.latency_s - latency) < 5 * sigma, (estimate, sigma)
    assert 0.5 * sigma < estimate.uncertainty_s < 2 * sigma, (estimate, sigma)
    # MediaPipe swaps a person's sides for 0.5 s now and then: 15 frames left out
    assert estimate.outliers <= 0.02 * estimate.frames and estimate.frames > 850
    assert estimate.explained > 0.9 and estimate.residual_m < 0.03
    assert estimate.suggested_latency_s >= estimate.latency_s + 2 * estimate.uncertainty_s


@pytest.mark.slow  # (the default suite's time budget)
def test_a_varying_delay_gives_its_mean(robot):
    """Frames delayed by latency + U(0, jitter): the estimate is latency + jitter / 2."""
    camera = CameraConfig.of("kinect_v2", latency_s=0.06, jitter_s=0.03, seed=8)
    t, hand, arm_t, flange = measured(robot, camera)
    estimate = estimate_latency(t, hand, arm_t, flange)
    # the jitter's own spread (0.03 / √12 per frame) adds to the noise's: 2 ms is 5 σ
    assert abs(estimate.latency_s - 0.075) < 0.002, estimate


@pytest.mark.parametrize(
    "shift",
    [
        0.0137,
        pytest.param(-0.041, marks=pytest.mark.slow),
        pytest.param(0.25, marks=pytest.mark.slow),
    ],
)
def test_shifting_the_arm_log_shifts_the_estimate_by_exactly_that(kinect, shift):
    """Arm samples stamped ``shift`` later: the camera lags them by ``shift`` less (and
    stamps of the camera ``shift`` later: it lags by ``shift`` more). Only frames inside the
    arm log at every lag, shifted or not, are given, so both fit the same frames."""
    t, hand, arm_t, flange = kinect
    cfg = LatencyConfig(min_lag_s=-0.4, max_lag_s=0.6)
    inner = (t - 0.6 - 0.3 >= arm_t[0]) & (t + 0.4 + 0.3 <= arm_t[-1])
    t, hand = t[inner], hand[inner]
    before = estimate_latency(t, hand, arm_t, flange, cfg).latency_s
    assert estimate_latency(t, hand, arm_t + shift, flange, cfg).latency_s == pytest.approx(
        before - shift, abs=1e-6
    )
    assert estimate_latency(t + shift, hand, arm_t, flange, cfg).latency_s == pytest.approx(
        before + shift, abs=1e-6
    )


def test_outliers_are_left_out(kinect):
    """A tracker's glitches (a hand 0.3 m off in 5 % of the frames) are left out and do not
    move the estimate; in 30 % of them the recording is refused."""
    t, hand, arm_t, flange = kinect
    clean = estimate_latency(t, hand, arm_t, flange)
    rng = np.random.default_rng(0)
    glitched = hand.copy()
    some = rng.choice(len(t), size=len(t) // 20, replace=False)
    glitched[some] += rng.normal(0.0, 1.0, (len(some), 3)) * 0.3 / math.sqrt(3)
    estimate = estimate_latency(t, glitched, arm_t, flange)
    assert estimate.outliers >= 0.9 * len(some)
    assert abs(estimate.latency_s - clean.latency_s) < clean.uncertainty_s
    many = rng.choice(len(t), size=len(t) * 3 // 10, replace=False)
    glitched[many] = hand[many] + [0.3, 0.0, 0.0]
    with pytest.raises(InputError, match="off the flange") as err:
        estimate_latency(t, glitched, arm_t, flange)
    assert err.value.name == "outliers" and err.value.value > 0.2 * len(t)


# --------------------------------------------------------------------------- refusals


def test_a_hand_off_the_flange_is_refused(robot):
    t, hand, arm_t, flange = measured(
        robot, CameraConfig.of("k4abt", latency_s=0.1, seed=1), excitation=SHORT, on_flange=False
    )
    with pytest.raises(InputError, match="did not follow the flange") as err:
        estimate_latency(t, hand, arm_t, flange)
    assert err.value.name == "residual_m" and err.value.value > 0.04


def test_the_other_hand_on_the_flange_is_refused(robot):
    """The left hand held it; the right hand (the default landmark) rested on the table."""
    t, hand, arm_t, flange = measured(
        robot, CameraConfig.of("kinect_v2", seed=1), excitation=SHORT, side="left"
    )
    with pytest.raises(InputError, match="right hand did not follow") as err:
        estimate_latency(t, hand, arm_t, flange)
    assert err.value.name == "residual_m"


def test_an_arm_at_rest_is_refused(robot):
    still = Excitation(amplitudes_rad=((0.0, 0.0), (0.0, 0.0)), duration_s=12.0)
    t, hand, arm_t, flange = measured(robot, CameraConfig.of("kinect_v2"), excitation=still)
    with pytest.raises(InputError, match=r"flange moved 0\.0 mm") as err:
        estimate_latency(t, hand, arm_t, flange)
    assert err.value.name == "motion_m" and err.value.value < 1e-6


def test_two_clocks_are_refused(kinect):
    """An arm log on a clock 100 s away (a run's log.npz starts at 0): no frame overlaps."""
    t, hand, arm_t, flange = kinect
    with pytest.raises(InputError, match="on one clock") as err:
        estimate_latency(t, hand, arm_t + 100.0, flange)
    assert err.value.name == "frames" and err.value.value == 0


def test_a_lag_beyond_the_range_searched_is_refused(kinect):
    t, hand, arm_t, flange = kinect
    with pytest.raises(InputError, match="at an end of the lags searched") as err:
        estimate_latency(t, hand, arm_t, flange, LatencyConfig(max_lag_s=0.05))
    assert err.value.name == "latency_s" and err.value.value == pytest.approx(0.05, abs=0.003)


@pytest.mark.parametrize(
    "field, value",
    [
        ("landmark", "nose"),
        ("max_lag_s", float("nan")),
        ("max_lag_s", 5.0),
        ("max_lag_s", -0.095),
        ("grid_step_s", 0.0),
        ("min_frames", 0),
        ("blocks", 1),
        ("min_explained", 1.5),
    ],
)
def test_a_bad_setting_is_refused_naming_it(field, value):
    with pytest.raises(InputError) as err:
        LatencyConfig(**{field: value})
    assert err.value.name == field and (err.value.value == value or value != value)


def test_bad_arrays_are_refused(kinect):
    t, hand, arm_t, flange = kinect
    with pytest.raises(InputError, match=r"camera_t.*increase strictly") as err:
        estimate_latency(t[::-1], hand, arm_t, flange)
    assert err.value.name == "camera_t"
    with pytest.raises(InputError, match="flange_m") as err:
        estimate_latency(t, hand, arm_t, flange[:, :2])
    assert err.value.name == "flange_m"
    with pytest.raises(InputError, match="camera_m") as err:
        estimate_latency(t, hand[:-1], arm_t, flange)


# --------------------------------------------------------------------------- files


@pytest.fixture(scope="module")
def files(robot, tmp_path_factory):
    """A Kinect v2 measurement at 80 ms written as a user's files, on a wall clock."""
    d = tmp_path_factory.mktemp("latency")
    recording, log = film_excitation(
        robot, CameraConfig.of("kinect_v2", latency_s=0.08, seed=3), clock_s=1.75e9
    )
    save_npz(d / "camera.npz", recording)
    save_csv(d / "camera.csv", recording)
    save_arm_log(d / "arm.npz", log, robot)
    header = ",".join(["t", *robot.joint_names])
    table = np.column_stack([log.t, log.q])
    np.savetxt(d / "arm.csv", table, delimiter=",", header=header, comments="", fmt="%.17g")
    return d, recording, log


def test_the_files_give_the_arrays_estimate(robot, files, kinect):
    """NPZ and CSV, on a wall clock (1.75e9 s): the estimate of the same arrays at 0 s."""
    d, _, _ = files
    arrays = estimate_latency(*kinect)
    for camera, arm in (("camera.npz", "arm.npz"), ("camera.csv", "arm.csv")):
        estimate = measure_latency(d / camera, d / arm, robot)
        assert estimate.latency_s == pytest.approx(arrays.latency_s, abs=1e-5)
        assert estimate.frames == arrays.frames


def test_a_per_sensor_recording_is_put_in_the_base_frame_and_on_the_arms_clock(
    robot, files, tmp_path
):
    """The same frames as a camera saw them (its own frame, its own clock 12.5 s behind),
    beside a second person walking by: the calibration puts them back, the hand on the
    flange is told from the passer-by, the estimate is the base-frame recording's."""
    d, recording, _ = files
    angle = np.radians(35.0)
    base_from_camera = np.eye(4)
    base_from_camera[:3, :3] = [
        [np.cos(angle), 0.0, np.sin(angle)],
        [0.0, 1.0, 0.0],
        [-np.sin(angle), 0.0, np.cos(angle)],
    ]
    base_from_camera[:3, 3] = [0.2, -1.5, 0.8]
    cal = SensorCalibration("cam", base_from_camera, time_offset_s=12.5)
    camera_from_base = np.linalg.inv(base_from_camera)
    own = recording.joints @ camera_from_base[:3, :3].T + camera_from_base[:3, 3]
    other = own + np.array([1.2, 0.0, 0.4])  # someone 1.3 m away, in the same frames
    n = recording.n_frames
    rec = SensorRecording(
        sensor="cam",
        t=np.concatenate([recording.t, recording.t]) - 12.5,
        body=np.repeat([0, 1], n),
        joints=np.concatenate([own, other]),
        state=np.concatenate([recording.state, recording.state]),
    )
    save_sensor_npz(tmp_path / "cam.npz", rec)
    calibration = Calibration({"cam": cal})
    estimate = measure_latency(tmp_path / "cam.npz", d / "arm.npz", robot, calibration)
    base = measure_latency(d / "camera.npz", d / "arm.npz", robot)
    assert estimate.latency_s == pytest.approx(base.latency_s, abs=1e-6)
    assert estimate.frames == base.frames
    with pytest.raises(InputError, match="needs the sensors' calibration") as err:
        measure_latency(tmp_path / "cam.npz", d / "arm.npz", robot)
    assert err.value.name == "--sensors"
    with pytest.raises(InputError, match="no frame of sensor 'nosuch'") as err:
        measure_latency(tmp_path / "cam.npz", d / "arm.npz", robot, calibration, "nosuch")
    assert err.value.value == "nosuch"
    with pytest.raises(RecordingError, match="base-frame recording"):
        measure_latency(d / "camera.npz", d / "arm.npz", robot, calibration)


def test_an_arm_log_that_does_not_fit_is_refused_naming_it(robot, files, tmp_path):
    d, _, log = files
    cases = {
        "text.npz": ("hello\n", "not a readable NPZ archive", None),
        "no_q.npz": ({"t": log.t}, "no array 'q'", "q"),
        "wide.npz": ({"t": log.t, "q": np.zeros((log.t.size, 7))}, r"expected \(M, 6\)", "q"),
        "back.npz": ({"t": log.t[::-1], "q": log.q}, "increase strictly", "t"),
        "nan.npz": ({"t": log.t, "q": np.full_like(log.q, np.nan)}, "non-finite", "q"),
        "other.npz": (
            {"t": log.t, "q": log.q, "joint_names": np.array([f"j{i}" for i in range(6)])},
            "another arm",
            "joint_names",
        ),
        "header.csv": ("t,q1,q2\n0,0,0\n", "CSV header must be t,A1,A2,A4", "header"),
        "missing.csv": (None, "not found", None),
    }
    for name, (content, message, key) in cases.items():
        path = tmp_path / name
        if isinstance(content, dict):
            np.savez(path, **content)
        elif content is not None:
            path.write_text(content)
        with pytest.raises(RecordingError, match=message) as err:
            read_arm_log(path, robot)
        assert name in str(err.value) and err.value.name == key, name
    assert read_arm_log(d / "arm.csv", robot).q == pytest.approx(log.q, abs=0)


# --------------------------------------------------------------------------- excitation


def test_the_excitation_starts_and_ends_at_rest_within_the_arms_limits(robot):
    exc = Excitation()
    t = np.arange(0.0, exc.duration_s + 1e-9, 0.002)
    q0 = inverse_kinematics(robot, default_task(robot).path.reference(0.0)[0])
    q, dq = exc.trajectory(robot, q0, t)
    assert np.all(dq[0] == 0) and np.all(np.abs(dq[-1]) < 1e-12)
    assert np.abs(dq).max() < 0.5  # rad/s, far below every joint's limit
    flange = flange_positions(robot, q[::10])
    speed = np.linalg.norm(np.diff(flange, axis=0), axis=1) / 0.02
    assert speed.max() < 0.25  # m/s: ISO 10218-1's reduced speed


def test_an_excitation_beyond_a_joint_limit_is_refused(robot):
    big = Excitation(amplitudes_rad=((3.0, 0.0), (0.0, 0.0)))
    with pytest.raises(InputError, match="beyond its limits") as err:
        big.trajectory(robot, np.zeros(robot.nq), np.linspace(0, 30, 301))
    assert err.value.name == "amplitudes_rad"
    with pytest.raises(InputError, match="nosuch"):
        Excitation(joints=("nosuch", "A2")).columns(robot)


@pytest.mark.slow  # 1.5 s of real time, on an arm that integrates on the wall clock
def test_driving_the_excitation_logs_the_arm_on_the_wall_clock(robot):
    """On the simulated arm in real time (1.5 s): every state stamped, the log the
    excitation's path; too fast an excitation is refused before the arm moves."""
    exc = Excitation(duration_s=1.5, ramp_s=0.5)
    q0 = np.array([1.0, 0.6, -1.4, 0.0, -1.0, 0.0])
    arm = SimulatedArm.ideal(robot, q0, 0.005)
    log = drive_excitation(arm, robot, exc, period_s=0.005)
    assert isinstance(log, ArmLog) and log.t.size == 302
    assert log.t[-1] - log.t[0] > 1.4 and np.all(np.diff(log.t) > 0)  # never faster
    planned, _ = exc.trajectory(robot, q0, np.arange(302) * 0.005)
    assert np.abs(log.q - planned).max() < 0.01
    fast = Excitation(frequencies_hz=((20.0, 30.0), (20.0, 30.0)), duration_s=1.0, ramp_s=0.5)
    arm = SimulatedArm.ideal(robot, q0, 0.005)
    with pytest.raises(InputError, match="breaks the arm's limits"):
        drive_excitation(arm, robot, fast, period_s=0.005)
    assert np.array_equal(arm.read().q, q0)


# --------------------------------------------------------------------------- command line


def test_the_command_prints_the_latency_and_what_to_run_with(files, monkeypatch, capsys):
    d, _, _ = files
    monkeypatch.chdir(d)
    before = sorted(p.name for p in d.iterdir())
    status = main(["latency", "--camera-recording", "camera.npz", "--arm-log", "arm.csv"])
    out = capsys.readouterr()
    assert status == 0, out.err
    lines = out.out.strip().splitlines()
    assert len(lines) == 3 and lines[0].startswith("camera latency 8")
    assert "followed the flange within" in lines[1]
    suggested = float(lines[2].split("--latency ")[1].split()[0])
    assert 0.08 < suggested < 0.085
    assert sorted(p.name for p in d.iterdir()) == before  # nothing written


@pytest.mark.slow  # seconds of subprocesses and of an arm in real time: with the slow suite
def test_the_examples_and_the_command_as_a_user_types_them(tmp_path):
    """examples/latency_simulated.py, then `qpavoid latency` on what it wrote; then
    examples/latency_excitation.py on the simulated arm (2 s)."""
    examples = Path(__file__).parents[1] / "examples"
    r = subprocess.run(
        [*PYTHON, str(examples / "latency_simulated.py"), str(tmp_path), "--latency", "0.09"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    cmd = [*PYTHON, "-m", "qpavoid", "latency", "--camera-recording", str(tmp_path / "camera.npz")]
    r = subprocess.run(
        [*cmd, "--arm-log", str(tmp_path / "arm.npz")], capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stderr
    measured = float(r.stdout.split("camera latency ")[1].split(" ms")[0])
    assert abs(measured - 90.0) < 6.0, r.stdout  # the k4abt's 5 mm: 5 σ_τ is about 6 ms
    excite = [*PYTHON, str(examples / "latency_excitation.py"), "sim", "--seconds", "2"]
    r = subprocess.run(
        [*excite, "--out", str(tmp_path / "excited.npz")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    log = read_arm_log(tmp_path / "excited.npz", load_robot("iiwa14"))
    assert log.t.size == 1002 and abs(log.t[0] - time.time()) < 60.0  # on the wall clock
