"""The sensors' side of a live run without sensors: per-sensor recordings streamed over UDP
in real time, each datagram signed with its sensor's key (``qpavoid replay``), and any
sensor's frames as they come (:func:`send_frames`: ``qpavoid send``'s simulated camera,
:mod:`qpavoid.loop.sender`)."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from itertools import groupby, pairwise

from qpavoid.core.errors import InputError
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.per_sensor import BodyFrame, SensorRecording
from qpavoid.sensing.signing import Signer
from qpavoid.sensing.wire import encode

__all__ = ["camera_frames", "send_frames", "stream"]


def stream(
    recordings: Sequence[SensorRecording],
    address: tuple[str, int],
    rate_hz: float = 30.0,
    calibration: Calibration | None = None,
    clock: Callable[[], float] = time.time,
    sleep: Callable[[float], None] = time.sleep,
    mangle: Callable[[int, bytes], Sequence[bytes]] | None = None,
    unsigned: bool = False,
    latency_s: float = 0.0,
) -> int:
    """Send ``recordings`` to ``address`` as live sensors would; returns datagrams sent.

    Each datagram is signed with its sensor's key from ``calibration`` (wire format
    version 2), or, with ``unsigned``, sent as an unsigned version-1 datagram (for a
    listener that accepts them, on loopback). The bodies a sensor's recording has at one
    time are one camera frame, sent back to back with the frame's manifest
    (:meth:`~qpavoid.sensing.signing.Signer.encode_frame`): the listener takes the frame
    only once all of them came.

    Frames go in the order of their capture times (each sensor's time stamps plus its
    ``time_offset_s`` in ``calibration``, 0 without one), paced so that the median frame
    interval of a sensor's body lasts ``1 / rate_hz`` (the recordings' own rate: real
    time). Each is stamped with its send time less ``latency_s`` on ``clock`` as its
    sensor's clock shows it (minus the offset), so the listener's calibration puts it
    back (:func:`send_frames`). Each datagram carries its recording's skeleton format
    (``format``, for a format other than the Kinect v2's:
    :func:`~qpavoid.sensing.wire.payload`). ``mangle(i, datagram)`` (tests) may replace
    datagram i by any datagrams, to inject faults.

    Raises
    ------
    InputError
        Without keys when signing, or (before anything is sent) for a recording whose
        format is not its sensors' calibrated one.
    """
    if calibration is not None:
        for rec in recordings:
            for sensor in rec.sensors:
                calibration.check_format(sensor, rec.format)
    signers = _signers(calibration, unsigned)
    offset = _offsets(calibration)
    # by capture time; a sensor's bodies of one time (one camera frame) side by side
    frames = sorted(
        (f for rec in recordings for f in rec.frames()),
        key=lambda f: (f.t + offset(f.sensor), f.sensor),
    )
    streams: dict[tuple[str, int], list[float]] = {}
    for f in frames:
        streams.setdefault((f.sensor, f.body), []).append(f.t)
    # the same frame twice (a recording given twice) is no step: only positive ones count
    steps = sorted(b - a for times in streams.values() for a, b in pairwise(times) if b > a)
    scale = (1.0 / rate_hz) / steps[len(steps) // 2] if steps else 1.0
    return _send(frames, address, calibration, signers, scale, clock, sleep, mangle, latency_s)


def send_frames(
    frames: Iterable[BodyFrame],
    address: tuple[str, int],
    calibration: Calibration | None = None,
    *,
    unsigned: bool = False,
    latency_s: float = 0.0,
    clock: Callable[[], float] = time.time,
    sleep: Callable[[float], None] = time.sleep,
) -> int:
    """Send ``frames`` to ``address`` as they come, in real time; returns datagrams sent.

    ``frames`` (an iterable, read one camera frame ahead: a generator may make each frame
    when it is due) are in order of capture time, their ``t`` on one clock; the bodies
    of one sensor and time are a camera frame, sent back to back with its manifest. The
    first is sent at once, each later one when its ``t`` has come on ``clock`` since the
    first's, stamped with its send time less ``latency_s`` (its capture time, for a
    camera that delivers a frame ``latency_s`` after taking it) and less its sensor's
    ``time_offset_s`` (its own clock); signed with its sensor's key from ``calibration``,
    or unsigned (version 1).

    Raises
    ------
    InputError
        Without keys when signing.
    """
    signers = _signers(calibration, unsigned)
    return _send(frames, address, calibration, signers, 1.0, clock, sleep, None, latency_s)


def _signers(calibration: Calibration | None, unsigned: bool) -> dict[str, Signer]:
    """Each sensor's signer (none when ``unsigned``); :class:`InputError` without keys."""
    if unsigned:
        return {}
    if calibration is None or not calibration.authenticated:
        raise InputError(
            "replay signs each datagram with its sensor's key: give --sensors with a "
            "calibration whose sensors have key files (qpavoid keygen), or --unsigned",
            name="--sensors",
        )
    return {name: Signer(calibration.cell, keys) for name, keys in calibration.keys.items()}


def _offsets(calibration: Calibration | None) -> Callable[[str], float]:
    """A sensor's clock offset (``time_offset_s``; 0 without a calibration)."""

    def offset(sensor: str) -> float:
        return calibration[sensor].time_offset_s if calibration is not None else 0.0

    return offset


def _send(
    frames: Iterable[BodyFrame],
    address: tuple[str, int],
    calibration: Calibration | None,
    signers: dict[str, Signer],
    scale: float,
    clock: Callable[[], float],
    sleep: Callable[[float], None],
    mangle: Callable[[int, bytes], Sequence[bytes]] | None,
    latency_s: float,
) -> int:
    """Each camera frame of ``frames`` sent when due: ``scale`` s of ``clock`` per s of
    capture time after the first; stamped and signed (:func:`send_frames`)."""
    offset = _offsets(calibration)
    family = socket.AF_INET6 if ":" in address[0] else socket.AF_INET
    sent = i = 0
    start = t0 = 0.0
    with socket.socket(family, socket.SOCK_DGRAM) as sock:
        for k, group in enumerate(camera_frames(frames)):
            sensor = group[0].sensor
            if k == 0:
                start, t0 = clock(), group[0].t + offset(sensor)
            due = start + (group[0].t + offset(sensor) - t0) * scale
            wait = due - clock()
            if wait > 0:
                sleep(wait)
            now = clock() - offset(sensor) - latency_s
            bodies = [f._replace(t=now) for f in group]
            if not signers:
                datagrams = [encode(f) for f in bodies]
            else:
                datagrams = signers[sensor].encode_frame(bodies)
            for data in datagrams:
                for datagram in mangle(i, data) if mangle else (data,):
                    sock.sendto(datagram, address)
                    sent += 1
                i += 1
    return sent


def camera_frames(frames: Iterable[BodyFrame]) -> Iterator[list[BodyFrame]]:
    """``frames`` (in order) as camera frames: the bodies one sensor has at one time, side
    by side; a body that comes again (a recording given twice) starts another frame."""
    for _, group in groupby(frames, key=lambda f: (f.sensor, f.t)):
        frame: list[BodyFrame] = []
        for body in group:
            if any(f.body == body.body for f in frame):
                yield frame
                frame = []
            frame.append(body)
        yield frame
