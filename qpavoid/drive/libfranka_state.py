"""A Franka arm's state as a binding of libfranka reads it, and the wait for rest.

Rest is judged from the joint angles over a window (:func:`wait_for_rest`), not from the
velocities the arm reports.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from qpavoid.core.errors import ArmError

__all__ = ["REST_RADPS", "REST_WINDOW_S", "RawState", "wait_for_rest"]

#: Joint speed below which the arm counts as at rest, rad/s, judged from its joint angles
#: over :data:`REST_WINDOW_S` (not its reported velocities: franky-sim's wrist, stopped after
#: moving, sticks and slips, reporting ±0.06-0.1 rad/s while it creeps at up to 0.016 rad/s;
#: a real arm holds still).
REST_RADPS = 0.02
#: Over this long, s.
REST_WINDOW_S = 0.1
#: The pause between reads while waiting for rest, s.
_POLL_S = 0.002


@dataclass(frozen=True)
class RawState:
    """One state of the arm's seven joints, as a binding reads it.

    Attributes
    ----------
    time_ms
        The arm's clock, ms.
    q, dq
        (7,) joint angles, rad, and velocities, rad/s.
    fault
        What the arm reports, if it has errors, is in a reflex or stopped by its user.
    """

    time_ms: int
    q: np.ndarray
    dq: np.ndarray
    fault: str | None = None

    @classmethod
    def of(cls, state: Any, faulted: bool) -> RawState:
        """The state of libfranka's ``RobotState`` ``state`` (either binding's), with its
        errors and mode as the fault if ``faulted``."""
        fault = f"{state.current_errors!r} in mode {state.robot_mode.name}" if faulted else None
        return cls(
            int(state.time.to_msec()),
            np.asarray(state.q, dtype=float),
            np.asarray(state.dq, dtype=float),
            fault,
        )


def wait_for_rest(read: Callable[[], RawState], timeout_s: float, arm: str, what: str) -> RawState:
    """The state ``read()`` gives once every joint of the arm ``arm`` is slower than
    :data:`REST_RADPS` over :data:`REST_WINDOW_S`, waiting at most ``timeout_s`` s after
    ``what`` (a stop, a motion).

    Raises
    ------
    ArmError
        "stalled" if the arm is not at rest by then; what ``read`` raises.
    """
    t_end = time.monotonic() + timeout_s
    seen: list[tuple[float, np.ndarray]] = []  # (wall time, the joint angles)
    while True:
        state = read()
        now, q7 = time.monotonic(), np.array(state.q, dtype=float)
        seen.append((now, q7))
        while len(seen) > 1 and seen[1][0] <= now - REST_WINDOW_S:
            seen.pop(0)
        span = now - seen[0][0]
        speed = float(np.max(np.abs(q7 - seen[0][1]))) / span if span > 0 else math.inf
        if span >= REST_WINDOW_S * 0.9 and speed < REST_RADPS:
            return state
        if now > t_end:
            raise ArmError(
                f"{arm}: not at rest {timeout_s:g} s after {what} (a joint at {speed:.4f} rad/s)",
                arm=arm,
                reason="stalled",
                value=speed,
            )
        time.sleep(_POLL_S)
