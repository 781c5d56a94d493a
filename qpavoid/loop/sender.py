"""A calibrated sensor simulated on the wire: what a camera's own process would send.

A live run (``qpavoid run --listen``) takes datagrams from the cell's cameras. Without a
camera, :func:`send` plays one: the true motion (the seated operator at rest, a scenario,
a recording) is filmed by the simulated camera of the sensor's calibrated format
(:class:`~qpavoid.loop.camera.Camera`: its joints placed by the format's ``[simulate]``
table, its noise, its left/right swaps, its frame rate), moved into the sensor's own
frame (the calibration's ``base_from_camera`` inverted: the format's axes, m, as the wire
carries them), and sent when the camera would deliver it, stamped with its capture time
(send time − the camera's latency), signed with the sensor's key
(:func:`~qpavoid.sensing.streamer.send_frames`). ``qpavoid send`` and
``examples/sensor_sender.py`` call it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from qpavoid.core.checks import check_range
from qpavoid.core.errors import InputError
from qpavoid.human.frames import HumanFrame, HumanMotion
from qpavoid.human.people import People
from qpavoid.human.posture import Operator
from qpavoid.human.skeleton import TRACKED
from qpavoid.loop.camera import Camera, CameraConfig
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.per_sensor import BodyFrame, SensorRecording
from qpavoid.sensing.streamer import send_frames

__all__ = [
    "AtRest",
    "SentSummary",
    "send",
    "sensor_frames",
    "sensor_latency_s",
]


@dataclass(frozen=True)
class AtRest:
    """The seated operator at rest (:meth:`~qpavoid.human.posture.Operator.rest`), every
    joint tracked, for ever: the motion of a sensor that films the cell with nobody moving."""

    operator: Operator

    def frame_at(self, t: float) -> HumanFrame:
        """The rest pose, whatever ``t``."""
        joints = self.operator.rest()
        return HumanFrame(joints, np.full(len(joints), TRACKED, dtype=np.int8))


@dataclass(frozen=True)
class SentSummary:
    """What :func:`send` sent: camera frames, bodies in them, datagrams, and the frames'
    rate (Hz) and latency (s)."""

    frames: int
    bodies: int
    datagrams: int
    rate_hz: float
    latency_s: float


def sensor_latency_s(calibration: Calibration, sensor: str) -> float:
    """The latency ``sensor``'s frames are stamped with by default, s: its calibration's
    (``latency_s``, a measured one) where it names one, else its format's
    (:attr:`~qpavoid.human.camera_spec.CameraSpec.latency_s`).

    Raises
    ------
    CalibrationError
        For a sensor not in ``calibration``.
    """
    return calibration[sensor].latency_used_s


def sensor_frames(
    motion: HumanMotion | SensorRecording,
    calibration: Calibration,
    sensor: str,
    duration_s: float | None = None,
    seed: int = 0,
) -> Iterator[BodyFrame]:
    """The frames ``sensor`` reports of ``motion`` for ``duration_s``, each made when asked
    (everything checked first, on the call).

    A motion (a scenario, a base-frame recording, :class:`AtRest`) is filmed: one camera
    frame every ``1 / frame_rate_hz`` of the sensor's format from its capture time 0
    (``t`` on the motion's clock, s), each person a body of it, the format's joints as
    its simulated camera films them (:class:`~qpavoid.loop.camera.Camera` on the format's
    own joints: noise from ``seed`` and the frame's number, a stereo camera's growing with
    the range from the calibrated camera's place, swaps), moved into the sensor's camera
    frame, m, with their tracking states. Bodies are numbered by first appearance; a
    person beyond the format's ``max_bodies`` is not reported, as by the camera. A
    per-sensor recording (``qpavoid replay``'s files) gives its frames of ``sensor``, as
    recorded, in time order. ``duration_s`` None: the motion's own (a recording's).

    Raises
    ------
    CalibrationError
        For a sensor not in ``calibration``, a recording of another format than its.
    InputError
        For a ``duration_s`` that is not positive (or a generated motion without one), a
        recording with no frame of ``sensor``.
    """
    cal = calibration[sensor]
    if isinstance(motion, SensorRecording):
        return _recorded(motion, calibration, sensor, duration_s)
    duration = getattr(motion, "duration_s", None) if duration_s is None else duration_s
    if duration is None or not (math.isfinite(duration) and duration > 0.0):
        raise InputError(
            f"the time to send must be positive and finite, got {duration!r} s (a generated "
            "motion has no end of its own)",
            name="duration_s",
            value=duration,
        )
    fmt = cal.skeleton
    camera_from_base = np.linalg.inv(cal.base_from_camera)
    R, p = camera_from_base[:3, :3], camera_from_base[:3, 3]
    where = tuple(float(v) for v in cal.base_from_camera[:3, 3])
    camera = Camera(motion, CameraConfig.of(fmt.name, seed=seed, sensor_position_m=where), fmt)
    n = max(math.floor(duration * fmt.sensor.frame_rate_hz + 1e-9), 1)

    def filmed() -> Iterator[BodyFrame]:
        bodies: dict[int, int] = {}
        for k in range(n):
            content, captured, _, _ = camera.frame(k)
            people = content if isinstance(content, People) else People((0,), (content,))
            for pid, frame in zip(people.ids, people.frames, strict=True):
                body = bodies.setdefault(pid, len(bodies))
                if body < fmt.sensor.max_bodies:
                    joints = frame.joints @ R.T + p  # NaN where lost: sent as state 0
                    yield BodyFrame(sensor, body, captured, joints, frame.state, fmt.name)

    return filmed()


def _recorded(
    recording: SensorRecording, calibration: Calibration, sensor: str, duration_s: float | None
) -> Iterator[BodyFrame]:
    """``sensor``'s frames of a per-sensor ``recording``, those of its first ``duration_s``
    (None: all): :func:`sensor_frames`."""
    calibration.check_format(sensor, recording.format)
    frames = [f for f in recording.frames() if f.sensor == sensor]
    if not frames:
        raise InputError(
            f"the recording has no frame of sensor {sensor!r} (it holds "
            f"{', '.join(map(repr, recording.sensors))})",
            name="sensor",
            value=sensor,
        )
    end = frames[0].t + (math.inf if duration_s is None else duration_s)
    return (f for f in frames if f.t < end)


def send(
    frames: Iterable[BodyFrame],
    calibration: Calibration,
    sensor: str,
    address: tuple[str, int],
    *,
    latency_s: float | None = None,
    unsigned: bool = False,
    clock: Callable[[], float] = time.time,
    sleep: Callable[[float], None] = time.sleep,
) -> SentSummary:
    """Play ``sensor``: send its ``frames`` (:func:`sensor_frames`) to ``address`` in real
    time, as its camera's process would.

    Each camera frame is sent when the camera would deliver it (its capture time plus the
    latency, the first at once) and stamped with its capture time on the sensor's clock:
    send time − ``latency_s`` (default :func:`sensor_latency_s`) − the sensor's
    ``time_offset_s``; signed with the sensor's key, or, ``unsigned``, as version-1
    datagrams for a listener that takes them
    (:func:`~qpavoid.sensing.streamer.send_frames`).

    Raises
    ------
    CalibrationError
        For a sensor not in ``calibration``.
    InputError
        For a latency outside 0-1 s, or signing without keys.
    """
    latency = sensor_latency_s(calibration, sensor) if latency_s is None else latency_s
    check_range("the latency (--latency)", latency, 0.0, 1.0, "s")
    made = bodies = 0

    def counted(stream: Iterable[BodyFrame]) -> Iterator[BodyFrame]:
        nonlocal made, bodies
        last = math.nan
        for f in stream:
            made += f.t != last
            bodies, last = bodies + 1, f.t
            yield f

    datagrams = send_frames(
        counted(frames),
        address,
        calibration,
        unsigned=unsigned,
        latency_s=latency,
        clock=clock,
        sleep=sleep,
    )
    rate = calibration[sensor].skeleton.sensor.frame_rate_hz
    return SentSummary(made, bodies, datagrams, rate, latency)
