"""Live skeletons over UDP: a listener for the controller, and a replayer that feeds it.

:class:`Listener` receives datagrams (:mod:`qpavoid.wire`) on a UDP socket in a thread of
its own that does nothing but receive: they wait in a bounded queue where, under a
flood, the newest win (the oldest are dropped and counted as ``overflow``). The control
loop takes what arrived since its last tick, at most ``queue_size`` datagrams, and checks
them: invalid ones are dropped and counted by reason (never a crash, never a stall). The
listener is a thread: a flood still competes with the loop for Python's interpreter lock
(measured in docs/sensors.md).

:class:`LiveSource` is what the control loop asks each tick: it drains the listener,
moves each frame's time stamp onto the run clock, fuses (:class:`~qpavoid.fusion.Fuser`;
out-of-order and duplicate frames are dropped there) and returns everybody with the
capture time of the newest frame used, so the controller judges the age of what it sees:
no fresh frame for the stale limit, and it stops.

:func:`replay` streams per-sensor recordings to a listener in real time, as live sensors
would: the whole path runs on one machine over loopback.
"""

from __future__ import annotations

import socket
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Sequence
from itertools import pairwise

from .calibration import Calibration
from .errors import InputError
from .fusion import Fuser, FusionConfig
from .people import People
from .sensor_recording import BodyFrame, SensorRecording
from .wire import WireError, Workspace, decode, encode

__all__ = ["Listener", "LiveSource", "parse_address", "replay"]

#: How often threads take turns while a listener runs, s (Python's default: 0.005).
SWITCH_INTERVAL_S = 0.0005


def parse_address(text: str, name: str = "--listen") -> tuple[str, int]:
    """``HOST:PORT`` as ``(host, port)``; :class:`InputError` if it is not one."""
    host, sep, port = str(text).rpartition(":")
    ascii_port = port.isascii() and port.isdigit()  # "５００６" is a digit to Python
    if not sep or not host or not ascii_port or not 1 <= int(port) <= 65535:
        raise InputError(
            f"{name} must be HOST:PORT with a port from 1 to 65535 (e.g. 127.0.0.1:5005), "
            f"got {text!r}",
            name=name,
            value=text,
        )
    return host.strip("[]"), int(port)


class Listener:
    """UDP datagrams in, checked :class:`BodyFrame` s out (module docstring).

    Parameters
    ----------
    address
        ``(host, port)`` to bind (port 0: any free port; :attr:`address` tells which).
    calibration
        The sensors; a datagram from another is dropped (``unknown_sensor``).
    workspace
        Where a joint may be in the base frame; a datagram with a joint outside is dropped.
    queue_size
        Most datagrams waiting for the control loop; beyond, the oldest are dropped
        (64: two sensors × six bodies × several frames; the loop checks at most this
        many a tick, about 1 ms).
    """

    def __init__(
        self,
        address: tuple[str, int],
        calibration: Calibration,
        workspace: Workspace | None = None,
        queue_size: int = 64,
    ):
        self.calibration = calibration
        self.workspace = workspace or Workspace()
        self.counters: Counter[str] = Counter()
        self._queue: deque[bytes] = deque(maxlen=queue_size)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        family = socket.AF_INET6 if ":" in address[0] else socket.AF_INET
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self._sock.bind(address)
        except OSError as exc:
            self._sock.close()
            raise InputError(
                f"cannot listen on {address[0]}:{address[1]}: {exc.strerror or exc}",
                name="--listen",
                value=address,
            ) from None
        self._sock.settimeout(0.05)
        self.address: tuple[str, int] = self._sock.getsockname()[:2]
        self._thread = threading.Thread(target=self._receive, name="qpavoid-udp", daemon=True)
        self._switch: float | None = None

    def __enter__(self) -> Listener:
        # While listening, threads take turns every 0.5 ms instead of Python's 5 ms, so a
        # flood keeps the control loop waiting for the interpreter lock 0.5 ms at most
        # (measured under a garbage flood: docs/sensors.md). Restored on close.
        self._switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the thread and close the socket."""
        if self._switch is not None:
            sys.setswitchinterval(self._switch)
            self._switch = None
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=1.0)
        self._sock.close()

    def _receive(self) -> None:
        """Receive only: raw datagrams into the bounded queue (newest win). The checks run
        in :meth:`drain`, on the control loop's side, on at most ``queue_size`` datagrams
        a tick: a flood costs this thread a ``recv`` and an ``append`` per datagram."""
        while not self._stop.is_set():
            try:
                data = self._sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:  # closed under us
                return
            with self._lock:
                self.counters["received"] += 1
                if len(self._queue) == self._queue.maxlen:
                    self.counters["dropped_overflow"] += 1
                self._queue.append(data)

    def drain(self) -> list[BodyFrame]:
        """The valid frames among the datagrams that arrived since the last call, oldest
        first; the others dropped and counted by reason."""
        with self._lock:
            raw = list(self._queue)
            self._queue.clear()
        frames = []
        for data in raw:
            try:
                frames.append(decode(data, self.calibration, self.workspace))
            except WireError as exc:
                self.counters[f"dropped_{exc.reason}"] += 1
            except Exception:  # a datagram must never end the loop: dropped, counted
                self.counters["dropped_unreadable"] += 1
        return frames


class LiveSource:
    """The control loop's view of live sensors: ``frame_at(t)`` → (people, capture time).

    Parameters
    ----------
    listener
        Where the frames come from.
    fusion
        Fusion settings.
    clock
        Wall clock (s) that datagram time stamps share; the run clock is its time since
        the first :meth:`frame_at`.
    """

    def __init__(
        self,
        listener: Listener,
        fusion: FusionConfig | None = None,
        clock: Callable[[], float] = time.time,
    ):
        self.listener = listener
        self.fuser = Fuser(listener.calibration, fusion)
        self.clock = clock
        self.start_s: float | None = None  # the wall time of run time 0, set on first use
        self.counters = self.fuser.counters  # out of order, duplicates, outliers, late
        self._captured = float("-inf")

    def report(self) -> dict[str, int]:
        """What came in and what was dropped, by reason (``metrics.json``: ``input``)."""
        counts = Counter(self.listener.counters)
        counts.update({k: v for k, v in self.counters.items() if v})
        return dict(sorted(counts.items()))

    def frame_at(self, t: float) -> tuple[People, float]:
        """Everybody fused at run time ``t`` and the capture time (run clock) of the newest
        frame used (``-inf`` before the first)."""
        if self.start_s is None:
            self.start_s = self.clock() - t
        max_age = self.fuser.cfg.max_age_s
        for frame in self.listener.drain():
            frame = frame._replace(t=frame.t - self.start_s)
            offset = self.listener.calibration[frame.sensor].time_offset_s
            if frame.t + offset < t - max_age:
                self.counters["late"] += 1
            elif frame.t + offset > t + max_age:  # a clock ahead of ours: never trusted
                self.counters["from_the_future"] += 1
            else:
                self.fuser.add(frame)
        fused = self.fuser.fuse(t)
        if fused.captured_s > self._captured:
            self._captured = fused.captured_s
        people = People(tuple(p.id for p in fused.people), tuple(p.frame for p in fused.people))
        return people, self._captured


def replay(
    recordings: Sequence[SensorRecording],
    address: tuple[str, int],
    rate_hz: float = 30.0,
    calibration: Calibration | None = None,
    clock: Callable[[], float] = time.time,
    sleep: Callable[[float], None] = time.sleep,
    mangle: Callable[[int, bytes], Sequence[bytes]] | None = None,
) -> int:
    """Send ``recordings`` to ``address`` as live sensors would; returns datagrams sent.

    Frames go in the order of their capture times (each sensor's time stamps plus its
    ``time_offset_s`` in ``calibration``, 0 without one), paced so that the median frame
    interval of a sensor's body lasts ``1 / rate_hz`` (the recordings' own rate: real
    time). Each is stamped with its send time on ``clock`` as its sensor's clock shows
    it (minus the offset), so the listener's calibration puts it back. ``mangle(i,
    datagram)`` (tests) may replace datagram i by any datagrams, to inject faults.
    """

    def offset(sensor: str) -> float:
        return calibration[sensor].time_offset_s if calibration is not None else 0.0

    frames = sorted(
        (f for rec in recordings for f in rec.frames()), key=lambda f: f.t + offset(f.sensor)
    )
    if not frames:
        return 0
    streams: dict[tuple[str, int], list[float]] = {}
    for f in frames:
        streams.setdefault((f.sensor, f.body), []).append(f.t)
    steps = sorted(b - a for times in streams.values() for a, b in pairwise(times))
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
            data = encode(frame._replace(t=clock() - offset(frame.sensor)))
            for datagram in mangle(i, data) if mangle else (data,):
                sock.sendto(datagram, address)
                sent += 1
    return sent
