"""The true motion of several people on one clock: what the simulated camera films and the
truth measures against."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from qpavoid.core.errors import InputError
from qpavoid.human.frames import HumanFrame, HumanMotion
from qpavoid.human.people import People
from qpavoid.sensing.recording import Recording

__all__ = ["Crowd"]


class Crowd:
    """The true motion of several people on one clock (a
    :class:`~qpavoid.human.frames.HumanMotion`).

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
