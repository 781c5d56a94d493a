"""The wire format of live skeletons: one UDP datagram per body per sensor frame.

**Version 2, signed** (the default: docs/security.md). A datagram is a binary header, a
JSON payload and an HMAC-SHA256 tag (big-endian integers)::

    offset  bytes  field
    0       4      magic b"QPAV"
    4       1      version, 2
    5       1      n, the length of the sensor's name
    6       n      the sensor's name (UTF-8), as in the calibration file
    6+n     4      key id (unsigned): which of the sensor's keys signed it
    10+n    8      sequence number (unsigned), one more per datagram of this sensor
    18+n    ...    payload: {"body": 0, "t": 1763864400.0333, "joints": [[x, y, z, state], ...]}
    end-32  32     tag = HMAC-SHA256(key, DOMAIN || len(cell) || cell || every byte before it)

The tag covers a domain string (so that no other message signed with the key can pass for
a datagram), the cell's name from the calibration file (so that one cell's datagrams are
refused by another's), the sensor, the key id, the sequence number and the raw payload
bytes. A sender's first sequence number is its start time in microseconds, so that a
sensor restarted later always counts on from above its last run's numbers (a sensor sends
some 200 datagrams a second, far fewer than a million). :class:`Signer` writes them;
:class:`Verifier` checks them in the cheap order: length, header, key, then the tag with a
constant-time compare **before any JSON is parsed**, then the sequence number against a
replay window, and only then the payload.

HMAC-SHA256 rather than an AEAD (ChaCha20-Poly1305): Python's standard library computes
it (no new dependency, no native code of ours), and it is what the black-channel safety
protocols ask of an untrusted network (integrity and authenticity). It does not hide the
skeletons, which are personal data: a cell network that must keep them confidential runs
the sensors' traffic through an encrypted link (docs/security.md).

**Version 1, unsigned** (only with an explicit opt-in, on loopback): one UTF-8 JSON
object::

    {"v": 1, "sensor": "kinect_left", "body": 0, "t": 1763864400.0333,
     "joints": [[x, y, z, state], ... 25 rows in Kinect JointType order]}

In both:

* ``sensor``: the sensor's name, as in the calibration file.
* ``body``: the sensor's body id, 0-5.
* ``t``: capture time, s, on a clock shared with the controller (UNIX time from PTP or
  NTP; the calibration's ``time_offset_s`` corrects a known offset).
* ``joints``: 25 rows ``[x, y, z, state]`` in the sensor's camera frame, m (six
  decimals); ``state`` 0
  (not tracked: the coordinates are ignored), 1 (inferred) or 2 (tracked).

JSON is chosen over a binary layout for the skeleton because every language and tool
reads it and a datagram of one body (about 1 kB) is parsed in tens of microseconds
(docs/sensors.md); a forged one is refused by its tag in a few (docs/performance.md).
:func:`decode` and :meth:`Verifier.decode` refuse anything else with a :class:`WireError`
whose ``reason`` is one of :data:`REASONS`: the listener counts the drops by reason and
carries on.
"""

from __future__ import annotations

import hmac
import json
import math
import struct
import time
from dataclasses import dataclass

import numpy as np

from .calibration import Calibration
from .errors import InputError
from .frames import N_KINECT_JOINTS
from .keys import SensorKeys
from .sensor_recording import MAX_BODIES, BodyFrame

__all__ = [
    "DOMAIN",
    "MAX_DATAGRAM_BYTES",
    "REASONS",
    "REPLAY_WINDOW",
    "VERSION",
    "ReplayWindow",
    "Signer",
    "Verifier",
    "WireError",
    "Workspace",
    "decode",
    "encode",
    "fields",
]

#: The unsigned JSON version (:func:`encode`, :func:`decode`).
VERSION = 1
#: The signed version (:class:`Signer`, :class:`Verifier`).
VERSION_2 = 2
MAGIC = b"QPAV"
#: What the tag signs first: no message of another protocol signed with the key can pass.
DOMAIN = b"qpavoid skeleton datagram v2\x00"
TAG_BYTES = 32
#: Sequence numbers accepted below the highest seen (RFC 4303's default window, 64): the
#: bodies of one frame may arrive in any order; a number seen or below the window is a
#: replay.
REPLAY_WINDOW = 64
_HEAD = struct.Struct("!4sBB")  # magic, version, length of the sensor's name
_IDS = struct.Struct("!IQ")  # key id, sequence number
#: The shortest signed datagram: a one-letter sensor, an empty payload of "{}", a tag.
MIN_SIGNED_BYTES = _HEAD.size + 1 + _IDS.size + 2 + TAG_BYTES
#: Longest datagram accepted, bytes (a body is about 1 kB; 8 kB leaves room, refuses junk).
MAX_DATAGRAM_BYTES = 8192
#: Coordinates are sent to the micrometre (a Kinect measures to the millimetre), which keeps
#: a body's datagram near 1 kB, inside one Ethernet frame.
COORDINATE_DECIMALS = 6
#: Why a datagram is dropped, in the order they are checked.
REASONS = (
    "too_long",
    "unauthenticated",
    "bad_header",
    "unknown_sensor",
    "unknown_key",
    "bad_tag",
    "replayed",
    "bad_json",
    "bad_version",
    "bad_field",
    "non_finite",
    "outside_workspace",
)


class WireError(InputError):
    """A datagram that is not a valid skeleton; ``reason`` is one of :data:`REASONS`."""

    def __init__(self, message: str, *, reason: str):
        super().__init__(message, name="datagram", value=reason)
        self.reason = reason


@dataclass(frozen=True)
class Workspace:
    """Where a person's joint may be, in the robot base frame, m (a box).

    The defaults hold a Kinect v2's 4.5 m range around a robot at the origin, with the
    floor a metre below its base; a joint outside is a calibration or sensor error.
    """

    lower_m: tuple[float, float, float] = (-6.0, -6.0, -1.5)
    upper_m: tuple[float, float, float] = (6.0, 6.0, 3.0)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(N,) True where a point (N, 3) is inside."""
        return np.all((points >= self.lower_m) & (points <= self.upper_m), axis=1)


def _rows(frame: BodyFrame) -> list[list[float]]:
    """The joints as sent: camera frame, to the micrometre, NaN joints as state 0."""
    joints = np.asarray(frame.joints, dtype=float)
    state = np.asarray(frame.state, dtype=int)
    rows = []
    for xyz, s in zip(joints, state, strict=True):
        if not np.isfinite(xyz).all():
            rows.append([0.0, 0.0, 0.0, 0])
        else:
            rows.append([*(round(float(v), COORDINATE_DECIMALS) for v in xyz), int(s)])
    return rows


def encode(frame: BodyFrame) -> bytes:
    """One unsigned version-1 datagram of ``frame`` (joints in its camera frame, to the
    micrometre; joints that are NaN are sent as state 0)."""
    message = {"v": VERSION, "sensor": frame.sensor, "body": int(frame.body), "t": frame.t}
    message["joints"] = _rows(frame)
    return json.dumps(message, separators=(",", ":")).encode()


def decode(data: bytes, calibration: Calibration, workspace: Workspace | None = None) -> BodyFrame:
    """The :class:`BodyFrame` of an unsigned version-1 datagram, checked; joints stay in
    the camera frame.

    Raises
    ------
    WireError
        With the reason (:data:`REASONS`) for anything that is not a valid version-1
        skeleton of a calibrated sensor whose tracked joints lie in ``workspace``.
    """
    if len(data) > MAX_DATAGRAM_BYTES:
        raise WireError(f"datagram of {len(data)} bytes", reason="too_long")
    msg = _json(data)
    if (
        msg.get("v") != VERSION
        or not isinstance(msg.get("v"), int)
        or isinstance(msg.get("v"), bool)
    ):
        raise WireError(f"version {msg.get('v')!r}, expected {VERSION}", reason="bad_version")
    sensor = msg.get("sensor")
    if not isinstance(sensor, str) or not sensor:
        raise WireError(f"sensor {sensor!r}", reason="bad_field")
    return _skeleton(msg, sensor, calibration, workspace)


def _json(data: bytes) -> dict:
    """The JSON object of ``data``, or :class:`WireError`."""
    try:
        msg = json.loads(data.decode("utf-8"), parse_constant=_refuse_constant)
    except _NonFiniteError as exc:
        raise WireError(f"non-finite number {exc}", reason="non_finite") from None
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise WireError(f"not JSON: {exc}", reason="bad_json") from None
    if not isinstance(msg, dict):
        raise WireError("not a JSON object", reason="bad_json")
    return msg


def _skeleton(
    msg: dict, sensor: str, calibration: Calibration, workspace: Workspace | None
) -> BodyFrame:
    """The body frame of a message's ``body``, ``t`` and ``joints``, checked."""
    body, t, rows = (msg.get(k) for k in ("body", "t", "joints"))
    if not isinstance(body, int) or isinstance(body, bool) or not 0 <= body < MAX_BODIES:
        raise WireError(f"body {body!r}", reason="bad_field")
    if not isinstance(t, (int, float)) or isinstance(t, bool):
        raise WireError(f"t {str(t)[:40]}", reason="bad_field")
    try:
        t = float(t)  # a JSON integer may be too large for a float
        arr = np.array(rows, dtype=float)
    except OverflowError:
        raise WireError("a number too large for a float", reason="non_finite") from None
    except (TypeError, ValueError):
        raise WireError("joints are not 25 rows of 4 numbers", reason="bad_field") from None
    if not math.isfinite(t):
        raise WireError(f"t {t!r}", reason="non_finite")
    if arr.shape != (N_KINECT_JOINTS, 4) or not _all_numbers(rows):
        raise WireError(f"joints of shape {arr.shape}, expected (25, 4)", reason="bad_field")
    if not np.isfinite(arr).all():
        raise WireError("a non-finite coordinate", reason="non_finite")
    state = arr[:, 3]
    if not np.isin(state, (0, 1, 2)).all():
        raise WireError(f"states {sorted(set(state.tolist()))}", reason="bad_field")
    if sensor not in calibration.sensors:
        raise WireError(f"unknown sensor {sensor!r}", reason="unknown_sensor")
    joints = arr[:, :3].copy()
    used = state > 0
    joints[~used] = np.nan
    if workspace is not None and used.any():
        in_base = calibration[sensor].to_base(joints[used])
        if not workspace.contains(in_base).all():
            raise WireError("a joint outside the workspace", reason="outside_workspace")
    return BodyFrame(sensor, body, float(t), joints, state.astype(np.int8))


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
        if not 1 <= len(name) <= 255:
            raise InputError(f"sensor name {keys.sensor!r} is not 1 to 255 bytes", name="sensor")
        self.key_id, self._secret = keys.signing
        self._head = _HEAD.pack(MAGIC, VERSION_2, len(name)) + name
        self._prefix = _tag_prefix(cell)
        self.sequence = time.time_ns() // 1000 if first_sequence is None else first_sequence

    def __repr__(self) -> str:
        return f"Signer(sensor={self.sensor!r}, key_id={self.key_id}, sequence={self.sequence})"

    def seal(self, payload: bytes, sequence: int | None = None) -> bytes:
        """One signed datagram of ``payload`` (raw bytes), with the next sequence number
        (or ``sequence``: a sensor's own fault played in a test, never a live sender)."""
        if sequence is None:
            sequence = self.sequence
            self.sequence += 1
        body = self._head + _IDS.pack(self.key_id, sequence) + payload
        return body + hmac.digest(self._secret, self._prefix + body, "sha256")

    def encode(self, frame: BodyFrame) -> bytes:
        """One signed datagram of ``frame`` (of this sensor: joints in its camera frame)."""
        if frame.sensor != self.sensor:
            raise InputError(
                f"a frame of sensor {frame.sensor!r} signed as {self.sensor!r}", name="sensor"
            )
        message = {"body": int(frame.body), "t": frame.t, "joints": _rows(frame)}
        return self.seal(json.dumps(message, separators=(",", ":")).encode())


def fields(datagram: bytes) -> tuple[str, int, int, bytes]:
    """``(sensor, key id, sequence number, payload)`` of a signed datagram, NOT verified
    (for tools and tests that look at or replay traffic).

    Raises
    ------
    WireError
        If it is not laid out as a signed datagram (``bad_header``).
    """
    if len(datagram) < MIN_SIGNED_BYTES or datagram[:5] != MAGIC + bytes([VERSION_2]):
        raise WireError("not a signed (version 2) datagram", reason="bad_header")
    end = 6 + datagram[5]
    if end + _IDS.size + TAG_BYTES > len(datagram):
        raise WireError("a sensor name longer than the datagram", reason="bad_header")
    key_id, sequence = _IDS.unpack_from(datagram, end)
    payload = datagram[end + _IDS.size : -TAG_BYTES]
    return datagram[6:end].decode("utf-8", "replace"), key_id, sequence, payload


class ReplayWindow:
    """Which sequence numbers of one sender were seen: the highest, and a bit for each of
    the :data:`REPLAY_WINDOW` below it (RFC 4303, section 3.4.3)."""

    def __init__(self, size: int = REPLAY_WINDOW):
        self.size, self.top, self._bits = size, -1, 0

    def accept(self, sequence: int) -> bool:
        """True, and ``sequence`` marked seen, if it was not seen and is not below the
        window; False otherwise (a replay)."""
        if sequence > self.top:
            shift = sequence - self.top
            self._bits = ((self._bits << shift) | 1) & ((1 << self.size) - 1)
            self.top = sequence
            return True
        offset = self.top - sequence
        if offset >= self.size or (self._bits >> offset) & 1:
            return False
        self._bits |= 1 << offset
        return True


class Verifier:
    """The receiving side: datagrams checked in the cheap order, the tag before any JSON.

    Parameters
    ----------
    calibration
        The sensors, their keys and the cell's name.
    workspace
        Where a joint may be in the base frame (None: anywhere).
    accept_v1
        Also take unsigned version-1 datagrams (:func:`decode`): an explicit opt-in, for
        loopback only (:class:`~qpavoid.live.Listener` enforces it).

    Holds a :class:`ReplayWindow` per sensor: one verifier per receiver.
    """

    def __init__(
        self,
        calibration: Calibration,
        workspace: Workspace | None = None,
        *,
        accept_v1: bool = False,
    ):
        self.calibration, self.workspace, self.accept_v1 = calibration, workspace, accept_v1
        self._prefix = _tag_prefix(calibration.cell)
        self._secrets = {
            (name.encode(), kid): secret
            for name, keys in calibration.keys.items()
            for kid, secret in keys.keys
        }
        self._sensors = {name.encode(): name for name in calibration.sensors}
        self._windows = {name: ReplayWindow() for name in calibration.sensors}

    def decode(self, data: bytes) -> BodyFrame:
        """The :class:`BodyFrame` of a datagram, verified and checked.

        Raises
        ------
        WireError
            With the first reason that applies, in the order of :data:`REASONS`.
        """
        n = len(data)
        if n > MAX_DATAGRAM_BYTES:
            raise WireError(f"datagram of {n} bytes", reason="too_long")
        if data[:1] == b"{":
            if not self.accept_v1:
                raise WireError("an unsigned (version 1) datagram", reason="unauthenticated")
            return decode(data, self.calibration, self.workspace)
        if n < MIN_SIGNED_BYTES or data[:5] != MAGIC + bytes([VERSION_2]):
            raise WireError("not a signed (version 2) datagram", reason="bad_header")
        end = 6 + data[5]
        if end + _IDS.size + TAG_BYTES > n:
            raise WireError("a sensor name longer than the datagram", reason="bad_header")
        name = self._sensors.get(data[6:end])
        if name is None:
            raise WireError("unknown sensor", reason="unknown_sensor")
        key_id, sequence = _IDS.unpack_from(data, end)
        secret = self._secrets.get((data[6:end], key_id))
        if secret is None:
            raise WireError(f"unknown key id {key_id} of {name!r}", reason="unknown_key")
        body, tag = data[:-TAG_BYTES], data[-TAG_BYTES:]
        if not hmac.compare_digest(hmac.digest(secret, self._prefix + body, "sha256"), tag):
            raise WireError(f"a tag that does not verify ({name!r})", reason="bad_tag")
        if not self._windows[name].accept(sequence):
            raise WireError(f"sequence number {sequence} of {name!r} seen", reason="replayed")
        return _skeleton(_json(body[end + _IDS.size :]), name, self.calibration, self.workspace)


class _NonFiniteError(ValueError):
    pass


def _refuse_constant(name: str) -> float:
    raise _NonFiniteError(name)


def _all_numbers(rows: object) -> bool:
    """True if ``rows`` is a list of lists of JSON numbers (no strings, no booleans)."""
    return isinstance(rows, list) and all(
        isinstance(r, list)
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in r)
        for r in rows
    )
