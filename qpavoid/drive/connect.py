"""Which arm a run drives, by name: ``sim``, ``franka:HOST``, ``panda:HOST`` or
``ros2:CELL.toml`` (the ``--arm`` flag).

A Franka arm is driven through the binding of libfranka its controller speaks
(:mod:`qpavoid.drive.libfranka`): ``franka:HOST`` through franky-control (libfranka 0.21:
an FR3 on robot system 5.9.0 or later), ``panda:HOST`` through panda-python (libfranka
0.9.2: a Panda on robot system 4.2.1 or later). Either checks at connect that the arm is
the one ``--robot`` describes. ``ros2:CELL.toml`` is an arm under ros2_control
(:mod:`qpavoid.drive.ros2_arm`), the cell file's (:func:`~qpavoid.sensing.ros2_cell.load_cell`).
"""

from __future__ import annotations

import contextlib
import importlib
from collections.abc import Iterator

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.core.errors import InputError
from qpavoid.drive.interface import Arm
from qpavoid.drive.libfranka import LibfrankaArm
from qpavoid.drive.ros2_arm import Ros2Arm
from qpavoid.drive.simulated import SimulatedArm
from qpavoid.sensing.ros2_cell import load_cell

__all__ = ["ARM_KINDS", "open_arm", "parse_arm"]

#: What ``--arm`` may name: the kinematic simulation on the wall clock, an FR3 (franky-sim
#: too) at an FCI address through franky-control, or a Panda through panda-python.
ARM_KINDS = ("sim", "franka:HOST", "panda:HOST", "ros2:CELL.toml")
#: The adapter of each Franka kind, as (module, class): imported when that arm is opened,
#: so that a run without it never loads its binding (franky-control takes about 0.1 s).
_FRANKA_ADAPTERS = {
    "franka": ("qpavoid.drive.franka", "FrankaArm"),
    "panda": ("qpavoid.drive.panda", "PandaArm"),
}


def franka_adapter(kind: str) -> type[LibfrankaArm]:
    """The adapter class of the Franka ``kind`` (``"franka"`` or ``"panda"``)."""
    module, name = _FRANKA_ADAPTERS[kind]
    adapter: type[LibfrankaArm] = getattr(importlib.import_module(module), name)
    return adapter


def parse_arm(text: str) -> tuple[str, str | None]:
    """``("sim", None)``, ``("franka", host)``, ``("panda", host)`` or ``("ros2", cell
    file)`` from ``--arm``'s text.

    Raises
    ------
    InputError
        Anything else, or a Franka without its address.
    """
    kind, _, host = str(text).partition(":")
    if kind == "sim" and not host:
        return "sim", None
    if (kind in _FRANKA_ADAPTERS or kind == "ros2") and host.strip():
        return kind, host.strip()
    raise InputError(
        f"--arm takes one of {', '.join(ARM_KINDS)}, got {text!r}", name="--arm", value=text
    )


@contextlib.contextmanager
def open_arm(
    text: str, robot: Robot, q0: np.ndarray, period_s: float, trust_ros_graph: bool = False
) -> Iterator[Arm]:
    """The arm ``text`` names, at the start configuration ``q0`` (rad; a real arm is moved
    there slowly by its own joint motion first), released on exit (stopped, disconnected).

    Raises
    ------
    InputError
        The adapter's binding is not installed (one line naming its extra).
    ArmError
        The arm is unreachable, refuses the connection, is not the one ``robot``
        describes ("model"), or cannot reach ``q0``; a ROS 2 arm: no controller subscribes
        (the run does not move), no joint state, not at ``q0``.
    """
    kind, host = parse_arm(text)
    if kind == "sim":
        yield SimulatedArm(robot, q0, period_s)
        return
    assert host is not None
    if kind == "ros2":  # not moved to q0: refused unless there (Ros2Arm.check_start)
        arm = Ros2Arm(robot, load_cell(host), period_s, trust_ros_graph)
        try:
            arm.connect()
            arm.check_start(q0)
            yield arm
        finally:
            arm.close()
        return
    with franka_adapter(kind)(robot, host, period_s=period_s) as franka:
        franka.move_to(q0)
        yield franka
