"""Skeleton fusion: several sensors' bodies → one skeleton per person in the base frame.

:class:`Fuser` takes time-stamped :class:`~qpavoid.sensing.per_sensor.BodyFrame` s of any
number of calibrated sensors, in any interleaving; at a fusion time ``t`` it returns
every person it knows (:class:`FusedFrame`). docs/sensors.md details and measures it:

1. each frame into the base frame and onto one clock (the sensor's calibration), and a
   frame of a camera format onto the body's landmarks
   (:func:`~qpavoid.human.landmarks.landmark_map`; a Kinect v2 frame is the landmarks
   already): a cell may mix formats, and everything after this works on the landmarks;
2. per sensor, its newest frame captured at or before ``t`` (never from the future) and
   no older than the sensor's age limit (its camera's latency, a frame period and a
   margin: :attr:`~qpavoid.sensing.calibration.SensorCalibration.age_limit_s`, or
   ``FusionConfig.max_age_s`` for every sensor where set);
3. bodies matched to people, left/right swaps undone (:mod:`qpavoid.fusion.association`);
4. per joint, the sensors that see it averaged by ``state weight × sensor weight ×
   freshness``; where they disagree by more than ``outlier_threshold_m`` one is believed,
   the others dropped (recorded); a joint no sensor sees stays missing, never invented;
5. the result filtered (α-β) and given a per-joint confidence in [0, 1] (0.5 per fresh
   sensor tracking it, 0.15 per one inferring it, capped at 1); a joint on which sensors
   disagreed is Inferred, whoever was believed, so the controller widens it;
6. each person dated by the oldest sensor frame behind them
   (:attr:`FusedPerson.captured_s`), the fused frame by the oldest behind anybody
   (:attr:`FusedFrame.oldest_s`): a joint only a late camera sees is as old as that
   camera's frame, and speed and separation counts that age (docs/sensors.md §3).

A person no sensor sees any more is reported with every joint missing for
``person_timeout_s`` (the controller's tracker bounds them meanwhile), then dropped, unless
they were last seen within ``forget_beyond_m`` of the robot: those are kept until seen.

One sender cannot hold the cell: nobody seen near the robot is ever refused, new people
far from it appear only in a cell of fewer than ``max_people`` and at a bounded rate, at
most ``max_tracks`` are kept (those seen now first), and a person who appears near
the robot out of nowhere, or whom only one sensor sees where another looks, is flagged
(:attr:`FusedPerson.flag`); :meth:`Fuser.clear_flagged` lets an operator drop them.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import NamedTuple

import numpy as np

from qpavoid.core.checks import finite_number
from qpavoid.core.errors import CalibrationError
from qpavoid.fusion._kernels import ingest
from qpavoid.fusion.admission import Admission
from qpavoid.fusion.association import (
    PersonTrack,
    associate,
    faces_robot,
    reference_rank,
    torso_centre,
)
from qpavoid.fusion.config import FusionConfig
from qpavoid.fusion.frame import FusedFrame, FusedPerson, OutlierChoice
from qpavoid.fusion.person import fuse_person, mirror_costs, warm_up
from qpavoid.human.frames import HumanFrame, nobody
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import FORMAT_NAMES, LandmarkMap, landmark_map
from qpavoid.human.skeleton import NOT_TRACKED, SkeletonFormat
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.per_sensor import BodyFrame, checked_arrays

__all__ = ["Fuser", "FusionConfig"]


HISTORY = 4  #: frames kept per (sensor, body)


class _Frame(NamedTuple):
    t: float  # capture time, controller clock, s
    joints: np.ndarray  # (J, 3) base frame, NaN where not usable
    state: np.ndarray  # (J,) NotTracked where not usable
    centre: tuple[float, float, float]  # torso centre, m (NaN: no joint usable)


class _Contribution(NamedTuple):
    sensor: str
    joints: np.ndarray  # (J, 3) base frame
    state: np.ndarray
    age: float


class Fuser:
    """Streaming fusion of calibrated sensors (module docstring).

    Parameters
    ----------
    calibration
        The sensors, each with its skeleton format (``format``: the cell may mix
        formats); a frame from any other sensor is refused by :meth:`add`.
    config
        Fusion settings.
    skeleton
        The body's skeleton format, whose joints the fusion returns (default: the Kinect
        v2's, the body's landmarks): a sensor of this format is taken as it is, one of
        another format is mapped onto it (its format's ``body`` must be this one).

    Attributes
    ----------
    landmark_uncertainty_m
        (J,) how far each of the body's landmarks may be from where the cell's cameras put
        it, m (read-only): for each landmark, the largest
        :attr:`~qpavoid.human.landmarks.LandmarkMap.uncertainty_m` over the calibration's
        sensors' formats. Conservative: a fused landmark may come from the sensor that
        derives it worst (a fused point is a weighted mean, no closer to the truth than
        its worst term can guarantee); zeros for a cell of the body's format only. The
        perception adds it to each landmark's uncertainty radius
        (:attr:`~qpavoid.perception.tracker.PerceptionConfig.landmark_uncertainty_m`).

    Raises
    ------
    CalibrationError
        For a sensor whose format does not map onto ``skeleton``.
    """

    def __init__(
        self,
        calibration: Calibration,
        config: FusionConfig | None = None,
        skeleton: SkeletonFormat = KINECT_V2,
    ):
        self.calibration = calibration
        self.cfg = config or FusionConfig()
        self.skeleton = skeleton
        self._nobody = nobody(skeleton)
        # writable copies of the format's arrays for the compiled fusion (numba types
        # read-only arrays apart, and dispatches them slower)
        self._parent, self._mirror, self._sided = (
            np.array(a) for a in (skeleton.parent, skeleton.mirror, skeleton.sided)
        )
        self.tracks: list[PersonTrack] = []
        self._seen_now: dict[int, tuple[PersonTrack, set[str]]] = {}  # the last fusion's
        self.counters: Counter[str] = Counter()
        # each body's newest frames (a few, so that a fusion time just before the newest
        # frame still finds the one before it), oldest first
        self._latest: dict[str, dict[int, list[_Frame]]] = {s: {} for s in calibration.names}
        # each sensor's frames captured before this (controller clock, s) are stale: it lost
        # a frame on the way (:meth:`lose`)
        self._stale_before = dict.fromkeys(calibration.names, -math.inf)
        self._assigned: dict[str, dict[int, int]] = {s: {} for s in calibration.names}
        #: each sensor's age limit, s: its camera's, or the configuration's for all
        self.max_age_s: dict[str, float] = (
            calibration.age_limits_s
            if self.cfg.max_age_s is None
            else dict.fromkeys(calibration.names, float(self.cfg.max_age_s))
        )
        # the freshness weights and the filter's restart count ages against the longest
        self._longest_age_s = max(self.max_age_s.values(), default=0.0)
        self._next_id = 0
        self._admission = Admission(calibration, self.cfg, self.counters, self.max_age_s)
        self._sensor_weight = {n: calibration[n].weight for n in calibration.names}
        # a fusion on a body skeleton of the user's own (no shipped format: its
        # sensors stream that skeleton, the calibration file's format key aside)
        self._own = own = skeleton.name not in FORMAT_NAMES
        self._formats = {n: skeleton if own else calibration[n].skeleton for n in calibration.names}
        # each sensor's map onto the body's landmarks; None: its frames are the landmarks
        self._maps: dict[str, LandmarkMap | None] = {
            n: self._landmark_map(n, fmt) for n, fmt in self._formats.items()
        }
        extra = np.zeros(skeleton.n_joints)
        for mapped in self._maps.values():
            if mapped is not None:
                extra = np.maximum(extra, mapped.uncertainty_m)
        extra.setflags(write=False)
        self.landmark_uncertainty_m = extra
        # each camera's rotation and translation as contiguous arrays: the types the
        # compiled intake was warmed up for (a view would compile anew at the first frame)
        self._pose = {
            n: (
                np.ascontiguousarray(calibration[n].base_from_camera[:3, :3]),
                np.ascontiguousarray(calibration[n].base_from_camera[:3, 3]),
            )
            for n in calibration.names
        }
        warm_up(skeleton)
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
            If the frame's sensor is not in the calibration, or its ``format`` is not the
            sensor's calibrated one.
        InputError
            If its time is not finite, its joints are not (J, 3) numbers (NaN: not
            usable) or its states not (J,) values in {0, 1, 2}, J its format's joints
            (recordings and datagrams are checked so already; a frame made by hand is
            checked here).
        """
        cal = self.calibration[frame.sensor]
        if frame.format != cal.format and not self._own:
            self.calibration.check_format(frame.sensor, frame.format, "a frame")
        t = finite_number(frame.t, "t (capture time, s)") + cal.time_offset_s
        joints_in, state_in = checked_arrays(frame, self._formats[frame.sensor])
        history = self._latest[frame.sensor].setdefault(int(frame.body), [])
        if history and t <= history[-1].t:
            self.counters["out_of_order_or_duplicate"] += 1
            return False
        rotation, translation = self._pose[frame.sensor]
        joints, state = ingest(joints_in, state_in, rotation, translation)
        mapped = self._maps[frame.sensor]
        if mapped is not None:  # a camera format's joints: the body's landmarks from them
            joints, state = mapped.map(joints, state)
            joints = np.ascontiguousarray(joints)
        centre = torso_centre(joints, self.skeleton)
        history.append(_Frame(t, joints, state, tuple(centre.tolist())))
        del history[:-HISTORY]
        self._admission.heard(frame.sensor, t)
        return True

    def lose(self, sensor: str, before_t: float) -> None:
        """``sensor`` lost a frame (a datagram missing on the way): its frames captured
        before ``before_t`` (s, its own clock, as :meth:`add`'s) are stale from now on, as
        if it had been silent for its age limit (a camera dropout: its people's joints are
        then seen by the others, or missing, never held on its old frames).

        Raises
        ------
        CalibrationError
            If the sensor is not in the calibration.
        """
        t = finite_number(before_t, "before_t (capture time, s)")
        t += self.calibration[sensor].time_offset_s
        self._stale_before[sensor] = max(self._stale_before[sensor], t)
        self._admission.lost(sensor, t)

    def fuse(self, t: float) -> FusedFrame:
        """Every known person at time ``t`` (s, controller clock), from frames captured by ``t``."""
        cfg = self.cfg
        self._admission.tick(t)
        per_track: dict[int, list[_Contribution]] = {}
        track_centres = {tr.id: tuple(tr.centre().tolist()) for tr in self.tracks}
        gates = {  # wider for a person unseen a while: they may have walked on meanwhile
            tr.id: min(
                cfg.association_gate_m + cfg.unseen_gate_speed_mps * max(t - tr.seen_s, 0.0),
                max(cfg.max_association_gate_m, cfg.association_gate_m),
            )
            for tr in self.tracks
        }
        for sensor in self.calibration.names:
            newest: dict[int, _Frame] = {}  # each body's newest frame captured by t
            for body, history in self._latest[sensor].items():
                c = next((c for c in reversed(history) if c.t <= t), None)
                if c is not None:
                    newest[body] = c
            oldest = max(t - self.max_age_s[sensor], self._stale_before[sensor])
            bodies = {
                body: c
                for body, c in newest.items()
                if oldest <= c.t and not math.isnan(c.centre[0])
            }
            self._renumbered(sensor, bodies)
            centres = {body: c.centre for body, c in bodies.items()}
            mapping = associate(centres, track_centres, self._assigned[sensor], gates)
            self._assigned[sensor] = {b: tid for b, tid in mapping.items() if tid is not None}
            for body, tid in mapping.items():
                tc, joints, state, centre = bodies[body]
                if tid is None:
                    track = self._new_person(joints, centre, t)
                    if track is None:
                        continue
                    track_centres[track.id] = centre
                    gates[track.id] = cfg.association_gate_m
                    self._assigned[sensor][body] = tid = track.id
                per_track.setdefault(tid, []).append(_Contribution(sensor, joints, state, t - tc))
        for track in self._admission.room(self.tracks, set(per_track)):
            self._drop(track.id)
        people = []
        for track in list(self.tracks):
            contributions = per_track.get(track.id)
            if contributions:
                people.append(self._fuse_person(track, contributions, t))
            elif t - track.seen_s > cfg.person_timeout_s and self._far(track):
                self.tracks.remove(track)
            else:
                unseen = np.zeros(self.skeleton.n_joints)
                people.append(FusedPerson(track.id, self._nobody, unseen, (), (), (), track.flag))
        self._seen_now = {
            tr.id: (tr, {c.sensor for c in per_track[tr.id]})
            for tr in self.tracks
            if tr.id in per_track
        }
        ages = [c.age for cs in per_track.values() for c in cs]
        if not ages:
            return FusedFrame(float(t), tuple(people))
        return FusedFrame(float(t), tuple(people), float(t - min(ages)), float(t - max(ages)))

    def _landmark_map(self, sensor: str, fmt: SkeletonFormat) -> LandmarkMap | None:
        """``sensor``'s map onto the body's landmarks (None: its frames are them)."""
        if fmt.name == self.skeleton.name:
            return None
        mapped = landmark_map(fmt)
        if mapped.target.name != self.skeleton.name:
            raise CalibrationError(
                f"sensor {sensor!r}: its format {fmt.name} gives the landmarks of "
                f"{mapped.target.name}, not of the fusion's skeleton {self.skeleton.name}",
                path=self.calibration.path,
                sensor=sensor,
                name="format",
                value=fmt.name,
            )
        return mapped

    def silent_sensors(self, t: float) -> tuple[tuple[str, float, int, str], ...]:
        """After :meth:`fuse` at ``t``: the sensors that sent nothing for more than
        ``silent_after_s`` while someone the last fusion saw stands in their view,
        ``(sensor, silent s, person id, a sensor that sees them)`` each (the input alert's;
        :meth:`~qpavoid.fusion.admission.Admission.silent`)."""
        return self._admission.silent(self._seen_now, t)

    def kept_unseen(self, t: float) -> tuple[tuple[int, float, float], ...]:
        """The people kept while no sensor sees them because they were last seen near the
        robot (within ``forget_beyond_m``: they may be hidden next to it), unseen for longer
        than ``person_timeout_s`` (when anybody else would have been dropped) at run time
        ``t``: ``(id, unseen s, last seen from the base m)`` each. Their growing
        uncertainty holds the robot until a sensor sees them again."""
        return tuple(
            (tr.id, t - tr.seen_s, float(np.linalg.norm(tr.centre())))
            for tr in self.tracks
            if t - tr.seen_s > self.cfg.person_timeout_s and not self._far(tr)
        )

    def clear_flagged(self) -> tuple[int, ...]:
        """Drop every flagged person (an operator who has looked and found nobody there);
        their ids. A flagged body still sent comes back as a new person, flagged again."""
        cleared = tuple(tr.id for tr in self.tracks if tr.flag)
        for tid in cleared:
            self._drop(tid)
        self.counters["flagged_cleared"] += len(cleared)
        return cleared

    def _drop(self, tid: int) -> None:
        """Forget person ``tid``: the track and every body assigned to it."""
        self.tracks = [tr for tr in self.tracks if tr.id != tid]
        for assigned in self._assigned.values():
            for body in [b for b, i in assigned.items() if i == tid]:
                del assigned[body]

    def _new_person(
        self, joints: np.ndarray, centre: tuple[float, float, float], t: float
    ) -> PersonTrack | None:
        """A new person for a body that fits nobody, or None if :class:`Admission` refuses
        them (a far newcomer to a full cell, or too many too fast)."""
        admitted, flag = self._admission.admit(centre, t, len(self.tracks))
        if not admitted:
            return None
        track = PersonTrack(
            self._next_id, joints.copy(), born_s=t, flag=flag, skeleton=self.skeleton
        )
        self._next_id += 1
        self.tracks.append(track)
        return track

    def _renumbered(self, sensor: str, bodies: dict[int, _Frame]) -> None:
        """Drop from ``sensor``'s ``bodies`` those it has renumbered: a camera frame
        reports every body it tracks with its time stamp, so a body missing from the
        sensor's newest frame is that person re-acquired under a new id (Kinect does so)
        if a body of that frame lies within the association gate of it and neither is
        known as someone else. Left in for its last ``max_age_s``, it would keep the
        person and the new id would become a second one."""
        if len(bodies) < 2:
            return
        now = max(c.t for c in bodies.values()) - self.cfg.same_frame_s
        assigned, gate = self._assigned[sensor], self.cfg.association_gate_m
        current = [(assigned.get(b), c.centre) for b, c in bodies.items() if c.t >= now]
        for body in [b for b, c in bodies.items() if c.t < now]:
            person, centre = assigned.get(body), bodies[body].centre
            for other, c in current:
                nobody_else = other in (None, person) or person is None
                if nobody_else and math.dist(centre, c) <= gate:
                    del bodies[body]
                    break

    def _fuse_person(
        self, track: PersonTrack, contributions: list[_Contribution], t: float
    ) -> FusedPerson:
        cfg = self.cfg
        recent = t - track.seen_s <= 0.5
        settling = t - track.born_s <= cfg.settle_s
        if not recent or settling:  # a new person: the best body is the others' reference
            contributions.sort(key=lambda c: reference_rank(c.joints, c.state, self.skeleton))
        P = np.array([c.joints for c in contributions])  # (S, J, 3), NaN not usable
        S = np.array([c.state for c in contributions])  # (S, J), NotTracked not usable
        names = [c.sensor for c in contributions]
        if recent and settling and self._mirrored_track(track, P[0]):
            track.mirror()  # its first frames came from a sensor behind the person
        joints, state, confidence, mirrored, disputed, keep = fuse_person(
            P,
            S,
            np.array([c.age for c in contributions]),
            np.array([self._sensor_weight[n] for n in names]),
            recent,
            track.joints,
            track.velocity,
            track.last_seen,
            track.bone,
            self._parent,
            self._mirror,
            self._sided,
            float(t),
            self._weight,
            self._confidence,
            self._longest_age_s,
            cfg.max_extrapolation_s,
            cfg.outlier_threshold_m,
            cfg.mirror_margin_m,
            cfg.velocity_alpha,
            cfg.velocity_beta,
            cfg.smooth,
        )
        track.seen_s = t
        if settling:
            track.seen_by.update(names)
        elif track.seen_by:  # settled: judged once, on who saw them meanwhile
            track.flag = self._admission.coverage_flag(track, t)
            track.seen_by = set()
        outliers = self._outliers(names, S, disputed, keep) if disputed.size else ()
        flipped: tuple[str, ...] = ()
        if mirrored.any():
            flipped = tuple(n for n, m in zip(names, mirrored, strict=True) if m)
            self.counters["mirrored_corrected"] += len(flipped)
        return FusedPerson(
            track.id,
            HumanFrame(joints, state),
            confidence,
            tuple(n for n in self.calibration.names if n in names),
            outliers,
            flipped,
            track.flag,
            float(t - max(c.age for c in contributions)),
        )

    def _far(self, track: PersonTrack) -> bool:
        """Last seen farther than ``forget_beyond_m`` from the robot's base (or nowhere)."""
        distance = float(np.linalg.norm(track.centre()))
        return not distance <= self.cfg.forget_beyond_m  # NaN (never placed): far

    def _mirrored_track(self, track: PersonTrack, reference: np.ndarray) -> bool:
        """The track faces away from the robot while the reference body (J, 3) faces it,
        and fits it better with left and right swapped: it started from a sensor behind
        the person (operators face their robot)."""
        sk = self.skeleton
        if not faces_robot(reference, sk) or faces_robot(track.joints, sk):
            return False
        as_is, swapped = mirror_costs(track.joints, reference, self._sided, self._mirror)
        return bool(swapped + self.cfg.mirror_margin_m < as_is)

    def _outliers(
        self, names: list[str], S: np.ndarray, disputed: np.ndarray, keep: np.ndarray
    ) -> tuple[OutlierChoice, ...]:
        """The record of whom :func:`~qpavoid.fusion.person.fuse_person` believed on each
        ``disputed`` joint (``keep``: (S, len(disputed)))."""
        dropped = (S[:, disputed] != NOT_TRACKED) & ~keep  # seen, not believed
        chosen = np.argmax(keep, axis=0).tolist()
        by_joint = zip(disputed.tolist(), chosen, dropped.T.tolist(), strict=True)
        self.counters["outliers_resolved"] += len(disputed)
        return tuple(
            OutlierChoice(j, names[c], tuple(n for n, d in zip(names, ds, strict=True) if d))
            for j, c, ds in by_joint
        )
