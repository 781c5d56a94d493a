"""A camera's latency measured, not assumed: the robot's own arm filmed against its encoders.

The person holds the robot's flange while the arm moves a known excitation
(:class:`~qpavoid.loop.excitation.Excitation`); the camera films their hand, the arm logs its
joint angles, both on one clock. The flange's path follows from the joint angles by the
arm's forward kinematics (:meth:`~qpavoid.arm.model.Robot.end_effector`, Pinocchio; the
log: :mod:`qpavoid.sensing.arm_log`); the hand's from the camera's frames, in the base
frame after the calibration (:mod:`qpavoid.sensing.hand_track`). The camera's latency is
the lag that best aligns the two (:func:`~qpavoid.sensing.latency_fit.estimate_latency`,
where the fit, its uncertainty and its refusals are)::

    h_k = p(t_k − τ) + b + e_k

``h_k`` the hand landmark of the frame stamped ``t_k``, ``p`` the flange's position from
the encoders, ``b`` the hand's offset from the flange, ``e_k`` the camera's noise.

**Which latency.** A frame stamped ``t_k`` shows the body as it was at ``t_k − τ``. What τ
is depends on the stamps the recording holds:

* **arrival stamps**, the time each frame became available to the program recording it,
  on the arm log's clock: τ is the camera's latency as the library uses it, from the
  instant the body is in a pose to the instant the frame showing it is available: the
  simulated camera delivers frame k, captured at ``c_k``, at ``c_k + latency_s``
  (:class:`~qpavoid.loop.camera.CameraConfig`), the frame's age at the controller is
  ``now − c_k``, and ``qpavoid run --latency`` sets both that delay and the stale limit
  (latency + 40 ms). With a delay that varies from frame to frame, τ is its mean.
* **capture stamps** (what a live sensor signs into its datagrams: the frame's capture
  time on the shared clock, docs/sensors.md §1): τ is how much later the stamps are than
  the poses they show: 0 within the uncertainty if they are right. Otherwise every frame
  is τ older than its stamp says: subtract τ from the sensor's ``time_offset_s``.
"""

from __future__ import annotations

from pathlib import Path

from qpavoid.arm.model import Robot
from qpavoid.core.errors import InputError
from qpavoid.sensing.arm_log import flange_positions, read_arm_log
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.hand_track import camera_track, nearest_body
from qpavoid.sensing.latency_fit import LatencyConfig, LatencyEstimate, estimate_latency
from qpavoid.sensing.per_sensor import (
    SensorRecording,
    is_sensor_recording,
    load_sensor_recording,
)
from qpavoid.sensing.recording import Recording, load_recording

__all__ = ["measure_latency"]


def measure_latency(
    camera_recording: str | Path,
    arm_log: str | Path,
    robot: Robot,
    calibration: Calibration | None = None,
    sensor: str | None = None,
    config: LatencyConfig | None = None,
) -> LatencyEstimate:
    """A camera's latency from its recording and the arm's log over the same time, on one
    clock (module docstring; docs/sensors.md §10, "Measuring your camera's latency").

    Parameters
    ----------
    camera_recording
        A base-frame recording (NPZ or CSV, docs/formats.md), or a per-sensor one with
        ``calibration``; each frame stamped as the module docstring says.
    arm_log
        The arm's joint angles (:func:`~qpavoid.sensing.arm_log.read_arm_log`).
    robot
        The arm's description (its forward kinematics, its active joints).
    calibration
        The sensors' calibration, for a per-sensor recording.
    sensor
        Which sensor of a per-sensor recording (default: its only one).
    config
        The landmark, the lags searched, the refusals.

    Raises
    ------
    RecordingError
        On a file that cannot be read as what it should be.
    InputError
        (CalibrationError) As :func:`~qpavoid.sensing.hand_track.camera_track`, or a
        recording that gives no latency (:func:`~qpavoid.sensing.latency_fit.estimate_latency`).
    """
    cfg = config or LatencyConfig()
    log = read_arm_log(arm_log, robot)
    if calibration is None and is_sensor_recording(camera_recording):
        raise InputError(
            f"{camera_recording}: a per-sensor recording (it names its sensor) needs the "
            "sensors' calibration (--sensors CALIBRATION.toml, docs/sensors.md)",
            name="--sensors",
            value=None,
        )
    recording: Recording | SensorRecording = (
        load_recording(camera_recording)
        if calibration is None
        else load_sensor_recording(camera_recording)
    )
    t, position = camera_track(recording, cfg.landmark, calibration, sensor)
    flange = flange_positions(robot, log.q)
    t, position = nearest_body(t, position, log.t, flange)
    return estimate_latency(t, position, log.t, flange, cfg)
