"""A ROS 2 cell file's shape: ``--listen ros2:<cell>.toml`` as a schema (msgspec).

The types, ranges, keys known and keys required of a cell file
(:mod:`qpavoid.sensing.ros2_cell`, ``docs/ros2.md``): the distribution, the DDS domain,
the arm's topics and its controller's joint order, and the rate and topics of qpavoid's
own outputs. A joint named twice is refused in code beside the reader.
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

from msgspec import Meta, Struct

__all__ = ["MAX_DOMAIN_ID", "TOPIC", "ArmTable", "CellFile", "OutputTable"]

#: ROS 2's highest domain id on Linux (ports beyond it overflow).
MAX_DOMAIN_ID = 232
#: A fully qualified ROS 2 topic name: ``/`` then tokens of letters, digits and ``_``, not
#: starting with a digit, no ``__`` (ROS 2's topic name rules).
TOPIC = r"^(?!.*__)(/[A-Za-z_][A-Za-z0-9_]*)+$"
Topic = Annotated[str, Meta(pattern=TOPIC, description="a ROS 2 topic such as /joint_states")]


class ArmTable(Struct, frozen=True, forbid_unknown_fields=True):
    """``[arm]``: the arm under ros2_control (:class:`~qpavoid.sensing.ros2_cell.ArmTopics`)."""

    joint_states: Topic = "/joint_states"
    controller: Topic = "/forward_velocity_controller"
    joints: Annotated[
        list[Annotated[str, Meta(min_length=1)]], Meta(description="a list of joint names")
    ] = []
    #: s: from 0.1 (a controller's subscription takes a discovery round) to a minute (a
    #: controller not there by then is not coming).
    subscriber_timeout_s: Annotated[float, Meta(ge=0.1, le=60.0, extra={"unit": "s"})] = 5.0


class OutputTable(Struct, frozen=True, forbid_unknown_fields=True):
    """``[output]``: what qpavoid publishes for RViz and Foxglove."""

    #: Hz: 1 to 30 (the loop's live rows come at 30 Hz at most).
    rate_hz: Annotated[float, Meta(ge=1.0, le=30.0, extra={"unit": "Hz"})] = 20.0
    diagnostics: Topic = "/diagnostics"
    markers: Topic = "/qpavoid/capsules"


class CellFile(Struct, frozen=True, forbid_unknown_fields=True):
    """A ROS 2 cell file."""

    docs: ClassVar[str] = "docs/ros2.md"

    #: The message types' definitions (:data:`~qpavoid.sensing.ros2_types.DISTRIBUTIONS`).
    distribution: Annotated[Literal["humble", "jazzy"], Meta(description="one of humble, jazzy")]
    #: ROS_DOMAIN_ID.
    domain_id: Annotated[int, Meta(ge=0, le=MAX_DOMAIN_ID)] = 0
    arm: ArmTable = ArmTable()
    output: OutputTable = OutputTable()
