"""The wire format of live skeletons: one UDP datagram per body per sensor frame.

A datagram is signed (version 2, the default: :mod:`qpavoid.sensing.signing` wraps the skeleton
below in a header and a tag, docs/security.md) or, only by an explicit opt-in on
loopback, unsigned (version 1). The skeleton itself is JSON in both; a signed one also
carries its frame's **manifest** (below).

**Version 1, unsigned** (only with an explicit opt-in, on loopback): one UTF-8 JSON
object::

    {"v": 1, "sensor": "kinect_left", "body": 0, "t": 1763864400.0333,
     "joints": [[x, y, z, state], ... one row per joint of the Kinect v2 format]}

In both (in a signed datagram the sensor's name and the capture time are in the header,
and the payload is ``{"body", "bodies", "joints"}``, ``bodies`` the manifest below, with
``"format"`` for a format other than the Kinect v2's):

* ``sensor``: the sensor's name, as in the calibration file.
* ``format`` (optional): the skeleton format of ``joints``, a name of
  :data:`~qpavoid.human.landmarks.FORMAT_NAMES` (missing: ``"kinect_v2"``, every
  datagram before formats were data); it must be the sensor's calibrated ``format``
  (else ``wrong_format``). :func:`encode` writes it for any other format than the
  Kinect v2's, so that a Kinect v2 datagram is as it was.
* ``body``: the sensor's body id, 0 to the format's ``max_bodies`` − 1 (0-5 on a
  Kinect v2).
* ``t``: capture time, s, on a clock shared with the controller (UNIX time from PTP or
  NTP; the calibration's ``time_offset_s`` corrects a known offset).
* ``joints``: one row ``[x, y, z, state]`` per joint of the format, in its order (25 in
  the Kinect SDK's JointType order: :data:`~qpavoid.human.kinect_v2.KINECT_V2`), in the
  sensor's camera frame, m (six decimals; :func:`~qpavoid.human.landmarks.camera_frame`
  converts an SDK's millimetres and confidence); ``state`` 0 (not tracked: the
  coordinates are ignored), 1 (inferred) or 2 (tracked).

**The manifest** (signed payloads only): the skeletons travel in clear, one body
per datagram, so a device on the path can tell the person near the robot from a bystander
and drop only the former's datagrams. Each datagram of a camera frame therefore says, inside
the signed bytes, what the whole frame holds:

* ``bodies``: the body ids the sensor reported in that frame, one per datagram, in the
  order of their datagrams (distinct; their count is the frame's, 1 to the format's
  ``max_bodies``).

The frame's datagrams carry consecutive sequence numbers (signed header) in that order, so
a datagram's place in its frame is its body's index in ``bodies``, and the **frame's
number** is the sequence number of its first datagram, ``sequence - bodies.index(body)``;
the sensor's next frame is numbered ``frame + len(bodies)``. A datagram is thereby
verifiably part of one frame (its own body not listed: ``bad_manifest``), and a forged or
altered manifest fails the tag. The receiver (:mod:`qpavoid.sensing.assembly`) delivers a
frame only once all its bodies came, and a frame missing or incomplete makes the sensor's
older frames stale at once. A signed payload without ``bodies`` (from a sender that
writes no manifest) is a frame of its one body at its own sequence number: a gap in the
numbers still shows. An unsigned datagram has no sequence number and no manifest: it is
delivered as it comes (docs/security.md §3).

**Why a manifest in each datagram, not a whole camera frame in one.** A body's datagram
stays inside one Ethernet frame: 926 bytes for a Kinect v2 body of a frame of six, and at
most 1433 for one of ten ZED bodies of 38 joints with every coordinate at its widest
(``benchmarks/wire.py``), under the 1452 bytes of a UDP payload in one IPv6 frame (1472 on
IPv4); six to ten bodies in one datagram (up to 14 kB) would be cut into IP fragments, any
one of which lost loses the frame, and would pass :data:`MAX_DATAGRAM_BYTES`. The per-body
slots, counters and senders stay as they were. The manifest costs 13 to 31 bytes, and its
check and the frame's assembly about 5 µs per datagram; a frame in one datagram would save
a tag per body (4 µs of the 50-90 a body costs to verify and parse). The frame's number
is the sequence number the header already signs, not a second counter in the payload (16
more bytes, which would take the widest datagram over the IPv6 frame). And the version-2
header is unchanged: the manifest is a key of the payload, which the tag covers and an
older receiver ignores, so no new version is needed.

JSON is chosen over a binary layout for the skeleton because every language and tool
reads it and a datagram of one body (about 1 kB) is parsed in tens of microseconds
(docs/sensors.md); a forged one is refused by its tag in a few (docs/security.md).
:func:`decode` and :meth:`qpavoid.sensing.signing.Verifier.decode` refuse anything else with a
:class:`WireError` whose ``reason`` is one of :data:`REASONS`: the listener counts the
drops by reason and carries on.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from qpavoid.core.errors import InputError
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.skeleton import TRACKING_STATES
from qpavoid.sensing.calibration import DEFAULT_FORMAT, Calibration, known_formats
from qpavoid.sensing.per_sensor import BodyFrame

__all__ = [
    "MAX_DATAGRAM_BYTES",
    "REASONS",
    "VERSION",
    "FormatMismatchError",
    "Manifest",
    "WireError",
    "Workspace",
    "decode",
    "encode",
    "json_object",
    "manifest",
    "payload",
    "rows",
    "skeleton",
]

#: The unsigned JSON version (:func:`encode`, :func:`decode`).
VERSION = 1
#: Longest datagram accepted, bytes (a body is about 1 kB; 8 kB leaves room, refuses junk).
MAX_DATAGRAM_BYTES = 8192
#: Coordinates are sent to the micrometre (a Kinect measures to the millimetre), which keeps
#: a body's datagram near 1 kB, inside one Ethernet frame.
COORDINATE_DECIMALS = 6
#: A datagram's skeleton when it names no ``format``: joints of the Kinect v2 format.
SKELETON = KINECT_V2
#: The tracking states a datagram's joint may carry.
STATES = tuple(code for _, code in TRACKING_STATES)
#: Why a datagram is dropped, in the order they are checked.
REASONS = (
    "too_long",
    "unauthenticated",
    "bad_header",
    "unknown_sensor",
    "unknown_key",
    "bad_tag",
    "replayed",
    "late",
    "from_the_future",
    "bad_json",
    "bad_version",
    "wrong_format",
    "bad_field",
    "non_finite",
    "outside_workspace",
    "bad_manifest",
)


class WireError(InputError):
    """A datagram that is not a valid skeleton; ``reason`` is one of :data:`REASONS`."""

    def __init__(self, message: str, *, reason: str):
        super().__init__(message, name="datagram", value=reason)
        self.reason = reason


class FormatMismatchError(WireError):
    """A datagram of a calibrated sensor whose skeleton format is not the sensor's
    (``wrong_format``): which format arrived and which was expected, so that a listener
    can say so (:meth:`~qpavoid.loop.live_input.Listener.format_mismatches`).

    Attributes
    ----------
    sensor
        The sensor's name.
    arrived
        The datagram's ``format`` (``"kinect_v2"`` where it names none; an unknown name as
        sent, at most 40 characters).
    expected
        The sensor's calibrated ``format``.
    """

    def __init__(self, sensor: str, arrived: str, expected: str):
        super().__init__(
            f"format {arrived!r} of sensor {sensor!r}, calibrated as {expected!r}",
            reason="wrong_format",
        )
        self.sensor, self.arrived, self.expected = sensor, arrived, expected


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


class Manifest(NamedTuple):
    """Where a signed datagram stands among its sensor's frames (module docstring).

    Attributes
    ----------
    key_id
        The key that signed it (a new key counts afresh, as its replay window does).
    sequence
        Its sequence number.
    frame
        Its frame's number: the sequence number of the frame's first datagram
        (``sequence - bodies.index(body)``).
    bodies
        The frame's body ids, in the order of its datagrams.
    """

    key_id: int
    sequence: int
    frame: int
    bodies: tuple[int, ...]


def manifest(msg: dict, body: int, key_id: int, sequence: int, max_bodies: int) -> Manifest:
    """The manifest of a signed payload ``msg`` whose skeleton is ``body``'s and whose
    header says ``key_id`` and ``sequence`` (a payload without ``bodies``, from a sender
    before manifests: a frame of its one body).

    Raises
    ------
    WireError
        ``bad_manifest``: ``bodies`` not 1 to ``max_bodies`` distinct body ids, ``body``
        not among them, or a frame that would start below sequence number 0.
    """
    if "bodies" not in msg:
        return Manifest(key_id, sequence, sequence, (body,))
    bodies = msg["bodies"]
    ids = tuple(bodies) if isinstance(bodies, list) else ()
    if (
        not 1 <= len(ids) <= max_bodies
        or not all(_is_int(b) and 0 <= b < max_bodies for b in ids)
        or len(set(ids)) != len(ids)
    ):
        raise WireError(f"bodies {str(bodies)[:60]}", reason="bad_manifest")
    if body not in ids or sequence < ids.index(body):
        raise WireError(
            f"body {body}, sequence number {sequence}, in a frame of bodies {list(ids)}",
            reason="bad_manifest",
        )
    return Manifest(key_id, sequence, sequence - ids.index(body), ids)


def rows(frame: BodyFrame) -> list[list[float]]:
    """The joints as sent: camera frame, to the micrometre, NaN joints as state 0."""
    joints = np.asarray(frame.joints, dtype=float)
    state = np.asarray(frame.state, dtype=int)
    out = []
    for xyz, s in zip(joints, state, strict=True):
        if not np.isfinite(xyz).all():
            out.append([0.0, 0.0, 0.0, 0])
        else:
            out.append([*(round(float(v), COORDINATE_DECIMALS) for v in xyz), int(s)])
    return out


def payload(frame: BodyFrame, bodies: Sequence[int] | None = None) -> dict:
    """What a datagram of ``frame`` says of its skeleton: ``body``, its camera frame's
    ``bodies`` (the manifest, if given), ``format`` (for a format other than the Kinect
    v2's) and ``joints`` (:func:`rows`)."""
    message: dict = {"body": int(frame.body)}
    if bodies is not None:
        message["bodies"] = [int(b) for b in bodies]
    if frame.format != DEFAULT_FORMAT:
        message["format"] = frame.format
    message["joints"] = rows(frame)
    return message


def encode(frame: BodyFrame) -> bytes:
    """One unsigned version-1 datagram of ``frame`` (joints in its camera frame, to the
    micrometre; joints that are NaN are sent as state 0; ``format`` for a format other
    than the Kinect v2's)."""
    message = {"v": VERSION, "sensor": frame.sensor, "body": int(frame.body), "t": frame.t}
    message.update(payload(frame))
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
    msg = json_object(data)
    if (
        msg.get("v") != VERSION
        or not isinstance(msg.get("v"), int)
        or isinstance(msg.get("v"), bool)
    ):
        raise WireError(f"version {msg.get('v')!r}, expected {VERSION}", reason="bad_version")
    sensor = msg.get("sensor")
    if not isinstance(sensor, str) or not sensor:
        raise WireError(f"sensor {sensor!r}", reason="bad_field")
    return skeleton(msg, sensor, calibration, workspace)


def json_object(data: bytes) -> dict:
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


def skeleton(
    msg: dict,
    sensor: str,
    calibration: Calibration,
    workspace: Workspace | None,
    t: object = None,
) -> BodyFrame:
    """The body frame of a message's ``format``, ``body``, ``t`` (or ``t`` given: a signed
    header's) and ``joints`` (``sensor``'s, camera frame), checked: :class:`WireError`
    otherwise."""
    name = msg.get("format", DEFAULT_FORMAT)
    fmt = known_formats().get(name) if isinstance(name, str) else None
    cal = calibration.sensors.get(sensor)
    if cal is not None and (fmt is None or cal.format != name):
        raise FormatMismatchError(sensor, str(name)[:40], cal.format)
    if fmt is None:
        raise WireError(f"format {str(name)[:40]!r}", reason="wrong_format")
    body, joint_rows = msg.get("body"), msg.get("joints")
    if t is None:
        t = msg.get("t")
    if not isinstance(body, int) or isinstance(body, bool) or not 0 <= body < fmt.sensor.max_bodies:
        raise WireError(f"body {body!r}", reason="bad_field")
    if not isinstance(t, (int, float)) or isinstance(t, bool):
        raise WireError(f"t {str(t)[:40]}", reason="bad_field")
    try:
        t = float(t)  # a JSON integer may be too large for a float
        arr = np.array(joint_rows, dtype=float)
    except OverflowError:
        raise WireError("a number too large for a float", reason="non_finite") from None
    except (TypeError, ValueError):
        raise WireError(
            f"joints are not {fmt.n_joints} rows of 4 numbers", reason="bad_field"
        ) from None
    if not math.isfinite(t):
        raise WireError(f"t {t!r}", reason="non_finite")
    if arr.shape != (fmt.n_joints, 4) or not _all_numbers(joint_rows):
        raise WireError(
            f"joints of shape {arr.shape}, expected ({fmt.n_joints}, 4) ({fmt.title})",
            reason="bad_field",
        )
    if not np.isfinite(arr).all():
        raise WireError("a non-finite coordinate", reason="non_finite")
    state = arr[:, 3]
    if not np.isin(state, STATES).all():
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
    return BodyFrame(sensor, body, float(t), joints, state.astype(np.int8), fmt.name)


class _NonFiniteError(ValueError):
    pass


def _refuse_constant(name: str) -> float:
    raise _NonFiniteError(name)


def _is_int(value: object) -> bool:
    """A JSON integer (not a boolean)."""
    return isinstance(value, int) and not isinstance(value, bool)


def _all_numbers(rows: object) -> bool:
    """True if ``rows`` is a list of lists of JSON numbers (no strings, no booleans)."""
    return isinstance(rows, list) and all(
        isinstance(r, list)
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in r)
        for r in rows
    )
