"""ROS 2 message types qpavoid reads and writes, per distribution, for rosbags and for DDS.

One source of truth per distribution: ``rosbags``' typestore (the ROS 2 definitions it
carries for Humble and Jazzy, with its own CDR serializer), plus the zed-ros2-wrapper's
``zed_msgs`` types, registered from their ``.msg`` fields (:data:`ZED_MSGS`, as
stereolabs/zed-ros2-interfaces 5.3.0 defines them: the same on its humble and jazzy
branches). The Cyclone DDS classes (:func:`dds_type`) are **generated** from that
typestore's field definitions, never written by hand: a type is one struct of fields,
each a base type, a nested type, a fixed array or a (bounded) sequence, which maps one to
one onto Cyclone's IDL types, under ROS 2's DDS names (``pkg::msg::dds_::Type_``;
topics ``rt/<topic>``: :func:`dds_topic`). ``tests/test_ros2_types.py`` checks that every
type serializes to the same bytes under both, on random messages, both ways.

Humble and Jazzy: the types qpavoid uses have the same fields in both (checked against
ros2/common_interfaces' humble and jazzy branches: Jazzy's ``Marker`` adds only the
constant ``ARROW_STRIP = 12``); the layouts that differ are Foxy's and Galactic's
``Marker`` (no texture and mesh-file fields), which qpavoid does not support.

``rosbags`` and ``cyclonedds`` are the ``ros2`` extra: imported on first use, and without
them :class:`Ros2UnavailableError` says ``pip install "qpavoid[ros2]"``.
"""

from __future__ import annotations

import importlib
import math
from functools import cache
from numbers import Integral
from types import ModuleType
from typing import Any

from qpavoid.core.errors import InputError

__all__ = [
    "DISTRIBUTIONS",
    "MESSAGE_TYPES",
    "ZED_MSGS",
    "Ros2UnavailableError",
    "dds_name",
    "dds_topic",
    "dds_type",
    "from_cdr",
    "need",
    "stamp_s",
    "time_msg",
    "to_cdr",
    "typestore",
]

#: The ROS 2 distributions whose types qpavoid has (rosbags' typestores of the same names).
DISTRIBUTIONS = ("humble", "jazzy")

#: Every message type qpavoid reads or writes (their nested types come with them).
MESSAGE_TYPES = (
    "visualization_msgs/msg/MarkerArray",
    "zed_msgs/msg/ObjectsStamped",
    "sensor_msgs/msg/JointState",
    "std_msgs/msg/Float64MultiArray",
    "diagnostic_msgs/msg/DiagnosticArray",
)

#: zed-ros2-interfaces' types that ``ObjectsStamped`` needs, their fields only (comments
#: dropped): stereolabs/zed-ros2-interfaces, msg/*.msg at 5.3.0 (package ``zed_msgs``; the
#: wrapper's 4.x releases called it ``zed_interfaces``, with the same fields since 2023).
ZED_MSGS = {
    "zed_msgs/msg/Keypoint2Di": "uint32[2] kp\n",
    "zed_msgs/msg/Keypoint2Df": "float32[2] kp\n",
    "zed_msgs/msg/Keypoint3D": "float32[3] kp\n",
    "zed_msgs/msg/BoundingBox2Di": "zed_msgs/Keypoint2Di[4] corners\n",
    "zed_msgs/msg/BoundingBox2Df": "zed_msgs/Keypoint2Df[4] corners\n",
    "zed_msgs/msg/BoundingBox3D": "zed_msgs/Keypoint3D[8] corners\n",
    "zed_msgs/msg/Skeleton2D": "zed_msgs/Keypoint2Df[70] keypoints\n",
    "zed_msgs/msg/Skeleton3D": "zed_msgs/Keypoint3D[70] keypoints\n",
    "zed_msgs/msg/Object": (
        "string label\nint16 label_id\nstring sublabel\nfloat32 confidence\n"
        "float32[3] position\nfloat32[6] position_covariance\nfloat32[3] velocity\n"
        "bool tracking_available\nint8 tracking_state\nint8 action_state\n"
        "zed_msgs/BoundingBox2Di bounding_box_2d\nzed_msgs/BoundingBox3D bounding_box_3d\n"
        "float32[3] dimensions_3d\nbool skeleton_available\nint8 body_format\n"
        "zed_msgs/BoundingBox2Df head_bounding_box_2d\n"
        "zed_msgs/BoundingBox3D head_bounding_box_3d\nfloat32[3] head_position\n"
        "zed_msgs/Skeleton2D skeleton_2d\nzed_msgs/Skeleton3D skeleton_3d\n"
    ),
    "zed_msgs/msg/ObjectsStamped": "std_msgs/Header header\nzed_msgs/Object[] objects\n",
}

#: rosbags' base type names as Cyclone's IDL types (names of ``cyclonedds.idl.types``;
#: ``bool`` and ``string`` are Python's own): ROS 2's ``char`` is an unsigned 8-bit
#: integer (rosidl's IDL mapping) and its ``byte`` an IDL octet, 0-255: Cyclone's Python
#: ``byte`` packs it signed (values from 128 raise), so it is the same byte as ``uint8``.
_DDS_BASE = {
    "byte": "uint8",
    "char": "uint8",
    "int8": "int8",
    "uint8": "uint8",
    "int16": "int16",
    "uint16": "uint16",
    "int32": "int32",
    "uint32": "uint32",
    "int64": "int64",
    "uint64": "uint64",
    "float32": "float32",
    "float64": "float64",
}
#: rosbags' node kinds (``rosbags.typesys.base.Nodetype``): a base type, a named type, a
#: fixed array, a sequence.
_BASE, _NAME, _ARRAY, _SEQUENCE = 1, 2, 3, 4
_EXTRA = 'pip install "qpavoid[ros2]"'


class Ros2UnavailableError(InputError):
    """The ``ros2`` extra is not installed (one line naming the install command)."""


def need(module: str) -> ModuleType:
    """Import ``module`` of the ``ros2`` extra (rosbags, cyclonedds, mcap).

    Raises
    ------
    Ros2UnavailableError
        If it is not installed: ``ROS 2 support needs <package>: pip install "qpavoid[ros2]"``.
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        package = module.split(".")[0]
        raise Ros2UnavailableError(
            f"ROS 2 support needs {package}, which is not installed: {_EXTRA}",
            name="ros2",
            value=package,
        ) from None


def _check_distribution(distribution: str) -> None:
    if distribution not in DISTRIBUTIONS:
        raise InputError(
            f"unknown ROS 2 distribution {distribution!r}; qpavoid has {', '.join(DISTRIBUTIONS)}",
            name="distribution",
            value=distribution,
        )


@cache
def typestore(distribution: str) -> Any:
    """rosbags' typestore of ``distribution`` (``"humble"`` or ``"jazzy"``) with the
    ``zed_msgs`` types registered (:data:`ZED_MSGS`).

    Raises
    ------
    InputError
        For another distribution; :class:`Ros2UnavailableError` without rosbags.
    """
    _check_distribution(distribution)
    typesys = need("rosbags.typesys")
    store = typesys.get_typestore(getattr(typesys.Stores, f"ROS2_{distribution.upper()}"))
    types: dict = {}
    for name, text in ZED_MSGS.items():
        types.update(typesys.get_types_from_msg(text, name))
    store.register(types)
    return store


def dds_name(name: str) -> str:
    """ROS 2's DDS type name of ``name``: ``sensor_msgs/msg/JointState`` is
    ``sensor_msgs::msg::dds_::JointState_``."""
    package, kind, typ = name.split("/")
    return f"{package}::{kind}::dds_::{typ}_"


def dds_topic(topic: str) -> str:
    """ROS 2's DDS topic name of a ROS topic: ``/k4a/body_tracking_data`` is
    ``rt/k4a/body_tracking_data``."""
    return "rt/" + topic.lstrip("/")


def dds_type(distribution: str, name: str) -> type:
    """The Cyclone DDS class of ROS type ``name`` in ``distribution``, generated from
    :func:`typestore`'s field definitions (module docstring); one class per type and
    distribution, nested types shared.

    Raises
    ------
    InputError
        For an unknown distribution or type; :class:`Ros2UnavailableError` without cyclonedds.
    """
    return _dds_types(distribution)(name)


@cache
def _dds_types(distribution: str) -> Any:
    store = typestore(distribution)
    idl = need("cyclonedds.idl")
    kinds = need("cyclonedds.idl.types")
    made: dict[str, type] = {}

    def field(desc: tuple) -> Any:
        kind, detail = desc
        if kind == _BASE:
            base, bound = detail
            if base == "string":
                return kinds.bounded_str[bound] if bound else str
            return bool if base == "bool" else getattr(kinds, _DDS_BASE[base])
        if kind == _NAME:
            return struct(detail)
        inner, size = detail
        if kind == _ARRAY:
            return kinds.array[field(inner), size]
        return kinds.sequence[field(inner), size] if size else kinds.sequence[field(inner)]

    def struct(name: str) -> type:
        if name not in made:
            if name not in store.fielddefs:
                raise InputError(
                    f"no ROS 2 type {name!r} in {distribution}", name="type", value=name
                )
            fields = {key: field(desc) for key, desc in store.fielddefs[name][1]}
            made[name] = idl.make_idl_struct(name.split("/")[-1], dds_name(name), fields)
        return made[name]

    return struct


def to_cdr(distribution: str, message: object, name: str) -> bytes:
    """``message`` (rosbags' class of ``name``) as CDR bytes (with the encapsulation
    header, as on DDS and in a bag)."""
    return bytes(typestore(distribution).serialize_cdr(message, name))


def from_cdr(distribution: str, data: bytes | memoryview, name: str) -> object:
    """CDR bytes as rosbags' message of type ``name``.

    Raises
    ------
    InputError
        For bytes that are not a message of that type (truncated, malformed); one line.
    """
    try:
        return typestore(distribution).deserialize_cdr(data, name)
    except Exception as exc:  # rosbags raises several kinds on malformed bytes
        raise InputError(
            f"not a {name} in CDR: {type(exc).__name__}: {str(exc)[:120]}",
            name="cdr",
            value=len(data),
        ) from None


def time_msg(distribution: str, seconds: float) -> object:
    """``builtin_interfaces/msg/Time`` of ``seconds`` (s since the epoch, >= 0)."""
    sec = math.floor(seconds)
    nanosec = round((seconds - sec) * 1e9)  # exact to the float's ns, whatever the epoch
    sec, nanosec = sec + nanosec // 1_000_000_000, nanosec % 1_000_000_000
    return typestore(distribution).types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def stamp_s(stamp: Any) -> float | None:
    """A ``builtin_interfaces/msg/Time`` (any object with ``sec`` and ``nanosec``) in
    seconds, or None if it is no time: a field that is not an integer, ``nanosec`` outside
    0 to 999 999 999, or ``sec`` outside int32 (a malformed or forged stamp)."""
    sec, nanosec = getattr(stamp, "sec", None), getattr(stamp, "nanosec", None)
    if not all(isinstance(v, Integral) and not isinstance(v, bool) for v in (sec, nanosec)):
        return None
    sec, nanosec = int(sec), int(nanosec)  # type: ignore[arg-type]
    if not (0 <= nanosec < 1_000_000_000 and -(2**31) <= sec < 2**31):
        return None
    return sec + nanosec * 1e-9
