"""Skeleton frames: joints, their tracking states, and the one place they are checked.

A :class:`HumanFrame` is one camera frame in the robot base frame: joint positions (m,
NaN where a joint is not usable) and tracking states, one row per joint of a skeleton
format (:class:`~qpavoid.human.skeleton.SkeletonFormat`; by default the Kinect v2's,
:data:`~qpavoid.human.kinect_v2.KINECT_V2`). It is checked once, where it
enters the library (:meth:`HumanFrame.check` for one frame from an API call or a live
source, :func:`check_joints` and :func:`check_states` on whole recordings), and trusted
after that: the controller builds its geometry once per frame object and never checks it
again.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np

from qpavoid.core.checks import as_array
from qpavoid.core.errors import InputError
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.skeleton import TRACKED, TRACKING_STATES, SkeletonFormat

__all__ = [
    "MAX_COORDINATE_M",
    "VALID_STATES",
    "HumanFrame",
    "HumanMotion",
    "check_joints",
    "check_states",
    "nobody",
]

#: Farthest a joint may be from the robot's base, m: a Kinect v2 sees to 4.5 m; a larger
#: number is a unit error (mm) or garbage, never a person.
MAX_COORDINATE_M = 100.0

#: The tracking states a frame may carry.
VALID_STATES = tuple(code for _, code in TRACKING_STATES)


class HumanFrame(NamedTuple):
    """One checked skeleton frame (unpacks as ``joints, state``).

    Attributes
    ----------
    joints
        (J, 3) float64 joint positions in the robot base frame, m; NaN = not usable (J the
        format's joints, :attr:`~qpavoid.human.skeleton.SkeletonFormat.n_joints`).
    state
        (J,) int8 tracking states (0 not tracked, 1 inferred, 2 tracked).
    """

    joints: np.ndarray
    state: np.ndarray

    @classmethod
    def check(
        cls, joints: object, state: object = None, skeleton: SkeletonFormat = KINECT_V2
    ) -> HumanFrame:
        """A frame of ``skeleton`` from raw arrays, checked (``state=None``: every joint
        tracked).

        A :class:`HumanFrame` is returned as it is, after a cheap check of its shape and
        that no coordinate is infinite (a frame built by hand, not by this method).

        Raises
        ------
        InputError
            On a wrong shape, an infinite coordinate or a state outside {0, 1, 2}.
        """
        if isinstance(joints, HumanFrame) and state is None:  # built already: its shape
            shape = np.shape(joints.joints)  # and no infinity, cheaply (a tick's hot path)
            if len(shape) != 2 or shape[1] != 3 or np.isinf(joints.joints).any():
                raise InputError(
                    f"a HumanFrame's joints must be (J, 3) with no infinite coordinate, got "
                    f"shape {shape} (build frames with HumanFrame.check)",
                    name="joints",
                    value=joints.joints,
                )
            return joints
        j = check_joints(joints, skeleton=skeleton)
        s = (
            np.full(skeleton.n_joints, TRACKED, dtype=np.int8)
            if state is None
            else check_states(state, skeleton=skeleton)
        )
        return cls(j, s)

    @property
    def usable(self) -> np.ndarray:
        """(J,) True where a joint has finite coordinates and is not NotTracked."""
        # (a sum is finite iff its terms are: no infinity passes HumanFrame.check; 0 is
        # NotTracked as a plain int, 6× faster than comparing with the IntEnum member)
        return np.isfinite(self.joints.sum(axis=1)) & (self.state != 0)


def nobody(skeleton: SkeletonFormat = KINECT_V2) -> HumanFrame:
    """A frame of ``skeleton`` with no usable joint (every distance to it +inf)."""
    return HumanFrame(
        np.full((skeleton.n_joints, 3), np.nan), np.zeros(skeleton.n_joints, dtype=np.int8)
    )


def check_joints(
    joints: object, times: np.ndarray | None = None, skeleton: SkeletonFormat = KINECT_V2
) -> np.ndarray:
    """Joint positions as float64, m: (J, 3), or (N, J, 3) for the N frames at ``times``
    (J the joints of ``skeleton``).

    NaN is allowed (a joint not usable); an infinite coordinate is not.
    """
    lead = () if times is None else (times.shape[0],)
    what = f"joints ({skeleton.title}, m)"
    arr = as_array(joints, (*lead, skeleton.n_joints, 3), what, finite=False)
    if np.any(np.isinf(arr)):
        *frame, joint, axis = (int(i) for i in np.argwhere(np.isinf(arr))[0])
        raise InputError(
            f"joints has an infinite coordinate at {_where(frame, times)}joint "
            f"{skeleton.joints[joint]}, axis {'xyz'[axis]}: "
            f"{float(arr[tuple([*frame, joint, axis])])!r}",
            name="joints",
            value=arr,
        )
    far = np.abs(arr) > MAX_COORDINATE_M
    if np.any(far):
        *frame, joint, axis = (int(i) for i in np.argwhere(far)[0])
        raise InputError(
            f"joints has a coordinate beyond {MAX_COORDINATE_M:g} m at {_where(frame, times)}"
            f"joint {skeleton.joints[joint]}, axis {'xyz'[axis]}: "
            f"{float(arr[tuple([*frame, joint, axis])])!r} (not metres?)",
            name="joints",
            value=arr,
        )
    return arr


def check_states(
    state: object, times: np.ndarray | None = None, skeleton: SkeletonFormat = KINECT_V2
) -> np.ndarray:
    """Tracking states as int8 in {0, 1, 2}: (J,), or (N, J) for the frames at ``times``."""
    lead = () if times is None else (times.shape[0],)
    what = (
        f"state ({skeleton.title} tracking states)" if times is None else "state (tracking states)"
    )
    arr = as_array(state, (*lead, skeleton.n_joints), what, finite=False)
    bad = ~np.isin(arr, VALID_STATES)
    if np.any(bad):
        *frame, joint = (int(i) for i in np.argwhere(bad)[0])
        index = ", ".join(str(i) for i in (*frame, joint))
        at = "" if times is None else f" at t={float(times[frame[0]])!r} s"
        raise InputError(
            f"state[{index}] ({skeleton.joints[joint]}{at}) is "
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
    """Anything that gives the skeleton frame at a time: generated scenarios, recordings."""

    def frame_at(self, t: float) -> tuple:
        """The frame shown at time t: a :class:`HumanFrame`, (joints (J, 3), state (J,)),
        or several people (:class:`~qpavoid.human.people.People`)."""
        ...
