"""A live run's progress in words: one line every few seconds of what the robot does and
what the cameras give, for the operator watching the terminal.

    12.0 s: moving, nearest person 0.412 m, frame 118 ms old; frames taken 360, refused 0
    14.0 s: speed and separation: person's head 0.300 m from robot link 'hand', needs
            0.340 m: holding; frames taken 420, refused 0

It reads the rows the run logger hands a watcher (:class:`~qpavoid.loop.run_log.RunLogger`:
at most 30 a second) and the live source's counts; it never touches the loop's time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

__all__ = ["REFUSED", "TAKEN_THEN_REFUSED", "LiveStatus"]

#: The live input's counts that are frames refused (besides every ``dropped_*``): too old
#: on arrival or when the loop took them, or stamped ahead of the clock.
REFUSED = ("late", "late_when_taken", "from_the_future", "from_the_future_when_taken")
#: Of those, the ones the receiver had accepted (counted in ``accepted`` too).
TAKEN_THEN_REFUSED = ("late_when_taken", "from_the_future_when_taken")


class LiveStatus:
    """Say a line about the run every ``every_s`` seconds of run time.

    Parameters
    ----------
    say
        Where the lines go (the command line prints them).
    counts
        The live input's counts so far (:meth:`~qpavoid.loop.live_input.LiveSource.report`:
        ``accepted`` and the drops by reason).
    every_s
        Run time between two lines, s (5: often enough to see a hold begin, rarely enough
        to read).
    """

    def __init__(
        self,
        say: Callable[[str], None],
        counts: Callable[[], Mapping[str, int]],
        every_s: float = 5.0,
    ):
        self.say, self.counts, self.every_s = say, counts, every_s
        self._next_s = every_s

    def __call__(self, row: Mapping[str, Any]) -> None:
        """Take one watched row (its ``t``, ``stop_reason``, ``distance``, ``frame_age_s``)."""
        t = float(row["t"])
        if t < self._next_s or "stop_reason" not in row:
            return
        self._next_s = t + self.every_s
        self.say(f"{t:6.1f} s: {self.line(row)}")

    def line(self, row: Mapping[str, Any]) -> str:
        """What the robot does and what came in, without the time."""
        reason = str(row["stop_reason"])
        distance = np.asarray(row["distance"], dtype=float)
        nearest = float(distance.min()) if distance.size else math.inf
        age = float(row["frame_age_s"])
        if reason:
            doing = reason
        elif math.isfinite(nearest):
            doing = f"moving, nearest person {nearest:.3f} m, frame {1e3 * age:.0f} ms old"
        else:
            doing = "moving, nobody seen"
        counts = self.counts()
        refused = sum(n for k, n in counts.items() if k.startswith("dropped_") or k in REFUSED)
        # accepted by the receiver, then replaced by a newer frame before the loop took
        # them, or dropped when it did: not taken
        replaced = counts.get("superseded", 0) + sum(counts.get(k, 0) for k in TAKEN_THEN_REFUSED)
        taken = counts.get("accepted", 0) - replaced
        alert = str(row.get("input_alert", ""))
        return f"{doing}; frames taken {taken}, refused {refused}" + (f"; {alert}" if alert else "")
