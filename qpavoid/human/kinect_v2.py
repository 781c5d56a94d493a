"""The Kinect v2 skeleton format: :data:`KINECT_V2`, read from ``formats/kinect_v2.toml``.

The one module whose code may name a Kinect v2 joint by its index: :class:`JointType` and
:class:`TrackingState` are the SDK's enumerations, for users who address a frame's rows
by them (``joints[JointType.HandRight]``). They are checked against the format file when
this module is imported, so that the file stays the one source of the format: a file
that reorders, renames or adds joints makes the import fail with a
:class:`~qpavoid.human.skeleton.SkeletonFormatError`, never a silently wrong row.
"""

from __future__ import annotations

from enum import IntEnum

from qpavoid.core.errors import SkeletonFormatError
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.human.skeleton_file import FORMATS_DIR

__all__ = ["KINECT_V2", "KINECT_V2_FILE", "N_KINECT_JOINTS", "JointType", "TrackingState"]

#: The Kinect v2 format file.
KINECT_V2_FILE = FORMATS_DIR / "kinect_v2.toml"
#: The Kinect v2 skeleton format (the default of every function that takes a format).
KINECT_V2 = SkeletonFormat.load(KINECT_V2_FILE)
#: Joints per Kinect v2 skeleton, from the format file.
N_KINECT_JOINTS = KINECT_V2.n_joints


class JointType(IntEnum):
    """Kinect v2 joint indices (the SDK's ``JointType`` order; checked against the file)."""

    SpineBase = 0
    SpineMid = 1
    Neck = 2
    Head = 3
    ShoulderLeft = 4
    ElbowLeft = 5
    WristLeft = 6
    HandLeft = 7
    ShoulderRight = 8
    ElbowRight = 9
    WristRight = 10
    HandRight = 11
    HipLeft = 12
    KneeLeft = 13
    AnkleLeft = 14
    FootLeft = 15
    HipRight = 16
    KneeRight = 17
    AnkleRight = 18
    FootRight = 19
    SpineShoulder = 20
    HandTipLeft = 21
    ThumbLeft = 22
    HandTipRight = 23
    ThumbRight = 24


class TrackingState(IntEnum):
    """Kinect v2 tracking state of a joint (the SDK's codes; checked against the file)."""

    NotTracked = 0
    Inferred = 1
    Tracked = 2


def check_enums(skeleton: SkeletonFormat) -> None:
    """Raise :class:`SkeletonFormatError` unless :class:`JointType` and
    :class:`TrackingState` are the joints and the tracking states of ``skeleton``."""
    joints = tuple(j.name for j in JointType)
    if joints != skeleton.joints:
        wrong = next(
            (k for k, (a, b) in enumerate(zip(joints, skeleton.joints, strict=False)) if a != b),
            min(len(joints), len(skeleton.joints)),
        )
        raise SkeletonFormatError(
            f"{KINECT_V2_FILE}: the joints are not the SDK's JointType: at id {wrong} the "
            f"file has {(skeleton.joints[wrong : wrong + 1] or ('nothing',))[0]!r}, the SDK "
            f"{(joints[wrong : wrong + 1] or ('nothing',))[0]!r}",
            path=KINECT_V2_FILE,
            name=f"joints[{wrong}]",
            value=skeleton.joints,
        )
    states = {"not_tracked": TrackingState.NotTracked, "inferred": TrackingState.Inferred}
    states["tracked"] = TrackingState.Tracked
    if {k: int(v) for k, v in states.items()} != dict(skeleton.tracking_states):
        raise SkeletonFormatError(
            f"{KINECT_V2_FILE}: tracking_states {dict(skeleton.tracking_states)} are not the "
            "SDK's TrackingState (0 not tracked, 1 inferred, 2 tracked)",
            path=KINECT_V2_FILE,
            name="tracking_states",
            value=dict(skeleton.tracking_states),
        )


check_enums(KINECT_V2)
