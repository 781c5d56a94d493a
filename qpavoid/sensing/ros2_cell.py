"""A ROS 2 cell file (TOML), and the Cyclone DDS plumbing every live ROS 2 piece shares.

The cell file names what the calibration does not: the distribution, the DDS domain, the
arm's topics and its controller's joint order, and the rate of qpavoid's own outputs::

    distribution = "humble"            # or "jazzy"
    domain_id = 0                      # ROS_DOMAIN_ID, 0-232
    [arm]
    joint_states = "/joint_states"
    controller = "/forward_velocity_controller"   # commands on <controller>/commands
    joints = ["shoulder_pan_joint", ...]          # the controller's order
    subscriber_timeout_s = 5.0
    [output]
    rate_hz = 20.0
    diagnostics = "/diagnostics"
    markers = "/qpavoid/capsules"

The cameras' topics are the calibration's (each sensor's ``topic`` key, docs/ros2.md §3).
:func:`load_cell` reads and checks it: a bad file is one :class:`InputError` line.

DDS (``cyclonedds``, the ``ros2`` extra, imported on first use): :func:`participant`,
:func:`reader` (best effort, keep last ``depth``: matches any publisher), :func:`writer`
(reliable, as ros2_control's controllers subscribe), :func:`take_raw` (each sample's CDR
bytes, so that one malformed sample is one dropped sample) and :func:`write_raw`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from qpavoid.core.errors import InputError
from qpavoid.core.file_bounds import read_toml
from qpavoid.core.schema import convert
from qpavoid.sensing.ros2_cell_schema import CellFile
from qpavoid.sensing.ros2_types import dds_topic, dds_type, need, typestore

__all__ = [
    "ArmTopics",
    "Cell",
    "OutputTopics",
    "dds_message",
    "load_cell",
    "participant",
    "reader",
    "take_raw",
    "write_raw",
    "writer",
]


@dataclass(frozen=True)
class ArmTopics:
    """The arm under ros2_control.

    Attributes
    ----------
    joint_states
        Its ``sensor_msgs/JointState`` topic.
    controller
        Its ``JointGroupVelocityController``'s name (a topic prefix): commands on
        ``<controller>/commands`` (:attr:`commands`).
    joints
        The controller's joints, in its order (the command's order); every one of the
        robot description's active joints, named as the description names them.
    subscriber_timeout_s
        How long to wait for the controller's subscription before refusing to move, s.
    """

    joint_states: str = "/joint_states"
    controller: str = "/forward_velocity_controller"
    joints: tuple[str, ...] = ()
    subscriber_timeout_s: float = 5.0

    @property
    def commands(self) -> str:
        """The command topic, ``<controller>/commands``."""
        return self.controller.rstrip("/") + "/commands"


@dataclass(frozen=True)
class OutputTopics:
    """What qpavoid publishes for RViz and Foxglove, off the loop's critical path.

    Attributes
    ----------
    rate_hz
        How often, Hz (1 to 30: the loop's live rows come at 30 Hz at most).
    diagnostics
        ``diagnostic_msgs/DiagnosticArray``: the stop reason, the nearest part, its clearance.
    markers
        ``visualization_msgs/MarkerArray``: the robot's and the person's capsules.
    """

    rate_hz: float = 20.0
    diagnostics: str = "/diagnostics"
    markers: str = "/qpavoid/capsules"


@dataclass(frozen=True)
class Cell:
    """A ROS 2 cell (module docstring).

    Attributes
    ----------
    path
        The file it was read from ("" if made by hand).
    distribution
        ``"humble"`` or ``"jazzy"``: the message types' definitions.
    domain_id
        The DDS domain (ROS_DOMAIN_ID).
    arm, output
        The arm's topics; qpavoid's outputs.
    """

    path: str = ""
    distribution: str = "humble"
    domain_id: int = 0
    arm: ArmTopics = ArmTopics()
    output: OutputTopics = OutputTopics()


def load_cell(path: str | Path) -> Cell:
    """The cell file at ``path``, checked (module docstring).

    Its shape is :class:`~qpavoid.sensing.ros2_cell_schema.CellFile`'s; a joint named twice
    is refused here.

    Raises
    ------
    InputError
        One line naming the field's path: the file cannot be read, is no TOML, or a key is
        unknown, missing or wrong.
    """
    where = str(path)

    def fail(name: str, message: str, value: object) -> InputError:
        return InputError(f"ROS 2 cell file {where}: {message}", name=name, value=value)

    file = convert(read_toml(Path(path), 1 << 16), CellFile, fail)
    arm, out = file.arm, file.output
    if len(set(arm.joints)) != len(arm.joints):
        raise fail("arm.joints", "arm.joints names a joint twice", arm.joints)
    return Cell(
        path=where,
        distribution=file.distribution,
        domain_id=file.domain_id,
        arm=ArmTopics(
            arm.joint_states, arm.controller, tuple(arm.joints), arm.subscriber_timeout_s
        ),
        output=OutputTopics(out.rate_hz, out.diagnostics, out.markers),
    )


def participant(domain_id: int) -> Any:
    """A Cyclone DDS participant on ``domain_id`` (the network it uses: ``CYCLONEDDS_URI``,
    docs/security.md)."""
    return need("cyclonedds.domain").DomainParticipant(domain_id)


def _qos(reliable: bool, depth: int) -> Any:
    core = need("cyclonedds.core")
    policy = core.Policy
    reliability = policy.Reliability.Reliable(0) if reliable else policy.Reliability.BestEffort
    return core.Qos(reliability, policy.History.KeepLast(depth), policy.Durability.Volatile)


def reader(dp: Any, distribution: str, topic: str, message: str, depth: int = 1) -> Any:
    """A best-effort reader of ``message`` (a ROS type) on ROS topic ``topic``, keep last
    ``depth``: it matches a reliable publisher as well as a best-effort one."""
    kind = dds_type(distribution, message)
    topic_ = need("cyclonedds.topic").Topic(dp, dds_topic(topic), kind)
    return need("cyclonedds.sub").DataReader(dp, topic_, qos=_qos(False, depth))


def writer(dp: Any, distribution: str, topic: str, message: str, reliable: bool = True) -> Any:
    """A writer of ``message`` on ROS topic ``topic`` (reliable by default, keep last 1)."""
    kind = dds_type(distribution, message)
    topic_ = need("cyclonedds.topic").Topic(dp, dds_topic(topic), kind)
    return need("cyclonedds.pub").DataWriter(dp, topic_, qos=_qos(reliable, 1))


def state_waitset(dp: Any, dds_reader: Any) -> Any:
    """A DDS wait set woken when ``dds_reader`` holds a sample (any state): its
    ``wait(timeout_ns)`` blocks until one arrives or the timeout passes."""
    core = need("cyclonedds.core")
    mask = core.SampleState.Any | core.ViewState.Any | core.InstanceState.Any
    waitset, condition = core.WaitSet(dp), core.ReadCondition(dds_reader, mask)
    waitset.attach(condition)
    waitset.condition = condition  # held as long as the wait set
    return waitset


def take_raw(dds_reader: Any, n: int = 64) -> list[bytes]:
    """The CDR bytes of up to ``n`` samples taken from ``dds_reader`` (valid data only):
    each deserialized by its caller, so that one malformed sample drops only itself."""
    clayer = need("cyclonedds._clayer")
    core = need("cyclonedds.core")
    mask = core.SampleState.Any | core.ViewState.Any | core.InstanceState.Any
    got = clayer.ddspy_take(dds_reader._ref, mask, n)
    if isinstance(got, int):
        return []
    return [bytes(data) for data, info in got if info.valid_data]


def write_raw(dds_writer: Any, cdr: bytes) -> None:
    """Write CDR bytes (with their encapsulation header) as one sample."""
    data = cdr.ljust((len(cdr) + 3) & ~3, b"\0")
    ret = need("cyclonedds._clayer").ddspy_write(dds_writer._ref, data)
    if ret < 0:
        raise InputError(f"DDS write failed ({ret})", name="dds", value=ret)


#: rosbags' field kinds (as :mod:`qpavoid.sensing.ros2_types` reads them).
_BASE, _NAME, _ARRAY = 1, 2, 3


def _zero(distribution: str, desc: tuple) -> Any:
    kind, detail = desc
    if kind == _BASE:
        base = detail[0]
        return (
            ""
            if base == "string"
            else False
            if base == "bool"
            else 0.0
            if base.startswith("float")
            else 0
        )
    if kind == _NAME:
        return dds_message(distribution, detail)
    if kind == _ARRAY:
        inner, size = detail
        return [_zero(distribution, inner) for _ in range(size)]
    return []


def dds_message(distribution: str, name: str, /, **fields: Any) -> Any:
    """A Cyclone DDS message of ROS type ``name`` with ``fields`` given and every other
    field zero (0, "", False, empty sequences, zero nested messages)."""
    store = typestore(distribution)
    values = {
        key: fields[key] if key in fields else _zero(distribution, desc)
        for key, desc in store.fielddefs[name][1]
    }
    return dds_type(distribution, name)(**values)
