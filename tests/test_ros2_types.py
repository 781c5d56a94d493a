"""The ROS 2 types qpavoid reads and writes: the same bytes under rosbags and cyclonedds.

Every type of :data:`~qpavoid.sensing.ros2_types.MESSAGE_TYPES`, in each distribution, on
random messages (every field random: sequences of 0-3 elements, NaN and infinities among
the floats, non-ASCII strings): serialized by rosbags, read by the generated Cyclone DDS
class and serialized again gives the same bytes; and the other way round.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("cyclonedds")

from qpavoid.sensing import ros2_types
from qpavoid.sensing.ros2_types import (
    DISTRIBUTIONS,
    MESSAGE_TYPES,
    dds_name,
    dds_topic,
    dds_type,
    from_cdr,
    stamp_s,
    to_cdr,
    typestore,
)

INTS = {
    "bool": (0, 2),
    "byte": (-128, 128),  # rosbags holds a ROS 2 byte as a signed int8 (the same byte)
    "char": (0, 256),
    "int8": (-128, 128),
    "uint8": (0, 256),
    "int16": (-(2**15), 2**15),
    "uint16": (0, 2**16),
    "int32": (-(2**31), 2**31),
    "uint32": (0, 2**32),
    "int64": (-(2**63), 2**63),
    "uint64": (0, 2**64),
}
NUMPY = {
    "float32": np.float32,
    "float64": np.float64,
    "int8": np.int8,
    "uint8": np.uint8,
    "byte": np.int8,
    "char": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "bool": np.bool_,
}


def _base(rng: np.random.Generator, name: str) -> object:
    if name == "string":
        return "".join(rng.choice(list("abcxyz_/é漢 ")) for _ in range(int(rng.integers(0, 6))))
    if name in ("float32", "float64"):
        special = [np.nan, np.inf, -np.inf, 0.0, -0.0]
        v = special[int(rng.integers(5))] if rng.random() < 0.2 else rng.normal() * 1e3
        return float(np.float32(v)) if name == "float32" else float(v)
    lo, hi = INTS[name]
    v = int(rng.integers(lo, hi, dtype=np.uint64 if name == "uint64" else np.int64))
    return bool(v) if name == "bool" else v


def random_message(store, name: str, rng: np.random.Generator) -> object:
    """A message of ``name`` with every field random (rosbags' classes: numpy arrays for
    sequences and arrays of numbers, as rosbags deserializes them)."""

    def value(desc):
        kind, detail = desc
        if kind == 1:
            return _base(rng, detail[0])
        if kind == 2:
            return random_message(store, detail, rng)
        inner, size = detail
        n = size if kind == 3 else int(rng.integers(0, 4))
        items = [value(inner) for _ in range(n)]
        if inner[0] == 1 and inner[1][0] != "string":
            return np.array(items, dtype=NUMPY[inner[1][0]])
        return items

    fields = {key: value(desc) for key, desc in store.fielddefs[name][1]}
    return store.types[name](**fields)


CASES = [(d, n) for d in DISTRIBUTIONS for n in MESSAGE_TYPES]


@pytest.mark.parametrize(("distribution", "name"), CASES)
def test_every_type_is_the_same_bytes_under_rosbags_and_cyclonedds(distribution, name):
    store = typestore(distribution)
    cls = dds_type(distribution, name)
    rng = np.random.default_rng(abs(hash((distribution, name))) % 2**32)
    for _ in range(20):
        # rosbags -> cyclonedds -> bytes
        data = to_cdr(distribution, random_message(store, name, rng), name)
        assert cls.deserialize(data).serialize() == data
        # cyclonedds -> rosbags -> bytes: a message made by the DDS class (here, read
        # from another random message's bytes and changed), written back by rosbags
        theirs = cls.deserialize(to_cdr(distribution, random_message(store, name, rng), name))
        data = theirs.serialize()
        assert to_cdr(distribution, from_cdr(distribution, data, name), name) == data


def test_a_joint_state_is_the_cdr_worked_by_hand():
    """sensor_msgs/JointState{stamp 3 s 5 ns, frame "a", name ["j"], position [1.5]}:
    the encapsulation header (CDR little-endian), then each field 4- or 8-aligned."""
    cls = dds_type("jazzy", "sensor_msgs/msg/JointState")
    header = dds_type("jazzy", "std_msgs/msg/Header")
    time = dds_type("jazzy", "builtin_interfaces/msg/Time")
    msg = cls(
        header=header(stamp=time(sec=3, nanosec=5), frame_id="a"),
        name=["j"],
        position=[1.5],
        velocity=[],
        effort=[],
    )
    expected = (
        b"\x00\x01\x00\x00"  # CDR_LE
        + (3).to_bytes(4, "little")
        + (5).to_bytes(4, "little")  # stamp
        + (2).to_bytes(4, "little")
        + b"a\x00"
        + b"\x00\x00"  # "a" + NUL, padding to 4
        + (1).to_bytes(4, "little")
        + (2).to_bytes(4, "little")
        + b"j\x00"
        + b"\x00\x00"
        + (1).to_bytes(4, "little")
        + np.float64(1.5).tobytes()  # at 32: 8-aligned
        + (0).to_bytes(4, "little")
        + (0).to_bytes(4, "little")
    )
    assert msg.serialize() == expected
    assert (
        to_cdr(
            "jazzy",
            from_cdr("jazzy", expected, "sensor_msgs/msg/JointState"),
            "sensor_msgs/msg/JointState",
        )
        == expected
    )


def test_dds_names_follow_ros2():
    assert dds_name("sensor_msgs/msg/JointState") == "sensor_msgs::msg::dds_::JointState_"
    assert dds_type("humble", "zed_msgs/msg/ObjectsStamped").__idl_typename__ == (
        "zed_msgs::msg::dds_::ObjectsStamped_"
    )
    assert dds_topic("/k4a/body_tracking_data") == "rt/k4a/body_tracking_data"


def test_humble_and_jazzy_types_have_the_same_fields():
    """ros2/common_interfaces: Jazzy's Marker adds a constant only (ARROW_STRIP)."""
    h, j = typestore("humble"), typestore("jazzy")
    for name in MESSAGE_TYPES:
        assert h.hash_rihs01(name) == j.hash_rihs01(name)


def test_stamps_and_their_refusals():
    t = typestore("humble").types["builtin_interfaces/msg/Time"]
    assert stamp_s(t(sec=1_700_000_000, nanosec=250_000_000)) == pytest.approx(1_700_000_000.25)
    assert stamp_s(t(sec=1, nanosec=1_000_000_000)) is None
    assert stamp_s(t(sec=1.5, nanosec=0)) is None
    assert stamp_s(object()) is None


def test_malformed_cdr_is_one_input_error():
    data = to_cdr(
        "humble",
        random_message(typestore("humble"), "sensor_msgs/msg/JointState", np.random.default_rng(1)),
        "sensor_msgs/msg/JointState",
    )
    with pytest.raises(ros2_types.InputError, match="not a sensor_msgs/msg/JointState"):
        from_cdr("humble", data[: len(data) // 2 - 3], "sensor_msgs/msg/JointState")
    with pytest.raises(ros2_types.InputError, match="unknown ROS 2 distribution"):
        typestore("foxy")
