"""The sensors' side of a live run without sensors: per-sensor recordings streamed over UDP
in real time, each datagram signed with its sensor's key (``qpavoid replay``)."""

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

__all__ = ["camera_frames", "stream"]


def stream(
    recordings: Sequence[SensorRecording],
    address: tuple[str, int],
    rate_hz: float = 30.0,
    calibration: Calibration | None = None,
    clock: Callable[[], float] = time.time,
    sleep: Callable[[float], None] = time.sleep,
    mangle: Callable[[int, bytes], Sequence[bytes]] | None = None,
    unsigned: bool = False,
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
    time). Each is stamped with its send time on ``clock`` as its sensor's clock shows
    it (minus the offset), so the listener's calibration puts it back. Each datagram
    carries its recording's skeleton format (``format``, for a format other than the
    Kinect v2's: :func:`~qpavoid.sensing.wire.payload`). ``mangle(i, datagram)`` (tests)
    may replace datagram i by any datagrams, to inject faults.

    Raises
    ------
    InputError
        Without keys when signing, or (before anything is sent) for a recording whose
        format is not its sensors' calibrated one.
    """

    def offset(sensor: str) -> float:
        return calibration[sensor].time_offset_s if calibration is not None else 0.0

    if calibration is not None:
        for rec in recordings:
            for sensor in rec.sensors:
                calibration.check_format(sensor, rec.format)
    signers: dict[str, Signer] = {}
    if not unsigned:
        if calibration is None or not calibration.authenticated:
            raise InputError(
                "replay signs each datagram with its sensor's key: give --sensors with a "
                "calibration whose sensors have key files (qpavoid keygen), or --unsigned",
                name="--sensors",
            )
        signers = {name: Signer(calibration.cell, keys) for name, keys in calibration.keys.items()}

    # by capture time; a sensor's bodies of one time (one camera frame) side by side
    frames = sorted(
        (f for rec in recordings for f in rec.frames()),
        key=lambda f: (f.t + offset(f.sensor), f.sensor),
    )
    if not frames:
        return 0
    streams: dict[tuple[str, int], list[float]] = {}
    for f in frames:
        streams.setdefault((f.sensor, f.body), []).append(f.t)
    # the same frame twice (a recording given twice) is no step: only positive ones count
    steps = sorted(b - a for times in streams.values() for a, b in pairwise(times) if b > a)
    scale = (1.0 / rate_hz) / steps[len(steps) // 2] if steps else 1.0
    family = socket.AF_INET6 if ":" in address[0] else socket.AF_INET
    sent = i = 0
    with socket.socket(family, socket.SOCK_DGRAM) as sock:
        start, t0 = clock(), frames[0].t + offset(frames[0].sensor)
        for group in camera_frames(frames):
            sensor = group[0].sensor
            due = start + (group[0].t + offset(sensor) - t0) * scale
            wait = due - clock()
            if wait > 0:
                sleep(wait)
            now = clock() - offset(sensor)
            bodies = [f._replace(t=now) for f in group]
            if unsigned:
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
