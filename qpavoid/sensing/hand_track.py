"""The hand on the flange as a camera recorded it: a landmark's times and positions.

A latency is measured by a landmark of the hand that holds the flange (:data:`LANDMARKS`):
:func:`camera_track` takes its times and positions from a recording (a base-frame one as
it is, a per-sensor one mapped onto the body's landmarks and moved by the sensor's
calibration), :func:`nearest_body` keeps, at each time, the body whose landmark is nearest
the flange (someone walking by is not the hand on the flange).
"""

from __future__ import annotations

import numpy as np

from qpavoid.core.errors import InputError
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import landmark_map
from qpavoid.human.skeleton import TRACKED
from qpavoid.sensing.calibration import Calibration, known_formats
from qpavoid.sensing.per_sensor import SensorRecording
from qpavoid.sensing.recording import Recording

__all__ = ["LANDMARKS", "camera_track", "landmark_index", "nearest_body"]

#: The landmarks a hand on the flange can be measured by: ``<side>_<role>`` with a side
#: and a role of the body's arm groups (:meth:`~qpavoid.human.skeleton.SkeletonFormat.group`).
LANDMARKS = tuple(
    f"{side}_{role}"
    for side in ("right", "left")
    for role in ("hand", "wrist", "hand_tip", "thumb")
)


def landmark_index(name: str) -> int:
    """The body's landmark ``name`` (one of :data:`LANDMARKS`) as its row in a frame.

    Raises
    ------
    InputError
        For a name not in :data:`LANDMARKS`.
    """
    if name not in LANDMARKS:
        raise InputError(
            f"unknown landmark {name!r}; choose from {', '.join(LANDMARKS)}",
            name="landmark",
            value=name,
        )
    side, role = name.split("_", 1)
    return KINECT_V2.group(f"arm_{side}")[role]


def camera_track(
    recording: Recording | SensorRecording,
    landmark: str = "right_hand",
    calibration: Calibration | None = None,
    sensor: str | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The landmark's times and positions in a recording, on the arm's clock and in the
    base frame.

    Parameters
    ----------
    recording
        A base-frame :class:`~qpavoid.sensing.recording.Recording` (times and frame as
        they are), or a per-sensor :class:`~qpavoid.sensing.per_sensor.SensorRecording`
        (mapped onto the body's landmarks, moved by the sensor's ``base_from_camera``, its
        times by its ``time_offset_s``).
    landmark
        One of :data:`LANDMARKS`.
    calibration
        The sensors' calibration: needed for a per-sensor recording, refused for a
        base-frame one.
    sensor
        Which sensor's rows (default: the recording's only one).

    Returns
    -------
    t, position
        (N,) s and (N, 3) m: one row per body per frame (a per-sensor recording may hold
        several bodies at one time), NaN where the landmark is not tracked (state 2).

    Raises
    ------
    InputError
        (CalibrationError) For a calibration missing or given where it does not belong, a
        sensor not in the recording or the calibration, a recording of several sensors
        without ``sensor``, a format other than the sensor's calibrated one.
    """
    index = landmark_index(landmark)
    if isinstance(recording, Recording):
        if calibration is not None or sensor is not None:
            raise InputError(
                "a base-frame recording names no sensor and needs no calibration (its joints "
                "are in the robot's base frame already): --sensors and --sensor are for "
                "per-sensor recordings",
                name="--sensors" if calibration is not None else "--sensor",
                value=calibration.path if calibration is not None else sensor,
            )
        return _tracked(recording.t, recording.joints[:, index], recording.state[:, index])
    if calibration is None:
        raise InputError(
            "a per-sensor recording (it names its sensor) needs the sensors' calibration "
            "(--sensors CALIBRATION.toml, docs/sensors.md)",
            name="--sensors",
            value=None,
        )
    sensors = recording.sensors
    if sensor is None and len(sensors) > 1:
        raise InputError(
            f"the recording holds the frames of sensors {', '.join(sensors)}: name the one to "
            "measure (--sensor)",
            name="--sensor",
            value=None,
        )
    name = sensors[0] if sensor is None else sensor
    if name not in sensors:
        raise InputError(
            f"the recording has no frame of sensor {name!r} (sensors: {', '.join(sensors)})",
            name="--sensor",
            value=name,
        )
    calibration.check_format(name, recording.format)
    cal = calibration[name]
    rows = recording.sensor == name
    body = landmark_map(known_formats()[recording.format]).map(
        recording.joints[rows], recording.state[rows]
    )
    t = recording.t[rows] + cal.time_offset_s
    return _tracked(t, cal.to_base(body.joints[:, index]), body.state[:, index])


def _tracked(t: np.ndarray, points: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``t`` and ``points`` as float arrays, NaN where the state is not tracked."""
    points = np.where((state == TRACKED)[:, None], points, np.nan)
    return np.asarray(t, dtype=float), points


def nearest_body(
    t: np.ndarray, position: np.ndarray, arm_t: np.ndarray, flange_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """One row per time: of the bodies seen at a time, the one whose landmark is nearest the
    flange then (someone walking by is not the hand on the flange), rows with no landmark
    dropped. Returns the times, increasing, and their positions."""
    seen = np.isfinite(position).all(axis=1)
    t, position = t[seen], position[seen]
    at = np.stack([np.interp(t, arm_t, flange_m[:, a]) for a in range(3)], axis=1)
    order = np.lexsort((np.linalg.norm(position - at, axis=1), t))
    first = np.ones(order.size, dtype=bool)
    first[1:] = np.diff(t[order]) > 0
    keep = order[first]
    return t[keep], position[keep]
