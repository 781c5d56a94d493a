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
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

#: KUKA LBR iiwa 14 R820 joint acceleration limits, rad/s² (A1..A7): docs/safety.md.
IIWA14_MAX_ACCELERATION_RADPS2 = (8.0, 8.0, 8.0, 8.0, 8.0, 8.0, 8.0)

#: From a command to the arm starting to follow it, s (one FRI period and the drives'
#: response): docs/safety.md.
IIWA14_REACTION_TIME_S = 0.004


@dataclass(frozen=True)
class BrakingConfig:
    """The arm's response to a velocity command.

    Attributes
    ----------
    reaction_time_s
        Delay from a command to the arm starting to follow it, s (rounded up to whole
        control periods in the simulation).
    max_acceleration_radps2
        Per-joint acceleration (and deceleration) limit, rad/s², A1 first; a shorter tuple
        is repeated from its last value for the remaining joints.
    """

    reaction_time_s: float = IIWA14_REACTION_TIME_S
    max_acceleration_radps2: tuple[float, ...] = IIWA14_MAX_ACCELERATION_RADPS2

    def accelerations(self, nv: int) -> np.ndarray:
        """(nv,) acceleration limits, rad/s²."""
        return per_joint(self.max_acceleration_radps2, nv)


def per_joint(values: tuple[float, ...], nv: int) -> np.ndarray:
    """(nv,) ``values`` for A1, A2, ..., the last one repeated for any joint beyond them."""
    a = list(values)
    return np.array((a + [a[-1]] * nv)[:nv], dtype=float)


def stop_time(dq: ArrayLike, max_acceleration: ArrayLike) -> float:
    """T_s = max_j |q̇_j| / a_j: the time a path-keeping stop from ``dq`` takes, s."""
    return float(np.max(np.abs(np.asarray(dq, dtype=float)) / np.asarray(max_acceleration)))


class ArmResponse:
    """The simulated arm's joint velocity under a command stream (build once per run).

    Parameters
    ----------
    cfg
        Reaction time and acceleration limits.
    nv
        Number of joints.
    dt
        Control period, s.
    """

    def __init__(self, cfg: BrakingConfig, nv: int, dt: float):
        self.a_dt = cfg.accelerations(nv) * dt
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
