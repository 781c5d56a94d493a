"""Several people at once: one frame of everybody in view.

Fusion (:mod:`qpavoid.fusion.fuser`) reports every person it knows; the controllers take them
all as one :class:`People` and measure every distance, rule and constraint against the
closest of them, per robot set and body part
(:func:`~qpavoid.distance.table.closest_of`). A single
:class:`~qpavoid.human.frames.HumanFrame` is one person with id 0. Their true motion is
:class:`~qpavoid.loop.crowd.Crowd`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from qpavoid.core.errors import InputError
from qpavoid.human.frames import HumanFrame, nobody
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.skeleton import SkeletonFormat

__all__ = ["NOBODY", "People", "as_people", "same_frames"]

#: Nobody in view: a Kinect v2 frame with no usable joint (every distance +inf);
#: :func:`~qpavoid.human.frames.nobody` for another format.
NOBODY = nobody()


class People(NamedTuple):
    """Everybody in one frame: stable ids, each person's frame (base frame, m) and, for
    people fused from several cameras, how much older than the frame's capture time each
    person is, s (``lag_s``: their oldest camera frame's; empty: everybody is as old as
    the frame). The controller counts the frame's age plus the largest lag."""

    ids: tuple[int, ...]
    frames: tuple[HumanFrame, ...]
    lag_s: tuple[float, ...] = ()

    @property
    def max_lag_s(self) -> float:
        """The largest of :attr:`lag_s`, s (0 without lags)."""
        return max(self.lag_s, default=0.0)

    @classmethod
    def check(cls, ids: Sequence[int], frames: Sequence[object]) -> People:
        """People from ids and raw frames (each checked by :meth:`HumanFrame.check`)."""
        ids = tuple(int(i) for i in ids)
        if len(ids) != len(frames) or len(set(ids)) != len(ids):
            raise InputError(
                f"people need one unique id per frame, got ids {ids} for {len(frames)} frames",
                name="ids",
                value=ids,
            )
        return cls(ids, tuple(HumanFrame.check(f) for f in frames))


def as_people(joints: object, state: object = None, skeleton: SkeletonFormat = KINECT_V2) -> People:
    """``joints`` as :class:`People` of ``skeleton``: itself, or one checked frame with id 0.

    Raises
    ------
    InputError
        If a frame (checked before, or raw) is not one of ``skeleton``: a frame of another
        camera's format read with this one's joint order would be another body.
    """
    people = (
        joints
        if isinstance(joints, People)
        else People((0,), (HumanFrame.check(joints, state, skeleton),))
    )
    lags = people.lag_s
    if lags and (len(lags) != len(people.ids) or not all(0.0 <= x < math.inf for x in lags)):
        raise InputError(
            f"people's lag_s must be one age >= 0 s per person ({len(people.ids)}), or none, "
            f"got {lags!r}",
            name="lag_s",
            value=lags,
        )
    for frame in people.frames:
        if isinstance(joints, People):  # frames built elsewhere: HumanFrame.check's glance
            HumanFrame.check(frame, None, skeleton)
        if frame.joints.shape[0] != skeleton.n_joints:
            raise InputError(
                f"a frame of {frame.joints.shape[0]} joints given where {skeleton.title} "
                f"frames have {skeleton.n_joints}: the body model and the frames must be of "
                "one skeleton format",
                name="joints",
                value=frame.joints.shape,
            )
    return people


def same_frames(a: People, b: People) -> bool:
    """The same people in the same frame objects: a frame wrapped anew (a single
    :class:`HumanFrame` made :class:`People` every tick) is not a new frame."""
    return a.ids == b.ids and all(x is y for x, y in zip(a.frames, b.frames, strict=True))
