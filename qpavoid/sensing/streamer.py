"""The sensors' side of a live run without sensors: per-sensor recordings streamed over UDP
in real time, each datagram signed with its sensor's key (``qpavoid replay``)."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Sequence
from itertools import pairwise

from qpavoid.core.errors import InputError
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.per_sensor import SensorRecording
from qpavoid.sensing.signing import Signer
from qpavoid.sensing.wire import encode

__all__ = ["stream"]


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
    listener that accepts them, on loopback).

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

    frames = sorted(
        (f for rec in recordings for f in rec.frames()), key=lambda f: f.t + offset(f.sensor)
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
    sent = 0
    with socket.socket(family, socket.SOCK_DGRAM) as sock:
        start, t0 = clock(), frames[0].t + offset(frames[0].sensor)
        for i, frame in enumerate(frames):
            due = start + (frame.t + offset(frame.sensor) - t0) * scale
            wait = due - clock()
            if wait > 0:
                sleep(wait)
            stamped = frame._replace(t=clock() - offset(frame.sensor))
            data = encode(stamped) if unsigned else signers[frame.sensor].encode(stamped)
            for datagram in mangle(i, data) if mangle else (data,):
                sock.sendto(datagram, address)
                sent += 1
    return sent
