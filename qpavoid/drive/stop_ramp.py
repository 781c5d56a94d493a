"""A stop for an arm that holds its last command until the next (ros2_control's velocity
controller): the braking ramp the loop itself would send, sent by whoever stops it."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.control.smoothing import CommandRamp
from qpavoid.drive.limits import CommandLimits

__all__ = ["ramp_to_rest"]

#: The longest a ramp to rest may take, s (a joint at full speed brakes in well under 1 s).
MAX_RAMP_S = 10.0


def ramp_to_rest(
    robot: Robot,
    limits: CommandLimits,
    last_two: tuple[np.ndarray, np.ndarray],
    send: Callable[[np.ndarray], None],
) -> int:
    """Send, one every ``limits.dt_s``, the commands of a braking ramp from the last two
    commands sent (``last_two``: the last, then the one before; rad/s) to rest, each within
    ``limits``' acceleration and jerk of the one before (:meth:`CommandRamp.brake
    <qpavoid.control.smoothing.CommandRamp.brake>`, on the line of the last command); the
    number sent, the last of them zero."""
    accelerations = tuple(zip(limits.joint_names, limits.acceleration_radps2, strict=True))
    ramp = CommandRamp(robot, limits.dt_s, accelerations, reaction_time_s=0.0)
    ramp.u1, ramp.u2 = (np.array(u, dtype=float) for u in last_two)
    next_at = time.perf_counter()
    for n in range(1, int(MAX_RAMP_S / limits.dt_s) + 1):
        u = ramp.brake()
        ramp.commit(u, stopping=True)
        next_at += limits.dt_s
        time.sleep(max(next_at - time.perf_counter(), 0.0))
        send(u)
        if not u.any():
            return n
    return n
