"""The ROS 2 cell end to end (issue 47; slow suite): three processes on a loopback DDS
domain of their own. A body-tracking driver's stand-in films a scenario's person at 30 Hz
through a worked calibration (docs/calibrations/, with its topic): the Azure Kinect
driver's MarkerArrays through k4abt.toml (test1's person), the ZED ROS 2 wrapper's
ObjectsStamped through zed_body_34.toml and zed_body_38.toml (a random approach's); the
kinematic ros2_control stand-in integrates the commands at 1 kHz and publishes the arm's
JointState (tests/ros2_cell_standin.py); the run is qpavoid's own (in-process where the
truth is measured, else ``qpavoid run`` as a user types it)."""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import PYTHON

pytest.importorskip("cyclonedds")

from ros2_cell_standin import OnRunClock
from ros2_standin import marker_array

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import load_robot
from qpavoid.control.journal import Journal, reproduce
from qpavoid.drive.limits import CommandCheck, CommandLimits
from qpavoid.experiments import runs
from qpavoid.experiments.reproduce import reproduce_bag
from qpavoid.experiments.runs import RunSpec, build_controller, simulate_one
from qpavoid.output.bag_writer import write_bag
from qpavoid.scenarios.motions import load_motion
from qpavoid.sensing.ros2_cell import participant, write_raw, writer
from qpavoid.sensing.ros2_types import to_cdr

pytestmark = pytest.mark.slow

HERE = Path(__file__).parent
STANDIN = str(HERE / "ros2_cell_standin.py")
DOCS = HERE.parent / "docs" / "calibrations"
TOPIC = "/k4a/body_tracking_data"
#: The ZED ROS 2 wrapper's body topic for a camera named zed (docs/ros2.md §2).
ZED_TOPIC = "/zed/zed_node/body_trk/skeletons"
MA = "visualization_msgs/msg/MarkerArray"
LOOPBACK = '<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General>'
os.environ.setdefault("CYCLONEDDS_URI", LOOPBACK)
ROBOT = "iiwa14"
#: The stand-in camera's person waits this long in its first pose (the run's start-up).
LEAD_S = 2.0
_DOMAIN = [150 + os.getpid() % 40]


def _domain() -> int:
    _DOMAIN[0] += 1
    return _DOMAIN[0] % 230


def _cell(tmp_path: Path, calibration: str = "k4abt", topic: str = TOPIC) -> tuple[str, str]:
    """A cell file on a domain of its own and the worked calibration
    docs/calibrations/``calibration``.toml, its key file replaced by the ``topic``."""
    robot = load_robot(ROBOT)
    cell = tmp_path / "cell.toml"
    cell.write_text(
        f'distribution = "humble"\ndomain_id = {_domain()}\n[arm]\n'
        f"joints = {list(robot.joint_names)!r}\n".replace("'", '"')
        + "subscriber_timeout_s = 10.0\n"
    )
    text, n = re.subn(
        r'^key_file = "[^"]*"$',
        f'topic = "{topic}"',
        (DOCS / f"{calibration}.toml").read_text(),
        flags=re.MULTILINE,
    )
    assert n == 1, calibration
    (tmp_path / "cal.toml").write_text(text)
    return str(cell), str(tmp_path / "cal.toml")


def _q0() -> np.ndarray:
    spec = RunSpec(scenario="test1", robot=ROBOT)
    robot = load_robot(ROBOT)
    return inverse_kinematics(robot, build_controller(spec, robot).path.reference(0.0)[0])


def _standins(
    tmp_path: Path,
    cell: str,
    cal: str,
    seconds: float,
    start_in_s: float = 4.0,
    scenario: str = "test1",
):
    """The arm's and the camera's stand-ins started, the camera filming ``scenario``'s
    person; the camera's frame 0 at wall time ``start``: (arm, camera, start)."""
    env = {**os.environ, "CYCLONEDDS_URI": LOOPBACK}
    q0 = ",".join(repr(float(v)) for v in _q0())
    command = [*PYTHON, STANDIN, "arm", "--cell", cell, "--q0", q0, "--rate", "1000"]
    command += ["--seconds", str(seconds + 20), "--record", str(tmp_path / "arm.npz")]
    arm = subprocess.Popen(
        command,
        env=env,
        stdout=subprocess.PIPE,
        text=True,
    )
    start = time.time() + start_in_s
    command = [*PYTHON, STANDIN, "camera", "--cell", cell, "--sensors", cal, "--robot", ROBOT]
    command += ["--start", repr(start), "--lead", str(LEAD_S), "--seconds", str(seconds)]
    command += ["--scenario", scenario]
    camera = subprocess.Popen(
        command,
        env=env,
        stdout=subprocess.PIPE,
        text=True,
    )
    return arm, camera, start


def _ended(*procs: subprocess.Popen) -> list[str]:
    out = []
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
        out.append(p.communicate(timeout=20)[0])
    return out


def _in_process_run(
    tmp_path: Path,
    during=None,
    calibration: str = "k4abt",
    topic: str = TOPIC,
    scenario: str = "test1",
    seconds: float = 28.0,
):
    """``scenario``'s person filmed by the camera stand-in through the worked
    ``calibration`` (on ``topic``) for ``seconds``, the arm stand-in driven, the run
    capped 2 s before the camera ends, the truth the stand-in's motion at each tick's wall
    time: (run, the arm stand-in's record, the lines said, the stand-ins' output)."""
    cell, cal = _cell(tmp_path, calibration, topic)
    robot = load_robot(ROBOT)
    arm, camera, start = _standins(tmp_path, cell, cal, seconds, scenario=scenario)
    sources: list = []

    class Recorded(runs.LiveSource):  # the run's live source, for its start time
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            sources.append(self)

    truth = OnRunClock(load_motion(robot, scenario), start, LEAD_S, lambda: sources[0].start_s)
    spec = RunSpec(
        listen=f"ros2:{cell}",
        sensors=cal,
        arm=f"ros2:{cell}",
        trust_ros_graph=True,
        robot=ROBOT,
        max_time_s=seconds - 2.0,
    )
    lines: list[str] = []
    helper: list[threading.Thread] = []

    def say(line: str) -> None:
        lines.append(line)
        if during is not None and line.startswith("listening on") and not helper:
            helper.append(threading.Thread(target=during, args=(cell,), daemon=True))
            helper[0].start()

    original = runs.LiveSource
    runs.LiveSource = Recorded  # type: ignore[misc]
    try:
        run = simulate_one(spec, motion=truth, say=say)
    finally:
        runs.LiveSource = original  # type: ignore[misc]
        outs = _ended(arm, camera)
    for t in helper:
        t.join(timeout=10)
    return run, np.load(tmp_path / "arm.npz"), lines, outs


def _stream_checked(commands: np.ndarray, period_s: float) -> CommandCheck:
    check = CommandCheck(CommandLimits.of(load_robot(ROBOT), period_s))
    check.stream(commands)
    return check


def _assert_commands_within_limits(arm, run) -> None:
    """Every command the arm stand-in received, from rest, within the arm's velocity,
    acceleration and jerk limits at the run's rate: with no excuse, also where the loop
    stood still longer than the watchdog's timeout (its stop is a ramp within the limits,
    and the loop starts again from rest after it: ros2_control holds the last command)."""
    check = _stream_checked(arm["commands"], 1.0 / run.spec.rate_hz)
    said = (run.metrics["loop"], run.metrics.get("watchdog_fired"))
    assert check.counts == {"velocity": 0, "acceleration": 0, "jerk": 0}, (check.worst, said)


def test_test1_reaches_its_goal_through_the_ros2_stand_ins_with_no_true_contact(tmp_path):
    run, arm, lines, outs = _in_process_run(tmp_path)
    m = run.metrics
    assert m["reached_goal"], (m["end_reason"], lines[-5:], outs)
    assert m["ticks_moving_in_true_contact"] == 0
    assert m["min_true_clearance_moving_m"] > 0.0
    assert np.isfinite(run.sim.log["true_distance"]).all()  # the truth measured every tick
    assert m["trust_ros_graph"] is True
    inputs = m["input"]
    assert inputs["accepted"] > 25 * 12 and not [k for k in inputs if k.startswith("dropped")]
    # every command the loop sent reached the ros2_control stand-in, in the controller's
    # order, within the arm's limits, ending at rest
    commands = arm["commands"]
    assert len(commands) >= m["ticks"] and list(arm["joints"]) == list(run.robot.joint_names)
    assert not commands[-1].any()
    assert np.abs(commands).max() > 0.05  # it moved
    _assert_commands_within_limits(arm, run)
    # the stand-in's 1 kHz: its JointStates came at 1 ms on average
    assert np.mean(np.diff(arm["state_t"])) == pytest.approx(1e-3, rel=0.1)
    # the same frames fed offline (what the controller was handed, tick by tick) give the
    # same commands; and so does the bag of the run, through qpavoid run --human RUN.mcap
    entries = Journal.split(run.sim.journal["journal_data"], run.sim.journal["journal_offsets"])
    again = reproduce(build_controller(run.spec, run.robot), entries)
    np.testing.assert_allclose(again, run.sim.log["dq_command"], rtol=0, atol=1e-9)
    bag = tmp_path / "live.mcap"
    log = run.sim.log | run.sim.journal
    write_bag(bag, log, run.robot.joint_names, run_spec=json.dumps(m["run_spec"]))
    assert reproduce_bag(bag).largest_difference_radps <= 1e-9


#: A random approach (generated.py's random_approach) the ZED test films: the left hand
#: reaches slowly (4.8 s) from 9.3 s on to 0.1 m of a point of the arm's nominal path,
#: holds 4 s and withdraws. Offline (qpavoid run random:13 --camera zed_body_34, and
#: zed_body_38) the iiwa stops for 6.3-6.4 s and reaches its goal with 0 ticks moving in
#: true contact (0.039 m, 0.046 m clearance while moving).
ZED_SCENARIO = "random:13"


@pytest.mark.parametrize("fmt", ["zed_body_34", "zed_body_38"])
def test_a_zed_filming_a_random_approach_drives_the_ros2_arm_with_no_true_contact(tmp_path, fmt):
    """The ZED ROS 2 wrapper's stand-in (ObjectsStamped on body_trk/skeletons, the worked
    ZED calibration's camera, keypoints in ROS axes) films a random approach; the run
    takes its frames, stops for the person and never moves into them."""
    run, arm, lines, outs = _in_process_run(
        tmp_path, calibration=fmt, topic=ZED_TOPIC, scenario=ZED_SCENARIO, seconds=40.0
    )
    m = run.metrics
    # the ZED's frames reached the controller: taken, none dropped, the ages finite from
    # the first one taken on
    inputs, zed = m["input"], m["sensors"]["zed"]
    assert zed["format"] == fmt and zed["first_frame_taken_s"] is not None, (zed, lines)
    assert inputs["accepted"] > 25 * 12 and not [k for k in inputs if k.startswith("dropped")]
    assert not inputs.get("incompatible_publishers"), inputs
    log = run.sim.log
    taken = log["t"] >= zed["first_frame_taken_s"]
    assert taken.mean() > 0.5 and np.isfinite(log["frame_age_s"][taken]).all()
    # the person came near the arm and the controller saw it: it stopped for them
    assert np.isfinite(log["true_distance"]).all()  # the truth measured every tick
    assert log["true_distance"].min() < 0.1, log["true_distance"].min()
    assert m["stopped_s"] > 0.0 and log["distance"].min() < 0.1
    # where it saw them: each set's distance to the person as seen within a few cm of the
    # true one (the ZED's ROS axes turned back into its frame; the seen one is nearer by
    # the body's uncertainty, and lags by the latency while the hand moves)
    both = np.isfinite(log["distance"]) & np.isfinite(log["true_distance"])
    error = (log["distance"] - log["true_distance"])[both]
    assert both.any() and np.median(np.abs(error)) < 0.05, np.percentile(error, [5, 50, 95])
    assert m["reached_goal"] or m["held_by_person"], (m["end_reason"], lines[-5:], outs)
    assert m["ticks_moving_in_true_contact"] == 0
    assert m["min_true_clearance_moving_m"] > 0.0
    # every command reached the ros2_control stand-in within the arm's limits
    commands = arm["commands"]
    assert len(commands) >= m["ticks"] and list(arm["joints"]) == list(run.robot.joint_names)
    assert np.abs(commands).max() > 0.05  # it moved
    _assert_commands_within_limits(arm, run)


def _burst(cell: str) -> None:
    """While the run goes on: a JointState publisher on the camera's topic, then a
    malformed MarkerArray, one with a NaN joint and one of 10 016 markers, each stamped
    now (the driver's frame minus its latency)."""
    from qpavoid.sensing.ros2_cell import load_cell

    domain = load_cell(cell).domain_id
    dp = participant(domain)
    writer(dp, "humble", TOPIC, "sensor_msgs/msg/JointState")
    w = writer(dp, "humble", TOPIC, MA)
    time.sleep(6.0)  # the run is under way
    joints = np.column_stack([np.zeros(32), np.zeros(32), np.full(32, 2.0)])
    for _ in range(3):
        t = time.time() - 0.1
        cdr = to_cdr("humble", marker_array(t, {1: joints}), MA)
        write_raw(w, cdr.replace(b"depth_camera_link", b"\xffepth_camera_link"))  # no UTF-8
        nan = marker_array(t + 1e-3, {1: joints})
        nan.markers[5].pose.position.z = math.nan
        write_raw(w, to_cdr("humble", nan, MA))
        many = marker_array(t + 2e-3, {1: joints})
        many.markers = many.markers * 313  # 10 016 markers
        write_raw(w, to_cdr("humble", many, MA))
        time.sleep(0.5)
    time.sleep(1.0)


def test_bad_messages_on_the_camera_topic_are_dropped_and_the_run_reaches_its_goal(tmp_path):
    run, _, lines, outs = _in_process_run(tmp_path, during=_burst)
    m = run.metrics
    inputs = m["input"]
    assert inputs.get("incompatible_publishers", 0) >= 1, inputs
    assert [line for line in lines if "matches no type" in line], lines
    for reason in ("dropped_unreadable", "dropped_non_finite", "dropped_too_many_markers"):
        assert inputs.get(reason, 0) >= 1, (reason, inputs)  # best effort: one may be lost
    assert m["reached_goal"], (m["end_reason"], lines[-5:], outs)
    assert m["ticks_moving_in_true_contact"] == 0


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_mid_motion_ramps_the_stand_ins_commands_to_rest(tmp_path, signum):
    cell, cal = _cell(tmp_path)
    arm, camera, _ = _standins(tmp_path, cell, cal, 20.0, start_in_s=2.0)
    command = [*PYTHON, "-m", "qpavoid", "run", "--listen", f"ros2:{cell}"]
    command += ["--arm", f"ros2:{cell}", "--sensors", cal, "--trust-ros-graph"]
    command += ["--robot", ROBOT, "--max-time", "20", "--out", str(tmp_path / "run")]
    command += ["--no-plots", "--no-view", "-q"]
    run = subprocess.Popen(
        command,
        env={**os.environ, "CYCLONEDDS_URI": LOOPBACK},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert run.stdout is not None
        for line in run.stdout:  # its status line at 5 s: test1's arm is under way
            if line.strip().startswith("5.0 s:"):
                break
        time.sleep(0.5)
        run.send_signal(signum)
        out = line + run.communicate(timeout=20)[0]
    finally:
        if run.poll() is None:
            run.kill()
        _ended(arm, camera)
    assert run.returncode == 0, out
    assert "interrupted" in out, out
    commands = np.load(tmp_path / "arm.npz")["commands"]
    moving = np.flatnonzero(np.abs(commands).max(axis=1) > 1e-9)
    assert len(moving) > 100 and not commands[-1].any(), out
    # the last commands: from its speed at the signal down to zero, within the limits
    check = _stream_checked(commands, 1.0 / 500.0)
    assert check.counts["velocity"] == 0 and check.counts["acceleration"] == 0, check.worst
    size = np.abs(commands).max(axis=1)
    first = moving[-1]
    while first > 0 and size[first - 1] >= size[first]:  # back to where the ramp began
        first -= 1
    ramp = size[first : moving[-1] + 2]
    assert ramp[0] > 0.02 and ramp[-1] == 0.0 and len(ramp) >= 3, ramp  # moving, then rest


def test_a_bad_cell_file_through_the_command_line_is_one_line_and_exit_2(tmp_path):
    _, cal = _cell(tmp_path)
    bad = tmp_path / "bad.toml"
    bad.write_text('distribution = "foxy"\n')
    command = [*PYTHON, "-m", "qpavoid", "run", "--listen", f"ros2:{bad}", "--sensors", cal]
    command += ["--arm", f"ros2:{bad}", "--trust-ros-graph", "--robot", ROBOT, "--no-view"]
    got = subprocess.run(
        command,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert got.returncode == 2
    assert got.stdout == "" and len(got.stderr.strip().splitlines()) == 1, got.stderr
    assert "distribution must be one of humble, jazzy" in got.stderr
