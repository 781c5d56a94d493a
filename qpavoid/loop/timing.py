"""A real-time loop's timing: missed deadlines, gaps between commands, latency, a stalled arm."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from qpavoid.core.errors import ArmError
from qpavoid.drive.interface import ArmState

__all__ = ["LoopTiming", "StallCheck"]


class LoopTiming:
    """What a real-time run's ticks did with their time (one per run).

    A tick's command misses its deadline when it is ready more than ``deadline_s`` after
    the tick began (its reading of the arm): the arm held the last command that much longer
    than planned.

    Parameters
    ----------
    period_s
        The control period, s.
    deadline_s
        How late a command may be, s.
    """

    def __init__(self, period_s: float, deadline_s: float):
        self.period_s, self.deadline_s = period_s, deadline_s
        self.misses = 0
        self.stalls: list[float] = []  # the loop's own stalls (gaps past the arm's hold), s
        self._sent: list[float] = []  # when each command was sent, run clock, s
        self._latency: list[float] = []  # a frame's capture to its first command, s
        self._captured = -math.inf

    def late(self, began_s: float, now_s: float) -> float | None:
        """How long (s) the tick that began at ``began_s`` took, its command ready at
        ``now_s`` (any one clock), if it missed its deadline (counted), else None."""
        late = now_s - began_s
        if late > self.deadline_s:
            self.misses += 1
            return late
        return None

    def stalled(self, gap_s: float) -> None:
        """The loop itself stood still for ``gap_s`` s (paused, starved of the CPU), longer
        than the arm holds a command: counted."""
        self.stalls.append(gap_s)

    def sent(self, now_s: float, captured_s: float) -> None:
        """A command went to the arm at ``now_s``, computed from the frame captured at
        ``captured_s`` (run clock, s)."""
        self._sent.append(now_s)
        if captured_s > self._captured and math.isfinite(captured_s):
            self._captured = captured_s
            self._latency.append(now_s - captured_s)

    def report(self) -> dict[str, Any]:
        """``deadline_misses``, ``commands_sent``, ``longest_gap_s`` between two commands,
        ``command_period_s`` (median, p99), ``frame_to_command_s`` (median, p99, max: from a
        frame's capture to the first command computed from it; for a live sensor's
        datagram, stamped when sent, its way to the arm's command)."""
        gaps = np.diff(self._sent) if len(self._sent) > 1 else np.zeros(1)
        lat = np.asarray(self._latency) if self._latency else np.full(1, np.nan)
        return {
            "deadline_misses": int(self.misses),
            "loop_stalls": len(self.stalls),
            "longest_stall_s": max(self.stalls, default=0.0),
            "commands_sent": len(self._sent),
            "longest_gap_s": float(gaps.max()),
            "command_period_s": {
                "median": float(np.median(gaps)),
                "p99": float(np.percentile(gaps, 99)),
            },
            "frame_to_command_s": {
                "median": float(np.median(lat)),
                "p99": float(np.percentile(lat, 99)),
                "max": float(lat.max()),
            },
        }


class StallCheck:
    """An arm whose state stands still is stalled (its clock, not its joints: an arm at rest
    still reports new states).

    Parameters
    ----------
    timeout_s
        How long (wall clock, s) the state's time may stand still.
    """

    def __init__(self, timeout_s: float):
        self.timeout_s = timeout_s
        self._time: float | None = None
        self._since = 0.0

    def __call__(self, state: ArmState, now_s: float) -> ArmState:
        """``state``, read at wall time ``now_s``.

        Raises
        ------
        ArmError
            (``reason="stalled"``) if its time has not advanced for ``timeout_s``, or ran
            backwards.
        """
        if self._time is None or state.time_s > self._time:
            self._time, self._since = state.time_s, now_s
        elif state.time_s < self._time:
            raise ArmError(
                f"the arm's clock ran backwards ({state.time_s:.6f} s after {self._time:.6f} s)",
                reason="stalled",
                value=state.time_s,
            )
        elif now_s - self._since > self.timeout_s:
            raise ArmError(
                f"the arm's state has not changed for {now_s - self._since:.3f} s "
                f"(max {self.timeout_s} s)",
                reason="stalled",
                value=now_s - self._since,
            )
        return state
