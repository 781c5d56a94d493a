"""How the real arm follows a velocity command: a reaction time and bounded acceleration.

A controller commands joint velocities; the arm starts to follow them ``reaction_time_s``
later and changes its joint velocities no faster than ``max_acceleration_radps2`` allows.
A change of command (a stop included) is a ramp along a straight line in joint-velocity
space: every joint reaches its new velocity at the same instant, at the rate of the joint
that needs longest, so a stop keeps the path (ISO 10218-1 stop category 1/2 behaviour)
and takes

    T_s = max_j |q̇_j| / a_j                                        (:func:`stop_time`)

during which the arm's points move at a speed falling linearly to zero: a point moving at
v travels ``v T_s / 2`` (the S_s of speed and separation monitoring, :mod:`qpavoid.ssm`).

The iiwa 14 defaults are in docs/safety.md ("Robot") with their sources.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .errors import InputError

#: KUKA LBR iiwa 14 R820 joint acceleration limits, rad/s², by joint: the average measured
#: accelerations of Larsen (2019), Table 4, as Drake's iiwa model uses them (docs/safety.md).
IIWA14_MAX_ACCELERATION_RADPS2 = (
    ("A1", 8.57),
    ("A2", 8.57),
    ("A3", 8.74),
    ("A4", 11.36),
    ("A5", 12.23),
    ("A6", 15.72),
    ("A7", 15.72),
)

#: From a command to the arm starting to follow it, s: one period of the iiwa's FRI link as
#: Drake configures it (5 ms); docs/safety.md.
IIWA14_REACTION_TIME_S = 0.005


@dataclass(frozen=True)
class BrakingConfig:
    """The arm's response to a velocity command.

    Attributes
    ----------
    reaction_time_s
        Delay from a command to the arm starting to follow it, s (rounded up to whole
        control periods in the simulation).
    max_acceleration_radps2
        ``(joint name, limit)`` pairs: each joint's acceleration (and deceleration) limit,
        rad/s².
    """

    reaction_time_s: float = IIWA14_REACTION_TIME_S
    max_acceleration_radps2: tuple[tuple[str, float], ...] = IIWA14_MAX_ACCELERATION_RADPS2


def per_joint(values: tuple[tuple[str, float], ...], joint_names: Sequence[str]) -> np.ndarray:
    """The values of ``(name, value)`` pairs for ``joint_names``, in that order.

    Raises
    ------
    InputError
        If a joint has no value.
    """
    table = dict(values)
    missing = [n for n in joint_names if n not in table]
    if missing:
        raise InputError(
            f"no acceleration limit for joints {missing} (given for {sorted(table)})",
            name="max_acceleration_radps2",
            value=values,
        )
    return np.array([table[n] for n in joint_names], dtype=float)


def stop_time(dq: ArrayLike, max_acceleration: ArrayLike) -> float:
    """T_s = max_j |q̇_j| / a_j: the time a path-keeping stop from ``dq`` takes, s."""
    return float(np.max(np.abs(np.asarray(dq, dtype=float)) / np.asarray(max_acceleration)))


class ArmResponse:
    """The simulated arm's joint velocity under a command stream (build once per run).

    Parameters
    ----------
    cfg
        Reaction time and acceleration limits.
    joint_names
        The arm's active joints.
    dt
        Control period, s.
    """

    def __init__(self, cfg: BrakingConfig, joint_names: Sequence[str], dt: float):
        self.a_dt = per_joint(cfg.max_acceleration_radps2, joint_names) * dt
        nv = len(joint_names)
        delay = int(np.ceil(cfg.reaction_time_s / dt - 1e-9))
        self._pending: deque[np.ndarray] = deque([np.zeros(nv)] * delay)
        self.dq = np.zeros(nv)

    def __call__(self, command: np.ndarray) -> np.ndarray:
        """The arm's joint velocity over the coming period, given this tick's command."""
        self._pending.append(np.asarray(command, dtype=float))
        target = self._pending.popleft()
        change = target - self.dq
        need = np.abs(change) / self.a_dt
        worst = float(need.max(initial=0.0))
        self.dq = target.copy() if worst <= 1.0 else self.dq + change / worst
        return self.dq
