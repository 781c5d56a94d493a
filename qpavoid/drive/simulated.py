"""The kinematic arm on the wall clock, behind the same :class:`~qpavoid.drive.interface.Arm`
interface as a real one: for a real-time loop without hardware, and for its tests."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from qpavoid.arm.braking import ArmResponse, BrakingConfig
from qpavoid.arm.model import Robot
from qpavoid.drive.interface import ArmState
from qpavoid.drive.limits import CommandLimits

__all__ = ["SimulatedArm"]


class SimulatedArm:
    """An arm that integrates its joint velocities in real time (explicit Euler, steps of at
    most ``period_s``), following each command after its reaction time and within its
    acceleration limits (:class:`~qpavoid.arm.braking.ArmResponse`, wall-clock mode).

    Parameters
    ----------
    robot
        The arm's description.
    q0
        (nv,) where it starts, rad.
    period_s
        Its integration step and the period of its reaction, s.
    braking
        How it follows a command (default: the description's reaction time and limits);
        None: exactly and at once.
    clock
        Its clock, s (default: ``time.perf_counter``).
    hold_s
        How long it follows a command with no newer one before it brakes to rest on its own,
        s (as franky holds a Franka's: :class:`~qpavoid.drive.franka.FrankaArm`'s
        ``watchdog_s``).
    """

    name = "simulation"

    def __init__(
        self,
        robot: Robot,
        q0: np.ndarray,
        period_s: float = 0.002,
        braking: BrakingConfig | None = None,
        clock: Callable[[], float] = time.perf_counter,
        hold_s: float = 0.1,
    ):
        self.joint_names = tuple(robot.joint_names)
        self.limits = CommandLimits.of(robot, period_s)
        cfg = (braking or BrakingConfig()).resolve(robot.arm)
        self._model: ArmResponse | None = ArmResponse(cfg, self.joint_names, period_s)
        self.period_s, self.clock = period_s, clock
        self.q = robot.check_q(q0).astype(float).copy()
        self.dq = np.zeros(robot.nv)
        self._command = np.zeros(robot.nv)
        self._t = clock()
        self.closed = False
        self.hold_s = hold_s
        self._expires: float | None = None  # when the held command runs out

    @classmethod
    def ideal(cls, robot: Robot, q0: np.ndarray, period_s: float = 0.002) -> SimulatedArm:
        """An arm that follows every command exactly and at once."""
        arm = cls(robot, q0, period_s)
        arm._model = None
        return arm

    def _advance(self) -> None:
        now = self.clock()
        while now - self._t > 1e-12:
            h = min(self.period_s, now - self._t)
            if self._expires is not None and self._t + h >= self._expires:
                h = max(self._expires - self._t, 0.0)  # up to the expiry, then rest
                if h <= 1e-12:
                    self._command = np.zeros_like(self._command)
                    if self._model is not None:
                        self._model.send(self._command, self._t)
                    self._expires = None
                    continue
            v = self._command if self._model is None else self._model.step(self._t)
            self.q = self.q + v * h
            self.dq, self._t = v.copy(), self._t + h

    def read(self) -> ArmState:
        """Where the arm is now."""
        self._advance()
        return ArmState(self._t, self.q.copy(), self.dq.copy())

    def send(self, dq: np.ndarray) -> None:
        """Follow ``dq`` (rad/s) from now."""
        self._advance()
        self._command = np.array(dq, dtype=float)
        self._expires = self._t + self.hold_s if np.any(self._command) else None
        if self._model is not None:
            self._model.send(self._command, self._t)

    def stop(self) -> None:
        """Command rest (the arm's own ramp brings it there)."""
        self.send(np.zeros_like(self.dq))

    def close(self) -> None:
        self.closed = True
