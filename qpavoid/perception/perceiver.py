"""Everybody as the controller may trust them: each person tracked, their body widened by
the uncertainty of lost joints, kept until the frame changes."""

from __future__ import annotations

import numpy as np

from qpavoid.human.body import BodyModel, HumanGeometry
from qpavoid.human.frames import HumanFrame, nobody
from qpavoid.human.people import People, as_people, same_frames
from qpavoid.perception import _kernels
from qpavoid.perception.tracker import PeopleTracker, Perceived, PerceptionConfig

__all__ = ["Perceiver"]


class Perceiver:
    """Everybody as the controller may trust them, updated once per new frame.

    One :class:`~qpavoid.perception.tracker.Tracker` per person id
    (:class:`~qpavoid.perception.tracker.PeopleTracker`), each person's geometry (widened by the
    uncertainty of lost joints) and part velocities (K, 3), kept until a new frame comes
    (the caller says which is new: :class:`~qpavoid.perception.freshness.FrameClock`). The
    frames are of the body model's skeleton format.

    Attributes
    ----------
    perceived, geometry, part_velocity
        Each person of the frame in hand, in its order: what their tracker trusts, their
        body, their parts' velocities ((P, K, 3), m/s). Always the frame in hand's people,
        never an earlier frame's: a frame held under another list of people (someone
        dropped or admitted by the fusion with no newer capture) rebuilds them.
    """

    def __init__(self, human: BodyModel, cfg: PerceptionConfig | None = None):
        self.human = human
        self.trackers = PeopleTracker(cfg, human.skeleton)
        _kernels.warm_up(human.skeleton)  # before any loop: not at the first person seen
        self._nobody = nobody(human.skeleton)
        self.perceived: list[Perceived] = []
        self.geometry: list[HumanGeometry] = []
        self.part_velocity = np.zeros((0, len(human.parts), 3))
        self._frame: People | None = None
        # each person's body and part velocities, and what the tracker gave them from
        self._bodies: dict[int, tuple[Perceived, HumanGeometry, np.ndarray]] = {}

    def update(
        self,
        people: People,
        captured_s: float,
        new: bool = True,
        extra_m: np.ndarray | None = None,
    ) -> Perceiver:
        """Take ``people``, captured at ``captured_s`` (s), if it is a ``new`` frame (or the
        first); a frame held from an earlier tick (:class:`~qpavoid.perception.freshness.
        FrameClock`) only becomes the frame in hand, which the trackers saw already: under
        another list of people, each of them as their tracker last saw them, and a person
        new to the list tracked from it (:meth:`~qpavoid.perception.tracker.PeopleTracker.
        update`). ``extra_m``: the landmark uncertainty of the frame's camera, m
        (:meth:`~qpavoid.perception.tracker.Tracker.update`)."""
        last = self._frame
        if new or last is None or people.ids != last.ids:
            held = not new and last is not None
            self.perceived = self.trackers.update(
                people.ids, people.frames, captured_s, extra_m, held
            )
            self._bodies = {
                i: self._body(i, p) for i, p in zip(people.ids, self.perceived, strict=True)
            }
            bodies = [self._bodies[i] for i in people.ids]
            self.geometry = [geometry for _, geometry, _ in bodies]
            self.part_velocity = np.array([velocity for _, _, velocity in bodies])
        self._frame = people
        return self

    def _body(self, pid: int, perceived: Perceived) -> tuple[Perceived, HumanGeometry, np.ndarray]:
        """Person ``pid``'s body and part velocities from what their tracker trusts (those
        made from this very ``perceived`` before, else made now)."""
        made = self._bodies.get(pid)
        if made is not None and made[0] is perceived:
            return made
        geometry, velocity = self.human.tracked_geometry(
            perceived.frame, perceived.joint_radius, perceived.joint_velocity
        )
        return perceived, geometry, velocity

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
