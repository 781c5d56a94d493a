"""A live run that tells the truth (issue 46): the ready line, the first frame of each
sensor, metrics.json's camera, latency, loop and sensors for a live run, strict JSON, the
stop reason in the operator's words, one meaning for --camera, the goal when within
tolerance.

The live runs here are short (3 s at 100 Hz) and on loopback; a k4abt camera sends the
seated operator, each frame stamped 0.10 s before it is sent (the format's own latency),
which the fixed 0.1 s age limit refused whole.
"""

from __future__ import annotations

import dataclasses
import json
import socket
import threading
import time
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
from conftest import PYTHON  # noqa: F401  (the suite's interpreter, for symmetry)

import qpavoid
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.cli.commands import main
from qpavoid.control.qp import QPController
from qpavoid.control.task import default_task
from qpavoid.control.tick import ControllerConfig
from qpavoid.core.errors import InputError
from qpavoid.experiments.runs import RunSpec, run_one, simulate_one
from qpavoid.human.frames import HumanFrame
from qpavoid.human.landmarks import LandmarkMap, skeleton_format
from qpavoid.human.posture import Operator
from qpavoid.laws.ssm import SSMConfig
from qpavoid.loop.live_input import Listener, LiveSource
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.output.run_files import strict_json
from qpavoid.perception.tracker import PerceptionConfig
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.keys import new_key_file
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.signing import Signer

#: x right, y down, z forward (k4abt's axes), 1.5 m behind the robot looking along +y
FEMTO = [[1, 0, 0, 0.15], [0, 0, 1, -1.5], [0, -1, 0, 0.6], [0, 0, 0, 1]]


def k4abt_cell(folder: Path, latency_s: float | None = None) -> Path:
    """A calibration of one signed k4abt camera (its key beside it)."""
    new_key_file(folder / "femto.key", "femto")
    rows = ",\n  ".join(str(r) for r in FEMTO)
    own = "" if latency_s is None else f"latency_s = {latency_s}\n"
    text = (
        f'cell = "test"\n[sensors.femto]\nformat = "k4abt"\nkey_file = "femto.key"\n{own}'
        f"base_from_camera = [\n  {rows}]\n"
    )
    (folder / "calib.toml").write_text(text)
    return folder / "calib.toml"


def send_seated(
    calib: Path,
    port: int,
    latency_s: float,
    seconds: float,
    robot: str,
    cal: Calibration | None = None,
) -> None:
    """The seated operator of ``robot``'s task, filmed by the k4abt camera: its joints in
    its own frame, each frame stamped ``latency_s`` before it is sent, 30 a second (signed
    with the key of ``cal``, default the calibration file's)."""
    cal = cal or load_calibration(str(calib))
    fmt = skeleton_format("k4abt")
    seated = default_task(qpavoid.load_robot(robot)).operator.rest()
    cam = LandmarkMap.simulated(fmt).map(seated, np.full(len(seated), 2, np.int8))
    T = np.linalg.inv(cal["femto"].base_from_camera)
    joints = cam.joints @ T[:3, :3].T + T[:3, 3]
    signer = Signer(cal.cell, cal.keys["femto"])
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        end = time.time() + seconds
        while time.time() < end:
            frame = BodyFrame("femto", 0, time.time() - latency_s, joints, cam.state, "k4abt")
            sock.sendto(signer.encode(frame), ("127.0.0.1", port))
            time.sleep(1 / 30)


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def strict_load(text: str) -> dict:
    """JSON as a strict parser reads it: NaN and Infinity refused."""

    def refuse(constant: str) -> None:
        raise ValueError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


def test_a_live_k4abt_run_says_when_it_listens_and_reports_what_it_used(tmp_path):
    calib = k4abt_cell(tmp_path)
    port = free_port()
    lines: list[str] = []
    sender = threading.Thread(target=send_seated, args=(calib, port, 0.10, 4.0, "iiwa14"))
    spec = RunSpec(listen=f"127.0.0.1:{port}", sensors=str(calib), rate_hz=100.0, max_time_s=3.0)
    assert spec.camera == "k4abt"  # the calibration's format, not the Kinect v2's

    def say(line: str) -> None:
        lines.append(line)
        if line.startswith("listening on") and not sender.is_alive():
            sender.start()  # the camera starts once the listener is ready

    m = run_one(spec, tmp_path / "live", plots=False, view=False, say=say)
    sender.join()
    # the paper's rules with a camera slower than 0.1 s: said first; then, at the loop's
    # first tick, the ready line
    assert lines[0].startswith("the paper rules do not count a frame's age: frames up to 140")
    assert lines[1] == (
        f"listening on 127.0.0.1:{port} for femto (k4abt, age limit 140 ms): signed "
        "datagrams of cell 'test'"
    )
    first = [x for x in lines if x.startswith("femto: first frame taken at")]
    assert len(first) == 1, lines
    # frames 0.10 s old taken under their 0.14 s limit (before issue 46 every one was
    # refused as late); one a loaded machine's receiver reached after the limit is rightly
    # late: a few (5 of 84 on a CI rehearsal beside two helpers), never most
    received = m["input"]["received"]
    assert m["input"]["accepted"] > 60 and m["input"].get("late", 0) < 0.2 * received, m["input"]
    on_disk = strict_load((tmp_path / "live" / "metrics.json").read_text())
    for metrics in (m, on_disk):
        assert metrics["camera"] == "k4abt"
        assert metrics["latency_s"] == 0.1 and metrics["frame_age_limit_s"] == 0.14
        assert metrics["arm"] == "the simulated arm in real time"
        femto = metrics["sensors"]["femto"]
        assert femto["format"] == "k4abt" and femto["age_limit_s"] == 0.14
        assert 0.1 <= femto["first_frame_age_s"] <= 0.14
        loop = metrics["loop"]
        assert loop["commands_sent"] == metrics["ticks"]  # each tick's command applied
        assert 0.1 <= loop["frame_to_command_s"]["median"] <= 0.2
    ages = np.load(tmp_path / "live" / "log.npz")["frame_age_s"]
    seen = ages[np.isfinite(ages)]
    assert seen.size > 200 and seen.min() >= 0.1  # counted at their true age


def test_a_hold_says_which_part_which_link_and_the_clearance_it_needs(robot):
    """The seated operator's head put near the end effector: both controllers hold and say
    so in the operator's words; the clearance needed is S_h + C + Z_d + Z_r at v_r = 0,
    v_h (T_f + T_r + T_s) with the head's 1.6 m/s (ISO 13855), computed here term by term
    (T_s: the stop time speed and separation allows this tick, its budget)."""
    config = ControllerConfig(control_period_s=0.002, safety="ssm")
    for make in (qpavoid.AnalyticController, QPController):
        ctrl = make(robot, config=config)
        q = inverse_kinematics(robot, ctrl.path.reference(0.0)[0])
        person = Operator().rest()
        head = ctrl.human.skeleton.joints.index("Head")
        ee = robot.end_effector(q)[:3, 3]
        person = person + (ee + np.array([0.0, 0.25, 0.0]) - person[head])
        ssm: SSMConfig = ctrl.ssm
        stop_time = ctrl.stop_budget.budget()
        cmd = ctrl.step(q, person, None, 0.0, 0.05, 1.0)
        reason = cmd.reason
        assert cmd.stopped and reason.startswith("speed and separation: person's head "), reason
        assert "QP not solved" not in reason and reason.endswith(": holding")
        assert "robot link 'EE'" in reason  # the iiwa's end-effector set
        d = float(reason.split("person's head ")[1].split(" m from")[0])
        assert d == pytest.approx(cmd.table.distance.min(), abs=5e-4)
        need = ssm.body_speed_mps * (0.05 + ssm.reaction_time_s + stop_time) + (
            ssm.intrusion_m + ssm.sensing_uncertainty_m + ssm.robot_uncertainty_m
        )
        assert d < need
        assert f"needs {need:.3f} m" in reason, (reason, need)


def test_camera_contradicting_the_calibration_is_refused_in_one_line(tmp_path, capsys):
    calib = k4abt_cell(tmp_path)
    with pytest.raises(InputError, match=r"--camera kinect_v2 contradicts the calibration"):
        RunSpec(listen="127.0.0.1:5999", sensors=str(calib), camera="kinect_v2")
    assert RunSpec(listen="127.0.0.1:5999", sensors=str(calib), camera="k4abt").camera == "k4abt"
    status = main(
        [
            "run",
            "--listen",
            "127.0.0.1:5999",
            "--sensors",
            str(calib),
            "--camera",
            "zed_body_34",
            "--out",
            str(tmp_path / "o"),
        ]
    )
    out, err = capsys.readouterr()
    assert status == 2 and out == ""
    (line,) = err.strip().splitlines()
    assert line.startswith("qpavoid: error: --camera zed_body_34 contradicts the calibration")
    assert "femto (k4abt)" in line and not (tmp_path / "o").exists()


def test_a_latency_contradicting_the_calibrations_is_refused(tmp_path):
    calib = k4abt_cell(tmp_path, latency_s=0.12)
    with pytest.raises(InputError, match=r"latency_s = 0.12 s, and --latency says 0.15 s"):
        RunSpec(listen="127.0.0.1:5999", sensors=str(calib), latency_s=0.15)
    assert RunSpec(listen="127.0.0.1:5999", sensors=str(calib)).frame_age_limit_s == 0.16


def test_json_files_hold_no_nan_or_infinity():
    text = strict_json({"a": float("nan"), "b": [np.inf, -np.inf, np.float64(2.5)], "c": (1,)})
    assert strict_load(text) == {"a": None, "b": [None, None, 2.5], "c": [1]}


@pytest.mark.slow  # the same rule as the next test's, reached another way
def test_a_run_at_its_goal_held_there_by_a_person_reached_it(robot):
    """The arm arrives at its goal in the very tick a hand appears beside it (the ideal
    bench: no latency, the paper's rules): it holds there, within the goal's tolerance, to
    the end of the run. It reached its goal (before: 'reached goal False', 0.001 mm from
    it)."""
    # a person held still in the simulation is not a frozen camera (the ideal bench's)
    config = ControllerConfig(
        control_period_s=0.01, perception=PerceptionConfig(max_identical_frames=None)
    )
    seated = Operator().rest()
    sim_cfg = SimConfig(control_rate_hz=100, max_time_s=17)
    first = simulate(QPController(robot, config=config), None, sim_cfg, source=Still(seated))
    arrived = float(first.log["t"][-1])  # the first tick at the goal, moving
    assert first.metrics["reached_goal"] and arrived < 16.0
    ctrl = QPController(robot, config=config)
    goal = ctrl.path.reference(ctrl.path.duration_s)[0][:3, 3]
    hand = ctrl.human.skeleton.joints.index("HandRight")
    near = seated + (goal + np.array([0.0, 0.05, 0.0]) - seated[hand])
    sim = simulate(ctrl, None, sim_cfg, source=Still(seated, near, arrived - 1e-9))
    log, m = sim.log, sim.metrics
    assert log["stopped"][-1] and log["t"][-1] == pytest.approx(17.0)  # held to the end
    assert m["final_position_error_m"] < 1e-3
    assert m["reached_goal"] and m["end_reason"] == "goal reached"


class Still:
    """A person at ``joints``, at ``then`` from ``at_s`` on (s); each tick a new frame,
    captured then (a source, not a camera: no frame period)."""

    def __init__(self, joints: np.ndarray, then: np.ndarray | None = None, at_s: float = 1e9):
        self.joints, self.then, self.at_s = joints, then, at_s

    def frame_at(self, t: float) -> tuple[HumanFrame, float]:
        joints = self.then if t >= self.at_s and self.then is not None else self.joints
        return HumanFrame(joints, np.full(len(joints), 2, np.int8)), t


@pytest.mark.parametrize(
    ("case", "fmt", "latency", "words"),
    [
        ("late", "k4abt", 0.2, "femto: frames refused as late: femto's age limit 0.140 s ="),
        pytest.param(
            "format",
            "kinect_v2",
            0.0,
            "femto: datagrams of k4abt frames dropped: the calib",
            marks=pytest.mark.slow,  # the receiver's record: tests/test_send.py
        ),
        pytest.param(
            "key",
            "k4abt",
            0.1,
            "datagrams dropped as bad_tag: not signed by this cell's keys",
            marks=pytest.mark.slow,
        ),
    ],
)
def test_the_listener_says_once_what_it_refuses_and_how_to_fix_it(
    tmp_path, case, fmt, latency, words
):
    """k4abt frames to a Kinect v2 calibration: said once, naming both formats; k4abt
    frames 0.2 s old to a k4abt calibration: said once, naming the age limit and how to
    set it; frames signed with another key: said once, with what to check; nothing taken
    in any case."""
    folder = tmp_path
    calib = k4abt_cell(folder)
    if fmt != "k4abt":  # the same camera calibrated as a Kinect v2
        calib.write_text(calib.read_text().replace('"k4abt"', f'"{fmt}"'))
    calibrated = load_calibration(str(calib))  # the sender's keys
    if case == "key":  # the listener's key file made anew: the sender's is another
        (folder / "femto.key").unlink()
        new_key_file(folder / "femto.key", "femto")
    lines: list[str] = []
    with Listener(("127.0.0.1", 0), load_calibration(str(calib))) as listener:
        source = LiveSource(listener, say=lines.append)
        port = listener.address[1]
        sender = threading.Thread(
            target=send_seated, args=(calib, port, latency, 1.0, "iiwa14", calibrated)
        )
        sender.start()
        t0 = time.time()
        while time.time() - t0 < 1.5:
            people, _ = source.frame_at(time.time() - t0)
            time.sleep(0.01)
        sender.join()
    said = [x for x in lines if x.startswith(words)]
    assert len(said) == 1, lines
    assert source.first_taken == {} and not people.ids
    if case == "late":
        assert "set latency_s for it in the calibration, or --latency" in said[0]
    elif case == "format":
        assert "says kinect_v2 (its format key)" in said[0]


def test_send_seats_the_operator_where_the_runs_task_file_does(tmp_path, capsys):
    """``qpavoid send --task FILE``: the operator at rest at the file's [operator] seat, as
    ``qpavoid run --task FILE`` seats them (the Panda's seat moved 0.25 m back); a task
    file naming what the arm lacks is refused in one line."""
    from qpavoid.cli.commands import build_parser
    from qpavoid.cli.sensors import send_motion

    text = (resources.files("qpavoid.robots") / "panda" / "task.toml").read_text()
    moved = tmp_path / "task.toml"
    moved.write_text(text.replace("distance_m = 1.0882", "distance_m = 1.3382", 1))
    calib = k4abt_cell(tmp_path)
    send = ["send", "femto", "--to", "127.0.0.1:5999", "--sensors", str(calib)]
    send += ["--robot", "panda", "--task", str(moved)]
    args = build_parser().parse_args(send)
    motion, said = send_motion(args, load_calibration(str(calib)))
    assert motion.operator.distance_m == 1.3382 and said.endswith(f"(the seat of {moved})")
    spec = RunSpec(scenario="free", robot="panda", task=str(moved))
    seated = spec.task_for(qpavoid.load_robot("panda")).operator
    np.testing.assert_array_equal(motion.frame_at(0.0).joints, seated.rest())
    moved.write_text(text.replace("[operator]", "[operator]\nelbow_m = 1", 1))
    status = main(send)
    out, err = capsys.readouterr()
    assert status == 2 and out == "" and err.startswith("qpavoid: error: --task ")
    assert len(err.strip().splitlines()) == 1


class GoesStale:
    """The seated operator, each tick a new frame until ``until_s``, then the same frame
    aging (a sender that stopped)."""

    def __init__(self, until_s: float):
        self.until_s = until_s

    def frame_at(self, t: float) -> tuple[HumanFrame, float]:
        joints = Operator().rest()
        return HumanFrame(joints, np.full(len(joints), 2, np.int8)), min(t, self.until_s)


def test_a_run_stopped_in_its_paths_last_moments_within_the_tolerance_reached_its_goal(robot):
    """The camera stops 0.3 s before the path ends: the arm brakes, its path clock stops
    at 14.8 s, and it stands 0.0006 mm from the goal (the path's end is slow): it reached
    its goal (before: 'reached goal False', 0.007 mm from it, an adversary's run). A run
    whose path still had millimetres to go has not."""
    config = ControllerConfig(
        control_period_s=0.02, perception=PerceptionConfig(max_identical_frames=None)
    )
    sim_cfg = SimConfig(control_rate_hz=50, max_time_s=15.5)
    ctrl = QPController(robot, config=config)
    sim = simulate(ctrl, None, sim_cfg, source=GoesStale(ctrl.path.duration_s - 0.3))
    assert sim.log["tau"][-1] < ctrl.path.duration_s and sim.log["stopped"][-1]
    assert sim.metrics["final_position_error_m"] < 1e-3
    assert sim.metrics["reached_goal"] and sim.metrics["end_reason"] == "goal reached"
    early_cfg = SimConfig(control_rate_hz=50, max_time_s=12.5)
    early = simulate(QPController(robot, config=config), None, early_cfg, source=GoesStale(12.0))
    assert early.metrics["final_position_error_m"] > 1e-3
    assert not early.metrics["reached_goal"]


def test_a_run_held_by_speed_and_separation_says_what_held_it_and_what_to_change():
    """The Panda beside its seated operator seen by a ZED (0.12 s): held the whole run.
    The time stopped is split by cause, summing to the time stopped, and the summary says
    what the protective distance counts and what to change."""
    from qpavoid.loop.metrics import describe

    spec = RunSpec(
        scenario="free",
        robot="panda",
        camera="zed_body_34",
        safety="ssm",
        controller="qp",
        rate_hz=100.0,
        max_time_s=3.0,  # held from its first ticks: 3 s of holding as good as 6
    )
    m = simulate_one(spec).metrics | {"scenario": "free"}
    causes = m["stopped_s_by_cause"]
    assert next(iter(causes)) == "speed and separation", causes
    assert sum(causes.values()) == pytest.approx(m["stopped_s"], abs=1e-6)
    text = describe(m)
    assert f"(speed and separation {causes['speed and separation']:.1f} s" in text
    assert "its protective distance counts the camera's latency (0.120 s here)" in text
    assert "seat the operator further from the path" in text


def test_a_loop_held_at_its_start_has_not_reached_its_goal():
    """A reviewer's case: a task out and back to its start (its goal), the run capped at
    0.2 s, the arm still at the start: not 'goal reached' (the rest of the path is judged,
    not only its pose now)."""
    task = Path(__file__).parent / "data" / "panda_out_and_back_task.toml"
    spec = RunSpec(scenario="test1", robot="panda", task=str(task), max_time_s=0.2, bench="ideal")
    m = simulate_one(spec).metrics
    assert m["final_position_error_m"] < 1e-3  # at the goal's pose ...
    assert not m["reached_goal"] and m["end_reason"] != "goal reached"  # ... not its goal


def test_a_spec_of_a_mixed_cell_is_copied_and_its_camera_is_the_landmarks(tmp_path):
    """A reviewer's case: dataclasses.replace on a spec of a cell mixing formats raised
    (its camera resolved to kinect_v2, then refused as contradicting the calibration)."""
    calib = k4abt_cell(tmp_path)
    text = calib.read_text()
    kinect = text.split("[sensors.femto]")[1].replace('format = "k4abt"', 'format = "kinect_v2"')
    calib.write_text(text + "\n[sensors.kinect]" + kinect.replace("femto.key", "kinect.key"))
    new_key_file(tmp_path / "kinect.key", "kinect")
    spec = RunSpec(listen="127.0.0.1:5999", sensors=str(calib))
    assert spec.camera == "kinect_v2"  # a mixed cell runs on the body's landmarks
    assert dataclasses.replace(spec, max_time_s=5.0).max_time_s == 5.0
    with pytest.raises(InputError, match="--camera k4abt contradicts the calibration"):
        dataclasses.replace(spec, camera="k4abt")


def test_the_time_stopped_is_split_by_kind_not_by_each_reasons_numbers():
    """A reviewer's case: the paper's rules' reasons carry numbers; each made a key."""
    from qpavoid.loop.metrics import stopped_by_cause

    reasons = np.array(
        [
            "d_L2 = 0.121 m <= 0.15 m",
            "d_L2 = 0.123 m <= 0.15 m",
            "",
            "f = 0.987 > 0.95",
            "human frame is stale (101.0 ms old, max 100.0 ms)",
            "f = 0.99 > 0.95",
            "d_L2 = 0.1 m",
        ]
    )
    assert stopped_by_cause(reasons, 0.5) == {"d_L2": 1.5, "f": 1.0, "human frame is stale": 0.5}
