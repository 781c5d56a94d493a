"""A Franka Emika Panda (FER) driven through ``panda-python``: joint velocities at the loop's
rate, its measured state and clock, a stop at the description's decelerations
(``--arm panda:HOST``).

A Panda's controller speaks libfranka's protocol up to version 5 (robot system 4.2.1 and
later), which only libfranka < 0.10 speaks (Franka's compatibility matrix): franky-control
2's libfranka 0.21 is refused by it. ``panda-python`` (the extra ``panda``: ``pip install
"qpavoid[panda]"``; import name ``panda_py``) 1.x's PyPI wheels bundle libfranka 0.9.2,
version 5. It is imported when a :class:`PandaArm` is made, not before: without it, one
line names the extra. At connect the arm is checked against the description
(:class:`~qpavoid.drive.franka_model.FrankaModel`): an arm whose controller speaks another
version (an FR3's 6-10, told by its refusal of libfranka 0.9.2 or by
``Robot.server_version()``) is refused in one line naming both.

panda-python drives the arm through torque controllers of its own, run in C++ at 1 kHz
by libfranka's real-time thread (its joint-velocity interface would run a Python callback
every millisecond instead). :class:`PandaArm` streams the commands into its joint
impedance controller (``controllers.JointPosition``: ``τ = K_p (q_d − q) + K_d (q̇_d −
q̇)``, panda-python's default gains, the Panda compensating gravity itself): q̇_d is the
command, q_d the reference the commands integrate (each send advances it by the previous
command over the time since, at most :data:`MAX_STEP_PERIODS` periods, so that a late send
never jumps it). The arm follows within the controller's lag, not along the Ruckig
profile franky's motion generator gives an FR3; a loop that stops sending leaves the
reference where it was, and the arm settles near it (within ``K_d q̇_d / K_p``) instead of
moving on. :meth:`PandaArm.stop` ramps the reference's velocity to zero along a straight
line in joint space at the description's decelerations (the loop's braking ramp, made by
the adapter), waits for rest and ends the controller. :meth:`PandaArm.move_to` is
panda-python's ``move_to_joint_position`` at ``move_dynamics_factor`` of its speed.

Nothing here has driven a Panda or a simulator of its protocol (there is none on this
machine: docs/real-robot.md §1b); the tests check the adapter's logic on a stand-in for
panda-python, and panda-python's own refusals of an FR3's and of franky-sim.
"""

from __future__ import annotations

import importlib
import math
import threading
import time
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.core.checks import one_line
from qpavoid.core.errors import InputError
from qpavoid.drive.franka_model import PANDA_PY
from qpavoid.drive.libfranka import LibfrankaArm
from qpavoid.drive.libfranka_state import RawState
from qpavoid.drive.limits import CommandLimits

__all__ = ["MAX_STEP_PERIODS", "PandaArm"]

#: How far one send may advance the reference, in command periods: two covers a send's
#: jitter (the loop's p99 period is 1.1-1.3 of its median: docs/real-robot.md §3) and
#: keeps a send after a stall from jumping the reference by the whole stall (a step of
#: K_p · q̇ · stall, 60 Nm at 600 Nm/rad, 1 rad/s and 0.1 s).
MAX_STEP_PERIODS = 2.0


def _import_panda_py() -> Any:
    """``panda_py`` with its controllers, imported now; :class:`InputError` naming the extra
    if it cannot be."""
    try:
        module = importlib.import_module("panda_py")
        importlib.import_module("panda_py.controllers")
        importlib.import_module("panda_py.libfranka")
    except ImportError as exc:
        raise InputError(
            f"--arm panda drives a Panda through panda-python: {PANDA_PY.install()} "
            f"(import panda_py: {one_line(exc)})",
            name="panda_py",
            value=None,
        ) from None
    return module


class PandaArm(LibfrankaArm):
    """A Franka Emika Panda (FER) through panda-python, as an
    :class:`~qpavoid.drive.interface.Arm` (parameters, errors and behaviour:
    :class:`~qpavoid.drive.libfranka.LibfrankaArm`).

    ``watchdog_s`` bounds nothing here: panda-python holds no command for a time, the
    reference stays where the last send left it (the loop's watchdog stops the arm after
    ``watchdog_s`` of silence in any case). ``move_dynamics_factor`` is panda-python's
    ``speed_factor`` of ``move_to_joint_position``. The limits every command is checked
    against are the description's (panda-python imposes none of its own).
    """

    binding = PANDA_PY

    def __init__(self, robot: Robot, host: str, **kwargs: Any):
        self._lock = threading.Lock()  # the reference: the loop's sends and a watchdog's stop
        self._controller: Any = None  # panda-python's JointPosition, while streaming
        self._reference = np.zeros(7)  # q_d, rad
        self._velocity = np.zeros(7)  # q̇_d, rad/s
        self._advanced = 0.0  # when the reference last moved on, monotonic s
        self._decel7 = np.full(7, np.inf)  # the seven joints' decelerations, rad/s²
        super().__init__(robot, host, **kwargs)

    # -- the binding ------------------------------------------------------------------------

    def _require(self) -> Any:
        return _import_panda_py()

    def _make(self, realtime: bool) -> Any:
        config = self._lib.libfranka.RealtimeConfig
        return self._lib.Panda(
            self.host, realtime_config=config.kEnforce if realtime else config.kIgnore
        )

    def _server_version(self) -> int:
        return int(self._call(self._robot.get_robot).server_version())

    def _set_limits(self, robot: Robot) -> CommandLimits:
        limits = CommandLimits.of(robot, self.period_s)
        self._decel7[list(self.joints.active)] = limits.acceleration_radps2
        return limits

    def _read(self) -> RawState:
        """panda-python's newest state (its control loop's while a controller runs, else
        one read from the arm), after any error of its control thread."""
        panda = self._usable()
        self._call(panda.raise_error)  # raises what the control thread stored
        state = self._call(panda.get_state)
        modes = self._lib.libfranka.RobotMode
        stopped = state.robot_mode in (modes.kReflex, modes.kUserStopped)
        return RawState.of(state, bool(state.current_errors) or stopped)

    def _advance(self, now: float) -> None:
        """Move the reference on by its velocity over the time since it last moved (at
        most :data:`MAX_STEP_PERIODS` periods)."""
        step = min(max(now - self._advanced, 0.0), MAX_STEP_PERIODS * self.period_s)
        self._reference = self._reference + self._velocity * step
        self._advanced = now

    def _stream(self, v7: np.ndarray) -> None:
        with self._lock:
            if self._controller is None:  # streaming starts: from where the arm is
                start = self._state().q
                controller = self._lib.controllers.JointPosition()
                self._call(self._robot.start_controller, controller)
                self._controller = controller
                self._reference, self._velocity = start.copy(), np.zeros(7)
                self._advanced = time.monotonic()
            self._advance(time.monotonic())
            self._velocity = np.array(v7, dtype=float)
            self._call(self._controller.set_control, self._reference, self._velocity)

    def _halt(self) -> None:
        """The reference's velocity ramped to zero along a straight line in joint space at
        the description's decelerations, one command period a step; then held. A reference
        left still (no send for :data:`MAX_STEP_PERIODS` periods) is held at once: the arm
        settled near it, and a ramp from the last command would move it on."""
        with self._lock:
            if self._controller is None:
                return
            now = time.monotonic()
            if now - self._advanced > MAX_STEP_PERIODS * self.period_s:
                self._velocity = np.zeros(7)
            self._advance(now)
            v0 = self._velocity.copy()
            duration_s = float(np.max(np.abs(v0) / self._decel7))
            steps = math.ceil(duration_s / self.period_s - 1e-9)
            due = now
            for k in range(1, steps + 1):
                due += self.period_s
                time.sleep(max(0.0, due - time.monotonic()))
                self._advance(time.monotonic())
                self._velocity = v0 * (1.0 - k / steps)
                self._call(self._controller.set_control, self._reference, self._velocity)
            self._velocity = np.zeros(7)
            self._call(self._controller.set_control, self._reference, self._velocity)

    def _rested(self) -> None:
        """End the controller (the arm, at rest, is held by its own)."""
        with self._lock:
            if self._controller is not None:
                self._controller = None
                self._call(self._robot.stop_controller)

    def _move(self, q7: np.ndarray, timeout_s: float) -> None:
        """panda-python's joint motion at ``move_dynamics_factor`` of its speed (its own
        trajectory controller; it ends any controller running, and blocks until the
        motion has ended: ``timeout_s`` bounds nothing here)."""
        with self._lock:
            self._controller = None
        self._call(self._robot.move_to_joint_position, q7, speed_factor=self.move_dynamics_factor)

    def _in_control(self) -> bool:
        return bool(self._robot.is_moving())
