"""The simulated camera between the true person and the controller: frame rate, latency,
noise, faults.

The true motion (a scenario, or a recording taken as ground truth) is what the person
does; :class:`Camera` is what a Kinect v2 pipeline makes of it. Frame k is *captured* at
``c_k`` (every ``1 / frame_rate_hz`` for a generated motion; the recording's own frame
times for a recording) and *delivered* ``latency_s`` (plus a random ``jitter_s``) later;
it may be dropped (``dropout_probability``). At run time t the controller holds the
newest delivered frame, and its age is ``t − c_k``.

Every usable joint of a delivered frame carries Gaussian noise of ``noise_m`` per axis:
a depth sensor never repeats a skeleton bit for bit, which is what lets the controller
tell a hung pipeline (frozen frames) from a person holding still.

:class:`CameraFault` injects what goes wrong in practice: a ``"freeze"`` (the same
skeleton repeated with advancing time stamps), joints ``"lost"`` (NaN, NotTracked) or
``"inferred"`` (held where they were, flagged Inferred), and ``"gap"`` (no frame).

Frames are deterministic: the noise and the dropouts of frame k come from a generator
seeded with ``(seed, k)``, whatever the order in which frames are asked for.

**Any camera's format** (``format``, :meth:`CameraConfig.of`): a camera of another format
than the body's films the true body through its format's ``[simulate]`` table (the body's
landmarks placed as its joints: its joint set, what it cannot see derived), adds its noise
to its own joints (growing with the square of the range from ``sensor_position_m`` for a
stereo camera, ``sensor.noise_reference_range_m``), swaps the person's left and right
for ``sensor.left_right_swap_s`` at a time, ``sensor.left_right_swap_per_s`` on average
(MediaPipe), and maps the result back onto the body's landmarks with its ``[landmarks]``
table, as a real frame of the format is (:mod:`qpavoid.human.landmarks`). Faults are laid
on the body's landmarks before the format films them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from qpavoid.core.errors import InputError
from qpavoid.human.frames import HumanFrame, HumanMotion
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import LandmarkMap, landmark_map, skeleton_format
from qpavoid.human.people import People
from qpavoid.human.skeleton import INFERRED, NOT_TRACKED, SkeletonFormat
from qpavoid.sensing.recording import Recording

#: Kinect v2 latency, s, from its format file (``sensor.latency_s``, with its source:
#: Microsoft's "~60 ms with processing"; docs/safety.md, "Sensor").
KINECT_V2_LATENCY_S = KINECT_V2.sensor.latency_s

#: Kinect v2 joint noise, standard deviation per axis, m, from its format file
#: (``sensor.noise_m``: our assumption, small on purpose; a real sensor is never noiseless,
#: which the frozen-frame check needs).
KINECT_V2_NOISE_M = KINECT_V2.sensor.noise_m

#: The kinds of :class:`CameraFault`.
FAULT_KINDS = ("freeze", "lost", "inferred", "gap")


@dataclass(frozen=True)
class CameraFault:
    """Something going wrong between ``start_s`` and ``end_s`` (run clock, s).

    Attributes
    ----------
    kind
        ``"freeze"``: frames captured in the window repeat the last frame captured before
        it (time stamps advance: a hung sensor PC); ``"lost"``: ``joints`` become NaN and
        NotTracked; ``"inferred"``: ``joints`` keep the position they had at ``start_s``
        and are flagged Inferred; ``"gap"``: no frame captured in the window is delivered.
    start_s, end_s
        The window, s.
    joints
        Joint ids of the frames' skeleton format (``lost`` and ``inferred``).
    """

    kind: str
    start_s: float
    end_s: float
    joints: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise InputError(
                f"unknown camera fault {self.kind!r}; choose from {FAULT_KINDS}",
                name="kind",
                value=self.kind,
            )

    def active(self, t: float) -> bool:
        """True while the fault is on at capture time ``t``."""
        return self.start_s <= t < self.end_s


@dataclass(frozen=True)
class CameraConfig:
    """A skeleton camera's timing and errors.

    Attributes
    ----------
    frame_rate_hz
        Frames per second of a generated motion (Kinect v2: 30 Hz); a recording keeps its
        own frame times.
    latency_s
        From capture to the frame reaching the controller, s (default: the Kinect v2
        measurement in docs/safety.md).
    noise_m
        Standard deviation of the Gaussian noise on each coordinate of a usable joint, m
        (default: the Kinect v2 jitter in docs/safety.md).
    jitter_s
        Each frame is delayed by a further uniform random time in [0, jitter_s], s.
    dropout_probability
        Chance that a frame is lost on the way.
    faults
        Faults to inject (:class:`CameraFault`).
    seed
        Seed of the noise, jitter and dropouts.
    format
        The camera's skeleton format (default the Kinect v2's, the body's own; module
        docstring). :meth:`of` takes its frame rate, latency and noise from its file.
    sensor_position_m
        Where the camera is in the base frame, m: the range a stereo camera's noise grows
        with. Default: behind the robot's base, facing the seated operator about 2 m away.
    """

    frame_rate_hz: float = KINECT_V2.sensor.frame_rate_hz
    latency_s: float = KINECT_V2_LATENCY_S
    noise_m: float = KINECT_V2_NOISE_M
    jitter_s: float = 0.0
    dropout_probability: float = 0.0
    faults: tuple[CameraFault, ...] = field(default=())
    seed: int = 0
    format: str = KINECT_V2.name
    sensor_position_m: tuple[float, float, float] = (0.15, -0.9, 0.6)

    def __post_init__(self) -> None:
        skeleton_format(self.format)  # an unknown format: InputError naming the known ones

    @classmethod
    def of(cls, format: str, **overrides: object) -> CameraConfig:
        """The simulated camera of ``format`` with its file's frame rate, latency and noise
        (``overrides`` replace any field)."""
        sensor = skeleton_format(format).sensor
        fields: dict[str, object] = {
            "frame_rate_hz": sensor.frame_rate_hz,
            "latency_s": sensor.latency_s,
            "noise_m": sensor.noise_m,
            "format": format,
        }
        fields.update(overrides)
        return cls(**fields)  # type: ignore[arg-type]

    @classmethod
    def ideal(cls, frame_rate_hz: float = KINECT_V2.sensor.frame_rate_hz) -> CameraConfig:
        """A perfect camera: the true skeleton at every frame, no latency, no noise."""
        return cls(frame_rate_hz, latency_s=0.0, noise_m=0.0)


class Camera:
    """What the controller receives from a true motion (build once per run).

    Parameters
    ----------
    motion
        The true motion (a scenario, or a recording taken as the truth).
    cfg
        Timing and errors.
    skeleton
        The skeleton the frames are given in: the body's landmarks (None, the default: a
        camera of another format is mapped onto them) or the camera's own format (its
        joints as it reports them, for a controller whose body model is on them:
        :func:`~qpavoid.human.body.body_model`).
    """

    def __init__(
        self, motion: HumanMotion, cfg: CameraConfig, skeleton: SkeletonFormat | None = None
    ):
        self.motion, self.cfg = motion, cfg
        self.recording = motion if isinstance(motion, Recording) else None
        self.t0 = float(self.recording.t[0]) if self.recording is not None else 0.0
        # a crowd of recordings ends with its last frame: after it, frames grow old
        self.end_s = float(getattr(motion, "duration_s", math.inf))
        self._cache: dict[int, tuple[HumanFrame | People, float, float, bool]] = {}
        self._held: tuple[int, HumanFrame | People, float] | None = None
        fmt = skeleton_format(cfg.format)
        self._films: LandmarkMap | None = None if not fmt.body else LandmarkMap.simulated(fmt)
        self._maps = landmark_map(fmt)
        #: frames in the camera's own joints (not mapped back onto the body's landmarks)
        self.native = self._films is not None and skeleton is not None and skeleton.name == fmt.name
        self._sensor = fmt.sensor
        self._mirror = fmt.mirror
        body = self._maps.target
        self._body_order, self._body_mirror = np.arange(body.n_joints), body.mirror
        self._anatomies: dict[int, np.ndarray] = {}

    def _capture_time(self, k: int) -> float:
        """Capture time of frame k on the run clock, s."""
        if self.recording is not None:
            return float(self.recording.t[min(max(k, 0), self.recording.n_frames - 1)]) - self.t0
        return k / self.cfg.frame_rate_hz

    def _last_index_before(self, t: float) -> int:
        """The last frame captured at or before run time t."""
        if self.recording is not None:
            return self.recording.index_at(self.t0 + t) if t >= 0.0 else -1
        return math.floor(min(t, self.end_s) * self.cfg.frame_rate_hz + 1e-9)

    def _true(self, k: int, captured: float) -> HumanFrame | People:
        if self.recording is not None:
            return self.recording.frame_at(self.t0 + max(captured, 0.0))
        frame = self.motion.frame_at(max(captured, 0.0))
        return frame if isinstance(frame, (HumanFrame, People)) else HumanFrame.check(*frame)

    def frame(self, k: int) -> tuple[HumanFrame | People, float, float, bool]:
        """Frame k as the camera makes it: (content, capture time, delivery time, dropped),
        times on the run clock, s (the same frame whenever asked: its noise, jitter and
        dropout come from the seed and k). A recorder's view: frame k is available from its
        delivery time on (:mod:`qpavoid.loop.excitation` stamps it so)."""
        return self._frame(k)

    def _frame(self, k: int) -> tuple[HumanFrame | People, float, float, bool]:
        """Frame k: (content, capture time, delivery time, dropped)."""
        if k in self._cache:
            return self._cache[k]
        cfg = self.cfg
        captured = self._capture_time(k)
        rng = np.random.default_rng([cfg.seed, k + 2**20])
        delay = cfg.latency_s + cfg.jitter_s * rng.random()
        dropped = bool(rng.random() < cfg.dropout_probability)
        source, source_k = captured, k
        for fault in cfg.faults:
            if fault.kind == "gap" and fault.active(captured):
                dropped = True
            if fault.kind == "freeze" and fault.active(captured):
                source_k = self._last_index_before(fault.start_s - 1e-9)
                source = self._capture_time(source_k)
        content: HumanFrame | People
        if source_k != k:
            content = self._frame(source_k)[0]  # bit for bit the frame before the freeze
        else:
            truth = self._true(k, source)
            if isinstance(truth, People):
                content = People(
                    truth.ids,
                    tuple(
                        self._degrade(f, captured, rng, pid)
                        for pid, f in zip(truth.ids, truth.frames, strict=True)
                    ),
                )
            else:
                content = self._degrade(truth, captured, rng, None)
        out = (content, captured, captured + delay, dropped)
        self._cache[k] = out
        if len(self._cache) > 256:
            self._cache.pop(next(iter(self._cache)))
        return out

    def _degrade(
        self, frame: HumanFrame, captured: float, rng: np.random.Generator, pid: int | None
    ) -> HumanFrame:
        """One person's frame as the camera reports it: lost and inferred faults, noise."""
        joints, state = frame.joints.copy(), frame.state.copy()
        for fault in self.cfg.faults:
            if fault.kind in ("lost", "inferred") and fault.active(captured):
                idx = list(fault.joints)
                if fault.kind == "lost":
                    joints[idx] = np.nan
                    state[idx] = NOT_TRACKED
                else:
                    at_start = self._true(-1, fault.start_s)
                    if isinstance(at_start, People):
                        if pid not in at_start.ids:
                            continue
                        at_start = at_start.frames[at_start.ids.index(pid)]
                    joints[idx] = at_start.joints[idx]
                    state[idx] = INFERRED
        if self._films is not None:  # another camera's format films the body
            return self._filmed(joints, state, captured, rng, pid)
        if self.cfg.noise_m > 0.0:
            joints = joints + rng.normal(0.0, self.cfg.noise_m, joints.shape)
        return HumanFrame(joints, state)

    def _filmed(
        self,
        joints: np.ndarray,
        state: np.ndarray,
        captured: float,
        rng: np.random.Generator,
        pid: int | None,
    ) -> HumanFrame:
        """The body's landmarks as a camera of another format reports them (module
        docstring): its joints, their noise and swaps, mapped back; each derived landmark
        off the true one by the person's own anatomy (:meth:`_anatomy`)."""
        assert self._films is not None
        cam = self._films.map(joints, state)
        points, seen = cam.joints, cam.state
        if self.native:  # where this person's joints really sit, off the rules' points
            points = points + self._anatomy(pid, self._films.uncertainty_m)
        # what the rules cannot recover of this body, noiseless: replaced by the anatomy
        bias = 0.0 if self.native else np.nan_to_num(self._maps.map(points, seen).joints - joints)
        order = self._body_order
        sensor = self._sensor
        if sensor.left_right_swap_per_s > 0.0:  # windows of swap_s, each swapped or not
            window = math.floor(captured / sensor.left_right_swap_s) + 2**20
            chance = sensor.left_right_swap_per_s * sensor.left_right_swap_s
            who = 0 if pid is None else pid + 1
            if np.random.default_rng([self.cfg.seed, window, who, 7]).random() < chance:
                points, seen = points[self._mirror], seen[self._mirror]
                order = self._body_mirror
        if self.cfg.noise_m > 0.0:
            sigma = np.full(len(points), self.cfg.noise_m)
            if sensor.noise_reference_range_m > 0.0:  # stereo: grows with range squared
                far = np.linalg.norm(points - np.asarray(self.cfg.sensor_position_m), axis=1)
                sigma = sigma * np.nan_to_num(far / sensor.noise_reference_range_m) ** 2
            points = points + rng.normal(0.0, 1.0, points.shape) * sigma[:, None]
        if self.native:  # the camera's joints as it reports them: nothing mapped
            return HumanFrame(points, seen)
        back = self._maps.map(points, seen)
        offset = self._anatomy(pid, self._maps.uncertainty_m) - bias
        return HumanFrame(back.joints + offset[order], back.state)

    def _anatomy(self, pid: int | None, u: np.ndarray) -> np.ndarray:
        """(L, 3) how far each of person ``pid``'s derived points is from where the
        format's rule puts it, m: a random point of the ball of the rule's uncertainty
        ``u`` (L,), the same for the whole run (a body's proportions; 0 for a point the
        camera measures). On the landmarks, the derived landmarks (the perception widens
        each by that uncertainty); on a camera's own body, its joints that the ``[simulate]``
        table places (nothing widens them: the campaigns test the body model's margins)."""
        who = -1 if pid is None else pid
        if who not in self._anatomies:
            rng = np.random.default_rng([self.cfg.seed, who + 1, 11])
            direction = rng.normal(size=(len(u), 3))
            direction /= np.linalg.norm(direction, axis=1, keepdims=True)
            radius = u * rng.random(len(u)) ** (1.0 / 3.0)  # uniform in the ball
            self._anatomies[who] = direction * radius[:, None]
        return self._anatomies[who]

    def frame_at(self, t: float) -> tuple[HumanFrame | People, float]:
        """The frame the controller holds at run time ``t`` and its capture time (run clock).

        The newest frame delivered by ``t`` (never a frame older than the one in hand). A
        generated motion has been filmed since before the run; a recording's first frame
        arrives ``latency_s`` into the run, and until then the controller holds that frame
        as captured at ``−latency_s`` (so a run on a recording starts with the robot
        waiting for fresh frames).
        """
        cfg = self.cfg
        k = self._last_index_before(t - cfg.latency_s)
        held = self._held
        # A generated motion has been filmed since before the run (frames k < 0 show the
        # person as at t = 0); a recording starts with its first frame.
        first = 0 if self.recording is not None else k - 16
        oldest = first if held is None else held[0] + 1
        best: tuple[int, HumanFrame | People, float] | None = None
        while k >= oldest:  # the newest frame delivered by now (jitter may hold some back)
            content, captured, delivered, dropped = self._frame(k)
            if not dropped and delivered <= t:
                best = (k, content, captured)
                break
            k -= 1
        if best is not None:
            self._held = best
        elif held is None:
            content = self._frame(0)[0]
            self._held = (-1, content, -cfg.latency_s)
        assert self._held is not None
        return self._held[1], self._held[2]
