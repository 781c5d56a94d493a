"""A Franka FR3 driven through ``franky-control``: joint velocities at the loop's rate, its
measured state and clock, a stop at its own deceleration (``--arm franka:HOST``).

``franky-control`` (the extra ``franka``: ``pip install "qpavoid[franka]"``) 2.x bundles
libfranka 0.21, which talks to the arm's controller (or to franky-sim, its simulator:
:mod:`qpavoid.drive.franka_sim`) at 1 kHz from a real-time thread of its own. libfranka
0.21 speaks version 10 of libfranka's protocol, an FR3's on robot system 5.9.0 or later; a
Panda's controller (versions 2-5, libfranka < 0.10) refuses it, and is driven through
panda-python instead (:mod:`qpavoid.drive.panda`, ``--arm panda:HOST``). At connect the arm
is checked against the description (:class:`~qpavoid.drive.franka_model.FrankaModel`): an arm
that accepts franky-control's libfranka speaks its version, and is refused unless the
description's ``franka.toml`` lists it (``--robot panda`` answered by an FR3: one line
naming both); the model the controller names in the URDF it sends (libfranka >= 0.15's
``getRobotModel``, franky's ``model_urdf``) is kept (:attr:`FrankaArm.reported_model`) and
said in that line.

Each :meth:`FrankaArm.send` hands franky's thread a new target (``robot.move(
JointVelocityMotion, asynchronous=True)`` replaces the running motion at the next 1 ms
cycle); franky reaches it along a Ruckig profile within the joint limits set here, so a
command stream that keeps those limits (checked by
:class:`~qpavoid.drive.limits.CommandCheck`, never clipped) is followed within a cycle or
two. A target is held for :attr:`FrankaArm.watchdog_s` only: when the loop stops sending
(it hangs, its process dies), the arm ramps itself to rest.

Joints: the description's active joints are some of the arm's seven (``fr3_joint1`` ...
``fr3_joint7``); a locked joint (the FR3's ``fr3_joint3`` in the paper's six-joint mode)
is held at its lock angle (velocity 0), and streaming refuses to start unless the arm's
locked joint is within :data:`LOCK_TOLERANCE_RAD` of it (:meth:`FrankaArm.move_to` puts it
there). The fingers (``held``) are the gripper's, not driven here.

Limits: franky refuses (faults on) a velocity target beyond its own joint limits, which
for franky 2.0 are the Panda's (2.175 rad/s on joints 1-4, 2.61 on 5-7; 7.5 rad/s² on
joint 2), tighter than the FR3's published ones in places. The limits the adapter sets
in franky and checks every command against are, per joint, the tighter of the
description's (``CommandLimits.of``) and franky's maxima (:attr:`FrankaArm.limits`).
"""

from __future__ import annotations

import dataclasses
import re
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.core.errors import ArmError, InputError
from qpavoid.drive.franka_joints import LOCK_TOLERANCE_RAD, FrankaJoints
from qpavoid.drive.franka_model import FRANKY
from qpavoid.drive.libfranka import LibfrankaArm
from qpavoid.drive.libfranka_state import REST_RADPS, RawState
from qpavoid.drive.limits import CommandLimits

try:
    import franky  # type: ignore[import-untyped]
except ImportError:  # the extra `franka` is not installed
    franky = None

__all__ = ["LOCK_TOLERANCE_RAD", "REST_RADPS", "FrankaArm", "FrankaJoints"]

#: The robot's name in a URDF (its first ``<robot name="...">``).
_URDF_ROBOT = re.compile(r"<robot\b[^>]*?\bname\s*=\s*[\"']([^\"']*)[\"']")


class FrankaArm(LibfrankaArm):
    """A Franka FR3 (or franky-sim) through franky-control, as an
    :class:`~qpavoid.drive.interface.Arm` (parameters, errors and behaviour:
    :class:`~qpavoid.drive.libfranka.LibfrankaArm`).

    ``watchdog_s`` is franky's hold of each target (millisecond resolution): the arm ramps
    itself to rest when no newer one comes within it. ``move_dynamics_factor`` is the
    fraction of the joint limits (velocity, acceleration and jerk) :meth:`move_to` moves at.
    """

    binding = FRANKY

    # -- the binding ------------------------------------------------------------------------

    def _require(self) -> Any:
        if franky is None:
            raise InputError(
                f"the Franka adapter needs franky-control: {FRANKY.install()}",
                name="franky",
                value=None,
            )
        return franky

    def _make(self, realtime: bool) -> Any:
        fk = self._lib
        config = fk.RealtimeConfig.Enforce if realtime else fk.RealtimeConfig.Ignore
        return fk.Robot(self.host, realtime_config=config)

    def _server_version(self) -> int:
        """franky-control's own version: the arm accepted it. The model the arm names is
        read from the URDF its controller sends (None if it sends none)."""
        try:
            urdf = str(self._robot.model_urdf)
        except Exception:  # informative only: a controller without getRobotModel
            urdf = ""
        found = _URDF_ROBOT.search(urdf[:4096])
        self.reported_model = found[1] if found else None
        return self.binding.server_version

    def _set_limits(self, robot: Robot) -> CommandLimits:
        """Set franky's joint limits to the tighter of the description's and franky's, and
        return the active joints' (what every command is checked against)."""
        r = self._robot
        v_max = np.array(r.joint_velocity_limit.max, dtype=float)
        a_max = np.array(r.joint_acceleration_limit.max, dtype=float)
        j_max = np.array(r.joint_jerk_limit.max, dtype=float)
        mine = CommandLimits.of(robot, self.period_s)
        v, a, j = v_max.copy(), a_max.copy(), j_max.copy()
        described_v = dict(robot.arm.max_velocity_radps)
        described_a = dict(robot.arm.max_acceleration_radps2)
        described_j = dict(robot.arm.max_jerk_radps3)
        for k, n in enumerate(self.joints.names):
            v[k] = min(v[k], described_v.get(n, np.inf))
            a[k] = min(a[k], described_a.get(n, np.inf))
            j[k] = min(j[k], described_j.get(n, np.inf))
        active = list(self.joints.active)
        v[active] = np.minimum(v[active], mine.velocity_radps)
        a[active] = np.minimum(a[active], mine.acceleration_radps2)
        j[active] = np.minimum(j[active], mine.jerk_radps3)
        self._call(r.joint_velocity_limit.set, v.tolist())
        self._call(r.joint_acceleration_limit.set, a.tolist())
        self._call(r.joint_jerk_limit.set, j.tolist())
        return dataclasses.replace(
            mine,
            velocity_radps=v[active],
            acceleration_radps2=a[active],
            jerk_radps3=j[active],
        )

    def _prepare(self) -> None:
        self._hold = self._lib.Duration(max(1, round(self.watchdog_s * 1000)))
        self._call(setattr, self._robot, "relative_dynamics_factor", 1.0)
        if self._call(getattr, self._robot, "has_errors"):
            self._call(self._robot.recover_from_errors)

    def _read(self) -> RawState:
        """franky's newest robot state, after any error of the motion thread."""
        robot = self._usable()
        self._call(robot.poll_motion)  # raises what the motion thread stored
        state = self._call(getattr, robot, "state")
        stopped = state.robot_mode in (franky.RobotMode.Reflex, franky.RobotMode.UserStopped)
        return RawState.of(state, any(state.current_errors.__getstate__()) or stopped)

    def _stream(self, v7: np.ndarray) -> None:
        motion = franky.JointVelocityMotion(v7, duration=self._hold)
        self._call(self._robot.move, motion, asynchronous=True)

    def _halt(self) -> None:
        """franky's stop motion of the running control signal (at the joint limits of
        :attr:`limits`), joined."""
        robot = self._robot
        kind = self._call(getattr, robot, "current_control_signal_type")
        if kind is not None:
            stop = (
                franky.JointStopMotion()
                if kind == franky.ControlSignalType.JointPositions
                else franky.JointVelocityStopMotion()
            )
            self._call(robot.move, stop, asynchronous=True)
        if not self._call(robot.join_motion, self.stop_timeout_s):
            raise ArmError(
                f"{self.name}: the stop did not end within {self.stop_timeout_s:g} s",
                arm=self.name,
                reason="stalled",
                value=self.stop_timeout_s,
            )

    def _move(self, q7: np.ndarray, timeout_s: float) -> None:
        """franky's joint motion at ``move_dynamics_factor`` of the limits, joined."""
        robot = self._robot
        motion = franky.JointMotion(q7, relative_dynamics_factor=self.move_dynamics_factor)
        self._call(robot.move, motion, asynchronous=True)
        if not self._call(robot.join_motion, timeout_s):
            self._call(robot.move, franky.JointStopMotion(), asynchronous=True)
            raise ArmError(
                f"{self.name}: move_to did not end within {timeout_s:g} s",
                arm=self.name,
                reason="stalled",
                value=timeout_s,
            )

    def _in_control(self) -> bool:
        return bool(self._robot.is_in_control)
