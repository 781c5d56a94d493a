"""Who may become a person, and who is suspect: the fusion's gate against one sender holding
the cell (docs/security.md §4; the settings are :class:`~qpavoid.fusion.fuser.FusionConfig`'s).

* A body seen near the robot (within ``forget_beyond_m`` of its base) always becomes a
  person: nobody near it is refused or displaced, however many others there are (a
  compromised sensor once pushed the real operator out of a full cell with six phantoms
  under the table).
* New people far from the robot come only while fewer than ``max_people`` are tracked,
  and at most at ``max_new_people_per_s``, in bursts of ``new_people_burst`` (a token
  bucket).
* The fusion's work stays bounded: beyond ``max_tracks``, the people *not seen now* are
  forgotten, flagged ones first, then those unseen longest
  (:meth:`~qpavoid.fusion.fuser.Fuser.fuse`); those seen now are at most six per sensor.
* After ``phantom_grace_s`` from the first frame (the people there at start-up), a person
  who appears near the
  robot is flagged, and so is one whom a single sensor saw through their first
  ``settle_s`` while another, fresh, had that place in its view.

A flag changes nothing the controller does: it says why a stop may be a phantom's.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping

from qpavoid.fusion.association import PersonTrack
from qpavoid.fusion.config import FusionConfig
from qpavoid.sensing.calibration import Calibration

__all__ = ["Admission"]


class Admission:
    """The caps on new people and the flags on phantoms, for one
    :class:`~qpavoid.fusion.fuser.Fuser`.

    Parameters
    ----------
    calibration
        The sensors (their views, for the coverage flag).
    config
        The fusion's settings.
    counters
        Where refusals and flags are counted (the fuser's).
    """

    def __init__(
        self,
        calibration: Calibration,
        config: FusionConfig,
        counters: Counter[str],
        max_age_s: Mapping[str, float],
    ):
        self.calibration, self.cfg, self.counters = calibration, config, counters
        self.max_age_s = max_age_s  # each sensor's age limit, s (a frame older is not fresh)
        self.first_s: float | None = None  # the first frame's capture time
        self._tokens, self._tokens_s = float(config.new_people_burst), -math.inf
        self._heard: dict[str, float] = {}  # each sensor's newest capture time
        self._sent: dict[str, float] = {}  # the same, a loss aside (what it last sent)

    def heard(self, sensor: str, t: float) -> None:
        """``sensor`` sent a frame captured at ``t`` (controller clock, s); the first frame
        starts the grace (the fusion may run long before any sensor sends)."""
        self._heard[sensor] = max(t, self._heard.get(sensor, -math.inf))
        self._sent[sensor] = max(t, self._sent.get(sensor, -math.inf))
        if self.first_s is None:
            self.first_s = t

    def lost(self, sensor: str, before_t: float) -> None:
        """``sensor``'s frames captured before ``before_t`` (controller clock, s) are stale:
        heard before it, it is not fresh."""
        if self._heard.get(sensor, -math.inf) < before_t:
            self._heard[sensor] = -math.inf

    def tick(self, t: float) -> None:
        """A fusion at time ``t``: the bucket refills for the time since the last."""
        refill = self.cfg.max_new_people_per_s * max(t - self._tokens_s, 0.0)
        self._tokens = min(float(self.cfg.new_people_burst), self._tokens + refill)
        self._tokens_s = t

    def admit(
        self, centre: tuple[float, float, float], t: float, n_tracks: int
    ) -> tuple[bool, str]:
        """May a body whose torso centre is ``centre`` (base frame, m) become a new person
        at ``t``, with ``n_tracks`` people tracked? ``(admitted, its flag)``."""
        cfg = self.cfg
        distance = math.hypot(*centre)
        near = distance <= cfg.forget_beyond_m
        if not near:
            if n_tracks >= cfg.max_people:
                self.counters["too_many_people"] += 1
                return False, ""
            if self._tokens < 1.0:
                self.counters["too_many_new_people"] += 1
                return False, ""
            self._tokens -= 1.0
        flag = ""
        if near and self.first_s is not None and t - self.first_s > cfg.phantom_grace_s:
            flag = f"appeared {distance:.2f} m from the robot's base, never seen approaching"
            self.counters["flagged_people"] += 1
        return True, flag

    def room(self, tracks: list[PersonTrack], seen: set[int]) -> list[PersonTrack]:
        """The tracks to forget so that at most ``max_tracks`` remain: never one ``seen``
        now; flagged ones first, then those unseen longest."""
        excess = len(tracks) - self.cfg.max_tracks
        if excess <= 0:
            return []
        unseen = sorted(
            (tr for tr in tracks if tr.id not in seen), key=lambda tr: (not tr.flag, tr.seen_s)
        )
        self.counters["forgotten_for_room"] += min(excess, len(unseen))
        return unseen[:excess]

    def silent(
        self, seen: dict[int, tuple[PersonTrack, set[str]]], t: float
    ) -> tuple[tuple[str, float, int, str], ...]:
        """The sensors that sent nothing for more than ``silent_after_s`` at ``t`` while a
        person seen now (``seen``: track id → the track and the sensors that saw it) stands
        in their view: ``(sensor, silent s, person id, a sensor that sees them)`` each,
        after the start-up grace. A camera that sees nobody sends nothing, so silence alone
        is no fault; silence where another camera sees someone is (a camera down, or its
        datagrams dropped on the way: docs/security.md)."""
        cfg = self.cfg
        if self.first_s is None or t - self.first_s <= cfg.phantom_grace_s:
            return ()
        out = []
        for name in self.calibration.names:
            quiet = t - self._sent.get(name, -math.inf)
            if quiet <= cfg.silent_after_s:
                continue
            for tid, (track, sensors) in seen.items():
                if name not in sensors and self.calibration[name].sees(track.centre()):
                    out.append((name, quiet, tid, sorted(sensors)[0]))
                    break
        return tuple(out)

    def coverage_flag(self, track: PersonTrack, t: float) -> str:
        """Once ``track`` has settled, its flag if a single sensor saw them while another,
        fresh, has that place in its view (``field_of_view_deg``, ``range_m``), else ""."""
        cfg = self.cfg
        late = self.first_s is not None and track.born_s - self.first_s > cfg.phantom_grace_s
        if track.flag or not late or len(track.seen_by) != 1:
            return track.flag
        (only,) = track.seen_by
        centre = track.centre()
        for name in self.calibration.names:
            fresh = t - self._heard.get(name, -math.inf) <= self.max_age_s[name]
            if name != only and fresh and self.calibration[name].sees(centre):
                self.counters["flagged_people"] += 1
                return f"seen by {only} only, in the view of {name}"
        return ""
