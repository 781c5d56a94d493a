"""Several people at once: one frame of everybody in view, and motions of several people.

Fusion (:mod:`qpavoid.fusion`) reports every person it knows; the controllers take them
all as one :class:`People` and measure every distance, rule and constraint against the
closest of them, per robot set and body part (:func:`closest_of`). A single
:class:`~qpavoid.frames.HumanFrame` is one person with id 0.

:class:`Crowd` is the true motion of several people (each a scenario or a recording on
one shared clock): the simulation's sensor films all of them and the truth measures the
clearance to the nearest.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from functools import partial
from typing import NamedTuple

import numpy as np

from .distance_table import DistanceTable
from .errors import InputError
from .frames import HumanFrame, HumanMotion
from .human import HumanGeometry, KinectHuman
from .perception import PeopleTracker, Perceived, PerceptionConfig
from .recording import Recording

__all__ = ["NOBODY", "Crowd", "People", "Perceiver", "as_people", "closest_of", "same_frames"]

#: Nobody in view: a frame with no usable joint (every distance +inf).
NOBODY = HumanFrame(np.full((25, 3), np.nan), np.zeros(25, dtype=np.int8))


class People(NamedTuple):
    """Everybody in one frame: stable ids and each person's frame (base frame, m)."""

    ids: tuple[int, ...]
    frames: tuple[HumanFrame, ...]

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


def as_people(joints: object, state: object = None) -> People:
    """``joints`` as :class:`People`: itself, or one checked frame with id 0."""
    if isinstance(joints, People):
        return joints
    return People((0,), (HumanFrame.check(joints, state),))


def same_frames(a: People, b: People) -> bool:
    """The same people in the same frame objects: a frame wrapped anew (a single
    :class:`HumanFrame` made :class:`People` every tick) is not a new frame."""
    return a.ids == b.ids and all(x is y for x, y in zip(a.frames, b.frames, strict=True))


def closest_of(tables: Sequence[DistanceTable]) -> tuple[DistanceTable, np.ndarray]:
    """Per robot set and body part, the entry of the closest person.

    Returns the combined table (its witness points picked when first asked) and ``who``
    (S, K): the index of the person each entry comes from.
    """
    if not tables:
        raise InputError("closest_of: no person's table (nobody: NOBODY's)", name="tables")
    if len(tables) == 1:
        return tables[0], np.zeros(tables[0].distance.shape, dtype=np.intp)
    D = np.stack([t.distance for t in tables])
    who = np.argmin(D, axis=0)

    pick = partial(_pick, tables, who)
    first = tables[0]
    return (
        DistanceTable(
            first.method,
            pick("distance"),
            pick("vector"),
            pick("robot_index"),
            pick("robot_s"),
            pick("human_index"),
            first.set_names,
            first.part_names,
            partial(_pick_witnesses, pick),  # only if asked: each person's costs ~6 µs
        ),
        who,
    )


def _pick(tables: Sequence[DistanceTable], who: np.ndarray, name: str) -> np.ndarray:
    """Attribute ``name`` of each entry's closest person's table (``who`` (S, K))."""
    a = np.stack([getattr(t, name) for t in tables])
    idx = who.reshape(1, *who.shape, *([1] * (a.ndim - 3)))
    return np.take_along_axis(a, idx, axis=0)[0]


def _pick_witnesses(pick: Callable[[str], np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    return pick("robot_point"), pick("human_point")


class Perceiver:
    """Everybody as the controller may trust them, updated once per new frame.

    One :class:`~qpavoid.perception.Tracker` per person id
    (:class:`~qpavoid.perception.PeopleTracker`), each person's geometry (widened by the
    uncertainty of lost joints) and part velocities (K, 3), kept until the frame changes:
    new frame objects (:func:`same_frames`) or a new capture time.
    """

    def __init__(self, human: KinectHuman, cfg: PerceptionConfig | None = None):
        self.human = human
        self.trackers = PeopleTracker(cfg)
        self.perceived: list[Perceived] = []
        self.geometry: list[HumanGeometry] = []
        self.part_velocity = np.zeros((0, len(human.parts), 3))
        self._frame: tuple[People, float | None] | None = None

    def update(self, people: People, frame_time_s: float | None, captured_s: float) -> Perceiver:
        """Take ``people`` (captured at ``captured_s``) unless it is the frame in hand."""
        last = self._frame
        if last is None or not same_frames(people, last[0]) or frame_time_s != last[1]:
            self.perceived = self.trackers.update(people.ids, people.frames, captured_s)
            bodies = [
                self.human.tracked_geometry(p.frame, p.joint_radius, p.joint_velocity)
                for p in self.perceived
            ]
            self.geometry = [geometry for geometry, _ in bodies]
            self.part_velocity = np.array([velocity for _, velocity in bodies])
            self._frame = (people, frame_time_s)
        return self

    def geometries(self, frame: HumanFrame | People) -> list[HumanGeometry]:
        """The geometries perceived for ``frame`` if it is the frame in hand, else its own
        (nothing filled in, no uncertainty; :data:`NOBODY`'s for nobody)."""
        people = frame if isinstance(frame, People) else as_people(frame)
        if self._frame is not None and same_frames(people, self._frame[0]) and self.geometry:
            return self.geometry
        return [self.human.geometry(f) for f in people.frames] or [self.human.geometry(NOBODY)]


class Crowd:
    """The true motion of several people on one clock (a :class:`~qpavoid.frames.HumanMotion`).

    Parameters
    ----------
    motions
        Each person's motion by id: generated (run clock) or recordings (their own clock,
        shared: the run starts at the earliest first frame). A recording's person is
        absent before its first frame and holds its last frame after its end, unless no
        joint of that frame is seen: then they have left (a fused recording's person,
        dropped by the fusion after ``person_timeout_s`` unseen) and are absent after it,
        as in a live run.
    """

    def __init__(self, motions: Mapping[int, HumanMotion]):
        if not motions:
            raise InputError("a crowd needs at least one person", name="motions")
        self.motions = dict(motions)
        starts = [float(m.t[0]) for m in self.motions.values() if isinstance(m, Recording)]
        self.t0 = min(starts) if starts else 0.0
        ends = [float(m.t[-1]) for m in self.motions.values() if isinstance(m, Recording)]
        self.duration_s = max(ends) - self.t0 if ends else float("inf")
        self._left = {  # people whose recording ends unseen: absent after its end
            pid: float(m.t[-1])
            for pid, m in self.motions.items()
            if isinstance(m, Recording) and not m.frame_at(float(m.t[-1])).usable.any()
        }

    def _frames(self, t: float, frame_of: object) -> People:
        assert callable(frame_of)
        ids, frames = [], []
        for pid, motion in self.motions.items():
            if isinstance(motion, Recording):
                if self.t0 + t < motion.t[0] or self.t0 + t > self._left.get(pid, np.inf):
                    continue
                frame = frame_of(motion, self.t0 + t)
            else:
                frame = frame_of(motion, t)
            ids.append(pid)
            frames.append(frame if isinstance(frame, HumanFrame) else HumanFrame.check(*frame))
        return People(tuple(ids), tuple(frames))

    def frame_at(self, t: float) -> People:
        """Everybody present at run time ``t`` (sample and hold), s."""
        return self._frames(t, lambda m, s: m.frame_at(s))

    def true_frames(self, t: float, true_frame: object) -> People:
        """Everybody present at run time ``t``, each by ``true_frame(motion, time)``."""
        return self._frames(t, true_frame)
