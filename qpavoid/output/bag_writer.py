"""A run as a ROS 2 bag: one MCAP file that ``ros2 bag play``, Foxglove and ``mcap`` open.

``qpavoid run ... --bag FILE.mcap`` writes, from the run's ``log.npz`` (docs/ros2.md):

========================================== ================================= ================
topic                                      type                              when
========================================== ================================= ================
``/joint_states``                          ``sensor_msgs/msg/JointState``    every tick: the
                                                                             arm's angles and
                                                                             velocities
``/forward_velocity_controller/commands``  ``std_msgs/msg/Float64MultiArray`` every tick: the
                                                                             command, in the
                                                                             arm's joint order
``/qpavoid/people``                        ``visualization_msgs/msg/         each new camera
                                           MarkerArray``                     frame: one sphere
                                                                             per usable joint
``/diagnostics``                           ``diagnostic_msgs/msg/            the first tick,
                                           DiagnosticArray``                 each change of
                                                                             stop, and 1 Hz
``/qpavoid/journal``                       ``std_msgs/msg/Float64MultiArray`` each entry of
                                                                             what the
                                                                             controller was
                                                                             handed (:mod:`~
                                                                             qpavoid.control.
                                                                             journal`)
``/qpavoid/run``                           ``std_msgs/msg/String``           once: the run's
                                                                             settings (JSON)
========================================== ================================= ================

The last two make the bag a run that ``qpavoid run --human FILE.mcap`` reproduces,
command by command (a live run's too): written where the run's log holds its journal.

Messages are CDR from ``rosbags``' serializer (:mod:`qpavoid.sensing.ros2_types`), each
channel with its ``ros2msg`` schema (the definition text rosbag2 itself stores), profile
``ros2``: readers need no ROS install to decode it. Stamps and log times are the run's
time plus ``start_s`` (the wall clock when the bag is written, unless given).
Joint markers follow the Azure Kinect ROS driver's ids (``person × 100 + joint``), in the
arm's base frame (``frame_id``), so RViz and Foxglove show them as they show a driver's.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.control.journal import KINDS, Journal
from qpavoid.core.errors import InputError
from qpavoid.output.run_files import check_output_file, load_log
from qpavoid.sensing.ros2_types import need, time_msg, to_cdr, typestore

__all__ = ["TOPICS", "check_bag_path", "write_bag", "write_run_bag"]

#: The bag's topics: what each holds (module docstring), its ROS type.
TOPICS = {
    "/joint_states": "sensor_msgs/msg/JointState",
    "/forward_velocity_controller/commands": "std_msgs/msg/Float64MultiArray",
    "/qpavoid/people": "visualization_msgs/msg/MarkerArray",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/qpavoid/journal": "std_msgs/msg/Float64MultiArray",
    "/qpavoid/run": "std_msgs/msg/String",
}
MULTI = "std_msgs/msg/Float64MultiArray"
#: Diagnostics at least this often, s (ROS's diagnostic aggregator expects about 1 Hz).
DIAGNOSTICS_PERIOD_S = 1.0
#: A joint marker's sphere diameter, m, and how long RViz keeps it without a new one, s.
MARKER_SIZE_M, MARKER_LIFETIME_S = 0.05, 0.25


class _Bag:
    """One MCAP writer with a channel per topic of :data:`TOPICS`."""

    def __init__(self, handle: Any, distribution: str) -> None:
        writer_module = need("mcap.writer")
        self.distribution = distribution
        self.store = typestore(distribution)
        self.writer = writer_module.Writer(handle)
        self.writer.start(profile="ros2", library="qpavoid")
        self.channels: dict[str, int] = {}
        self.counts: Counter[str] = Counter()
        for topic, name in TOPICS.items():
            text, _ = self.store.generate_msgdef(name, ros_version=2)
            schema = self.writer.register_schema(name=name, encoding="ros2msg", data=text.encode())
            self.channels[topic] = self.writer.register_channel(
                topic=topic, message_encoding="cdr", schema_id=schema
            )

    def make(self, type_name: str, /, **fields: Any) -> Any:
        return self.store.types[type_name](**fields)

    def header(self, t: float, frame_id: str = "") -> Any:
        return self.make(
            "std_msgs/msg/Header", stamp=time_msg(self.distribution, t), frame_id=frame_id
        )

    def add(self, topic: str, message: Any, t: float) -> None:
        ns = round(t * 1e9)
        data = to_cdr(self.distribution, message, TOPICS[topic])
        self.writer.add_message(
            self.channels[topic],
            log_time=ns,
            data=data,
            publish_time=ns,
            sequence=self.counts[topic],
        )
        self.counts[topic] += 1


def _people(bag: _Bag, t: float, joints: np.ndarray, state: np.ndarray, frame_id: str) -> Any:
    """One sphere marker per usable joint (finite, state > 0), as the Azure Kinect ROS
    driver's (id = person × 100 + joint; person 0: the log holds one)."""
    usable = np.isfinite(joints).all(axis=1) & (state > 0)
    header = bag.header(t, frame_id)
    markers = []
    for j in np.flatnonzero(usable).tolist():
        x, y, z = (float(v) for v in joints[j])
        inferred = int(state[j]) == 1
        markers.append(
            bag.make(
                "visualization_msgs/msg/Marker",
                header=header,
                ns="qpavoid_people",
                id=j,
                type=2,  # SPHERE
                action=0,  # ADD
                pose=bag.make(
                    "geometry_msgs/msg/Pose",
                    position=bag.make("geometry_msgs/msg/Point", x=x, y=y, z=z),
                    orientation=bag.make(
                        "geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=1.0
                    ),
                ),
                scale=bag.make(
                    "geometry_msgs/msg/Vector3", x=MARKER_SIZE_M, y=MARKER_SIZE_M, z=MARKER_SIZE_M
                ),
                color=bag.make(
                    "std_msgs/msg/ColorRGBA", r=1.0, g=0.5 if inferred else 0.2, b=0.0, a=1.0
                ),
                lifetime=bag.make(
                    "builtin_interfaces/msg/Duration", sec=0, nanosec=round(MARKER_LIFETIME_S * 1e9)
                ),
                frame_locked=False,
                points=[],
                colors=[],
                texture_resource="",
                texture=bag.make(
                    "sensor_msgs/msg/CompressedImage",
                    header=bag.header(0.0),
                    format="",
                    data=np.zeros(0, dtype=np.uint8),
                ),
                uv_coordinates=[],
                text="",
                mesh_resource="",
                mesh_file=bag.make(
                    "visualization_msgs/msg/MeshFile", filename="", data=np.zeros(0, dtype=np.uint8)
                ),
                mesh_use_embedded_materials=False,
            )
        )
    return bag.make("visualization_msgs/msg/MarkerArray", markers=markers)


def _diagnostics(
    bag: _Bag, t: float, stopped: bool, reason: str, nearest_m: float, hardware: str
) -> Any:
    """One status: OK while moving, WARN while stopped (the reason), the nearest clearance."""
    values = [
        bag.make("diagnostic_msgs/msg/KeyValue", key=key, value=value)
        for key, value in (
            ("stopped", str(bool(stopped)).lower()),
            ("stop_reason", reason),
            ("nearest_clearance_m", f"{nearest_m:.4f}" if np.isfinite(nearest_m) else "none"),
        )
    ]
    status = bag.make(
        "diagnostic_msgs/msg/DiagnosticStatus",
        level=np.uint8(1 if stopped else 0).item(),
        name="qpavoid: collision avoidance",
        message=(reason or "stopped") if stopped else "moving",
        hardware_id=hardware,
        values=values,
    )
    return bag.make("diagnostic_msgs/msg/DiagnosticArray", header=bag.header(t), status=[status])


def write_bag(
    path: str | Path,
    log: dict[str, np.ndarray],
    joint_names: Sequence[str],
    *,
    start_s: float | None = None,
    frame_id: str = "world",
    hardware: str = "arm",
    distribution: str = "humble",
    run_spec: str | None = None,
) -> dict[str, int]:
    """Write the run ``log`` (the arrays of ``log.npz``) as an MCAP bag at ``path``.

    Parameters
    ----------
    joint_names
        The arm's joint names, in the order of ``log["q"]``'s columns.
    start_s
        The bag's time of the run's t = 0, s since the epoch (None: now).
    frame_id
        The arm's base frame, the people markers' frame.
    hardware
        The diagnostics' ``hardware_id`` (the arm's name).
    distribution
        Whose type definitions the schemas carry (the wire is the same for Humble and
        Jazzy).
    run_spec
        The run's settings as JSON (``metrics.json``'s ``run_spec``), written on
        ``/qpavoid/run`` if given; the log's journal (``journal_data``,
        ``journal_offsets``), if it has one, on ``/qpavoid/journal``.

    Returns
    -------
    dict
        Messages written per topic.
    """
    start = time.time() if start_s is None else float(start_s)
    t = np.asarray(log["t"], dtype=np.float64)
    q, dq = np.asarray(log["q"]), np.asarray(log["dq"])
    command = np.asarray(log.get("dq_command", dq))
    joints, state = np.asarray(log["joints"]), np.asarray(log["state"])
    stopped = np.asarray(log["stopped"], dtype=bool)
    reasons = np.asarray(log.get("stop_reason", np.full(len(t), "")), dtype=str)
    distance = np.asarray(log.get("distance", np.full((len(t), 1), np.inf)), dtype=np.float64)
    names = [str(n) for n in joint_names]
    with Path(path).open("wb") as handle:
        bag = _Bag(handle, distribution)
        layout = bag.make(
            "std_msgs/msg/MultiArrayLayout",
            dim=[
                bag.make(
                    "std_msgs/msg/MultiArrayDimension",
                    label="joints",
                    size=len(names),
                    stride=len(names),
                )
            ],
            data_offset=0,
        )
        last_frame: np.ndarray | None = None
        last_status: tuple[bool, str] | None = None
        last_diag = -np.inf
        for k in range(len(t)):
            now = start + float(t[k])
            bag.add(
                "/joint_states",
                bag.make(
                    "sensor_msgs/msg/JointState",
                    header=bag.header(now),
                    name=names,
                    position=q[k].astype(np.float64),
                    velocity=dq[k].astype(np.float64),
                    effort=np.zeros(0),
                ),
                now,
            )
            bag.add(
                "/forward_velocity_controller/commands",
                bag.make(
                    "std_msgs/msg/Float64MultiArray",
                    layout=layout,
                    data=command[k].astype(np.float64),
                ),
                now,
            )
            if last_frame is None or not np.array_equal(joints[k], last_frame, equal_nan=True):
                bag.add("/qpavoid/people", _people(bag, now, joints[k], state[k], frame_id), now)
                last_frame = joints[k]
            status = (bool(stopped[k]), str(reasons[k]))
            if status != last_status or float(t[k]) - last_diag >= DIAGNOSTICS_PERIOD_S:
                finite = distance[k][np.isfinite(distance[k])]
                nearest = float(finite.min()) if finite.size else float("inf")
                message = _diagnostics(bag, now, status[0], status[1], nearest, hardware)
                bag.add("/diagnostics", message, now)
                last_status, last_diag = status, float(t[k])
        if run_spec is not None:
            bag.add("/qpavoid/run", bag.make("std_msgs/msg/String", data=run_spec), start)
        if "journal_data" in log and "journal_offsets" in log:
            _journal(bag, log["journal_data"], log["journal_offsets"], start + t)
        bag.writer.finish()
    return dict(bag.counts)


def _journal(bag: _Bag, data: np.ndarray, offsets: np.ndarray, times: np.ndarray) -> None:
    """Each journal entry a ``Float64MultiArray`` at its tick's time (an entry before the
    tick's row is logged belongs to it; those after the last row, to the last)."""
    logged = KINDS["logged"]
    layout = bag.make("std_msgs/msg/MultiArrayLayout", dim=[], data_offset=0)
    tick = 0
    for entry in Journal.split(np.asarray(data, dtype=np.float64), offsets):
        now = float(times[min(tick, len(times) - 1)]) if len(times) else 0.0
        bag.add("/qpavoid/journal", bag.make(MULTI, layout=layout, data=entry), now)
        tick += bool(entry[0] == logged)


def check_bag_path(path: str) -> Path:
    """``path`` if the ``ros2`` extra is installed and a file can be written there; else
    :class:`~qpavoid.core.errors.InputError` (one line: the extra's install command, or why
    the file cannot be written), before a run starts."""
    need("mcap.writer")
    need("rosbags.typesys")
    if not path.lower().endswith(".mcap"):
        raise InputError(
            f"--bag {path!r}: the bag is one MCAP file, FILE.mcap", name="--bag", value=path
        )
    return check_output_file(path, "--bag")


def write_run_bag(path: str | Path, run_dir: str | Path, robot: Robot) -> dict[str, int]:
    """The run written into ``run_dir`` (its ``log.npz`` and ``metrics.json``'s
    ``run_spec``) as a bag at ``path`` (:func:`write_bag`: the arm's joint names and name
    from ``robot``)."""
    metrics = json.loads((Path(run_dir) / "metrics.json").read_text())
    spec = metrics.get("run_spec")
    return write_bag(
        path,
        load_log(run_dir),
        robot.joint_names,
        hardware=robot.name,
        run_spec=None if spec is None else json.dumps(spec),
    )
