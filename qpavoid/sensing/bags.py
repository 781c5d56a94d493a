"""ROS 2 bags in: the cameras' body topics as per-sensor recordings, the arm's joint states.

A bag is a rosbag2 folder (``metadata.yaml`` with sqlite3 or MCAP files) or a bare MCAP
or sqlite3 file (``.mcap``, ``.db3``), read through ``rosbags`` (the ``ros2`` extra).
Each sensor of the calibration that names a ``topic`` (docs/sensors.md §1, docs/ros2.md)
is read from that topic through its format's driver
(:class:`~qpavoid.sensing.ros2_bodies.BodyTopic`): the messages' stamps are the capture
times, their bodies become a :class:`~qpavoid.sensing.per_sensor.SensorRecording` of that
sensor, fused as per-sensor NPZ and CSV files are (``qpavoid run --human cell.mcap
--sensors cell.toml``). A message that cannot be read, or that its driver's checks refuse,
is dropped and counted (:attr:`BagContents.drops`); a bag without one of the calibrated
topics, or whose topic has another type than its driver's, is refused in one line.

Definitions: an MCAP bag (and a rosbag2 folder from Iron on) carries its message
definitions, which rosbags uses; an older sqlite3 bag has none, and is read with the
types of :func:`~qpavoid.sensing.ros2_types.typestore` (Humble's; Jazzy's have the same
fields for every type read here).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from qpavoid.core.errors import InputError, RecordingError
from qpavoid.core.file_bounds import MAX_ROWS
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.per_sensor import BodyFrame, SensorRecording, load_sensor_recording
from qpavoid.sensing.ros2_bodies import BodyTopic
from qpavoid.sensing.ros2_types import need, stamp_s, typestore

__all__ = [
    "BAG_SUFFIXES",
    "JOINT_STATE",
    "BagContents",
    "JointStates",
    "RunRecord",
    "has_run",
    "is_bag",
    "read_bag",
    "read_run",
    "sensor_recordings",
]

#: The suffixes of a bare bag file (else a rosbag2 folder: ``metadata.yaml`` inside).
BAG_SUFFIXES = (".mcap", ".db3")
#: The arm's joint-state message type.
JOINT_STATE = "sensor_msgs/msg/JointState"


def is_bag(path: str | Path) -> bool:
    """True for a bare bag file (by suffix) or a rosbag2 folder; opens nothing."""
    p = Path(path)
    if p.is_dir():
        return (p / "metadata.yaml").is_file()
    return p.suffix.lower() in BAG_SUFFIXES


@dataclass(frozen=True)
class JointStates:
    """The arm's ``sensor_msgs/JointState`` messages of one topic.

    Attributes
    ----------
    topic, names
        The topic and the joint names of its first message (a message naming others is
        dropped: ``drops["joint_names"]``).
    t
        (N,) header stamps, s.
    position, velocity
        (N, J) rad and rad/s (NaN where a message gives none).
    """

    topic: str
    names: tuple[str, ...]
    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray


@dataclass
class BagContents:
    """What :func:`read_bag` found: each sensor's recording, the arm's joint states (None:
    no JointState topic), and the messages dropped per topic, by reason."""

    recordings: list[SensorRecording]
    joint_states: JointStates | None
    drops: dict[str, Counter[str]] = field(default_factory=dict)
    empty: Counter[str] = field(default_factory=Counter)


def _fail(
    path: Path, message: str, name: str | None = None, value: object = None
) -> RecordingError:
    return RecordingError(f"{path}: {message}", path=str(path), name=name, value=value)


def read_bag(
    path: str | Path, calibration: Calibration, distribution: str = "humble"
) -> BagContents:
    """Read the calibrated sensors' topics (and the arm's JointState) of the bag at ``path``.

    Raises
    ------
    RecordingError
        For a bag that cannot be opened, a calibration naming no topic, a calibrated topic
        missing from the bag or of another type than its driver's, a topic with no body
        at all, or more than :data:`~qpavoid.core.file_bounds.MAX_ROWS` bodies of a sensor;
        one line naming the bag. :class:`~qpavoid.sensing.ros2_types.Ros2UnavailableError`
        without the ``ros2`` extra.
    """
    p = Path(path)
    topics = {cal.topic: name for name, cal in calibration.sensors.items() if cal.topic}
    if not topics:
        raise _fail(
            p,
            f"the calibration {calibration.path} names no sensor's topic: give each camera's "
            'topic = "/.../body_tracking_data" in its [sensors.NAME] table (docs/ros2.md)',
            "topic",
        )
    highlevel = need("rosbags.highlevel")
    readers = {
        topic: BodyTopic(sensor, calibration.sensors[sensor].format)
        for topic, sensor in topics.items()
    }
    frames: dict[str, list[BodyFrame]] = {sensor: [] for sensor in topics.values()}
    contents = BagContents([], None)
    arm: dict[str, list] = {"t": [], "q": [], "dq": []}
    names: tuple[str, ...] | None = None
    joint_topic: str | None = None
    try:
        with highlevel.AnyReader([p], default_typestore=typestore(distribution)) as reader:
            have = {c.topic: c.msgtype for c in reader.connections}
            for topic, body_topic in readers.items():
                if topic not in have:
                    raise _fail(
                        p,
                        f"no topic {topic} (sensor {body_topic.sensor}) in the bag; it has "
                        f"{', '.join(sorted(have)) or 'no topic'}",
                        "topic",
                        topic,
                    )
                if have[topic] != body_topic.message:
                    raise _fail(
                        p,
                        f"topic {topic} is {have[topic]}, but sensor {body_topic.sensor}'s "
                        f"{body_topic.format} driver publishes {body_topic.message}",
                        "topic",
                        topic,
                    )
            joint_topic = next((t for t, m in sorted(have.items()) if m == JOINT_STATE), None)
            wanted = [c for c in reader.connections if c.topic in readers or c.topic == joint_topic]
            for connection, _, raw in reader.messages(connections=wanted):
                drops = contents.drops.setdefault(connection.topic, Counter())
                try:
                    message = reader.deserialize(raw, connection.msgtype)
                except Exception:  # malformed CDR: rosbags raises several kinds
                    drops["unreadable"] += 1
                    continue
                if connection.topic == joint_topic:
                    names = _joint_state(message, names, arm, drops)
                    continue
                body_topic = readers[connection.topic]
                frame = body_topic.read(message)
                if frame is None:
                    continue
                if not frame.bodies:
                    contents.empty[connection.topic] += 1
                rows = frames[body_topic.sensor]
                rows.extend(frame.bodies)
                if len(rows) > MAX_ROWS:
                    raise _fail(p, f"more than {MAX_ROWS} bodies on {connection.topic}")
            for topic, body_topic in readers.items():
                contents.drops.setdefault(topic, Counter()).update(body_topic.drops)
    except InputError:
        raise
    except Exception as exc:  # rosbags' reader errors, an unreadable file
        raise _fail(
            p, f"not a readable ROS 2 bag: {type(exc).__name__}: {str(exc)[:160]}"
        ) from None
    for topic, sensor in topics.items():
        if not frames[sensor]:
            dropped = sum(contents.drops.get(topic, Counter()).values())
            raise _fail(
                p,
                f"topic {topic} (sensor {sensor}) has no body in the bag "
                f"({contents.empty[topic]} empty messages, {dropped} dropped)",
                "topic",
                topic,
            )
        contents.recordings.append(SensorRecording.from_frames(frames[sensor]))
    if joint_topic is not None and names is not None:
        contents.joint_states = JointStates(
            joint_topic, names, np.array(arm["t"]), np.array(arm["q"]), np.array(arm["dq"])
        )
    return contents


def _joint_state(
    message: object, names: tuple[str, ...] | None, arm: dict[str, list], drops: Counter[str]
) -> tuple[str, ...] | None:
    """Append one JointState to ``arm`` (t, q, dq); the joint names of the first one."""
    try:
        these = tuple(str(n) for n in message.name)  # type: ignore[attr-defined]
        position = np.asarray(message.position, dtype=np.float64)  # type: ignore[attr-defined]
        velocity = np.asarray(message.velocity, dtype=np.float64)  # type: ignore[attr-defined]
        t = stamp_s(message.header.stamp)  # type: ignore[attr-defined]
    except (AttributeError, TypeError, ValueError):
        drops["unreadable"] += 1
        return names
    if t is None:
        drops["bad_stamp"] += 1
        return names
    if (names is not None and these != names) or position.shape != (len(these),):
        drops["joint_names"] += 1
        return names
    if not np.isfinite(position).all():
        drops["non_finite"] += 1
        return names
    if velocity.shape != position.shape:
        velocity = np.full(position.shape, np.nan)
    arm["t"].append(t)
    arm["q"].append(position)
    arm["dq"].append(velocity)
    return these


def sensor_recordings(path: str | Path, calibration: Calibration) -> list[SensorRecording]:
    """The per-sensor recordings of ``path``: a bag's calibrated topics (:func:`read_bag`)
    or a per-sensor NPZ or CSV file (one recording)."""
    if is_bag(path):
        return read_bag(path, calibration).recordings
    return [load_sensor_recording(path)]


#: The topics of a run qpavoid wrote (:mod:`qpavoid.output.bag_writer`) that reproduce it.
JOURNAL_TOPIC, RUN_TOPIC = "/qpavoid/journal", "/qpavoid/run"
COMMAND_TOPIC = "/forward_velocity_controller/commands"


@dataclass(frozen=True)
class RunRecord:
    """A run as qpavoid wrote it in a bag: its settings (``/qpavoid/run``, JSON), what its
    controller was handed (``/qpavoid/journal``, one entry per message) and its commands
    (T, nv), rad/s."""

    spec_json: str
    entries: list[np.ndarray]
    commands: np.ndarray


def has_run(path: str | Path) -> bool:
    """True if the bag at ``path`` is a run qpavoid wrote with its journal (it has the
    topics :data:`JOURNAL_TOPIC` and :data:`RUN_TOPIC`)."""
    highlevel = need("rosbags.highlevel")
    try:
        with highlevel.AnyReader([Path(path)], default_typestore=typestore("humble")) as reader:
            return {JOURNAL_TOPIC, RUN_TOPIC} <= {c.topic for c in reader.connections}
    except Exception:  # not a bag rosbags opens: the recording's reader says why
        return False


def read_run(path: str | Path) -> RunRecord:
    """The run qpavoid wrote in the bag at ``path`` (:func:`has_run`).

    Raises
    ------
    RecordingError
        For a bag without the run's topics or settings, or that cannot be read (one line).
    """
    p = Path(path)
    highlevel = need("rosbags.highlevel")
    spec: list[str] = []
    entries: list[np.ndarray] = []
    commands: list[np.ndarray] = []
    try:
        with highlevel.AnyReader([p], default_typestore=typestore("humble")) as reader:
            mine = (JOURNAL_TOPIC, RUN_TOPIC, COMMAND_TOPIC)
            wanted = [c for c in reader.connections if c.topic in mine]
            for connection, _, raw in reader.messages(connections=wanted):
                message = reader.deserialize(raw, connection.msgtype)
                if connection.topic == RUN_TOPIC:
                    spec.append(str(message.data))
                elif connection.topic == JOURNAL_TOPIC:
                    entries.append(np.asarray(message.data, dtype=np.float64))
                else:
                    commands.append(np.asarray(message.data, dtype=np.float64))
    except Exception as exc:  # rosbags' reader errors, an unreadable file
        raise _fail(
            p, f"not a readable ROS 2 bag: {type(exc).__name__}: {str(exc)[:160]}"
        ) from None
    if len(spec) != 1 or not entries:
        raise _fail(p, f"not a run qpavoid wrote: no {RUN_TOPIC} or {JOURNAL_TOPIC} in it")
    return RunRecord(spec[0], entries, np.array(commands))
