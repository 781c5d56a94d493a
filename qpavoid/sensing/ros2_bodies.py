"""The ROS 2 body-tracking drivers' messages as qpavoid's per-sensor frames.

Two drivers, described as data in ``ros2_drivers.toml`` beside this module (which
message, which skeleton formats, the axes of the positions, the marker ids, the states):

* the **Azure Kinect ROS driver** (an Azure Kinect, or an Orbbec Femto through Orbbec's
  K4A wrapper): ``visualization_msgs/MarkerArray`` on ``body_tracking_data``, one sphere
  marker per joint, ``id = body id × 100 + joint index``, metres in the depth camera's
  frame, stamped with the capture time; an empty array when nobody is seen;
* the **ZED ROS 2 wrapper**: ``zed_msgs/ObjectsStamped`` on ``body_trk/skeletons``, one
  ``Object`` per body, its keypoints in ``skeleton_3d`` (metres, ROS axes: x forward,
  y left, z up), the format in ``body_format``; no object when nobody is seen.

:class:`BodyTopic` reads one sensor's topic: each message becomes a :class:`TopicFrame`
(its capture time and each body as a :class:`~qpavoid.sensing.per_sensor.BodyFrame`, in
the sensor's calibrated format's camera frame, metres, states 0/1/2, body ids numbered
0 to the format's ``max_bodies`` − 1 as long as the driver keeps its own), or is dropped
and counted by reason (:data:`DROP_REASONS`, :attr:`BodyTopic.drops`): never an exception
out of :meth:`BodyTopic.read`. A message with more markers or bodies than the format can
hold is refused from its length alone, before any of them is looked at.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from qpavoid.core.errors import InputError
from qpavoid.core.file_bounds import read_toml
from qpavoid.human.frames import MAX_COORDINATE_M
from qpavoid.human.skeleton import AXIS_DIRECTIONS, SkeletonFormat
from qpavoid.sensing.calibration import known_formats
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.ros2_types import stamp_s

__all__ = ["DROP_REASONS", "BodyTopic", "Driver", "TopicFrame", "driver_of", "drivers"]

#: Why a message is dropped (the keys of :attr:`BodyTopic.drops`).
DROP_REASONS = (
    "unreadable",  # not a message of the topic's type (a field missing or mistyped)
    "too_many_markers",  # more markers than max_bodies × the format's joints
    "too_many_bodies",  # more bodies than the format's max_bodies
    "bad_marker",  # a marker that is no joint: id < 0, an action other than ADD
    "joint_beyond_format",  # a marker's joint index (id % stride) beyond the format's
    "duplicate_joint",  # the same body's joint twice in one message
    "duplicate_body",  # the same body id twice in one message
    "mixed_headers",  # markers of one message with different stamps or frames
    "bad_stamp",  # a header stamp that is no time (nanosec out of range, ...)
    "non_finite",  # an infinite coordinate, or a NaN one where the driver sends none
    "outside_range",  # a coordinate beyond 100 m (a unit error, never a person)
    "wrong_format",  # a ZED body of another body format than the sensor's
    "out_of_order_or_duplicate",  # a stamp not after the sensor's last message's
)
_DRIVER_KEYS = (
    "title",
    "message",
    "formats",
    "axes",
    "source",
    "marker_id_stride",
    "state",
    "body_format",
    "keypoint_slots",
    "tracking_states",
)


@dataclass(frozen=True)
class Driver:
    """One driver's conventions (``ros2_drivers.toml``; the keys' meaning is there).

    Attributes
    ----------
    name, title, message, formats, source
        Its key, its name, the ROS message type it publishes, the skeleton formats it
        carries, where its conventions were read.
    to_format
        (3, 3) rotation, the message's axes to the camera axes of each format
        (``axes_of(format) @ p``): :meth:`rotation`.
    marker_id_stride, state
        Markers: ``id = body × stride + joint``; the state of every joint given.
    body_format, keypoint_slots, tracking_states
        Objects: each format's ``body_format`` code, the keypoint array's length, the
        library state of each ``tracking_state`` (−1: the body is left out).
    """

    name: str
    title: str
    message: str
    formats: tuple[str, ...]
    axes: tuple[str, str, str]
    source: str
    marker_id_stride: int = 0
    state: int = 2
    body_format: Mapping[str, int] | None = None
    keypoint_slots: int = 0
    tracking_states: tuple[int, ...] = ()

    def rotation(self, fmt: SkeletonFormat) -> np.ndarray:
        """(3, 3): a point in this driver's axes into ``fmt``'s camera axes."""
        ours = np.array([AXIS_DIRECTIONS[a] for a in self.axes]).T  # into the optical frame
        return np.asarray(fmt.axes_matrix).T @ ours


def _driver(name: str, table: object) -> Driver:
    def fail(message: str) -> InputError:
        return InputError(f"ros2_drivers.toml [{name}]: {message}", name=name, value=table)

    if not isinstance(table, Mapping):
        raise fail("must be a table")
    unknown = sorted(set(table) - set(_DRIVER_KEYS))
    if unknown:
        raise fail(f"unknown key {unknown[0]!r}")
    axes = table.get("axes")
    if not (isinstance(axes, list) and len(axes) == 3 and set(axes) <= set(AXIS_DIRECTIONS)):
        raise fail(f"axes must be three of {list(AXIS_DIRECTIONS)}")
    formats = table.get("formats")
    if not (isinstance(formats, list) and formats and set(formats) <= set(known_formats())):
        raise fail(f"formats must name skeleton formats, got {formats!r}")
    codes = table.get("body_format")
    if codes is not None and set(codes) != set(formats):
        raise fail("body_format must give a code for each of formats")
    return Driver(
        name=name,
        title=str(table["title"]),
        message=str(table["message"]),
        formats=tuple(formats),
        axes=(axes[0], axes[1], axes[2]),
        source=str(table["source"]),
        marker_id_stride=int(table.get("marker_id_stride", 0)),
        state=int(table.get("state", 2)),
        body_format=dict(codes) if codes is not None else None,
        keypoint_slots=int(table.get("keypoint_slots", 0)),
        tracking_states=tuple(int(s) for s in table.get("tracking_states", ())),
    )


@cache
def drivers() -> dict[str, Driver]:
    """Every driver of ``ros2_drivers.toml``, by name."""
    data = read_toml(Path(__file__).with_name("ros2_drivers.toml"), 1 << 16)
    return {name: _driver(name, table) for name, table in data.items()}


def driver_of(format_name: str) -> Driver:
    """The driver that publishes bodies of the skeleton format ``format_name``.

    Raises
    ------
    InputError
        For a format no driver publishes (naming the formats that one does).
    """
    for driver in drivers().values():
        if format_name in driver.formats:
            return driver
    have = ", ".join(f for d in drivers().values() for f in d.formats)
    raise InputError(
        f"no ROS 2 driver publishes {format_name} bodies; a topic's sensor must be of "
        f"format {have}",
        name="format",
        value=format_name,
    )


@dataclass(frozen=True)
class TopicFrame:
    """One message of a body topic: its capture time (None: an empty MarkerArray, which
    has no stamp) and its bodies (empty: nobody seen)."""

    t: float | None
    bodies: tuple[BodyFrame, ...]


class _DropError(Exception):
    """A message refused for ``reason`` (one of :data:`DROP_REASONS`)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class BodyTopic:
    """One sensor's body-tracking topic, read message by message (module docstring).

    Parameters
    ----------
    sensor
        The sensor's name (the calibration's).
    format_name
        Its calibrated skeleton format; the driver is the one that publishes it
        (:func:`driver_of`).

    Attributes
    ----------
    drops
        Messages dropped, by reason.
    taken
        Messages read (empty ones included).
    """

    def __init__(self, sensor: str, format_name: str) -> None:
        self.sensor = sensor
        self.format = format_name
        self.driver = driver_of(format_name)
        self.skeleton = known_formats()[format_name]
        self.rotation = self.driver.rotation(self.skeleton)
        self.max_bodies = self.skeleton.sensor.max_bodies
        self.drops: Counter[str] = Counter()
        self.taken = 0
        self._last_t = -math.inf
        self._slots: dict[int, int] = {}  # the driver's body id -> our body id
        self._free = list(range(self.max_bodies))  # least recently used first

    @property
    def message(self) -> str:
        """The ROS message type of the topic."""
        return self.driver.message

    def read(self, message: object) -> TopicFrame | None:
        """The frame of one message, or None if it is dropped (counted in :attr:`drops`)."""
        try:
            if self.driver.marker_id_stride:
                t, bodies = self._markers(message)
            else:
                t, bodies = self._objects(message)
            if t is not None:
                if not t > self._last_t:
                    raise _DropError("out_of_order_or_duplicate")
                self._last_t = t
            frames = self._number(t, bodies)
        except _DropError as drop:
            self.drops[drop.reason] += 1
            return None
        except (AttributeError, TypeError, ValueError, IndexError, OverflowError):
            self.drops["unreadable"] += 1
            return None
        self.taken += 1
        return TopicFrame(t, frames)

    def _number(
        self, t: float | None, bodies: dict[int, tuple[np.ndarray, np.ndarray]]
    ) -> tuple[BodyFrame, ...]:
        """Each driver body id as one of ours, kept while the driver keeps it; a body id
        gone from a message frees its number (reused last)."""
        for gone in set(self._slots) - set(bodies):
            self._free.append(self._slots.pop(gone))
        out = []
        for body_id, (joints, state) in bodies.items():
            if body_id not in self._slots:
                self._slots[body_id] = self._free.pop(0)
            assert t is not None  # a message with bodies has a stamp
            out.append(BodyFrame(self.sensor, self._slots[body_id], t, joints, state, self.format))
        return tuple(out)

    def _points(self, raw: np.ndarray, nan_is_missing: bool) -> np.ndarray:
        """(J, 3) positions in the message's axes into the format's camera frame, checked."""
        if np.isinf(raw).any() or (not nan_is_missing and np.isnan(raw).any()):
            raise _DropError("non_finite")
        if (np.abs(raw[np.isfinite(raw)]) > MAX_COORDINATE_M).any():
            raise _DropError("outside_range")
        return raw @ self.rotation.T

    def _markers(
        self, message: Any
    ) -> tuple[float | None, dict[int, tuple[np.ndarray, np.ndarray]]]:
        markers = message.markers
        n_joints, stride = self.skeleton.n_joints, self.driver.marker_id_stride
        if len(markers) > self.max_bodies * n_joints:  # before touching any marker
            raise _DropError("too_many_markers")
        if not len(markers):
            return None, {}
        stamps = {(int(m.header.stamp.sec), int(m.header.stamp.nanosec)) for m in markers}
        frames = {m.header.frame_id for m in markers}
        if len(stamps) > 1 or len(frames) > 1:
            raise _DropError("mixed_headers")
        t = stamp_s(markers[0].header.stamp)
        if t is None:
            raise _DropError("bad_stamp")
        ids = np.array([int(m.id) for m in markers], dtype=np.int64)
        if (ids < 0).any() or any(int(m.action) != 0 for m in markers):
            raise _DropError("bad_marker")
        body, joint = np.divmod(ids, stride)
        if (joint >= n_joints).any():
            raise _DropError("joint_beyond_format")
        if len(np.unique(ids)) != len(ids):
            raise _DropError("duplicate_joint")
        people = np.unique(body)
        if len(people) > self.max_bodies:
            raise _DropError("too_many_bodies")
        p = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z] for m in markers])
        points = self._points(p.astype(np.float64), nan_is_missing=False)
        out = {}
        for b in people.tolist():
            rows = body == b
            joints = np.full((n_joints, 3), np.nan)
            state = np.zeros(n_joints, dtype=np.int8)
            joints[joint[rows]] = points[rows]
            state[joint[rows]] = self.driver.state
            out[int(b)] = (joints, state)
        return t, out

    def _objects(
        self, message: Any
    ) -> tuple[float | None, dict[int, tuple[np.ndarray, np.ndarray]]]:
        objects = message.objects
        if len(objects) > self.max_bodies:  # before touching any object
            raise _DropError("too_many_bodies")
        t = stamp_s(message.header.stamp)
        if t is None:
            raise _DropError("bad_stamp")
        n = self.skeleton.n_joints
        code = self.driver.body_format[self.format] if self.driver.body_format else -1
        states = self.driver.tracking_states
        out = {}
        for obj in objects:
            tracking = int(obj.tracking_state)
            if not obj.skeleton_available or not 0 <= tracking < len(states):
                continue  # not a skeleton, or a state the message does not define
            if states[tracking] < 0:
                continue  # OFF: "object not valid"
            if int(obj.body_format) != code:
                raise _DropError("wrong_format")
            body_id = int(obj.label_id)
            if body_id in out:
                raise _DropError("duplicate_body")
            keypoints = obj.skeleton_3d.keypoints
            if len(keypoints) != self.driver.keypoint_slots:
                raise _DropError("unreadable")
            raw = np.array([k.kp for k in keypoints[:n]], dtype=np.float64).reshape(n, 3)
            joints = self._points(raw, nan_is_missing=True)
            seen = np.isfinite(joints).all(axis=1)
            joints[~seen] = np.nan
            state = np.where(seen, states[tracking], 0).astype(np.int8)
            out[body_id] = (joints, state)
        return t, out
