"""Two cameras watching a known motion: synthetic per-sensor data for fusion, without hardware.

:func:`two_sensor_data` films one or more true motions (base frame; a scenario or a
recording) with two simulated sensors and returns what each reported, in its own camera
frame and on its own clock, with the calibration that undoes both:

* **formats**: each sensor is a camera of a skeleton format (``formats``: two Kinect v2
  by default); one of another format films the body's landmarks through its simulated
  map (:meth:`~qpavoid.human.landmarks.LandmarkMap.simulated`: each of its joints from
  the landmarks), reports its own joints in its own order, and is calibrated with its
  format, its camera's view and a weight for its noise (below);
* **poses**: each sensor ``distance_m`` from the person, ``height_m`` up, on either side
  (``azimuth_deg``), looking at the person's chest (in its format's camera frame: a
  Kinect's x to its left, y up, z forward; an Azure Kinect's x right, y down);
* **noise**: Gaussian, scaled so that a Kinect v2's mean 3D joint error is
  ``noise_mean_m`` (50 mm: the upper-body error the paper cites for the Kinect v2); a
  camera of another format's with its ``sensor.noise_m`` above the Kinect v2's added
  (:func:`noise_sigma`), and calibrated with the inverse-variance weight (1 for a
  Kinect v2: two Kinect v2 are what they always were);
* **time**: each sensor captures at 30 Hz, the second ``phase_s`` after the first
  (unsynchronised), and stamps frames on its own clock, ``clock_offset_s`` behind
  (the calibration's ``time_offset_s`` puts it back);
* **occlusions**: random windows in which the arm on the far side of a sensor is lost
  (NaN, NotTracked) or guessed (Inferred, 0.1 m off): a camera's joints placed from the
  far arm's landmarks (its simulated map's rows that use them);
* **mirroring**: random windows in which one sensor swaps left and right (the person
  turned away from it; its format's mirror), its joints then mostly Inferred.

Several motions become several bodies (ids 0, 1, ...) in each sensor (at most a format's
``max_bodies``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from qpavoid.core.errors import InputError
from qpavoid.human.frames import HumanFrame, HumanMotion
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import LandmarkMap
from qpavoid.human.posture import arm
from qpavoid.human.skeleton import INFERRED, NOT_TRACKED, TRACKED, SkeletonFormat
from qpavoid.sensing.calibration import (
    Calibration,
    SensorCalibration,
    check_format_name,
    known_formats,
)
from qpavoid.sensing.keys import SensorKeys
from qpavoid.sensing.per_sensor import BodyFrame, SensorRecording

__all__ = ["TwoSensorConfig", "TwoSensorData", "look_at", "noise_sigma", "two_sensor_data"]

#: The simulated sensors' skeleton format by default, and the body's: the Kinect v2's.
SKELETON = KINECT_V2
#: A Kinect v2's depth camera: 70.6 × 60 degrees, 0.5 to 4.5 m (Microsoft's specification,
#: in the format file); written into the simulated sensors' calibration so that the fusion
#: knows where each looks.
KINECT_V2_FIELD_OF_VIEW_DEG = SKELETON.sensor.field_of_view_deg
KINECT_V2_RANGE_M = SKELETON.sensor.range_m
#: The mean norm of a 3D isotropic Gaussian of unit σ per axis: √(8/π).
_MEAN_NORM = float(np.sqrt(8.0 / np.pi))


@dataclass(frozen=True)
class TwoSensorConfig:
    """How the two sensors see the person (module docstring).

    Attributes
    ----------
    names
        The two sensors' names.
    formats
        The two sensors' skeleton formats (names of
        :data:`~qpavoid.human.landmarks.FORMAT_NAMES`).
    azimuth_deg
        Each sensor's direction from the person, degrees about the vertical from the
        person's facing direction (+y towards the robot is 0).
    distance_m, height_m
        Each sensor's horizontal distance from the person's chest and height, m.
    noise_mean_m
        Mean 3D joint error of a Kinect v2, m (another format's: :func:`noise_sigma`).
    frame_rate_hz
        Frames per second of each sensor.
    phase_s
        The second sensor captures this long after the first, s.
    clock_offset_s
        The second sensor's time stamps are this far behind the run clock, s.
    occlusions_per_s, occlusion_s
        Rate (per sensor) and length of occlusion windows, 1/s and s.
    mirror_per_s, mirror_s
        Rate (per sensor) and length of left/right swap windows, 1/s and s.
    inferred_error_m
        How far an Inferred joint is off, m.
    seed
        Seed of everything random.
    cell
        The cell's name in the calibration (each sensor gets a new random key).
    """

    names: tuple[str, str] = ("kinect_left", "kinect_right")
    cell: str = "two-sensors"
    formats: tuple[str, str] = (SKELETON.name, SKELETON.name)
    azimuth_deg: tuple[float, float] = (50.0, -50.0)
    distance_m: float = 1.6
    height_m: float = 1.3
    noise_mean_m: float = 0.05
    frame_rate_hz: float = SKELETON.sensor.frame_rate_hz
    phase_s: float = 0.013
    clock_offset_s: float = 0.25
    occlusions_per_s: float = 0.3
    occlusion_s: float = 0.6
    mirror_per_s: float = 0.05
    mirror_s: float = 0.8
    inferred_error_m: float = 0.1
    seed: int = 0

    def __post_init__(self) -> None:
        for name in self.formats:
            problem = check_format_name(name)
            if problem is not None:
                raise InputError(problem, name="formats", value=self.formats)


@dataclass(frozen=True)
class TwoSensorData:
    """What :func:`two_sensor_data` returns.

    Attributes
    ----------
    recordings
        Each sensor's :class:`SensorRecording`, by name.
    calibration
        The sensors' true poses and clock offsets.
    """

    recordings: dict[str, SensorRecording]
    calibration: Calibration


def look_at(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(4, 4) base_from_camera of a Kinect at ``position`` looking at ``target`` (y up)."""
    z = np.asarray(target, float) - np.asarray(position, float)
    z /= np.linalg.norm(z)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = position
    return T


def two_sensor_data(
    motions: Sequence[HumanMotion], duration_s: float, cfg: TwoSensorConfig | None = None
) -> TwoSensorData:
    """Film ``motions`` (one per body) for ``duration_s`` with two sensors (module docstring)."""
    cfg = cfg or TwoSensorConfig()
    rng = np.random.default_rng([cfg.seed, 10])
    first = _frame(motions[0], 0.0)
    chest = first.joints[SKELETON.group("spine")["chest"]]
    facing = np.array([0.0, -1.0, 0.0])  # the seated operator faces the robot (-y)
    formats = [known_formats()[name] for name in cfg.formats]
    for fmt in formats:
        if len(motions) > fmt.sensor.max_bodies:
            raise InputError(
                f"{len(motions)} people for one {fmt.title} camera, which tracks at most "
                f"{fmt.sensor.max_bodies}",
                name="motions",
                value=len(motions),
            )
    sigma = cfg.noise_mean_m / _MEAN_NORM
    sensors = {}
    for k, (name, az) in enumerate(zip(cfg.names, cfg.azimuth_deg, strict=True)):
        where = chest + cfg.distance_m * Rotation.from_euler("z", az, degrees=True).apply(facing)
        where[2] = cfg.height_m
        fmt = formats[k]
        pose = look_at(where, chest)
        if fmt is not SKELETON:  # from the format's camera frame (its axes), not a Kinect's
            pose[:3, :3] = pose[:3, :3] @ (SKELETON.axes_matrix.T @ fmt.axes_matrix)
        # inverse-variance weights: two Kinect v2 weigh 1 (the default), as they always did
        weight = 1.0 if fmt is SKELETON or sigma == 0 else (sigma / noise_sigma(sigma, fmt)) ** 2
        sensors[name] = SensorCalibration(
            name,
            pose,
            time_offset_s=cfg.clock_offset_s * k,
            weight=weight,
            field_of_view_deg=fmt.sensor.field_of_view_deg,
            range_m=fmt.sensor.range_m,
            format=fmt.name,
        )
    # each simulated sensor signs its datagrams with a key of its own (docs/security.md)
    keys = {name: SensorKeys.generate(name) for name in sensors}
    calibration = Calibration(sensors, cell=cfg.cell, keys=keys)
    recordings = {}
    for k, name in enumerate(cfg.names):
        cal, fmt = sensors[name], formats[k]
        camera = _Camera(fmt, arm(SKELETON, "right" if cfg.azimuth_deg[k] > 0 else "left"))
        noise = noise_sigma(sigma, fmt)
        occluded = _windows(rng, duration_s, cfg.occlusions_per_s, cfg.occlusion_s)
        mirrored = _windows(rng, duration_s, cfg.mirror_per_s, cfg.mirror_s)
        camera_from_base = np.linalg.inv(cal.base_from_camera)
        frames = []
        for i in range(int(duration_s * cfg.frame_rate_hz)):
            t = i / cfg.frame_rate_hz + cfg.phase_s * k
            for body, motion in enumerate(motions):
                truth = camera.film(_frame(motion, t))
                joints = truth.joints + rng.normal(0.0, noise, truth.joints.shape)
                state = truth.state.copy()
                for start, end, kind in occluded:
                    if start <= t < end:
                        idx = camera.far_arm
                        if kind < 0.5:
                            joints[idx], state[idx] = np.nan, NOT_TRACKED
                        else:
                            joints[idx] += rng.normal(0.0, cfg.inferred_error_m / _MEAN_NORM, 3)
                            state[idx] = INFERRED
                if any(s <= t < e for s, e, _ in mirrored):
                    joints, state = joints[fmt.mirror], state[fmt.mirror]
                    state[state == TRACKED] = INFERRED
                seen = joints @ camera_from_base[:3, :3].T + camera_from_base[:3, 3]
                frames.append(BodyFrame(name, body, t - cal.time_offset_s, seen, state, fmt.name))
        recordings[name] = SensorRecording.from_frames(frames)
    return TwoSensorData(recordings, calibration)


def noise_sigma(sigma: float, fmt: SkeletonFormat) -> float:
    """Per-axis noise of a simulated camera of ``fmt``, m, when a Kinect v2's is ``sigma``:
    its ``sensor.noise_m`` above the Kinect v2's added in quadrature,
    ``sqrt(sigma² + noise_m² − noise_m(Kinect v2)²)`` (``sigma`` itself for a Kinect v2).

    Why not ``sigma × noise_m / noise_m(Kinect v2)``: ``sigma`` (31 mm for the 50 mm mean
    error) is the body tracker's error, the formats' ``noise_m`` (2 mm for the Kinect v2,
    "small on purpose"; 15 mm for a ZED at 2 m) a camera's depth noise on a joint; their
    ratio would make a ZED's mean error 0.37 m and an Azure Kinect's 0.12 m, beyond
    what the fusion's outlier threshold (0.2 m) is made for (two such Azure Kinects
    fused were worse than either alone). The difference of the noises is what the other
    camera adds to a body tracker's error.
    """
    if fmt is SKELETON:
        return sigma
    extra = fmt.sensor.noise_m**2 - SKELETON.sensor.noise_m**2
    return float(np.sqrt(max(sigma**2 + extra, 0.0)))


class _Camera:
    """How a camera of ``fmt`` films the body's landmarks: its joints from them, and which
    of its joints the far arm (the body's landmarks ``far_arm``) places."""

    def __init__(self, fmt: SkeletonFormat, far_arm: tuple[int, ...]):
        self.fmt = fmt
        if fmt is SKELETON:  # the body's own format: as it always was
            self.simulated: LandmarkMap | None = None
            self.far_arm = list(far_arm)
        else:
            self.simulated = LandmarkMap.simulated(fmt)
            uses = self.simulated.weights[:, list(far_arm)] != 0.0
            self.far_arm = np.flatnonzero(uses.any(axis=1)).tolist()

    def film(self, truth: HumanFrame) -> HumanFrame:
        """The camera's true frame (its joints, base frame) of the body's ``truth``."""
        if self.simulated is None:
            return truth
        return self.simulated.map(truth.joints, truth.state)


def _frame(motion: HumanMotion, t: float) -> HumanFrame:
    frame = motion.frame_at(t)
    return frame if isinstance(frame, HumanFrame) else HumanFrame.check(*frame)


def _windows(
    rng: np.random.Generator, duration_s: float, rate: float, length_s: float
) -> list[tuple[float, float, float]]:
    """Random (start, end, kind ∈ [0, 1)) windows, about ``rate`` per second."""
    n = rng.poisson(rate * duration_s)
    starts = rng.uniform(0.0, duration_s, n)
    return [(float(s), float(s) + length_s, float(rng.random())) for s in starts]
