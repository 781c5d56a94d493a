"""ROS 2 bags in and out.

In: the frames of two cameras (an Azure Kinect and a ZED, filmed by the simulated cameras
on test1's person) published as their drivers publish them, recorded in a rosbag2 folder
(MCAP) with a malformed message, an empty one and the arm's joint states: ``qpavoid run
--human BAG --sensors CAL`` gives the same commands as the same frames in per-sensor NPZ
files. Out: a run's bag read back in full by rosbags and by ``mcap``'s own reader.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("mcap")

from ros2_standin import (
    marker_array,
    objects_stamped,
    to_ros_axes,
    zed_object,
)

from qpavoid.core.errors import InputError
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.runs import simulate_one
from qpavoid.output.bag_writer import TOPICS, check_bag_path, write_bag
from qpavoid.sensing.bags import read_bag
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.per_sensor import SensorRecording, save_sensor_npz
from qpavoid.sensing.ros2_types import (
    Ros2UnavailableError,
    stamp_s,
    time_msg,
    to_cdr,
    typestore,
)
from qpavoid.sensing.synthetic_pair import TwoSensorConfig, two_sensor_data

TOPIC = {"femto": "/femto/body_tracking_data", "zed": "/zed/zed_node/body_trk/skeletons"}
SECONDS = 2.0


def _as_the_driver_sends(rec: SensorRecording) -> SensorRecording:
    """The frames a driver's message can carry: a joint seen or not (markers and objects
    carry no per-joint confidence), the ZED's keypoints in float32."""
    joints = rec.joints.copy()
    if rec.format.startswith("zed"):
        joints = joints.astype(np.float32).astype(np.float64)
    joints[rec.state == 0] = np.nan
    state = np.where(rec.state == 0, 0, 2).astype(np.int8)
    t = np.array([stamp_s(time_msg("humble", float(v))) for v in rec.t])  # stamps: ns
    return SensorRecording(rec.sensor, t, rec.body, joints, state, rec.format)


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    from qpavoid.arm.model import load_robot
    from qpavoid.scenarios.generated import make_scenario

    folder = tmp_path_factory.mktemp("bags")
    motion = make_scenario("test1", load_robot("iiwa14"))
    cfg = TwoSensorConfig(
        names=("femto", "zed"),
        formats=("k4abt", "zed_body_34"),
        clock_offset_s=0.0,
        mirror_per_s=0.0,
        seed=3,
    )
    data = two_sensor_data([motion], SECONDS, cfg)
    sensors = {
        n: dataclasses.replace(s, topic=TOPIC[n]) for n, s in data.calibration.sensors.items()
    }
    (folder / "cell.toml").write_text(Calibration(sensors).to_toml())
    files, recordings = [], {}
    for name, rec in data.recordings.items():
        recordings[name] = _as_the_driver_sends(rec)
        files.append(str(folder / f"{name}.npz"))
        save_sensor_npz(files[-1], recordings[name])
    bag = folder / "cell_bag"
    _record(bag, recordings)
    return folder, files, str(bag), recordings


def _record(path: Path, recordings: dict[str, SensorRecording]) -> None:
    """A rosbag2 folder (MCAP) of the drivers' messages, in capture order, with an empty
    MarkerArray before the first body, a malformed message and the arm's joint states."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = typestore("humble")
    rows = []
    for name, rec in recordings.items():
        for i in range(rec.n_rows):
            joints = rec.joints[i]
            if name == "femto":
                msg = marker_array(float(rec.t[i]), {int(rec.body[i]) + 5: joints})
                rows.append(
                    (float(rec.t[i]), TOPIC[name], msg, "visualization_msgs/msg/MarkerArray")
                )
            else:
                obj = zed_object(
                    int(rec.body[i]) + 9, to_ros_axes(rec.format, joints), body_format=1
                )
                msg = objects_stamped(float(rec.t[i]), [obj])
                rows.append((float(rec.t[i]), TOPIC[name], msg, "zed_msgs/msg/ObjectsStamped"))
    rows.sort(key=lambda r: r[0])
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {
            TOPIC["femto"]: writer.add_connection(
                TOPIC["femto"], "visualization_msgs/msg/MarkerArray", typestore=store
            ),
            TOPIC["zed"]: writer.add_connection(
                TOPIC["zed"], "zed_msgs/msg/ObjectsStamped", typestore=store
            ),
            "/joint_states": writer.add_connection(
                "/joint_states", "sensor_msgs/msg/JointState", typestore=store
            ),
        }
        empty = store.types["visualization_msgs/msg/MarkerArray"](markers=[])
        t0 = 0.0  # received (log time) 20 ms after capture (the stamps) below
        writer.write(
            conns[TOPIC["femto"]],
            round(t0 * 1e9),
            to_cdr("humble", empty, "visualization_msgs/msg/MarkerArray"),
        )
        writer.write(conns[TOPIC["zed"]], round(t0 * 1e9), b"\x00\x01\x00\x00\xff")  # malformed
        for t, topic, msg, name in rows:
            writer.write(conns[topic], round((t + 0.02) * 1e9), to_cdr("humble", msg, name))
            js = store.types["sensor_msgs/msg/JointState"](
                header=msg.header if hasattr(msg, "header") else msg.markers[0].header,
                name=["a1", "a2"],
                position=np.array([t, -t]),
                velocity=np.array([1.0, -1.0]),
                effort=np.zeros(0),
            )
            writer.write(
                conns["/joint_states"],
                round((t + 0.02) * 1e9),
                to_cdr("humble", js, "sensor_msgs/msg/JointState"),
            )


def test_a_bag_reads_as_the_per_sensor_recordings_it_was_made_from(cell):
    folder, _, bag, recordings = cell
    contents = read_bag(bag, load_calibration(folder / "cell.toml"))
    got = {r.sensors[0]: r for r in contents.recordings}
    for name, rec in recordings.items():
        np.testing.assert_array_equal(got[name].t, rec.t)
        np.testing.assert_array_equal(got[name].body, rec.body)
        np.testing.assert_array_equal(got[name].state, rec.state)
        np.testing.assert_allclose(got[name].joints, rec.joints, rtol=0, atol=1e-12)
    assert contents.empty[TOPIC["femto"]] == 1
    assert contents.drops[TOPIC["zed"]] == {"unreadable": 1}
    arm = contents.joint_states
    assert arm is not None and arm.names == ("a1", "a2")
    assert len(arm.t) == sum(r.n_rows for r in recordings.values())
    np.testing.assert_allclose(arm.position[:, 0], arm.t, atol=1e-9)


def test_a_run_on_the_bag_gives_the_commands_of_the_run_on_the_npz_files(cell):
    folder, files, bag, _ = cell
    cal = str(folder / "cell.toml")
    runs = [
        simulate_one(RunSpec(sensor_files=tuple(human), sensors=cal, max_time_s=SECONDS))
        for human in (files, [bag])
    ]
    a, b = (r.sim.log["dq_command"] for r in runs)
    assert a.shape == b.shape and np.abs(a).max() > 0
    np.testing.assert_array_equal(a, b)


def test_a_bag_without_the_calibrated_topics_is_refused_in_one_line(cell, tmp_path):
    folder, _, bag, _ = cell
    text = (folder / "cell.toml").read_text().replace(TOPIC["zed"], "/zed/other")
    (tmp_path / "cal.toml").write_text(text)
    with pytest.raises(InputError, match=r"no topic /zed/other \(sensor zed\) in the bag") as err:
        read_bag(bag, load_calibration(tmp_path / "cal.toml"))
    assert "\n" not in str(err.value)


def _log(n: int = 50) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.002
    joints = np.repeat(rng.normal(size=(n // 10 + 1, 25, 3)), 10, axis=0)[:n]
    state = np.full((n, 25), 2, np.int8)
    state[:, 3] = 0
    stopped = np.zeros(n, bool)
    stopped[30:] = True
    return {
        "t": t,
        "q": rng.normal(size=(n, 6)),
        "dq": rng.normal(size=(n, 6)),
        "dq_command": rng.normal(size=(n, 6)),
        "joints": joints,
        "state": state,
        "stopped": stopped,
        "stop_reason": np.where(stopped, "stale frame", ""),
        "distance": rng.uniform(0.1, 1.0, (n, 3)),
    }


def test_a_written_bag_is_read_back_in_full_by_rosbags_and_by_mcap(tmp_path):
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import get_types_from_msg

    log = _log()
    path = tmp_path / "run.mcap"
    counts = write_bag(path, log, [f"j{k}" for k in range(6)], start_s=1_700_000_000.0)
    assert counts == {
        "/joint_states": 50,
        "/forward_velocity_controller/commands": 50,
        "/qpavoid/people": 5,
        "/diagnostics": 2,
    }
    with AnyReader([path]) as reader:  # the definitions the bag carries, no typestore given
        got: dict[str, list] = {}
        for conn, stamp, raw in reader.messages():
            got.setdefault(conn.topic, []).append((stamp, reader.deserialize(raw, conn.msgtype)))
    assert {t: len(m) for t, m in got.items()} == counts
    for k, (stamp, js) in enumerate(got["/joint_states"]):
        assert stamp == round((1_700_000_000.0 + log["t"][k]) * 1e9)
        assert list(js.name) == [f"j{i}" for i in range(6)]
        np.testing.assert_array_equal(js.position, log["q"][k])
        np.testing.assert_array_equal(js.velocity, log["dq"][k])
    for k, (_, cmd) in enumerate(got["/forward_velocity_controller/commands"]):
        np.testing.assert_array_equal(cmd.data, log["dq_command"][k])
    _, people = got["/qpavoid/people"][1]
    assert [m.id for m in people.markers] == [j for j in range(25) if j != 3]
    np.testing.assert_array_equal(people.markers[0].pose.position.x, log["joints"][10, 0, 0])
    _, diag = got["/diagnostics"][1]
    assert diag.status[0].level == 1 and diag.status[0].message == "stale frame"
    # mcap's own reader: every message, each channel's schema a ros2msg definition from
    # which the message decodes
    with path.open("rb") as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()
        assert summary.statistics.message_count == sum(counts.values())
        seen = {}
        for schema, channel, message in reader.iter_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
            if seen[channel.topic] == 1:
                from rosbags.typesys import Stores, get_typestore

                store = get_typestore(Stores.EMPTY)
                store.register(get_types_from_msg(schema.data.decode(), schema.name))
                store.deserialize_cdr(message.data, schema.name)
    assert seen == counts and set(seen) <= set(TOPICS)


def test_the_bag_option_needs_the_ros2_extra(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "mcap.writer", None)
    with pytest.raises(Ros2UnavailableError, match=r'pip install "qpavoid\[ros2\]"'):
        check_bag_path(str(tmp_path / "run.mcap"))
    monkeypatch.undo()
    with pytest.raises(InputError, match=r"FILE\.mcap"):
        check_bag_path(str(tmp_path / "run.bag"))
