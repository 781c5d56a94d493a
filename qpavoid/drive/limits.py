"""Every command checked against the arm's published limits, by qpavoid itself.

A real arm faults on a command beyond its limits (libfranka's ``joint_motion_generator_*``
reflexes, the UR controller's protective stop); a simulator may not (franky-sim accepts
anything). :class:`CommandCheck` is the check the loop applies to every command it sends,
whatever the arm: with ``u_k`` the command of tick k, sent every ``dt`` s, starting from rest
(``u_{-1} = u_{-2} = 0``),

    |u_k,j| ≤ v_j (1 + ε)                                  velocity
    |u_k,j − u_{k-1},j| ≤ a_j dt (1 + ε)                    acceleration
    |u_k,j − 2 u_{k-1},j + u_{k-2},j| ≤ j_j dt² (1 + ε)     jerk (where the arm publishes one)

with v_j the joint's velocity limit (the tighter of the URDF's and the maker's), a_j its
acceleration limit and j_j its jerk limit (the description's ``[arm]``), ε = 1e-6 for
rounding.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from qpavoid.arm.model import Robot

__all__ = ["CommandCheck", "CommandLimits"]

#: Relative tolerance of the checks (rounding of the ramps' arithmetic, not a margin).
TOLERANCE = 1e-6


@dataclass(frozen=True)
class CommandLimits:
    """The limits a command stream must keep (per active joint).

    Attributes
    ----------
    velocity_radps, acceleration_radps2, jerk_radps3
        (nv,) each joint's limits; ``jerk_radps3`` is ``inf`` for a joint without one.
    dt_s
        The command period, s.
    joint_names
        The joints, in order.
    """

    velocity_radps: np.ndarray
    acceleration_radps2: np.ndarray
    jerk_radps3: np.ndarray
    dt_s: float
    joint_names: tuple[str, ...]

    @classmethod
    def of(cls, robot: Robot, dt_s: float) -> CommandLimits:
        """The robot description's limits at a command period of ``dt_s`` s."""
        names = tuple(robot.joint_names)
        accel = dict(robot.arm.max_acceleration_radps2)
        jerk = dict(robot.arm.max_jerk_radps3)
        return cls(
            np.array(robot.dq_max, dtype=float),
            np.array([accel[n] for n in names], dtype=float),
            np.array([jerk.get(n, np.inf) for n in names], dtype=float),
            float(dt_s),
            names,
        )


@dataclass
class CommandCheck:
    """The command stream so far, and what it broke (one per run).

    Attributes
    ----------
    limits
        What it is checked against.
    counts
        How many commands broke each limit (``"velocity"``, ``"acceleration"``, ``"jerk"``).
    worst
        Each limit's largest ratio of a command's value to the limit (1 = at the limit).
    """

    limits: CommandLimits
    counts: dict[str, int] = field(
        default_factory=lambda: {"velocity": 0, "acceleration": 0, "jerk": 0}
    )
    worst: dict[str, float] = field(
        default_factory=lambda: {"velocity": 0.0, "acceleration": 0.0, "jerk": 0.0}
    )

    def __post_init__(self) -> None:
        n = len(self.limits.joint_names)
        self._u1, self._u2 = np.zeros(n), np.zeros(n)
        self.last = ""  # why the last command broke a limit ("" if it did not)

    def __call__(self, dq: np.ndarray) -> str:
        """Check the next command (nv,), rad/s; why it breaks a limit ("" if it keeps all).

        Each limit broken is counted once per command; the stream moves on either way.
        """
        self.last = self._check(np.asarray(dq, dtype=float)[None, :])
        return self.last

    def restart(self) -> None:
        """The arm came to rest on its own (it held the last command past its hold, or was
        stopped): the stream starts again from rest (``u_{k-1} = u_{k-2} = 0``); the counts
        are kept."""
        self._u1, self._u2 = np.zeros_like(self._u1), np.zeros_like(self._u2)

    def stream(self, commands: np.ndarray) -> None:
        """Check a whole stream of commands (T, nv) at once, as :meth:`__call__` one by one
        (an offline run's, after it: the same counts and ratios, vectorised)."""
        u = np.asarray(commands, dtype=float)
        if len(u):
            self.last = self.last or self._check(u)

    def _check(self, u: np.ndarray) -> str:
        """Count the limits the commands ``u`` (T, nv) break, following the stream so far;
        why the first broken one breaks ("" if none)."""
        lim, dt = self.limits, self.limits.dt_s
        full = np.vstack([self._u2, self._u1, u])
        ratios = {
            "velocity": np.abs(u) / lim.velocity_radps,
            "acceleration": np.abs(np.diff(full, axis=0)[1:]) / (lim.acceleration_radps2 * dt),
            "jerk": np.abs(np.diff(full, 2, axis=0)) / (lim.jerk_radps3 * dt * dt),
        }
        self._u2, self._u1 = full[-2].copy(), full[-1].copy()
        why = ""
        for kind, ratio in ratios.items():
            worst = ratio.max(axis=1)
            self.worst[kind] = max(self.worst[kind], float(np.nanmax(worst, initial=0.0)))
            broken = ~(worst <= 1.0 + TOLERANCE)  # NaN too
            self.counts[kind] += int(broken.sum())
            if broken.any() and not why:
                k = int(np.argmax(broken))
                j = int(np.nanargmax(ratio[k])) if np.isfinite(ratio[k]).any() else 0
                why = (
                    f"{kind} limit of {lim.joint_names[j]} broken "
                    f"({ratio[k, j]:.3f} times the limit)"
                )
        return why

    def total(self) -> int:
        """Commands counted beyond any limit (a command breaking two counts twice)."""
        return sum(self.counts.values())
