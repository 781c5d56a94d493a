"""Signed skeleton datagrams (wire format version 2): :class:`Signer` on the sensor's side,
:class:`Verifier` on the receiver's (docs/security.md).

A datagram is a binary header, a
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
"""

from __future__ import annotations

import hmac
import json
import struct
import time

from .calibration import Calibration
from .errors import InputError
from .keys import SensorKeys
from .sensor_recording import BodyFrame
from .wire import (
    MAX_DATAGRAM_BYTES,
    WireError,
    Workspace,
    decode,
    json_object,
    rows,
    skeleton,
)

__all__ = [
    "DOMAIN",
    "MAGIC",
    "REPLAY_WINDOW",
    "VERSION_2",
    "ReplayWindow",
    "Signer",
    "Verifier",
    "fields",
]

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
        message = {"body": int(frame.body), "t": frame.t, "joints": rows(frame)}
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
        payload = json_object(body[end + _IDS.size :])
        return skeleton(payload, name, self.calibration, self.workspace)
