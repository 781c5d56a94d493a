"""How sensors are merged: :class:`FusionConfig` (used by :class:`~qpavoid.fusion.fuser.Fuser`;
docs/sensors.md measures the defaults)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FusionConfig"]


@dataclass(frozen=True)
class FusionConfig:
    """How sensors are merged (module docstring; docs/sensors.md measures the defaults).

    Attributes
    ----------
    max_age_s
        A sensor's frame older than this at the fusion time is not used, s; None (the
        default): each sensor's own age limit, its camera's latency (the calibration's
        ``latency_s``, else its format's), a frame period and a margin
        (:attr:`~qpavoid.sensing.calibration.SensorCalibration.age_limit_s`: 0.1 s for a
        Kinect v2, 0.14 s for an Azure Kinect), which is also the age at which the
        listener refuses its datagrams. A camera's frames arrive as old as its latency:
        one limit for all refused every frame of a slower camera.
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
    settle_s
        For this long after a person is first seen, the body facing the robot decides
        their left and right (the track is swapped if it started from a sensor behind
        them), s (0.2: six Kinect frames, both sensors' first ones).
    association_gate_m
        Farthest a body's torso centre may be from a person's to be that person, m, for a
        person seen now.
    unseen_gate_speed_mps, max_association_gate_m
        A person unseen for t s is theirs within ``association_gate_m + v t`` (v 2.0 m/s:
        ISO 13855's hand speed, the tracker's bound on how far an unseen person's joints
        may have gone), at most ``max_association_gate_m`` (1.5 m: ``forget_beyond_m``'s
        reach). With the fixed 0.6 m gate, a person who walked 0.9 m during a 0.45 s
        dropout came back as a second person, and the first, last seen near the robot,
        was kept unseen and held the robot for good (27 datagrams dropped on the path:
        docs/security.md).
    same_frame_s
        Bodies of one camera frame share its time stamp: a body whose newest frame is older
        than its sensor's newest by more than this is not in that frame, s (0.005: far
        below a Kinect frame's 33 ms); with a body of that frame near it, it was renumbered.
    person_timeout_s
        A person seen by no sensor for this long is dropped, s, if they were last seen
        farther than ``forget_beyond_m`` from the robot (sensors must cover every approach
        to the robot, so a person unseen far from it has walked away).
    forget_beyond_m
        A person last seen within this distance of the robot's base is never dropped while
        unseen (they may be hidden next to it, e.g. behind the operator): the robot stays
        stopped by their growing uncertainty until a sensor sees them again, m (1.5: the
        iiwa's 0.82 m reach plus an arm's length).
    max_people
        New people far from the robot (beyond ``forget_beyond_m``) join only while fewer
        than this many are tracked (6: a Kinect v2 tracks six bodies, and no cell's table
        seats more); others are dropped and counted (``too_many_people``). A body near the
        robot always joins: nobody near it is refused or displaced.
    max_tracks
        At most this many people are kept (24: four cells' worth; the fusion's work grows
        with each, docs/performance.md); beyond, those not seen now are forgotten, flagged
        ones first, then those unseen longest (``forgotten_for_room``). Those seen now are
        at most six per sensor, so a flood of forged bodies cannot grow the fusion's work.
    max_new_people_per_s, new_people_burst
        New people far from the robot (beyond ``forget_beyond_m``) may appear at this
        mean rate, 1/s, in bursts of at most ``new_people_burst`` (a token bucket: people
        walk in one at a time, and six cover a whole cell in view at the start); more are
        dropped and counted (``too_many_new_people``). A body near the robot is never held
        back by the rate.
    phantom_grace_s
        Who appears within this time of the first frame any sensor sent is the cell's people at
        start-up, s; after it, a person who appears within ``forget_beyond_m`` of the
        robot's base, never seen approaching, is flagged (:attr:`FusedPerson.flag`), and
        so is one seen by one sensor only through their first ``settle_s`` while another
        sensor, fresh, has them in its view (``field_of_view_deg``, ``range_m`` in the
        calibration). A flag changes nothing in what the robot does (an unexplained body
        near it still stops it): it tells the operator why, who may clear it.
    silent_after_s
        A sensor that sent nothing for this long while a person another sensor sees
        stands in its view raises the input alert
        (:meth:`~qpavoid.fusion.fuser.Fuser.silent_sensors`), s (0.5: fifteen Kinect
        frames, past any dropout the frames' own loss rules see; a silenced camera left
        the robot on one camera with nothing said: docs/security.md).
    velocity_alpha, velocity_beta
        Gains of the α-β filter on each person's fused joints (measured: docs/sensors.md).
    smooth
        Report the filtered joints (True: 24 mm mean error, not 37, from 50 mm sensors)
        or the sensors' weighted mean (False).
    """

    max_age_s: float | None = None
    max_extrapolation_s: float = 0.0
    weight_tracked: float = 1.0
    weight_inferred: float = 0.2
    confidence_tracked: float = 0.5
    confidence_inferred: float = 0.15
    outlier_threshold_m: float = 0.2
    mirror_margin_m: float = 0.05
    settle_s: float = 0.2
    association_gate_m: float = 0.6
    unseen_gate_speed_mps: float = 2.0
    max_association_gate_m: float = 1.5
    same_frame_s: float = 0.005
    person_timeout_s: float = 2.0
    forget_beyond_m: float = 1.5
    max_people: int = 6
    max_tracks: int = 24
    max_new_people_per_s: float = 2.0
    new_people_burst: int = 6
    phantom_grace_s: float = 1.0
    silent_after_s: float = 0.5
    velocity_alpha: float = 0.3
    velocity_beta: float = 0.05
    smooth: bool = True
