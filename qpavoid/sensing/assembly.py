"""A sensor's camera frames from its datagrams: whole frames only, and every loss seen.

The safety protocols of IEC 61784-3 detect loss on a black channel by a sequence number
and a watchdog. The skeletons travel one body per datagram; a receiver that took each
body as it came would let a device on the path drop only the datagrams of the person
near the robot, forwarding a bystander's: the input stays fresh while that person
vanishes (492 ticks moving in true contact, docs/security.md). Each signed datagram carries its
frame's manifest (:mod:`qpavoid.sensing.wire`: the body ids of all the datagrams of its
camera frame, in order; the frame's number is the sequence number of its first datagram),
and :func:`assemble` applies two rules per sensor:

* **A frame counts only when every body its manifest lists came.** Until then its bodies
  are held; the bodies of one frame may come in any order.
* **A frame missing or incomplete makes the sensor's older frames stale at once.** A
  datagram of a later frame than the one expected (a gap in the frame numbers), or while
  a frame is still incomplete, is a loss: every frame of that sensor captured before it
  is stale (:meth:`qpavoid.fusion.fuser.Fuser.lose`), which is how the fusion already
  treats a sensor that has been silent for ``max_age_s``, the camera dropout: a person
  no sensor sees freshly keeps every joint at its last place with an uncertainty growing
  at 2 m/s (the controller's tracker), and with no fresh frame at all the robot stops.
  The frame that shows the loss is used once it is whole, so the stop lasts while
  datagrams are missing.

A datagram of a frame already closed (delivered, or found incomplete) is dropped
(``out_of_order_or_duplicate``). A new key counts afresh (a key rotated in the sender),
as its replay window does: the change is counted as one loss. Total silence is the
existing staleness's (no fresh frame for ``max_age_s``). Unsigned (version 1) datagrams
have no sequence number: they are delivered as they come, without loss detection.

:class:`LossWatch` turns each sensor's count of lost frames into the input alert of a
live run (``input_alert`` in the log, the live view) when a sensor keeps losing frames
(:class:`LossConfig`).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import NamedTuple

from qpavoid.core.checks import finite_number
from qpavoid.core.errors import InputError
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.wire import Manifest, WireError

__all__ = ["LossConfig", "LossWatch", "Pending", "SensorFrames", "Step", "assemble"]


class Pending(NamedTuple):
    """A frame of which some bodies came: its manifest, capture time (s, the sensor's
    clock) and bodies by place (None: not come yet)."""

    manifest: Manifest
    t: float
    bodies: tuple[BodyFrame | None, ...]


class SensorFrames(NamedTuple):
    """One sensor's assembly between datagrams.

    Attributes
    ----------
    key_id
        The key of its frames so far (None before its first datagram).
    expected
        The number the sensor's next frame should have (None before its first frame).
    pending
        The frame being assembled (None: none).
    """

    key_id: int | None = None
    expected: int | None = None
    pending: Pending | None = None


class Step(NamedTuple):
    """What one datagram did to its sensor's assembly (:func:`assemble`).

    Attributes
    ----------
    state
        The sensor's assembly after it.
    complete
        A whole frame to deliver, its bodies in the manifest's order (empty: none).
    lost
        A frame was found missing or incomplete: the sensor's frames captured before
        ``stale_before_s`` are stale.
    stale_before_s
        The datagram's capture time if ``lost`` (s, the sensor's clock), else -inf.
    discarded
        Datagrams of the incomplete frame, now never delivered.
    closed
        The datagram belongs to a frame already closed: dropped.
    """

    state: SensorFrames
    complete: tuple[BodyFrame, ...] = ()
    lost: bool = False
    stale_before_s: float = -math.inf
    discarded: int = 0
    closed: bool = False


def assemble(state: SensorFrames, frame: BodyFrame, place: Manifest) -> Step:
    """One verified datagram of a sensor (its body's ``frame`` and its manifest ``place``)
    into the sensor's assembly ``state`` (module docstring).

    Raises
    ------
    WireError
        ``bad_manifest``: a manifest or capture time that differs from the rest of its
        frame's (only the sensor's key holder can sign one).
    """
    pending = state.pending
    place_in_frame = place.sequence - place.frame
    same_key = state.key_id is None or place.key_id == state.key_id
    current = pending.manifest.frame if pending is not None else state.expected
    if same_key and current is not None and place.frame < current:
        return Step(state, closed=True)
    if same_key and pending is not None and place.frame == pending.manifest.frame:
        if place.bodies != pending.manifest.bodies or frame.t != pending.t:
            raise WireError(
                f"frame {place.frame} as bodies {list(place.bodies)} at {frame.t!r} s, "
                f"before as {list(pending.manifest.bodies)} at {pending.t!r} s",
                reason="bad_manifest",
            )
        if pending.bodies[place_in_frame] is not None:  # taken already (a sensor's fault)
            return Step(state, closed=True)
        return _filled(state, pending, place_in_frame, frame)
    # a new frame: the one pending is incomplete, or frames between are missing
    lost = pending is not None or (
        state.expected is not None and (place.frame != state.expected or not same_key)
    )
    started = Pending(place, float(frame.t), (None,) * len(place.bodies))
    step = _filled(SensorFrames(place.key_id, state.expected, None), started, place_in_frame, frame)
    if not lost:
        return step
    discarded = sum(b is not None for b in pending.bodies) if pending is not None else 0
    return step._replace(lost=True, stale_before_s=float(frame.t), discarded=discarded)


def _filled(state: SensorFrames, pending: Pending, place: int, frame: BodyFrame) -> Step:
    """``pending`` with ``frame`` at ``place``: delivered if whole, else still pending."""
    bodies = (*pending.bodies[:place], frame, *pending.bodies[place + 1 :])
    if any(b is None for b in bodies):
        return Step(state._replace(pending=pending._replace(bodies=bodies)))
    whole = tuple(b for b in bodies if b is not None)
    after = pending.manifest.frame + len(bodies)
    return Step(SensorFrames(pending.manifest.key_id, after, None), complete=whole)


@dataclass(frozen=True)
class LossConfig:
    """When lost frames raise a live run's input alert (:class:`LossWatch`).

    Attributes
    ----------
    window_s
        The window the losses are counted over, s (1.0: thirty frames of a Kinect).
    alert_frames
        A sensor that loses at least this many frames within ``window_s`` raises the
        alert (3: a tenth of a Kinect's frames. Loopback and a switched cell network lose
        practically none; a sender restarted, a key rotated or one datagram reordered
        across frames costs one; three a second is a failing link or a device on the path
        dropping datagrams, which the operator must look at). Each loss stops the robot
        on its own, alert or not: the alert says why.
    """

    window_s: float = 1.0
    alert_frames: int = 3

    def __post_init__(self) -> None:
        finite_number(self.window_s, "window_s", positive=True)
        if isinstance(self.alert_frames, bool) or not (
            isinstance(self.alert_frames, int) and self.alert_frames >= 1
        ):
            raise InputError(
                "alert_frames must be a whole number of frames, at least 1",
                name="alert_frames",
                value=self.alert_frames,
            )


class LossWatch:
    """Each sensor's lost frames over the last ``window_s``, and the alert they raise.

    Parameters
    ----------
    config
        The window and the alert's threshold.
    """

    def __init__(self, config: LossConfig | None = None):
        self.cfg = config or LossConfig()
        # per sensor, (time, lost frames so far) at each change, the last one at or
        # before the window's start first
        self._history: dict[str, deque[tuple[float, int]]] = {}

    def alert(self, t: float, lost: Mapping[str, int]) -> str:
        """The alert at time ``t`` (s) given each sensor's lost frames so far (a
        counter that only grows): "" if no sensor lost ``alert_frames`` frames within the
        last ``window_s``."""
        window = self.cfg.window_s
        words = []
        for sensor, total in lost.items():
            history = self._history.setdefault(sensor, deque([(-math.inf, 0)]))
            if total != history[-1][1]:
                history.append((t, total))
            while len(history) > 1 and history[1][0] <= t - window:
                history.popleft()
            recent = total - history[0][1]
            if recent >= self.cfg.alert_frames:
                words.append(
                    f"{sensor} lost {recent} frames in the last {window:g} s "
                    "(datagrams missing on the way: a failing link, or a device on the path)"
                )
        return "; ".join(words)
