"""The person (or people) a run is about: a scenario, a recording, or fused sensor recordings.

* a generated scenario (:func:`~qpavoid.scenarios.generated.make_scenario`);
* a base-frame recording (docs/formats.md); one with a ``body`` array (a fused recording
  of several people) becomes a :class:`~qpavoid.human.people.Crowd`;
* per-sensor recordings with a calibration (docs/sensors.md): fused offline
  (:func:`~qpavoid.fusion.offline.fuse_recordings`) and taken as the truth, one person or a crowd.
"""

from __future__ import annotations

from collections.abc import Sequence

from qpavoid.arm.model import Robot
from qpavoid.control.task import Task
from qpavoid.core.errors import InputError
from qpavoid.fusion.offline import fuse_recordings, load_people
from qpavoid.human.frames import HumanMotion
from qpavoid.loop.crowd import Crowd
from qpavoid.scenarios.generated import make_scenario
from qpavoid.sensing.bags import is_bag, sensor_recordings
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.per_sensor import is_sensor_recording
from qpavoid.sensing.recording import load_recording

__all__ = ["check_human_files", "check_inputs", "load_motion"]


def check_human_files(files: Sequence[str], sensors: str | None) -> None:
    """Refuse a mix that cannot work: several files without ``sensors``, per-sensor files
    without it, or base-frame files with it."""
    if not files:
        if sensors is not None:
            raise InputError(
                "--sensors needs per-sensor recordings (--human A.npz B.npz)",
                name="--sensors",
                value=sensors,
            )
        return
    per_sensor = [f for f in files if is_sensor_recording(f) or is_bag(f)]
    if sensors is None and (len(files) > 1 or per_sensor):
        raise InputError(
            f"{(per_sensor or list(files))[0]}: per-sensor recordings (with a sensor name) "
            "need --sensors CALIBRATION.toml (docs/sensors.md); a base-frame recording is "
            "one file",
            name="--sensors",
            value=None,
        )


def check_inputs(files: Sequence[str], sensors: str | None) -> None:
    """Read every file a run names (recordings, calibration) and check that they fit, so
    that a bad one fails before any work; nothing is fused."""
    check_human_files(files, sensors)
    if sensors is None:
        for f in files:
            if load_people(f) is None:
                load_recording(f)
        return
    calibration = load_calibration(sensors)
    for f in files:
        for recording in sensor_recordings(f, calibration):
            calibration.check_names(recording.sensors)


def load_motion(
    robot: Robot,
    scenario: str | None = None,
    human_files: Sequence[str] = (),
    sensors: str | None = None,
    task: Task | None = None,
) -> HumanMotion:
    """The true motion a run replays (module docstring); a generated scenario's along
    ``task``'s path with its operator's seat (default: the robot's own task,
    :func:`~qpavoid.control.task.default_task`).

    Raises
    ------
    InputError
        (RecordingError, CalibrationError) on a bad file, a sensor missing from the
        calibration, or a combination :func:`check_human_files` refuses.
    """
    check_human_files(human_files, sensors)
    if not human_files:
        return make_scenario(str(scenario), robot, task=task)
    if sensors is None:
        people = load_people(human_files[0])
        if people is None:
            return load_recording(human_files[0])
        return Crowd(people) if len(people) > 1 else next(iter(people.values()))
    calibration = load_calibration(sensors)
    recordings = [r for f in human_files for r in sensor_recordings(f, calibration)]
    people = fuse_recordings(recordings, calibration).people()
    return Crowd(people) if len(people) > 1 else next(iter(people.values()))
