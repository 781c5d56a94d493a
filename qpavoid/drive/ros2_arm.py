"""An arm under ros2_control, over Cyclone DDS: its ``sensor_msgs/JointState`` in, joint
velocities out as its ``JointGroupVelocityController`` takes them
(``std_msgs/Float64MultiArray`` on ``<controller>/commands``, the controller's joint order;
published reliable, as the controller subscribes).

ros2_controllers' velocity controller has **no timeout**: it holds the last command until
the next. The loop's :class:`~qpavoid.loop.plants.DrivenArm` ramps to rest on every exit
path the process reaches (the goal, Ctrl-C, SIGTERM, an error, a lost camera) and then
calls :meth:`Ros2Arm.stop` (a braking ramp within the arm's limits, then zeros, sent
twice; the loop's watchdog calls it too); a *killed* process sends nothing, and the
arm keeps its last velocity unless the arm side has a watchdog (docs/ros2.md §8).

At connect (:meth:`Ros2Arm.connect`): the command topic must have a subscriber within the
cell's ``subscriber_timeout_s`` (else the run refuses to move, one line), and a JointState
must come that names every joint of the controller (else one line). Joint states naming
other joints (a gripper, a second arm) are mapped by name; one missing a controller joint,
or with NaN, is dropped and counted (:attr:`Ros2Arm.counters`).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import Counter
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.core.errors import ArmError, InputError
from qpavoid.drive.interface import ArmState
from qpavoid.drive.limits import CommandLimits
from qpavoid.drive.stop_ramp import ramp_to_rest
from qpavoid.sensing.dds_input import check_trust
from qpavoid.sensing.ros2_cell import (
    Cell,
    participant,
    reader,
    state_waitset,
    take_raw,
    writer,
)
from qpavoid.sensing.ros2_types import dds_type, need, stamp_s

__all__ = ["START_TOLERANCE_RAD", "Ros2Arm"]

#: How far from the run's start configuration the arm may be when the run begins, rad (it
#: is not moved there: bring it with its own tools, e.g. a joint trajectory controller).
START_TOLERANCE_RAD = 0.05
#: How long :meth:`Ros2Arm.connect` waits for the first JointState, s.
STATE_TIMEOUT_S = 5.0


class Ros2Arm:
    """An :class:`~qpavoid.drive.interface.Arm` under ros2_control (module docstring).

    Parameters
    ----------
    robot
        The arm's description; its active joints are the controller's (any order).
    cell
        The cell: distribution, domain, the arm's topics and the controller's joint order.
    period_s
        The control period, s (the limits' and :meth:`read`'s wait).
    trust_ros_graph
        The explicit opt-in to take the arm's state from the ROS graph.
    """

    #: How long the arm holds a command on its own before it brakes, s: None, the
    #: controller holds the last command until the next (the loop's watchdog stops it,
    #: :meth:`stop`).
    holds_command_s: float | None = None

    def __init__(self, robot: Robot, cell: Cell, period_s: float, trust_ros_graph: bool = False):
        check_trust(trust_ros_graph, cell.domain_id)
        arm = cell.arm
        self.name = f"ros2:{arm.controller}"
        self.joint_names = tuple(robot.joint_names)
        order = arm.joints or self.joint_names
        if sorted(order) != sorted(self.joint_names):
            raise InputError(
                f"ROS 2 cell file {cell.path}: [arm] joints {list(order)} are not the "
                f"robot's joints {list(self.joint_names)} (its description's names, in the "
                "controller's order)",
                name="joints",
                value=list(order),
            )
        self.controller_joints = tuple(order)
        #: for each controller joint, its index in the description's joints
        self._to_controller = np.array([self.joint_names.index(j) for j in order])
        self.limits = CommandLimits.of(robot, period_s)
        self.period_s, self.cell = period_s, cell
        self._robot = robot
        n = len(self.joint_names)
        self._sent = (np.zeros(n), np.zeros(n))  # the last two commands published
        self._sending = threading.RLock()  # a stop's ramp and a send never interleave
        self.counters: Counter[str] = Counter()
        self._dp = participant(cell.domain_id)
        self._states = reader(
            self._dp, cell.distribution, arm.joint_states, "sensor_msgs/msg/JointState"
        )
        self._arrival = state_waitset(self._dp, self._states)
        self._commands = writer(
            self._dp, cell.distribution, arm.commands, "std_msgs/msg/Float64MultiArray"
        )
        self._js: Any = dds_type(cell.distribution, "sensor_msgs/msg/JointState")
        self._cmd = dds_type(cell.distribution, "std_msgs/msg/Float64MultiArray")
        self._layout = dds_type(cell.distribution, "std_msgs/msg/MultiArrayLayout")(
            dim=[], data_offset=0
        )
        self._index: dict[tuple[str, ...], np.ndarray | None] = {}
        self._state: ArmState | None = None
        self._lock = threading.Lock()
        self.closed = False

    def connect(self, timeout_s: float | None = None) -> ArmState:
        """Wait for the controller's subscription and the first joint state.

        Raises
        ------
        ArmError
            No subscriber on the command topic within the timeout (the run does not move),
            or no usable JointState.
        """
        arm = self.cell.arm
        wait = arm.subscriber_timeout_s if timeout_s is None else timeout_s
        until = time.monotonic() + wait
        while not self._commands.get_matched_subscriptions():
            if time.monotonic() > until:
                raise ArmError(
                    f"nobody subscribes to {arm.commands} on DDS domain {self.cell.domain_id} "
                    f"after {wait:g} s: is the controller loaded and active (ros2 control "
                    "list_controllers)? The run does not move",
                    reason="no controller",
                )
            time.sleep(0.02)
        until = time.monotonic() + STATE_TIMEOUT_S
        while (state := self._take()) is None:
            if time.monotonic() > until:
                seen = dict(self.counters)
                raise ArmError(
                    f"no usable sensor_msgs/JointState on {arm.joint_states} naming the "
                    f"controller's joints {list(self.controller_joints)} within "
                    f"{STATE_TIMEOUT_S:g} s (dropped: {seen or 'none came'})",
                    reason="no joint states",
                )
            time.sleep(0.002)
        return state

    def check_start(self, q0: np.ndarray) -> None:
        """Refuse (ArmError, one line) an arm further than :data:`START_TOLERANCE_RAD` from
        the run's start ``q0`` (rad)."""
        state = self._state or self.connect()
        off = np.abs(state.q - q0)
        if off.max() > START_TOLERANCE_RAD:
            j = int(off.argmax())
            raise ArmError(
                f"the arm is {off[j]:.3f} rad from the run's start at {self.joint_names[j]} "
                f"(tolerance {START_TOLERANCE_RAD} rad): move it to "
                f"{np.round(q0, 4).tolist()} rad first (the description's joint order)",
                reason="not at start",
            )

    def _names_index(self, names: tuple[str, ...]) -> np.ndarray | None:
        if names not in self._index:
            if len(self._index) > 16:
                self._index.clear()
            try:
                self._index[names] = np.array([names.index(j) for j in self.joint_names])
            except ValueError:
                self._index[names] = None
        return self._index[names]

    def _take(self) -> ArmState | None:
        """The newest usable joint state taken now (None: none new)."""
        newest = None
        for data in take_raw(self._states, 16):
            self.counters["received"] += 1
            try:
                msg = self._js.deserialize(data)
                names = tuple(msg.name)
                index = self._names_index(names)
                if index is None:
                    self.counters["dropped_wrong_joints"] += 1
                    continue
                q = np.asarray(msg.position, dtype=float)
                if len(q) != len(names):
                    raise ValueError("positions")
                dq = np.asarray(msg.velocity, dtype=float)
                t = stamp_s(msg.header.stamp)
            except Exception:
                self.counters["dropped_unreadable"] += 1
                continue
            if t is None:
                self.counters["dropped_bad_stamp"] += 1
                continue
            if not np.isfinite(q[index]).all():
                self.counters["dropped_non_finite"] += 1
                continue
            v = dq[index] if len(dq) == len(names) and np.isfinite(dq[index]).all() else None
            if self._state is not None and t <= self._state.time_s:
                self.counters["out_of_order_or_duplicate"] += 1
                continue
            if v is None:  # no velocities: from the last state
                last = self._state
                v = (
                    np.zeros(len(index))
                    if last is None
                    else (q[index] - last.q) / (t - last.time_s)
                )
            newest = self._state = ArmState(t, q[index].copy(), np.asarray(v, dtype=float).copy())
            self.counters["accepted"] += 1
        return newest

    def read(self, fresh: bool = False) -> ArmState:
        """The newest joint state (waits at most one period for a newer one; the stamps'
        clock is the arm's: a state that stops coming is a stalled arm).

        With ``fresh``, the states already queued are taken as the past and the call waits
        (on a DDS wait set, at most one period) for the next one to arrive, so that a tick
        starts on a state one DDS hop old rather than up to one arm period older
        (benchmarks/ros2_hop.py measures both)."""
        if self.closed:
            raise ArmError("the ROS 2 arm is closed", reason="closed")
        until = time.perf_counter() + self.period_s
        if fresh:
            self._take()
        while (state := self._take()) is None and (left := until - time.perf_counter()) > 0:
            self._arrival.wait(int(left * 1e9))
        if state is None:
            state = self._state
        if state is None:
            raise ArmError("no joint state from the arm", reason="no joint states")
        return state

    def send(self, dq: np.ndarray) -> None:
        """Publish ``dq`` (rad/s, the description's joints) in the controller's order."""
        if self.closed:
            raise ArmError("the ROS 2 arm is closed", reason="closed")
        u = np.asarray(dq, dtype=float)
        values = u[self._to_controller]
        if not np.isfinite(values).all():
            raise ArmError(f"a command that is not finite: {values}", reason="command")
        with self._sending:
            try:
                self._commands.write(self._cmd(layout=self._layout, data=values.tolist()))
            except Exception as exc:
                raise ArmError(
                    f"cannot publish on {self.cell.arm.commands}: {exc}", reason="dds"
                ) from None
            self._sent = (u.copy(), self._sent[0])

    def stop(self) -> None:
        """Bring the arm to rest: a braking ramp from the last two commands, one a period,
        within the arm's acceleration and jerk limits (:meth:`CommandRamp.brake
        <qpavoid.control.smoothing.CommandRamp.brake>`), then zeros, twice. The controller
        holds what it last got, and a step to zero would break the limits the loop keeps
        (a ramp of at most a few tenths of a second: the watchdog calls it too)."""
        if self.closed:
            return
        with self._sending:
            ramp_to_rest(self._robot, self.limits, self._sent, self.send)
            zero = np.zeros(len(self.joint_names))
            self.send(zero)
            self.send(zero)

    def close(self) -> None:
        """Leave the domain (idempotent; after :meth:`stop`), once the last commands are
        acknowledged (at most 0.5 s)."""
        if self.closed:
            return
        self.closed = True
        duration = need("cyclonedds.util").duration
        with contextlib.suppress(Exception):
            self._commands.wait_for_acks(duration(seconds=0.5))
        self._dp = None

    def report(self) -> dict[str, Any]:
        """The joint states taken and dropped, by reason."""
        return dict(sorted(self.counters.items()))
