"""Signed skeleton datagrams (wire format version 2): :class:`Signer` on the sensor's side,
:class:`Verifier` on the receiver's (docs/security.md).

A datagram is a binary header, a JSON payload and an HMAC-SHA256 tag (big-endian)::

    offset  bytes  field
    0       4      magic b"QPAV"
    4       1      version, 2
    5       1      n, the length of the sensor's name
    6       n      the sensor's name (UTF-8), as in the calibration file
    6+n     4      key id (unsigned): which of the sensor's keys signed it
    10+n    8      sequence number (unsigned), one more per datagram of this sensor
    18+n    8      capture time t, s (IEEE double), on the sensor's clock
    26+n    ...    payload: {"body": 3, "bodies": [0, 3], "joints": [[x, y, z, state],
                   ... 25 rows]} (and "format": "k4abt", then its 32 rows, for a format
                   not the Kinect v2's)
    end-32  32     tag = HMAC-SHA256(key, DOMAIN || len(cell) || cell || every byte before it)

``bodies`` is the frame's manifest (:mod:`qpavoid.sensing.wire`): the body ids of all the
datagrams of its camera frame, which carry consecutive sequence numbers in that order, so
that the frame's number is ``sequence - bodies.index(body)``; :meth:`Signer.encode_frame`
sends a camera frame's bodies so, and the receiver delivers a frame only once every body
it lists came (:mod:`qpavoid.sensing.assembly`). The manifest is in the payload, so the tag
covers it and the header is as it was: no new version (the choice and its reasons:
:mod:`qpavoid.sensing.wire`, docs/security.md §2).

The tag covers a domain string (so that no other message signed with the key can pass for
a datagram), the cell's name from the calibration file (so that one cell's datagrams are
refused by another's), the sensor, the key id, the sequence number, the capture time and
the raw payload bytes. A sender's first sequence number is its start time in
microseconds, so that a sensor restarted later always counts on from above its last run's
numbers (a sensor sends some 200 datagrams a second, far fewer than a million).

:class:`Signer` writes them; :class:`Verifier` checks them in the cheap order, **all but
the last before any JSON is parsed**: length, header, key, the tag (constant-time
compare), the sequence number against a replay window, the capture time against the time
window, and only then the payload and its manifest (:meth:`Verifier.read`). A sequence
number is marked seen only once its datagram has passed the time window: an old genuine
datagram (a recording of the cell's traffic) is ``late`` and moves nothing (an
adversarial tester's: one week-old datagram per sensor had blinded both for good).

HMAC-SHA256, not an AEAD, and why: docs/security.md §2.
"""

from __future__ import annotations

import hmac
import json
import math
import struct
import time
from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

from qpavoid.core.errors import InputError
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.keys import SensorKeys, sensor_name_error
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.replay_window import ReplayWindow
from qpavoid.sensing.wire import (
    MAX_DATAGRAM_BYTES,
    Manifest,
    WireError,
    Workspace,
    decode,
    json_object,
    manifest,
    payload,
    skeleton,
)

__all__ = [
    "DOMAIN",
    "FUTURE_TOLERANCE_S",
    "MAGIC",
    "VERSION_2",
    "Datagram",
    "Fields",
    "Signer",
    "Verifier",
    "fields",
]

#: The signed version (:class:`Signer`, :class:`Verifier`).
VERSION_2 = 2
#: How far after now a frame's capture time may be, s. On one shared clock a frame cannot
#: arrive before it was captured (a Kinect stamps at least 60 ms before); 5 ms covers what
#: PTP or NTP on a cell's network leaves between two clocks, and is far below the 0.1 s a
#: forger once used to make every real frame of a body look out of order.
FUTURE_TOLERANCE_S = 0.005
#: A sender counts from its start time in microseconds and sends far fewer than a million
#: datagrams a second, so its numbers never pass the clock in µs: one that is more than
#: this ahead of it (clocks a second apart) is refused, or a sensor's key holder could set
#: its window's top to 2^64 - 1 and blind it (an adversarial tester's).
SEQUENCE_LEAD_S = 1.0
MAGIC = b"QPAV"
_SIGNED = MAGIC + bytes([VERSION_2])  # the first five bytes of a signed datagram
#: What the tag signs first: no message of another protocol signed with the key can pass.
DOMAIN = b"qpavoid skeleton datagram v2\x00"
TAG_BYTES = 32
_HEAD = struct.Struct("!4sBB")  # magic, version, length of the sensor's name
_IDS = struct.Struct("!IQd")  # key id, sequence number, capture time (s)
#: The shortest signed datagram: a one-letter sensor, a payload of "{}", a tag.
MIN_SIGNED_BYTES = _HEAD.size + 1 + _IDS.size + 2 + TAG_BYTES


def _tag_prefix(cell: str) -> bytes:
    """What every tag of ``cell`` signs before the datagram's own bytes."""
    name = cell.encode()
    return DOMAIN + bytes([len(name)]) + name


class Signer:
    """The sending side of one sensor: its frames as signed version-2 datagrams.

    Parameters
    ----------
    cell
        The cell's name (the calibration's ``cell``).
    keys
        The sensor's keys; the first signs.
    first_sequence
        The first datagram's sequence number (default: now, in microseconds since 1970:
        module docstring).
    """

    def __init__(self, cell: str, keys: SensorKeys, first_sequence: int | None = None):
        self.sensor = keys.sensor
        name = keys.sensor.encode()
        bad_name = sensor_name_error(keys.sensor)
        if bad_name is not None:
            raise InputError(f"sensor {keys.sensor[:80]!r}: {bad_name}", name="sensor")
        self.key_id, self._secret = keys.signing
        self._head = _HEAD.pack(MAGIC, VERSION_2, len(name)) + name
        self._prefix = _tag_prefix(cell)
        self.sequence = time.time_ns() // 1000 if first_sequence is None else first_sequence

    def __repr__(self) -> str:
        return f"Signer(sensor={self.sensor!r}, key_id={self.key_id}, sequence={self.sequence})"

    def seal(self, t: float, payload: bytes, sequence: int | None = None) -> bytes:
        """One signed datagram of ``payload`` (raw bytes) captured at ``t`` (s, the sensor's
        clock), with the next sequence number (or ``sequence``: a sensor's own fault played
        in a test, never a live sender)."""
        if sequence is None:
            sequence = self.sequence
            self.sequence += 1
        body = self._head + _IDS.pack(self.key_id, sequence, t) + payload
        return body + hmac.digest(self._secret, self._prefix + body, "sha256")

    def encode_frame(self, bodies: Sequence[BodyFrame]) -> list[bytes]:
        """The signed datagrams of one camera frame: one per body of ``bodies`` (this
        sensor's, captured at one time, joints in its camera frame), in their order, each
        with the frame's manifest (module docstring). A real camera's process sends every
        body of each frame it captures so: the receiver delivers the frame only once all
        came.

        Raises
        ------
        InputError
            For no body, another sensor's body, bodies of several capture times, or one
            body twice.
        """
        if not bodies:
            raise InputError("a frame of no body: send nothing", name="bodies", value=0)
        for frame in bodies:
            if frame.sensor != self.sensor:
                raise InputError(
                    f"a frame of sensor {frame.sensor!r} signed as {self.sensor!r}",
                    name="sensor",
                    value=frame.sensor,
                )
        times = {float(f.t) for f in bodies}
        ids = [int(f.body) for f in bodies]
        if len(times) > 1 or len(set(ids)) != len(ids):
            raise InputError(
                f"one frame's bodies {ids} captured at {sorted(times)} s: a frame's bodies "
                "are distinct and share its capture time",
                name="bodies",
                value=ids,
            )
        datagrams = []
        for frame in bodies:  # consecutive sequence numbers, in the order of ids
            message = json.dumps(payload(frame, ids), separators=(",", ":")).encode()
            datagrams.append(self.seal(float(frame.t), message))
        return datagrams

    def encode(self, frame: BodyFrame) -> bytes:
        """One signed datagram of ``frame`` (of this sensor: joints in its camera frame),
        a frame of that one body (:meth:`encode_frame` sends a frame of several)."""
        return self.encode_frame([frame])[0]


class Datagram(NamedTuple):
    """A datagram read by :meth:`Verifier.read`: its body's frame, and where it stands
    among its sensor's frames (None for an unsigned datagram: no sequence number)."""

    frame: BodyFrame
    manifest: Manifest | None


class Fields(NamedTuple):
    """The fields of a signed datagram (:func:`fields`)."""

    sensor: str
    key_id: int
    sequence: int
    t: float
    payload: bytes


def fields(datagram: bytes) -> Fields:
    """The fields of a signed datagram, NOT verified (for tools and tests that look at or
    replay traffic).

    Raises
    ------
    WireError
        If it is not laid out as a signed datagram (``bad_header``).
    """
    end = _name_end(datagram)
    key_id, sequence, t = _IDS.unpack_from(datagram, end)
    payload = datagram[end + _IDS.size : -TAG_BYTES]
    return Fields(datagram[6:end].decode("utf-8", "replace"), key_id, sequence, t, payload)


def _name_end(data: bytes) -> int:
    """Where the sensor's name of a signed datagram ends; ``bad_header`` if not laid out so."""
    if len(data) < MIN_SIGNED_BYTES or data[:5] != _SIGNED:
        raise WireError("not a signed (version 2) datagram", reason="bad_header")
    end = 6 + data[5]
    if end + _IDS.size + TAG_BYTES > len(data):
        raise WireError("a sensor name longer than the datagram", reason="bad_header")
    return end


class Verifier:
    """The receiving side: datagrams checked in the cheap order, the tag before any JSON.

    Parameters
    ----------
    calibration
        The sensors, their keys and the cell's name.
    workspace
        Where a joint may be in the base frame (None: anywhere).
    accept_v1
        Also take unsigned version-1 datagrams (:func:`decode`) of sensors that have no
        key: an explicit opt-in, for loopback only (:class:`~qpavoid.loop.live_input.Listener`
        enforces it). A sensor with a key is never believed unsigned.
    max_age_s, future_tolerance_s
        The time window, s: a frame captured more than ``max_age_s`` before ``clock()``
        is ``late``, one more than ``future_tolerance_s`` after it ``from_the_future``
        (each sensor's ``time_offset_s`` applied). ``max_age_s`` is one limit for every
        sensor or each sensor's by name (a live listener's: each camera's
        :attr:`~qpavoid.sensing.calibration.SensorCalibration.age_limit_s`);
        ``max_age_s=None``: no time window (recordings, tests).
    clock
        The shared clock, s.

    Holds a :class:`~qpavoid.sensing.replay_window.ReplayWindow` per sensor and key: one verifier
    per receiver.
    """

    def __init__(
        self,
        calibration: Calibration,
        workspace: Workspace | None = None,
        *,
        accept_v1: bool = False,
        max_age_s: float | Mapping[str, float] | None = None,
        future_tolerance_s: float = FUTURE_TOLERANCE_S,
        clock: Callable[[], float] = time.time,
    ):
        self.calibration, self.workspace, self.accept_v1 = calibration, workspace, accept_v1
        self.max_age_s, self.future_tolerance_s, self.clock = max_age_s, future_tolerance_s, clock
        self._max_age: Mapping[str, float] | None = None  # each sensor's, s
        if isinstance(max_age_s, Mapping):
            self._max_age = {name: float(max_age_s[name]) for name in calibration.sensors}
        elif max_age_s is not None:  # one for all (any real number, numpy's too)
            self._max_age = dict.fromkeys(calibration.sensors, float(max_age_s))
        self._sensors = {name.encode(): name for name in calibration.sensors}
        # one window per sensor and key: a new key counts afresh, whatever an old key's
        # holder did to its window
        self._windows: dict[tuple[str, int], ReplayWindow] = {}
        self.rekey(calibration)

    def rekey(self, calibration: Calibration) -> None:
        """Take the cell's name and the keys of ``calibration`` (the same sensors, read
        again: a key rotated); the windows of the keys kept are kept."""
        self._prefix = _tag_prefix(calibration.cell)
        self._secrets = {
            (name.encode(), kid): secret
            for name, keys in calibration.keys.items()
            if name in self.calibration.sensors
            for kid, secret in keys.keys
        }
        kept = {(n.decode(), kid) for n, kid in self._secrets}
        self._windows = {k: w for k, w in self._windows.items() if k in kept}

    def decode(self, data: bytes) -> BodyFrame:
        """The :class:`BodyFrame` of a datagram, verified and checked (:meth:`read`)."""
        return self.read(data).frame

    def read(self, data: bytes) -> Datagram:
        """A datagram verified and checked: its body's frame and, if signed, its manifest
        (checked against the datagram's own body and sequence number).

        Raises
        ------
        WireError
            With the first reason that applies, in the order of :data:`REASONS`.
        """
        n = len(data)
        if n > MAX_DATAGRAM_BYTES:
            raise WireError(f"datagram of {n} bytes", reason="too_long")
        if data[:1] == b"{":
            if not self.accept_v1 or self.calibration.authenticated:
                raise WireError("an unsigned (version 1) datagram", reason="unauthenticated")
            frame = decode(data, self.calibration, self.workspace)
            self._check_time(frame.sensor, frame.t, self.clock())
            return Datagram(frame, None)
        end = _name_end(data)
        raw_name = data[6:end]
        name = self._sensors.get(raw_name)
        if name is None:
            raise WireError("unknown sensor", reason="unknown_sensor")
        key_id, sequence, t = _IDS.unpack_from(data, end)
        secret = self._secrets.get((raw_name, key_id))
        if secret is None:
            raise WireError(f"unknown key id {key_id} of {name!r}", reason="unknown_key")
        body, tag = data[:-TAG_BYTES], data[-TAG_BYTES:]
        if not hmac.compare_digest(hmac.digest(secret, self._prefix + body, "sha256"), tag):
            raise WireError(f"a tag that does not verify ({name!r})", reason="bad_tag")
        window = self._windows.setdefault((name, key_id), ReplayWindow())
        if window.seen(sequence):
            raise WireError(f"sequence number {sequence} of {name!r} seen", reason="replayed")
        now = self.clock()
        if sequence > (now + SEQUENCE_LEAD_S) * 1e6:
            raise WireError(f"sequence number {sequence} ahead of the clock", reason="replayed")
        self._check_time(name, t, now)
        window.mark(sequence)  # only now: an old or future datagram moves nothing
        message = json_object(body[end + _IDS.size :])
        frame = skeleton(message, name, self.calibration, self.workspace, t)
        max_bodies = self.calibration[name].skeleton.sensor.max_bodies
        return Datagram(frame, manifest(message, frame.body, key_id, sequence, max_bodies))

    def _check_time(self, sensor: str, t: float, now: float) -> None:
        """:class:`WireError` ``late`` or ``from_the_future`` outside the time window
        around ``now``."""
        if self._max_age is None:
            return
        if not math.isfinite(t):
            raise WireError(f"t {t!r}", reason="non_finite")
        age = now - (t + self.calibration[sensor].time_offset_s)
        limit = self._max_age[sensor]
        if age > limit:
            raise WireError(
                f"captured {age:.3f} s ago, over {sensor}'s age limit {limit:.3f} s", reason="late"
            )
        if age < -self.future_tolerance_s:
            raise WireError(f"captured {-age:.3f} s from now", reason="from_the_future")
