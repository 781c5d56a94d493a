"""The receiving side of a live listener, in a process of its own: datagrams in, each
sensor's whole frames out (the newest of each body, in shared memory), and its losses.

A flood of datagrams must not delay the control loop. In a thread, receiving and
checking them competes with the loop for Python's interpreter lock (measured in
docs/sensors.md: 73 overruns in 6 s under a flood of valid datagrams). So :func:`serve`
runs in a child process (``multiprocessing``, spawn), at a lower priority than the loop
(``nice`` +10), and does all the work per datagram: receive, check
(:func:`~qpavoid.sensing.wire.decode`, drops counted by reason), assemble each sensor's camera
frames (:func:`~qpavoid.sensing.assembly.assemble`: a frame is delivered only once every body
its manifest lists came) and keep each body's newest frame in a :class:`SlotTable`, one
fixed slot per (sensor, body), with each sensor's lost frames and the capture time before
which its frames are stale (:meth:`SlotTable.losses`).

Each datagram is verified first (:class:`~qpavoid.sensing.wire.Verifier`: length, header, key,
the tag in constant time before any JSON, the sequence number against a replay window,
then the skeleton); then, its time stamp now authenticated, a frame captured longer before
now than its sensor's age limit is dropped (``late``: :attr:`~qpavoid.sensing.calibration.
SensorCalibration.age_limit_s`, the camera's latency, a frame and a margin), one captured more than
``future_tolerance_s`` after now too (``from_the_future``: a sensor stamps its capture
before it sends, so a clock ahead of ours must not poison the order), and one not newer
than its body's last, or of a frame already closed (``out_of_order_or_duplicate``); the
others wait for the rest of their frame and are ``accepted`` when it is whole, or, when a
later frame shows it incomplete, counted ``incomplete_frame`` (``lost_frames`` counts the
frames found incomplete or missing). One replaced before the loop took it is counted
``superseded``: ``received`` is ``accepted`` plus every drop, plus the datagrams of the
frames still incomplete (at most a frame's bodies less one per sensor). The loop's side
(:meth:`SlotTable.take`) costs the same whatever arrives: one lock, one copy of at most
sensors × bodies slots (the most ``max_bodies`` of the sensors' formats a sensor, six for
the Kinect v2). Each slot is as wide as the cell's widest format; a sensor's frames fill
its format's share of it.
"""

from __future__ import annotations

import contextlib
import math
import os
import socket
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from multiprocessing.context import SpawnContext
from typing import Any, NamedTuple

import numpy as np

from qpavoid.core.errors import CalibrationError
from qpavoid.core.signals import worker_process
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.sensing.assembly import SensorFrames, Step, assemble
from qpavoid.sensing.calibration import Calibration, known_formats
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.signing import FUTURE_TOLERANCE_S, Verifier
from qpavoid.sensing.wire import REASONS, SKELETON, FormatMismatchError, WireError, Workspace

__all__ = ["COUNTERS", "SensorLoss", "SlotTable", "serve"]

#: The time window's drops, counted under their own names (not ``dropped_...``).
TIME_REASONS = ("late", "from_the_future")

#: What the receiver counts, in this order in shared memory.
COUNTERS = (
    "received",
    "accepted",
    "superseded",
    "late",
    "from_the_future",
    "out_of_order_or_duplicate",
    *(f"dropped_{reason}" for reason in REASONS if reason not in TIME_REASONS),
    "dropped_unreadable",
    "keys_reloaded",
    "keys_reload_failed",
    "lost_frames",
    "incomplete_frame",
)
#: How often the receiver looks whether the calibration or a key file changed, s (a
#: rotation is taken within a second, without a stop; a stat of three files costs µs).
KEY_CHECK_S = 1.0
#: A slot's values before the frame's: sequence number written, sequence number taken, t
#: (then the joints, J × 3, and their states, J).
SLOT_HEAD = 3
#: Priority the receiver drops to, so that the control loop gets the CPU first.
NICE = 10
#: Bytes kept of the first wrong format a sensor sent (:meth:`SlotTable.format_mismatches`):
#: a format's name as :class:`~qpavoid.sensing.wire.FormatMismatchError` keeps it.
FORMAT_NAME_BYTES = 40


class SensorLoss(NamedTuple):
    """A sensor's losses so far (:meth:`SlotTable.losses`): frames found missing or
    incomplete, and the capture time (s, the sensor's clock; -inf: none) before which its
    frames are stale."""

    frames: int
    stale_before_s: float


@dataclass
class SlotTable:
    """Each (sensor, body)'s newest frame, in memory shared by the receiver and the loop.

    Built by :meth:`create`. A slot holds :data:`SLOT_HEAD` values, then a frame's joints
    (``n_joints × 3``) and states (``n_joints``); each sensor has ``max_bodies`` slots.

    Attributes
    ----------
    sensors
        The sensors' names, in slot order.
    values
        The slots (a multiprocessing Array of doubles, sensors × max_bodies × slot width).
    counts
        The counters (a multiprocessing Array of int64, in :data:`COUNTERS` order).
    lost
        Each sensor's :class:`SensorLoss` (a multiprocessing Array of doubles, two a
        sensor, in slot order).
    lock
        Guards the three.
    n_joints, max_bodies
        Joints per frame and bodies per sensor of the slots: the most of the sensors'
        formats.
    formats
        Each sensor's skeleton format (a name, in slot order): a frame of another is
        not kept (``dropped_wrong_format``).
    wrong_formats
        The first other format each sensor sent (a multiprocessing Array of
        :data:`FORMAT_NAME_BYTES` bytes a sensor, in slot order; empty: none yet):
        :meth:`format_mismatches`.
    """

    sensors: tuple[str, ...]
    values: Any
    counts: Any
    lost: Any
    lock: Any
    n_joints: int
    max_bodies: int
    formats: tuple[str, ...] = ()
    wrong_formats: Any = None

    @classmethod
    def create(
        cls,
        context: SpawnContext,
        sensors: Sequence[str] | Calibration,
        skeleton: SkeletonFormat = SKELETON,
    ) -> SlotTable:
        """Zeroed slots and counters for ``sensors``' bodies.

        Parameters
        ----------
        context
            The multiprocessing context that makes the shared arrays and the lock.
        sensors
            The sensors: a calibration (each sensor's slots for its calibrated format), or
            their names, in slot order (every sensor's of ``skeleton``).
        skeleton
            The skeleton format of the frames of sensors given by name (by default the
            wire format's, :data:`~qpavoid.sensing.wire.SKELETON`).
        """
        if isinstance(sensors, Calibration):
            names, formats = sensors.names, sensors.formats
        else:
            names, formats = tuple(sensors), (skeleton.name,) * len(sensors)
        kinds = [known_formats().get(f, skeleton) for f in formats] or [skeleton]
        n_joints = max(fmt.n_joints for fmt in kinds)
        max_bodies = max(fmt.sensor.max_bodies for fmt in kinds)
        n = len(names) * max_bodies * (SLOT_HEAD + 4 * n_joints)
        values = context.Array("d", n, lock=False)
        counts = context.Array("q", len(COUNTERS), lock=False)
        lost = context.Array("d", [0.0, -math.inf] * len(names), lock=False)
        lock = context.Lock()
        wrong = context.Array("c", FORMAT_NAME_BYTES * len(names), lock=False)
        return cls(names, values, counts, lost, lock, n_joints, max_bodies, tuple(formats), wrong)

    def _arrays(self) -> tuple[np.ndarray, np.ndarray]:
        width = SLOT_HEAD + 4 * self.n_joints
        rows = np.frombuffer(self.values, dtype=np.float64).reshape(-1, width)
        return rows, np.frombuffer(self.counts, dtype=np.int64)

    def counters(self) -> dict[str, int]:
        """Every counter, by name."""
        counts = self._arrays()[1]
        with self.lock:
            values = counts.tolist()
        return dict(zip(COUNTERS, values, strict=True))

    def losses(self) -> dict[str, SensorLoss]:
        """Each sensor's losses so far (the loop's side). Read after :meth:`take`: a loss
        is written with the frame that showed it, so every loss of a frame taken is seen."""
        lost = np.frombuffer(self.lost, dtype=np.float64)
        with self.lock:
            values = lost.tolist()
        return {
            name: SensorLoss(int(values[2 * i]), values[2 * i + 1])
            for i, name in enumerate(self.sensors)
        }

    def format_mismatches(self) -> dict[str, tuple[str, str]]:
        """Each sensor that sent a datagram of another skeleton format than its calibrated
        one (``dropped_wrong_format``): (the first format that arrived, the format
        expected), by name."""
        if self.wrong_formats is None:
            return {}
        with self.lock:
            raw = bytes(self.wrong_formats)
        out = {}
        for i, name in enumerate(self.sensors):
            arrived = raw[i * FORMAT_NAME_BYTES : (i + 1) * FORMAT_NAME_BYTES].rstrip(b"\0")
            if arrived:
                out[name] = (arrived.decode("utf-8", "replace"), self._format(i).name)
        return out

    def _note_wrong_format(self, sensor: int, arrived: str) -> None:
        """Keep ``arrived`` as the ``sensor``-th sensor's first wrong format (the lock held)."""
        if self.wrong_formats is None:
            return
        at = sensor * FORMAT_NAME_BYTES
        if self.wrong_formats[at] == b"\0":
            name = arrived.encode("utf-8", "replace")[:FORMAT_NAME_BYTES] or b"?"
            self.wrong_formats[at : at + len(name)] = name

    def take(self) -> list[BodyFrame]:
        """The frames written since the last call, oldest first (the loop's side)."""
        rows, _ = self._arrays()
        with self.lock:
            new = np.flatnonzero(rows[:, 0] > rows[:, 1])
            picked = rows[new].copy()
            rows[new, 1] = rows[new, 0]
        bodies, states = self.max_bodies, SLOT_HEAD + 3 * self.n_joints
        frames = []
        for slot, row in zip(new, picked, strict=True):
            sensor = slot // bodies
            fmt = self._format(sensor)
            n = fmt.n_joints
            frames.append(
                BodyFrame(
                    self.sensors[sensor],
                    int(slot % bodies),
                    float(row[2]),
                    row[SLOT_HEAD : SLOT_HEAD + 3 * n].reshape(n, 3),
                    row[states : states + n].astype(np.int8),
                    fmt.name,
                )
            )
        return sorted(frames, key=lambda f: f.t)

    def _format(self, sensor: int) -> SkeletonFormat:
        """The skeleton format of the ``sensor``-th sensor's slots."""
        name = self.formats[sensor] if self.formats else SKELETON.name
        return known_formats()[name]


def serve(
    address: tuple[str, int],
    calibration: Calibration,
    workspace: Workspace,
    table: SlotTable,
    status: Connection,
    stop: Any,
    max_age_s: float | Mapping[str, float],
    parent_pid: int,
    accept_v1: bool = False,
    future_tolerance_s: float = FUTURE_TOLERANCE_S,
    key_check_s: float = KEY_CHECK_S,
) -> None:
    """The receiver process: bind ``address``, tell ``status`` ``("ok", address)`` or
    ``("error", why)``, then receive until ``stop`` (an Event) is set or the parent
    process ``parent_pid`` is gone (killed: the port must not stay taken).

    Ctrl-C is the parent's to handle (it stops this process): ignored here. Datagrams are
    verified (unsigned ones taken only with ``accept_v1``); a frame captured more than
    ``max_age_s`` (one for all, or each sensor's by name) before now (``late``) or more
    than ``future_tolerance_s`` after now
    (``from_the_future``, a clock ahead of ours) is dropped before it can count as its
    body's newest. The calibration and key files are looked at every ``key_check_s`` and
    read again when one changed (a rotated key).
    """
    worker_process()  # Ctrl-C ignored, SIGTERM ends it, both unblocked (blocked by the parent)
    with contextlib.suppress(OSError):  # not allowed here: it runs at the loop's priority
        os.nice(NICE)
    family = socket.AF_INET6 if ":" in address[0] else socket.AF_INET
    with socket.socket(family, socket.SOCK_DGRAM) as sock:
        try:
            sock.bind(address)
        except OSError as exc:
            status.send(("error", exc.strerror or str(exc)))
            return
        status.send(("ok", sock.getsockname()[:2]))
        sock.settimeout(0.05)
        verifier = Verifier(
            calibration,
            workspace,
            accept_v1=accept_v1,
            max_age_s=max_age_s,
            future_tolerance_s=future_tolerance_s,
        )
        _receive(sock, verifier, _KeyWatch(calibration, key_check_s), table, stop, parent_pid)


class _KeyWatch:
    """The calibration file and its key files, read again when one of them changes, so
    that a rotated key is taken without a stop (docs/security.md §6). A reading that fails
    (a key file caught half-written, a mode made loose) keeps the keys in use."""

    def __init__(self, calibration: Calibration, every_s: float):
        self.calibration, self.path = calibration, calibration.path
        self.files = _watched(calibration)
        self.stamp = self._stamp()
        self.every_s = every_s
        self.next_s = time.monotonic() + every_s

    def _stamp(self) -> tuple:
        stamps: list[tuple[int, int, int, int] | None] = []
        for f in self.files:
            try:
                info = os.stat(f)
                stamps.append((info.st_mtime_ns, info.st_size, info.st_ino, info.st_mode))
            except OSError:
                stamps.append(None)
        return tuple(stamps)

    def changed(self) -> Calibration | str | None:
        """A calibration read again if a file changed, why not if reading it failed (a
        string), None if nothing changed (or it is not time to look)."""
        now = time.monotonic()
        if self.path is None or now < self.next_s:
            return None
        self.next_s = now + self.every_s
        stamp = self._stamp()
        if stamp == self.stamp:
            return None
        self.stamp = stamp
        try:
            again = load_calibration(self.path)
        except CalibrationError as exc:
            return str(exc)
        if not _same_sensors(again, self.calibration):
            return (
                "only the keys are read again: a new pose, clock, format or sensor needs a restart"
            )
        self.files = _watched(again)  # a key_file that now names another file: that one
        self.stamp = self._stamp()
        return again


def _watched(calibration: Calibration) -> list[str]:
    """The calibration file and the key files it names."""
    return [f for f in (calibration.path, *calibration.key_files.values()) if f]


def _same_sensors(a: Calibration, b: Calibration) -> bool:
    """The same sensors, poses, clocks, weights, views and formats (keys and cell aside)."""
    return list(a.sensors) == list(b.sensors) and all(
        np.array_equal(a[n].base_from_camera, b[n].base_from_camera)
        and (a[n].time_offset_s, a[n].weight, a[n].field_of_view_deg, a[n].range_m, a[n].format)
        == (b[n].time_offset_s, b[n].weight, b[n].field_of_view_deg, b[n].range_m, b[n].format)
        for n in a.sensors
    )


def _receive(
    sock: socket.socket,
    verifier: Verifier,
    watch: _KeyWatch,
    table: SlotTable,
    stop: Any,
    parent_pid: int,
) -> None:
    rows, counts = table._arrays()
    lost = np.frombuffer(table.lost, dtype=np.float64).reshape(-1, 2)
    index = {name: i for i, name in enumerate(table.sensors)}
    formats = {name: table._format(i).name for i, name in enumerate(table.sensors)}
    code = {name: i for i, name in enumerate(COUNTERS)}
    newest = np.full(len(rows), -np.inf)
    assembly = {name: SensorFrames() for name in table.sensors}
    bodies, states = table.max_bodies, SLOT_HEAD + 3 * table.n_joints
    while not stop.is_set() and os.getppid() == parent_pid:
        reread = watch.changed()
        if reread is not None:
            if isinstance(reread, Calibration):
                verifier.rekey(reread)
            failed = isinstance(reread, str)
            with table.lock:
                counts[code["keys_reload_failed" if failed else "keys_reloaded"]] += 1
        try:
            data = sock.recv(65536)
        except TimeoutError:
            continue
        except OSError:  # closed under us
            return
        step: Step | None = None  # what the datagram did to its sensor's frames, if taken
        reason = "out_of_order_or_duplicate"  # why not, if not
        mismatch: FormatMismatchError | None = None
        try:
            frame, place = verifier.read(data)
            if frame.format != formats[frame.sensor]:  # a table not made for this calibration
                raise FormatMismatchError(frame.sensor, frame.format, formats[frame.sensor])
            newer = frame.t > newest[index[frame.sensor] * bodies + int(frame.body)]
            if newer and place is None:  # unsigned: no sequence number, a frame of its own
                step = Step(SensorFrames(), (frame,))
            elif newer and place is not None:
                step = assemble(assembly[frame.sensor], frame, place)
                assembly[frame.sensor] = step.state
                step = None if step.closed else step
        except WireError as exc:
            reason = exc.reason if exc.reason in TIME_REASONS else f"dropped_{exc.reason}"
            mismatch = exc if isinstance(exc, FormatMismatchError) else None
        except Exception:  # a datagram must never end the receiver: dropped, counted
            reason = "dropped_unreadable"
        with table.lock:
            counts[0] += 1
            if step is None:
                counts[code[reason]] += 1
                if mismatch is not None and mismatch.sensor in index:
                    table._note_wrong_format(index[mismatch.sensor], mismatch.arrived)
                continue
            if step.lost:
                sensor = lost[index[frame.sensor]]
                sensor[0] += 1
                sensor[1] = max(sensor[1], step.stale_before_s)
                counts[code["lost_frames"]] += 1
                counts[code["incomplete_frame"]] += step.discarded
            for whole in step.complete:
                slot = index[whole.sensor] * bodies + int(whole.body)
                n = len(whole.state)
                row = rows[slot]
                counts[code["accepted"]] += 1
                counts[code["superseded"]] += row[0] > row[1]  # the last one was never taken
                row[0] += 1.0
                row[2] = whole.t
                row[SLOT_HEAD : SLOT_HEAD + 3 * n] = np.ravel(whole.joints)
                row[states : states + n] = whole.state
                newest[slot] = whole.t
