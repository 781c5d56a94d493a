"""The live ROS 2 participant (issue 47) on a loopback DDS domain of its own per test:
the cameras' topics into the live source's listener interface, the arm under ros2_control,
the cell file, the opt-in."""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest

from qpavoid.core.errors import ArmError, InputError
from qpavoid.sensing.calibration import Calibration, SensorCalibration
from qpavoid.sensing.ros2_cell import Cell, load_cell, participant, write_raw, writer
from qpavoid.sensing.ros2_types import to_cdr

pytest.importorskip("cyclonedds")

from ros2_standin import marker_array

os.environ.setdefault(
    "CYCLONEDDS_URI", '<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General>'
)
TOPIC = "/femto/body_tracking_data"
MA = "visualization_msgs/msg/MarkerArray"
_DOMAIN = [100 + (os.getpid() % 100)]


def _domain() -> int:
    _DOMAIN[0] += 1
    return _DOMAIN[0] % 230


def _calibration() -> Calibration:
    return Calibration(
        {"femto": SensorCalibration("femto", np.eye(4), format="k4abt", topic=TOPIC)}
    )


def _joints() -> np.ndarray:
    return np.column_stack([np.linspace(-0.3, 0.3, 32), np.zeros(32), np.full(32, 2.0)])


def _until(check, timeout_s: float = 3.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if check():
            return True
        time.sleep(0.01)
    return False


def test_a_cell_file_is_read_and_a_bad_one_is_one_line(tmp_path):
    good = tmp_path / "cell.toml"
    good.write_text(
        'distribution = "jazzy"\ndomain_id = 7\n[arm]\njoints = ["a", "b"]\n'
        'controller = "/forward_velocity_controller"\n[output]\nrate_hz = 10\n'
    )
    cell = load_cell(good)
    assert (cell.distribution, cell.domain_id, cell.arm.joints) == ("jazzy", 7, ("a", "b"))
    assert cell.arm.commands == "/forward_velocity_controller/commands"
    for text, says in (
        ('distribution = "foxy"\n', "distribution must be one of humble, jazzy"),
        ('distribution = "humble"\ndomain_id = 300\n', "domain_id must be"),
        ('distribution = "humble"\n[arm]\njoint_states = "joint states"\n', "ROS 2 topic"),
        ('distribution = "humble"\nspeed = 1\n', "the top level has unknown key(s) ['speed']"),
        ('distribution = "humble"\n[arm]\njoints = ["a", "a"]\n', "twice"),
    ):
        good.write_text(text)
        with pytest.raises(InputError) as err:
            load_cell(good)
        assert says in str(err.value) and "\n" not in str(err.value)


def test_a_ros2_input_without_the_opt_in_refuses_to_start(tmp_path):
    from qpavoid.experiments.run_spec import RunSpec
    from qpavoid.sensing.dds_input import DdsListener

    with pytest.raises(InputError, match="--trust-ros-graph"):
        DdsListener(Cell(domain_id=_domain()), _calibration())
    (tmp_path / "cell.toml").write_text('distribution = "humble"\n')
    (tmp_path / "cal.toml").write_text(_calibration().to_toml())
    with pytest.raises(InputError, match="--trust-ros-graph"):
        RunSpec(listen=f"ros2:{tmp_path / 'cell.toml'}", sensors=str(tmp_path / "cal.toml"))
    spec = RunSpec(
        listen=f"ros2:{tmp_path / 'cell.toml'}",
        sensors=str(tmp_path / "cal.toml"),
        trust_ros_graph=True,
    )
    assert spec.trust_ros_graph


@pytest.mark.slow
def test_camera_topics_feed_the_listener_interface_and_bad_messages_are_dropped():
    from qpavoid.sensing.dds_input import DdsListener

    domain = _domain()
    lines: list[str] = []
    with DdsListener(Cell(domain_id=domain), _calibration(), True, lines.append) as listener:
        dp = participant(domain)
        w = writer(dp, "humble", TOPIC, MA)
        assert _until(lambda: bool(w.get_matched_subscriptions()))
        t0 = time.time()
        joints = _joints()
        write_raw(w, to_cdr("humble", marker_array(t0, {}), MA))  # nobody seen
        time.sleep(0.05)
        write_raw(w, to_cdr("humble", marker_array(t0 + 0.033, {7: joints}), MA))
        assert _until(lambda: listener.counters["accepted"] == 2)
        frames = listener.drain()
        assert len(frames) == 1 and frames[0].sensor == "femto" and frames[0].body == 0
        assert frames[0].t == pytest.approx(t0 + 0.033, abs=1e-6)
        assert np.allclose(frames[0].joints, joints)  # k4abt's axes are the driver's
        # malformed CDR, NaN, 10 000 markers, an unknown joint id: each dropped, counted
        with pytest.raises(InputError):  # truncated CDR: Cyclone itself refuses it
            write_raw(w, b"\x00\x01\x00\x00\xff\xff\xff\x7f\x01\x02")
        cdr = to_cdr("humble", marker_array(t0 + 0.05, {7: joints}), MA)
        write_raw(w, cdr.replace(b"depth_camera_link", b"\xffepth_camera_link"))  # no UTF-8
        nan = marker_array(t0 + 0.066, {7: joints})
        nan.markers[3].pose.position.x = math.nan  # the driver never sends one
        write_raw(w, to_cdr("humble", nan, MA))
        many = marker_array(t0 + 0.1, {7: joints})
        many.markers = many.markers * 313  # 10 016 markers
        write_raw(w, to_cdr("humble", many, MA))
        time.sleep(0.1)  # 3 MB on a best-effort topic: the next must not be lost behind it
        bad_id = marker_array(t0 + 0.133, {7: joints})
        bad_id.markers[0].id = 7 * 100 + 55  # joint 55 of a 32-joint format
        write_raw(w, to_cdr("humble", bad_id, MA))
        write_raw(w, to_cdr("humble", marker_array(t0 + 0.166, {7: joints}), MA))
        want = {
            "dropped_unreadable": 1,
            "dropped_non_finite": 1,
            "dropped_too_many_markers": 1,
            "dropped_joint_beyond_format": 1,
        }
        assert _until(lambda: listener.counters["received"] == 7), listener.counters
        assert {k: listener.counters[k] for k in want} == want, listener.counters
        assert [f.t for f in listener.drain()] == [pytest.approx(t0 + 0.166, abs=1e-6)]
        # the four dropped between 0.033 s and 0.166 s left a gap: 3 frames lost
        assert listener.losses()["femto"].frames == 3
        # a gap of 0.5 s in the stamps (15 frames at 30 Hz) is a dropout
        write_raw(w, to_cdr("humble", marker_array(t0 + 0.666, {7: joints}), MA))
        assert _until(lambda: listener.losses()["femto"].frames > 3)
        loss = listener.losses()["femto"]
        assert loss.frames == 3 + 14 and loss.stale_before_s == pytest.approx(t0 + 0.666)
        assert not lines


@pytest.mark.slow
def test_a_publisher_of_another_type_on_a_camera_topic_is_said_once():
    from qpavoid.sensing.dds_input import DdsListener

    domain = _domain()
    lines: list[str] = []
    with DdsListener(Cell(domain_id=domain), _calibration(), True, lines.append) as listener:
        dp = participant(domain)
        writer(dp, "humble", TOPIC, "sensor_msgs/msg/JointState")
        assert _until(lambda: bool(lines), 4.0)
        time.sleep(0.6)
        assert len(lines) == 1 and TOPIC in lines[0] and "matches no type" in lines[0]
        assert listener.counters["incompatible_publishers"] >= 1


def _arm(domain: int, timeout_s: float = 0.3):
    from qpavoid.arm.model import load_robot
    from qpavoid.drive.ros2_arm import Ros2Arm
    from qpavoid.sensing.ros2_cell import ArmTopics

    robot = load_robot("iiwa14")
    order = tuple(reversed(robot.joint_names))  # the controller's order: reversed
    cell = Cell(domain_id=domain, arm=ArmTopics(joints=order, subscriber_timeout_s=timeout_s))
    return Ros2Arm(robot, cell, 0.002, True), robot.joint_names


def _joint_state(t: float, names, q):
    """A JointState stamped ``t`` (s) naming ``names`` at positions ``q``."""
    from qpavoid.sensing.ros2_cell import dds_message

    stamp = dds_message(
        "humble", "builtin_interfaces/msg/Time", sec=int(t), nanosec=int((t % 1) * 1e9)
    )
    return dds_message(
        "humble",
        "sensor_msgs/msg/JointState",
        header=dds_message("humble", "std_msgs/msg/Header", stamp=stamp),
        name=list(names),
        position=list(q),
        velocity=[0.0] * len(q),
    )


def test_no_controller_on_the_command_topic_refuses_to_move():
    arm, _ = _arm(_domain())
    with pytest.raises(ArmError) as err:
        arm.connect()
    assert "nobody subscribes to /forward_velocity_controller/commands" in str(err.value)
    assert "does not move" in str(err.value) and "\n" not in str(err.value)
    arm.close()


@pytest.mark.slow
def test_the_arm_reads_joint_states_by_name_and_commands_in_the_controllers_order():
    from qpavoid.sensing.ros2_cell import reader, take_raw

    domain = _domain()
    arm, names = _arm(domain, 3.0)
    dp = participant(domain)
    commands = reader(
        dp,
        "humble",
        "/forward_velocity_controller/commands",
        "std_msgs/msg/Float64MultiArray",
        depth=10,
    )
    states = writer(dp, "humble", "/joint_states", "sensor_msgs/msg/JointState")

    assert _until(lambda: bool(states.get_matched_subscriptions()))
    n = len(names)
    q = 0.1 * np.arange(1, n + 1)
    shuffled = np.random.default_rng(0).permutation(n).tolist()
    states.write(
        _joint_state(10.0, ("gripper", *(names[i] for i in shuffled)), (9.0, *q[shuffled]))
    )
    got = arm.connect()
    assert np.allclose(got.q, q) and got.time_s == pytest.approx(10.0)
    states.write(_joint_state(10.1, names[:-1], q[:-1]))  # a joint missing: dropped
    time.sleep(0.05)
    assert np.allclose(arm.read().q, q)
    states.write(_joint_state(10.2, names, [math.nan, *q[1:]]))  # NaN: dropped
    time.sleep(0.05)
    assert np.allclose(arm.read().q, q)
    assert arm.counters["dropped_wrong_joints"] == 1 and arm.counters["dropped_non_finite"] == 1
    arm.send(0.01 * np.arange(1, n + 1))
    arm.stop()
    from qpavoid.sensing.ros2_types import dds_type

    kind = dds_type("humble", "std_msgs/msg/Float64MultiArray")
    got_cmds: list = []
    assert _until(
        lambda: (
            got_cmds.extend(kind.deserialize(d).data for d in take_raw(commands))
            or len(got_cmds) >= 3
        )
    )
    assert np.allclose(got_cmds[0], 0.01 * np.arange(n, 0, -1))  # the controller's order
    assert list(got_cmds[-1]) == [0.0] * n
    arm.close()


@pytest.mark.slow
def test_a_fresh_read_waits_for_the_next_state_and_a_plain_one_takes_the_queued():
    """``read()`` gives the newest state queued at once; ``read(fresh=True)`` takes the
    queued one as the past and gives the next to arrive (here 0.1 s later, within its
    wait of one period, 0.5 s); with none arriving, it gives the last after the wait."""
    import threading

    from qpavoid.arm.model import load_robot
    from qpavoid.drive.ros2_arm import Ros2Arm
    from qpavoid.sensing.ros2_cell import ArmTopics, reader

    domain = _domain()
    robot = load_robot("iiwa14")
    names = robot.joint_names
    arm = Ros2Arm(robot, Cell(domain_id=domain, arm=ArmTopics(subscriber_timeout_s=3.0)), 0.5, True)
    dp = participant(domain)
    commands = reader(  # noqa: F841  (held: the controller on the command topic)
        dp, "humble", "/forward_velocity_controller/commands", "std_msgs/msg/Float64MultiArray"
    )
    states = writer(dp, "humble", "/joint_states", "sensor_msgs/msg/JointState")
    assert _until(lambda: bool(states.get_matched_subscriptions()))
    q = np.zeros(len(names))
    states.write(_joint_state(20.0, names, q))
    assert arm.connect().time_s == pytest.approx(20.0)
    states.write(_joint_state(20.1, names, q))
    assert _until(lambda: arm.read().time_s == pytest.approx(20.1))
    states.write(_joint_state(20.2, names, q))
    time.sleep(0.05)
    later = threading.Timer(0.1, lambda: states.write(_joint_state(20.3, names, q)))
    later.start()
    assert arm.read(fresh=True).time_s == pytest.approx(20.3)  # 20.2 was queued: the past
    later.join()
    began = time.perf_counter()
    assert arm.read(fresh=True).time_s == pytest.approx(20.3)  # none came: the last
    assert time.perf_counter() - began >= 0.5  # after its whole wait
    arm.close()
