"""Everybody as the controller may trust them: each person tracked, their body widened by
the uncertainty of lost joints, kept until the frame changes."""

from __future__ import annotations

import numpy as np

from qpavoid.human.body import BodyModel, HumanGeometry
from qpavoid.human.frames import HumanFrame, nobody
from qpavoid.human.people import People, as_people, same_frames
from qpavoid.perception.tracker import PeopleTracker, Perceived, PerceptionConfig

__all__ = ["Perceiver"]


class Perceiver:
    """Everybody as the controller may trust them, updated once per new frame.

    One :class:`~qpavoid.perception.tracker.Tracker` per person id
    (:class:`~qpavoid.perception.tracker.PeopleTracker`), each person's geometry (widened by the
    uncertainty of lost joints) and part velocities (K, 3), kept until a new frame comes
    (the caller says which is new: :class:`~qpavoid.perception.freshness.FrameClock`). The
    frames are of the body model's skeleton format.
    """

    def __init__(self, human: BodyModel, cfg: PerceptionConfig | None = None):
        self.human = human
        self.trackers = PeopleTracker(cfg, human.skeleton)
        self._nobody = nobody(human.skeleton)
        self.perceived: list[Perceived] = []
        self.geometry: list[HumanGeometry] = []
        self.part_velocity = np.zeros((0, len(human.parts), 3))
        self._frame: People | None = None

    def update(
        self,
        people: People,
        captured_s: float,
        new: bool = True,
        extra_m: np.ndarray | None = None,
    ) -> Perceiver:
        """Take ``people``, captured at ``captured_s`` (s), if it is a ``new`` frame (or the
        first); a frame held from an earlier tick (:class:`~qpavoid.perception.freshness.
        FrameClock`) only becomes the frame in hand, which the trackers saw already.
        ``extra_m``: the landmark uncertainty of the frame's camera, m
        (:meth:`~qpavoid.perception.tracker.Tracker.update`)."""
        if new or self._frame is None:
            self.perceived = self.trackers.update(people.ids, people.frames, captured_s, extra_m)
            bodies = [
                self.human.tracked_geometry(p.frame, p.joint_radius, p.joint_velocity)
                for p in self.perceived
            ]
            self.geometry = [geometry for geometry, _ in bodies]
            self.part_velocity = np.array([velocity for _, velocity in bodies])
        self._frame = people
        return self

    def geometries(self, frame: HumanFrame | People) -> list[HumanGeometry]:
        """The geometries perceived for ``frame`` if it is the frame in hand, else its own
        (nothing filled in, no uncertainty; an empty frame's for nobody)."""
        people = (
            frame if isinstance(frame, People) else as_people(frame, skeleton=self.human.skeleton)
        )
        if self._frame is not None and same_frames(people, self._frame) and self.geometry:
            return self.geometry
        return [self.human.geometry(f) for f in people.frames] or [
            self.human.geometry(self._nobody)
        ]
