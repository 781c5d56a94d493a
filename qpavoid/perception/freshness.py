"""Which frame is new, and how old the frame in hand is: by the frame's own time, not calls.

A control loop ticks faster than a camera delivers (1 kHz against 30 Hz): most ticks hand
the controller the frame it already has. :class:`FrameClock` tells a new frame from the one
in hand by, in order of preference,

1. the caller's ``frame_id`` (a camera's frame counter), if given;
2. the frame's capture time ``frame_time_s``, if given;
3. its content: the people's ids and every joint and tracking state, bit for bit.

A frame whose capture time is not later than the newest taken is never new, whatever its id
or content (out of order, a sensor's clock restarted, a counter over a frozen clock): the
frame in hand keeps aging. Only a new frame reaches the trackers, so a frame held for many
ticks is never taken for a frozen sensor; a frozen sensor, one that keeps sending the same
skeleton under new ids or times, still is (``PerceptionConfig.max_identical_frames``), and
a frame held with no new one behind it grows old until it is stale
(``ControllerConfig.max_frame_age_s``).

The frame's age is the caller's ``frame_age_s`` (now minus the capture time) when given; if
not, it is measured on the controller's clock: the time since the frame first arrived.
"""

from __future__ import annotations

import math
from collections.abc import Hashable

from qpavoid.human.people import People

__all__ = ["FrameClock"]


class FrameClock:
    """When the frame in hand arrived, on the controller's clock (one per controller)."""

    def __init__(self) -> None:
        self._key: Hashable | None = None
        self._people: People | None = None
        self._arrived_s = 0.0
        self._newest_s = -math.inf  # the newest capture time taken, s

    def observe(
        self,
        people: People,
        clock_s: float,
        frame_age_s: float | None,
        frame_time_s: float | None,
        frame_id: Hashable | None,
    ) -> tuple[bool, float]:
        """Whether ``people`` is a new frame, and its age, s.

        Parameters
        ----------
        people
            The frame handed in this tick.
        clock_s
            The controller's clock now, s.
        frame_age_s
            The caller's age of the frame (now minus its capture time), s, or None.
        frame_time_s, frame_id
            The frame's capture time (any clock, s) and the caller's id of it, or None.
        """
        key = self._key_of(people, frame_time_s, frame_id)
        new = self._people is None or key != self._key
        if new and frame_time_s is not None:  # a time at or before the newest: not new
            new = frame_time_s > self._newest_s
        if new:
            self._key, self._arrived_s = key, clock_s
            if frame_time_s is not None:
                self._newest_s = frame_time_s
        self._people = people
        held = clock_s - self._arrived_s  # how long the frame in hand has been held
        if frame_age_s is None:
            return new, held
        return new, frame_age_s if new else max(frame_age_s, held)

    def _key_of(
        self, people: People, frame_time_s: float | None, frame_id: Hashable | None
    ) -> Hashable:
        """The frame's identity: its id, else its time, else its content."""
        if frame_id is not None:
            return ("id", frame_id)
        if frame_time_s is not None:
            return ("time", frame_time_s)
        last = self._people
        if (
            last is not None
            and people.ids == last.ids
            and all(a is b for a, b in zip(people.frames, last.frames, strict=True))
        ):
            return self._key  # the same frame objects: no need to read them
        return (
            "content",
            people.ids,
            tuple(f.joints.tobytes() + f.state.tobytes() for f in people.frames),
        )
