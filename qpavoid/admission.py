"""Who may become a person, and who is suspect: the fusion's gate against one sender holding
the cell (docs/security.md §4; the settings are :class:`~qpavoid.fusion.FusionConfig`'s).

* At most ``max_people`` are tracked; a body that would be one more is let in only in
  place of the person farthest from the robot's base, if it is nearer (the controller acts
  on the nearest).
* New people far from the robot (beyond ``forget_beyond_m``) come at most at
  ``max_new_people_per_s``, in bursts of ``new_people_burst`` (a token bucket); near the
  robot, nobody is held back by the rate.
* After ``phantom_grace_s`` from the first frame (the people there at start-up), a person
  who appears near the
  robot is flagged, and so is one whom a single sensor saw through their first
  ``settle_s`` while another, fresh, had that place in its view.

A flag changes nothing the controller does: it says why a stop may be a phantom's.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np

from .association import PersonTrack
from .calibration import Calibration
from .fusion_config import FusionConfig

__all__ = ["Admission"]


class Admission:
    """The caps on new people and the flags on phantoms, for one :class:`~qpavoid.fusion.Fuser`.

    Parameters
    ----------
    calibration
        The sensors (their views, for the coverage flag).
    config
        The fusion's settings.
    counters
        Where refusals and flags are counted (the fuser's).
    """

    def __init__(self, calibration: Calibration, config: FusionConfig, counters: Counter[str]):
        self.calibration, self.cfg, self.counters = calibration, config, counters
        self.first_s: float | None = None  # the first frame's capture time
        self._tokens, self._tokens_s = float(config.new_people_burst), -math.inf
        self._heard: dict[str, float] = {}  # each sensor's newest capture time

    def heard(self, sensor: str, t: float) -> None:
        """``sensor`` sent a frame captured at ``t`` (controller clock, s); the first frame
        starts the grace (the fusion may run long before any sensor sends)."""
        self._heard[sensor] = max(t, self._heard.get(sensor, -math.inf))
        if self.first_s is None:
            self.first_s = t

    def tick(self, t: float) -> None:
        """A fusion at time ``t``: the bucket refills for the time since the last."""
        refill = self.cfg.max_new_people_per_s * max(t - self._tokens_s, 0.0)
        self._tokens = min(float(self.cfg.new_people_burst), self._tokens + refill)
        self._tokens_s = t

    def admit(
        self, centre: tuple[float, float, float], t: float, tracks: list[PersonTrack]
    ) -> tuple[bool, PersonTrack | None, str]:
        """May a body whose torso centre is ``centre`` (base frame, m) become a new person
        at ``t``? ``(admitted, the tracked person to drop for it or None, its flag)``."""
        cfg = self.cfg
        distance = math.hypot(*centre)
        near = distance <= cfg.forget_beyond_m
        if not near and self._tokens < 1.0:
            self.counters["too_many_new_people"] += 1
            return False, None, ""
        evicted = None
        if len(tracks) >= cfg.max_people:
            evicted = max(tracks, key=lambda tr: _distance_or_inf(tr.centre()))
            if not _distance_or_inf(evicted.centre()) > distance:
                self.counters["too_many_people"] += 1
                return False, None, ""
            self.counters["dropped_for_a_nearer_person"] += 1
        if not near:
            self._tokens -= 1.0
        flag = ""
        if near and self.first_s is not None and t - self.first_s > cfg.phantom_grace_s:
            flag = f"appeared {distance:.2f} m from the robot's base, never seen approaching"
            self.counters["flagged_people"] += 1
        return True, evicted, flag

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
            fresh = t - self._heard.get(name, -math.inf) <= cfg.max_age_s
            if name != only and fresh and self.calibration[name].sees(centre):
                self.counters["flagged_people"] += 1
                return f"seen by {only} only, in the view of {name}"
        return ""


def _distance_or_inf(centre: np.ndarray) -> float:
    """Distance of a torso centre from the robot's base, m (inf if not known)."""
    distance = float(np.linalg.norm(centre))
    return distance if math.isfinite(distance) else math.inf
