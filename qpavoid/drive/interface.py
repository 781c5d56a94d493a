"""What the control loop needs of an arm: its state and clock, a velocity command, a stop.

Every arm the loop drives, simulated or real, is an :class:`Arm`. The loop
(:mod:`qpavoid.loop.runner`) reads the arm's state once a tick, computes the controller's
command from it and sends it; it never reaches past this interface, so the kinematic
simulation, a live run and a Franka through ``franky-control`` run the same code.

Joint vectors are in the robot description's active joints (``robot.joint_names``, nv of
them): an adapter maps them to the arm's own joints and keeps the rest (a locked joint,
the fingers) where the description holds them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from qpavoid.drive.limits import CommandLimits

__all__ = ["Arm", "ArmState"]


@dataclass(frozen=True)
class ArmState:
    """What an arm reports at one instant.

    Attributes
    ----------
    time_s
        When the state was measured, on the arm's clock, s (monotonic; a clock that stops
        advancing is a stalled arm).
    q
        (nv,) joint angles, rad, the description's active joints.
    dq
        (nv,) joint velocities, rad/s, as the arm measures (or commands) them.
    """

    time_s: float
    q: np.ndarray
    dq: np.ndarray


@runtime_checkable
class Arm(Protocol):
    """An arm the control loop can drive.

    Attributes
    ----------
    name
        Which arm, for logs and errors (``"simulation"``, ``"franka:127.0.0.1"``).
    joint_names
        The description's active joints, in the order of every vector exchanged.
    limits
        The limits every command must keep (:class:`~qpavoid.drive.limits.CommandLimits`):
        the description's, or tighter where the arm's interface imposes its own
        (franky-control's); the loop tightens the controller to them
        (:meth:`~qpavoid.control.controller.Controller.accept_limits`) and checks every
        command against them.

    Every method may raise :class:`~qpavoid.core.errors.ArmError` (unreachable, stalled,
    a rejected command, a fault the arm reports); the loop then stops and ends the run with
    the error as its ``end_reason``.
    """

    name: str
    joint_names: tuple[str, ...]
    limits: CommandLimits

    def read(self) -> ArmState:
        """The arm's newest state (waits at most one of its periods for it)."""
        ...

    def send(self, dq: np.ndarray) -> None:
        """Command the joint velocities ``dq`` (nv,), rad/s, held until the next command.

        The command is within the arm's limits (the controller's commands are: checked by
        :class:`~qpavoid.drive.limits.CommandCheck`); an adapter refuses, with an
        :class:`~qpavoid.core.errors.ArmError`, one it would have to clip.
        """
        ...

    def stop(self) -> None:
        """Bring the arm to rest along its path at its own deceleration (a category 2
        stop), and return once it is at rest or raise :class:`ArmError`."""
        ...

    def close(self) -> None:
        """Release the arm (idempotent; after :meth:`stop`)."""
        ...
