"""Which arm a run drives, by name: ``sim`` or ``franka:HOST`` (the ``--arm`` flag)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.core.errors import InputError
from qpavoid.drive.franka import FrankaArm
from qpavoid.drive.interface import Arm
from qpavoid.drive.simulated import SimulatedArm

__all__ = ["ARM_KINDS", "open_arm", "parse_arm"]

#: What ``--arm`` may name: the kinematic simulation on the wall clock, or a Franka (FR3,
#: Panda; franky-sim too) at an FCI address through franky-control.
ARM_KINDS = ("sim", "franka:HOST")


def parse_arm(text: str) -> tuple[str, str | None]:
    """``("sim", None)`` or ``("franka", host)`` from ``--arm``'s text.

    Raises
    ------
    InputError
        Anything else, or a Franka without its address.
    """
    kind, _, host = str(text).partition(":")
    if kind == "sim" and not host:
        return "sim", None
    if kind == "franka" and host.strip():
        return "franka", host.strip()
    raise InputError(
        f"--arm takes one of {', '.join(ARM_KINDS)}, got {text!r}", name="--arm", value=text
    )


@contextlib.contextmanager
def open_arm(text: str, robot: Robot, q0: np.ndarray, period_s: float) -> Iterator[Arm]:
    """The arm ``text`` names, at the start configuration ``q0`` (rad; a real arm is moved
    there slowly by its own joint motion first), released on exit (stopped, disconnected).

    Raises
    ------
    ArmError
        The arm is unreachable, refuses the connection, or cannot reach ``q0``.
    """
    kind, host = parse_arm(text)
    if kind == "sim":
        yield SimulatedArm(robot, q0, period_s)
        return
    assert host is not None
    with FrankaArm(robot, host, period_s=period_s) as franka:
        franka.move_to(q0)
        yield franka
