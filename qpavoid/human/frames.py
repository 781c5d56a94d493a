"""Kinect v2 frames: the 25 joints, their tracking states, and the one place they are checked.

A :class:`HumanFrame` is one camera frame in the robot base frame: joint positions (m,
NaN where a joint is not usable) and tracking states. It is checked once, where it
enters the library (:meth:`HumanFrame.check` for one frame from an API call or a live
source, :func:`check_joints` and :func:`check_states` on whole recordings), and trusted
after that: the controller builds its geometry once per frame object and never checks it
again.
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple, Protocol

import numpy as np

from qpavoid.core.checks import as_array
from qpavoid.core.errors import InputError

#: Joints per Kinect v2 skeleton.
N_KINECT_JOINTS = 25
#: Farthest a joint may be from the robot's base, m: a Kinect v2 sees to 4.5 m; a larger
#: number is a unit error (mm) or garbage, never a person.
MAX_COORDINATE_M = 100.0


class JointType(IntEnum):
    """Kinect v2 joint indices (``JointType`` order of the SDK)."""

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
    """Kinect v2 tracking state of a joint."""

    NotTracked = 0
    Inferred = 1
    Tracked = 2


def _mirror() -> np.ndarray:
    names = [j.name for j in JointType]
    swap = {"Left": "Right", "Right": "Left"}
    out = []
    for name in names:
        side = next((k for k in swap if name.endswith(k)), None)
        out.append(names.index(name[: -len(side)] + swap[side]) if side else names.index(name))
    return np.array(out)


#: ``MIRROR[j]``: joint j's counterpart on the other side (itself on the spine): the
#: relabelling that undoes a Kinect v2 left/right swap (``joints[MIRROR]``).
MIRROR = _mirror()

#: Each joint's parent in the Kinect v2 skeleton (the upper body; -1 for the root).
PARENT = np.full(N_KINECT_JOINTS, -1)
for _child, _parent in (
    (JointType.SpineMid, JointType.SpineBase),
    (JointType.SpineShoulder, JointType.SpineMid),
    (JointType.Neck, JointType.SpineShoulder),
    (JointType.Head, JointType.Neck),
    (JointType.ShoulderLeft, JointType.SpineShoulder),
    (JointType.ElbowLeft, JointType.ShoulderLeft),
    (JointType.WristLeft, JointType.ElbowLeft),
    (JointType.HandLeft, JointType.WristLeft),
    (JointType.HandTipLeft, JointType.HandLeft),
    (JointType.ThumbLeft, JointType.HandLeft),
    (JointType.ShoulderRight, JointType.SpineShoulder),
    (JointType.ElbowRight, JointType.ShoulderRight),
    (JointType.WristRight, JointType.ElbowRight),
    (JointType.HandRight, JointType.WristRight),
    (JointType.HandTipRight, JointType.HandRight),
    (JointType.ThumbRight, JointType.HandRight),
):
    PARENT[int(_child)] = int(_parent)


#: Upper bound on each bone's length (from a joint to its parent), m: our choice, about
#: 25 % above average adult male segment lengths (upper arm 0.40, forearm 0.33, wrist to
#: hand 0.12, hand to fingertip 0.15, thumb 0.12; spine, neck and head likewise). A
#: longer bone once seen raises its own bound. 0 for joints outside the upper body.
MAX_BONE_M = np.zeros(N_KINECT_JOINTS)
for _joint, _length in (
    (JointType.SpineMid, 0.35),
    (JointType.SpineShoulder, 0.35),
    (JointType.Neck, 0.15),
    (JointType.Head, 0.25),
    (JointType.ShoulderLeft, 0.25),
    (JointType.ShoulderRight, 0.25),
    (JointType.ElbowLeft, 0.40),
    (JointType.ElbowRight, 0.40),
    (JointType.WristLeft, 0.33),
    (JointType.WristRight, 0.33),
    (JointType.HandLeft, 0.12),
    (JointType.HandRight, 0.12),
    (JointType.HandTipLeft, 0.15),
    (JointType.HandTipRight, 0.15),
    (JointType.ThumbLeft, 0.12),
    (JointType.ThumbRight, 0.12),
):
    MAX_BONE_M[int(_joint)] = _length


#: The tracking states a frame may carry.
VALID_STATES = tuple(int(s) for s in TrackingState)


class HumanFrame(NamedTuple):
    """One checked Kinect v2 frame (unpacks as ``joints, state``).

    Attributes
    ----------
    joints
        (25, 3) float64 joint positions in the robot base frame, m; NaN = not usable.
    state
        (25,) int8 tracking states (0 not tracked, 1 inferred, 2 tracked).
    """

    joints: np.ndarray
    state: np.ndarray

    @classmethod
    def check(cls, joints: object, state: object = None) -> HumanFrame:
        """A frame from raw arrays, checked (``state=None``: every joint tracked).

        Raises
        ------
        InputError
            On a wrong shape, an infinite coordinate or a state outside {0, 1, 2}.
        """
        if isinstance(joints, HumanFrame) and state is None:
            return joints
        j = check_joints(joints)
        s = (
            np.full(N_KINECT_JOINTS, TrackingState.Tracked, dtype=np.int8)
            if state is None
            else check_states(state)
        )
        return cls(j, s)

    @property
    def usable(self) -> np.ndarray:
        """(25,) True where a joint has finite coordinates and is not NotTracked."""
        # (a sum is finite iff its terms are: no infinity passes HumanFrame.check; 0 is
        # NotTracked as a plain int, 6× faster than comparing with the IntEnum member)
        return np.isfinite(self.joints.sum(axis=1)) & (self.state != 0)


def check_joints(joints: object, times: np.ndarray | None = None) -> np.ndarray:
    """Joint positions as float64, m: (25, 3), or (N, 25, 3) for the N frames at ``times``.

    NaN is allowed (a joint not usable); an infinite coordinate is not.
    """
    lead = () if times is None else (times.shape[0],)
    what = "joints (Kinect v2, m)" if times is None else "joints (robot base frame, m)"
    arr = as_array(joints, (*lead, N_KINECT_JOINTS, 3), what, finite=False)
    if np.any(np.isinf(arr)):
        *frame, joint, axis = (int(i) for i in np.argwhere(np.isinf(arr))[0])
        raise InputError(
            f"joints has an infinite coordinate at {_where(frame, times)}joint "
            f"{JointType(joint).name}, axis {'xyz'[axis]}: "
            f"{float(arr[tuple([*frame, joint, axis])])!r}",
            name="joints",
            value=arr,
        )
    far = np.abs(arr) > MAX_COORDINATE_M
    if np.any(far):
        *frame, joint, axis = (int(i) for i in np.argwhere(far)[0])
        raise InputError(
            f"joints has a coordinate beyond {MAX_COORDINATE_M:g} m at {_where(frame, times)}"
            f"joint {JointType(joint).name}, axis {'xyz'[axis]}: "
            f"{float(arr[tuple([*frame, joint, axis])])!r} (not metres?)",
            name="joints",
            value=arr,
        )
    return arr


def check_states(state: object, times: np.ndarray | None = None) -> np.ndarray:
    """Tracking states as int8 in {0, 1, 2}: (25,), or (N, 25) for the frames at ``times``."""
    lead = () if times is None else (times.shape[0],)
    what = "state (Kinect tracking states)" if times is None else "state (tracking states)"
    arr = as_array(state, (*lead, N_KINECT_JOINTS), what, finite=False)
    bad = ~np.isin(arr, VALID_STATES)
    if np.any(bad):
        *frame, joint = (int(i) for i in np.argwhere(bad)[0])
        index = ", ".join(str(i) for i in (*frame, joint))
        at = "" if times is None else f" at t={float(times[frame[0]])!r} s"
        raise InputError(
            f"state[{index}] ({JointType(joint).name}{at}) is "
            f"{_number_text(arr[tuple([*frame, joint])])}, expected 0 (not tracked), "
            "1 (inferred) or 2 (tracked)",
            name="state",
            value=arr,
        )
    return arr.astype(np.int8)


def _where(frame: list[int], times: np.ndarray | None) -> str:
    if times is None:
        return ""
    return f"frame {frame[0]} (t={float(times[frame[0]])!r} s), "


def _number_text(value: object) -> str:
    """``3`` for an integral value, else the float's repr (``1.5``, ``nan``)."""
    x = float(value)  # type: ignore[arg-type]
    return str(int(x)) if x.is_integer() else repr(x)


class HumanMotion(Protocol):
    """Anything that gives the Kinect frame at a time: generated scenarios, recordings."""

    def frame_at(self, t: float) -> tuple:
        """The frame shown at time t: a :class:`HumanFrame`, (joints (25, 3), state (25,)),
        or several people (:class:`~qpavoid.human.people.People`)."""
        ...
