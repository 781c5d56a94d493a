"""Skeleton fusion: several sensors' bodies → one skeleton per person in the base frame.

:class:`Fuser` takes time-stamped :class:`~qpavoid.sensor_recording.BodyFrame` s of any
number of calibrated sensors, in any interleaving; at a fusion time ``t`` it returns
every person it knows (:class:`FusedFrame`). docs/sensors.md details and measures it:

1. each frame into the base frame and onto one clock (the sensor's calibration);
2. per sensor, its newest frame captured at or before ``t`` (never from the future) and
   no older than ``max_age_s``;
3. bodies matched to people, left/right swaps undone (:mod:`qpavoid.association`);
4. per joint, the sensors that see it averaged by ``state weight × sensor weight ×
   freshness``; where they disagree by more than ``outlier_threshold_m`` one is believed,
   the others dropped (recorded); a joint no sensor sees stays missing, never invented;
5. the result filtered (α-β) and given a per-joint confidence in [0, 1] (0.5 per fresh
   sensor tracking it, 0.15 per one inferring it, capped at 1); a joint on which sensors
   disagreed is Inferred, whoever was believed, so the controller widens it.

A person no sensor sees any more is reported with every joint missing for
``person_timeout_s`` (the controller's tracker bounds them meanwhile), then dropped.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .association import (
    PersonTrack,
    associate,
    mirror_suspects,
    reference_rank,
    torso_centre,
    unmirrored,
)
from .calibration import Calibration
from .frames import N_KINECT_JOINTS, HumanFrame, TrackingState
from .fusion_kernels import believed, disagreement, merge, warm_up
from .people import NOBODY
from .perception import PARENT
from .sensor_recording import BodyFrame

__all__ = ["FusedFrame", "FusedPerson", "Fuser", "FusionConfig", "OutlierChoice"]


@dataclass(frozen=True)
class FusionConfig:
    """How sensors are merged (module docstring; docs/sensors.md measures the defaults).

    Attributes
    ----------
    max_age_s
        A sensor's frame older than this at the fusion time is not used, s (0.1: three
        Kinect frames, the controller's own stale limit on the real bench).
    max_extrapolation_s
        Farthest a frame is moved along the person's velocity to the fusion time, s.
    weight_tracked, weight_inferred
        Averaging weights of a Tracked and an Inferred joint (the SDK: an Inferred
        joint's "confidence ... is very low").
    confidence_tracked, confidence_inferred
        What one fresh sensor adds to a joint's confidence.
    outlier_threshold_m
        Two sensors farther apart than this on one joint disagree, m (0.2: about three
        standard deviations of the difference of two 50 mm sensors).
    mirror_margin_m
        A body is relabelled left/right when that fits the person better by this much, m.
    association_gate_m
        Farthest a body's torso centre may be from a person's to be that person, m.
    person_timeout_s
        A person seen by no sensor for this long is dropped, s (sensors must cover every
        approach to the robot).
    velocity_alpha, velocity_beta
        Gains of the α-β filter on each person's fused joints (measured: docs/sensors.md).
    smooth
        Report the filtered joints (True: 24 mm mean error, not 37, from 50 mm sensors)
        or the sensors' weighted mean (False).
    """

    max_age_s: float = 0.1
    max_extrapolation_s: float = 0.0
    weight_tracked: float = 1.0
    weight_inferred: float = 0.2
    confidence_tracked: float = 0.5
    confidence_inferred: float = 0.15
    outlier_threshold_m: float = 0.2
    mirror_margin_m: float = 0.05
    association_gate_m: float = 0.6
    person_timeout_s: float = 2.0
    velocity_alpha: float = 0.3
    velocity_beta: float = 0.05
    smooth: bool = True


class OutlierChoice(NamedTuple):
    """Sensors that disagreed on a joint: the one ``chosen`` and the ones dropped."""

    joint: int
    chosen: str
    rejected: tuple[str, ...]


class FusedPerson(NamedTuple):
    """One person at the fusion time.

    Attributes
    ----------
    id
        Stable id (:class:`~qpavoid.association.PersonTrack`).
    frame
        Joints in the robot base frame, m, and states (NaN and NotTracked where no
        sensor sees the joint).
    confidence
        (25,) per joint, in [0, 1].
    sensors
        Names of the sensors that contributed.
    outliers
        Joints on which sensors disagreed, and who was believed.
    mirrored
        Sensors whose body was relabelled left/right.
    """

    id: int
    frame: HumanFrame
    confidence: np.ndarray
    sensors: tuple[str, ...]
    outliers: tuple[OutlierChoice, ...]
    mirrored: tuple[str, ...]


class FusedFrame(NamedTuple):
    """Every person known at fusion time ``t`` (s, controller clock), and the capture time
    of the newest frame used (``-inf`` if none: nobody seen by a fresh frame)."""

    t: float
    people: tuple[FusedPerson, ...]
    captured_s: float = float("-inf")


HISTORY = 4  #: frames kept per (sensor, body)
#: Tracking states as plain ints (comparing an array with an IntEnum member is 6× slower).
NOT_TRACKED, INFERRED, TRACKED = (int(s) for s in TrackingState)
_UNKNOWN = np.full((N_KINECT_JOINTS, 3), np.nan)  #: a new person's prediction: nothing


class _Frame(NamedTuple):
    t: float  # capture time, controller clock, s
    joints: np.ndarray  # (25, 3) base frame, NaN where not usable
    state: np.ndarray  # (25,) NotTracked where not usable
    centre: np.ndarray  # torso centre, m


class _Contribution(NamedTuple):
    sensor: str
    joints: np.ndarray  # (25, 3) base frame
    state: np.ndarray
    age: float


class Fuser:
    """Streaming fusion of calibrated sensors (module docstring).

    Parameters
    ----------
    calibration
        The sensors; a frame from any other sensor is refused by :meth:`add`.
    config
        Fusion settings.
    """

    def __init__(self, calibration: Calibration, config: FusionConfig | None = None):
        self.calibration = calibration
        self.cfg = config or FusionConfig()
        self.tracks: list[PersonTrack] = []
        self.counters: Counter[str] = Counter()
        # each body's newest frames (a few, so that a fusion time just before the newest
        # frame still finds the one before it), oldest first
        self._latest: dict[str, dict[int, list[_Frame]]] = {s: {} for s in calibration.names}
        self._assigned: dict[str, dict[int, int]] = {s: {} for s in calibration.names}
        self._next_id = 0
        warm_up()
        # averaging weight and confidence by tracking state (NotTracked, Inferred, Tracked)
        self._weight = np.array([0.0, self.cfg.weight_inferred, self.cfg.weight_tracked])
        self._confidence = np.array(
            [0.0, self.cfg.confidence_inferred, self.cfg.confidence_tracked]
        )

    def add(self, frame: BodyFrame) -> bool:
        """Take one body frame; False if it is not newer than that body's last (dropped).

        Raises
        ------
        CalibrationError
            If the frame's sensor is not in the calibration.
        """
        cal = self.calibration[frame.sensor]
        t = float(frame.t) + cal.time_offset_s
        history = self._latest[frame.sensor].setdefault(int(frame.body), [])
        if history and t <= history[-1].t:
            self.counters["out_of_order_or_duplicate"] += 1
            return False
        state = np.asarray(frame.state, dtype=np.int8)
        joints = cal.to_base(frame.joints)
        usable = ~np.isnan(joints[:, 0]) & (state != NOT_TRACKED)  # NaN spreads
        if not usable.all():
            joints = np.where(usable[:, None], joints, np.nan)
            state = np.where(usable, state, NOT_TRACKED).astype(np.int8)
        history.append(_Frame(t, joints, state, torso_centre(joints)))
        del history[:-HISTORY]
        return True

    def fuse(self, t: float) -> FusedFrame:
        """Every known person at time ``t`` (s, controller clock), from frames captured by ``t``."""
        cfg = self.cfg
        per_track: dict[int, list[_Contribution]] = {}
        track_centres = {tr.id: tr.centre() for tr in self.tracks}
        for sensor in self.calibration.names:
            bodies = {}
            for body, history in self._latest[sensor].items():
                c = next((c for c in reversed(history) if c.t <= t), None)
                if c is not None and t - cfg.max_age_s <= c.t and not np.isnan(c.centre[0]):
                    bodies[body] = c
            centres = {body: c.centre for body, c in bodies.items()}
            mapping = associate(
                centres, track_centres, self._assigned[sensor], cfg.association_gate_m
            )
            self._assigned[sensor] = {b: tid for b, tid in mapping.items() if tid is not None}
            for body, tid in mapping.items():
                tc, joints, state, _ = bodies[body]
                if tid is None:
                    track = PersonTrack(self._next_id, joints.copy())
                    self._next_id += 1
                    self.tracks.append(track)
                    track_centres[track.id] = bodies[body].centre
                    self._assigned[sensor][body] = tid = track.id
                per_track.setdefault(tid, []).append(_Contribution(sensor, joints, state, t - tc))
        people = []
        for track in list(self.tracks):
            contributions = per_track.get(track.id)
            if contributions:
                people.append(self._fuse_person(track, contributions, t))
            elif t - track.seen_s > cfg.person_timeout_s:
                self.tracks.remove(track)
            else:
                people.append(FusedPerson(track.id, NOBODY, np.zeros(N_KINECT_JOINTS), (), (), ()))
        ages = [c.age for cs in per_track.values() for c in cs]
        return FusedFrame(float(t), tuple(people), float(t - min(ages)) if ages else -np.inf)

    def _fuse_person(
        self, track: PersonTrack, contributions: list[_Contribution], t: float
    ) -> FusedPerson:
        cfg = self.cfg
        recent = t - track.seen_s <= 0.5
        if not recent:  # a new person: the first contribution is the others' reference
            contributions.sort(key=lambda c: reference_rank(c.joints, c.state))
        P = np.array([c.joints for c in contributions])  # (S, 25, 3), NaN not usable
        S = np.array([c.state for c in contributions])  # (S, 25), NotTracked not usable
        prediction = track.predicted(t, 0.1) if recent else None
        reference = prediction if prediction is not None else P[0]
        mirrored = []
        for i in np.flatnonzero(mirror_suspects(P, reference)):
            fixed = unmirrored(P[i], S[i], reference, cfg.mirror_margin_m)
            if fixed is not None:
                P[i], S[i] = fixed
                mirrored.append(contributions[i].sensor)
                self.counters["mirrored_corrected"] += 1
        age = np.array([c.age for c in contributions])
        if cfg.max_extrapolation_s > 0.0:
            P = P + track.velocity[None] * np.minimum(age, cfg.max_extrapolation_s)[:, None, None]
        fresh = np.minimum(np.maximum(1.0 - 0.5 * age / cfg.max_age_s, 0.0), 1.0)
        W = (
            self._weight[S]
            * (fresh * [self.calibration[c.sensor].weight for c in contributions])[:, None]
        )
        conf = self._confidence[S] * fresh[:, None]
        outliers = self._settle(contributions, P, S, W, conf, prediction, track)
        joints, state = merge(
            P, S, W, np.isin(np.arange(N_KINECT_JOINTS), [o.joint for o in outliers])
        )
        track.update(joints, state, t, cfg.velocity_alpha, cfg.velocity_beta, cfg.max_age_s)
        seen, got = state != NOT_TRACKED, {c.sensor for c in contributions}
        return FusedPerson(
            track.id,
            HumanFrame(
                np.where(seen[:, None], track.joints, np.nan) if cfg.smooth else joints, state
            ),
            np.minimum(conf.sum(axis=0), 1.0),
            tuple(n for n in self.calibration.names if n in got),
            tuple(outliers),
            tuple(mirrored),
        )

    def _settle(
        self,
        contributions: list[_Contribution],
        P: np.ndarray,
        S: np.ndarray,
        W: np.ndarray,
        conf: np.ndarray,
        prediction: np.ndarray | None,
        track: PersonTrack,
    ) -> list[OutlierChoice]:
        """Joints on which the sensors disagree: whom to believe (the others' ``W`` and
        ``conf`` zeroed in place)."""
        threshold = self.cfg.outlier_threshold_m
        disputed = np.flatnonzero(disagreement(P) > threshold)  # -1: fewer than two see it
        if not disputed.size:
            return []
        expected = prediction if prediction is not None else _UNKNOWN
        keep = believed(P, S, disputed, expected, track.bone, PARENT, threshold)
        W[:, disputed] *= keep
        conf[:, disputed] *= keep
        names = np.array([c.sensor for c in contributions])
        dropped = (S[:, disputed] != NOT_TRACKED) & ~keep  # seen, not believed
        chosen = names[np.argmax(keep, axis=0)].tolist()
        by_joint = zip(disputed.tolist(), chosen, dropped.T, strict=True)
        outliers = [OutlierChoice(j, c, tuple(names[d].tolist())) for j, c, d in by_joint]
        self.counters["outliers_resolved"] += len(outliers)
        return outliers
