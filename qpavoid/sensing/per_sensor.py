"""Per-sensor recordings: skeletons as each camera reported them, before fusion.

Where :class:`~qpavoid.sensing.recording.Recording` holds one person in the robot base frame, a
:class:`SensorRecording` holds what one or more sensors reported: one row per body per
camera frame, joints in **the sensor's own camera frame**, each row with its ``sensor``
name and ``body`` id (Kinect v2 tracks up to six bodies) and the time stamp on the
sensor's clock. :mod:`qpavoid.sensing.calibration` puts the rows in the base frame and
:mod:`qpavoid.fusion.fuser` merges them. The file formats (docs/formats.md, "Per-sensor
recordings") extend the base-frame ones:

* **NPZ**: ``t`` (N,), ``joints`` (N, J, 3), ``state`` (N, J) as before (J the joints of
  the file's skeleton format: 25 for the Kinect v2's), plus ``sensor`` (a string, or (N,)
  strings), optionally ``body`` (N,) integers (default 0) and ``format`` (a string: the
  skeleton format's name, :data:`~qpavoid.human.landmarks.FORMAT_NAMES`; none is
  ``"kinect_v2"``).
* **CSV**: the header ``t,sensor,body,SpineBase_x,...,ThumbRight_state`` (``body`` may be
  left out), one row per body per frame; the joint columns (``<Joint>_x,_y,_z,_state``
  of a format's joints, in its order) name the format.

A file holds one format's frames, in metres, with the library's tracking states 0/1/2
(:func:`~qpavoid.human.landmarks.camera_frame` converts an SDK's own units and
confidence); the calibration's ``format`` of each of its sensors must be that format.

Within one (sensor, body) the times must increase strictly; rows of different bodies or
sensors may share a time.
"""

from __future__ import annotations

import csv
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from qpavoid.core.checks import as_array
from qpavoid.core.compiling import kernel_input
from qpavoid.core.errors import InputError
from qpavoid.core.file_bounds import check_file_size
from qpavoid.human.frames import check_joints, check_states
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.sensing.calibration import DEFAULT_FORMAT, check_format_name, known_formats
from qpavoid.sensing.recording_files import (
    CSV_JOINT_FIELDS,
    joint_columns,
    read_by_suffix,
    read_csv_columns,
    read_csv_format,
    read_npz,
)

__all__ = [
    "BodyFrame",
    "SensorRecording",
    "load_sensor_recording",
    "save_sensor_csv",
    "save_sensor_npz",
]

SENSOR_NPZ_EXPECTED = (
    f"expected a per-sensor NPZ recording: arrays t (N,), joints (N, {KINECT_V2.n_joints}, 3) "
    f"in the camera frame, state (N, {KINECT_V2.n_joints}), sensor (a name, or N names) and "
    "optionally body (N,)"
)
SENSOR_CSV_EXPECTED = (
    f"expected a per-sensor CSV recording: the header t,sensor,body,{KINECT_V2.joints[0]}_x,"
    f"...,{KINECT_V2.joints[-1]}_state (body optional), one row per body per frame"
)


class BodyFrame(NamedTuple):
    """One body in one camera frame, as the sensor reported it.

    Attributes
    ----------
    sensor
        The sensor's name (a key of the calibration file).
    body
        The sensor's body id (0-5 on a Kinect v2; stable while the sensor tracks the body).
    t
        Capture time on the sensor's clock, s.
    joints
        (J, 3) joint positions in the sensor's camera frame, m; NaN = not usable.
    state
        (J,) tracking states (0 not tracked, 1 inferred, 2 tracked).
    format
        The skeleton format of ``joints`` and ``state`` (J its joints, in its order): a name
        of :data:`~qpavoid.human.landmarks.FORMAT_NAMES`, the sensor's calibrated format.
    """

    sensor: str
    body: int
    t: float
    joints: np.ndarray
    state: np.ndarray
    format: str = DEFAULT_FORMAT


def checked_arrays(
    frame: BodyFrame, skeleton: SkeletonFormat = KINECT_V2
) -> tuple[np.ndarray, np.ndarray]:
    """A frame's joints as (J, 3) float64 and states as (J,) int8 (J the joints of
    ``skeleton``), writeable and contiguous (the compiled fusion's input types:
    :func:`~qpavoid.core.compiling.kernel_input`).

    Raises
    ------
    InputError
        For joints that are not (J, 3) numbers (NaN: not usable) or states that are not
        (J,) values in {0, 1, 2}. Recordings and datagrams are checked so already; a
        frame made by hand is checked here, in a few microseconds.
    """
    joints, state = frame.joints, frame.state
    n = skeleton.n_joints
    if not (isinstance(joints, np.ndarray) and joints.shape == (n, 3) and joints.dtype.kind == "f"):
        joints = check_joints(joints, skeleton=skeleton)
    if not (
        isinstance(state, np.ndarray)
        and state.dtype == np.int8
        and state.shape == (n,)
        and ((state >= 0) & (state <= 2)).all()
    ):
        state = check_states(state, skeleton=skeleton)
    return kernel_input(joints, np.float64), kernel_input(state, np.int8)


@dataclass(frozen=True, eq=False)
class SensorRecording:
    """Rows of (sensor, body, t, joints, state), checked and read-only (module docstring).

    ``format`` names the rows' skeleton format (default ``"kinect_v2"``): ``joints`` are
    (N, J, 3) and ``state`` (N, J) with J its joints.

    Raises
    ------
    InputError
        On an unknown format, wrong shapes, a non-finite time, an empty sensor name, a
        body id outside the format's (0-5 for the Kinect v2), or times that do not
        increase within one (sensor, body).
    """

    sensor: np.ndarray
    t: np.ndarray
    body: np.ndarray
    joints: np.ndarray
    state: np.ndarray
    format: str = DEFAULT_FORMAT

    def __post_init__(self) -> None:
        problem = check_format_name(self.format)
        if problem is not None:
            raise InputError(problem, name="format", value=self.format)
        fmt = known_formats()[self.format]
        t = as_array(self.t, (None,), "t (capture times, s)")
        n = t.shape[0]
        if n == 0:
            raise InputError("the recording has no frame: t is empty", name="t", value=t)
        sensor = np.asarray(self.sensor, dtype=str)
        sensor = np.full(n, str(sensor)) if sensor.ndim == 0 else sensor
        if sensor.shape != (n,) or any(not s.strip() for s in sensor):
            raise InputError(
                f"sensor must be one non-empty name or {n} of them, got {sensor!r:.80}",
                name="sensor",
                value=self.sensor,
            )
        body = as_array(self.body, (n,), "body (body ids)")
        max_bodies = fmt.sensor.max_bodies  # body ids 0-5 on a Kinect v2: its format file
        wrong = (body != np.round(body)) | (body < 0) | (body >= max_bodies)
        if np.any(wrong):
            bad = int(np.flatnonzero(wrong)[0])
            raise InputError(
                f"body[{bad}] is {body[bad].item()!r}; the body ids of {fmt.title} are 0 to "
                f"{max_bodies - 1}",
                name="body",
                value=body,
            )
        body = body.astype(np.int64)
        for key in zip(*np.unique(np.stack([sensor, body.astype(str)]), axis=1), strict=True):
            rows = np.flatnonzero((sensor == key[0]) & (body == int(key[1])))
            steps = np.diff(t[rows])
            if np.any(steps <= 0):
                i = rows[int(np.flatnonzero(steps <= 0)[0]) + 1]
                raise InputError(
                    f"times of sensor {str(key[0])!r}, body {key[1]} must increase strictly: "
                    f"row {i} (t={float(t[i])!r} s) is not after the one before",
                    name="t",
                    value=t,
                )
        joints = check_joints(self.joints, t, skeleton=fmt)
        state = check_states(self.state, t, skeleton=fmt)
        for name, arr in (
            ("sensor", sensor),
            ("t", t),
            ("body", body),
            ("joints", joints),
            ("state", state),
        ):
            arr = np.array(arr, copy=True)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def n_rows(self) -> int:
        """Number of rows (bodies × frames)."""
        return int(self.t.shape[0])

    @property
    def sensors(self) -> tuple[str, ...]:
        """The sensors named, in order of first appearance."""
        return tuple(dict.fromkeys(self.sensor.tolist()))

    def frames(self) -> Iterator[BodyFrame]:
        """The rows as :class:`BodyFrame`, in time order (stable for equal times)."""
        for i in np.argsort(self.t, kind="stable"):
            yield BodyFrame(
                str(self.sensor[i]),
                int(self.body[i]),
                float(self.t[i]),
                self.joints[i],
                self.state[i],
                self.format,
            )

    @classmethod
    def from_frames(cls, frames: list[BodyFrame]) -> SensorRecording:
        """A recording of ``frames`` (any order; kept as given), all of one format.

        Raises
        ------
        InputError
            For frames of several formats (a file holds one), or as the class does.
        """
        formats = list(dict.fromkeys(f.format for f in frames)) or [DEFAULT_FORMAT]
        if len(formats) > 1:
            raise InputError(
                f"the frames are of several skeleton formats ({', '.join(map(str, formats))}); "
                "a recording holds one",
                name="format",
                value=formats,
            )
        problem = check_format_name(formats[0])
        if problem is not None:
            raise InputError(problem, name="format", value=formats[0])
        n = known_formats()[formats[0]].n_joints
        return cls(
            sensor=np.array([f.sensor for f in frames], dtype=str),
            t=np.array([f.t for f in frames]),
            body=np.array([f.body for f in frames]),
            joints=np.array([f.joints for f in frames]).reshape(-1, n, 3),
            state=np.array([f.state for f in frames]).reshape(-1, n),
            format=formats[0],
        )


def _names(with_body: bool, skeleton: SkeletonFormat = KINECT_V2) -> list[str]:
    head = ["t", "sensor", "body"] if with_body else ["t", "sensor"]
    return head + joint_columns(skeleton)


def is_sensor_recording(path: str | Path) -> bool:
    """True if the file at ``path`` names its sensor (a per-sensor recording); reads no
    array, and opens no file over its size bound (False: the loader says why)."""
    p = Path(path)
    try:
        if p.suffix.lower() == ".npz":
            check_file_size(p, "npz")
            with zipfile.ZipFile(p) as archive:  # numpy's NpzFile.files: names less .npy
                return any(m in ("sensor", "sensor.npy") for m in archive.namelist())
        if p.suffix.lower() == ".csv":
            header = _csv_first_row(p)
            return len(header) > 1 and header[1] == "sensor"
    except Exception:  # unreadable or too large: the loader that runs next says why
        return False
    return False


def _csv_first_row(path: Path) -> list[str]:
    """The stripped cells of a CSV file's first row ([] if the csv module refuses it);
    RecordingError, unopened, if the file is over :data:`~qpavoid.core.file_bounds.MAX_CSV_BYTES`
    (a line can be the whole file). Binary data is read_csv_columns' to refuse."""
    check_file_size(path, "csv")
    with path.open("r", encoding="utf-8-sig", errors="replace", newline="") as handle:
        try:
            return [cell.strip() for cell in next(csv.reader(handle), [])]
        except csv.Error:  # a field over the csv module's limit...
            return []


def load_sensor_recording(path: str | Path) -> SensorRecording:
    """Read a per-sensor recording (NPZ or CSV, by suffix; module docstring).

    Raises
    ------
    RecordingError
        On a missing or unreadable file, a file without ``sensor`` (a base-frame
        recording), or invalid content; one line naming the file and the problem.
    """
    return read_by_suffix(path, {".npz": _load_npz, ".csv": _load_csv}, "per-sensor recording")


def _load_npz(path: Path) -> SensorRecording:
    arrays = read_npz(path, None, SENSOR_NPZ_EXPECTED, formatted=True)
    missing = [k for k in ("t", "joints", "state", "sensor") if k not in arrays]
    if missing:
        hint = (
            " (a base-frame recording, not one sensor's: it needs no calibration)"
            if missing == ["sensor"]
            else ""
        )
        raise InputError(
            f"NPZ file has no array {missing[0]!r}{hint}; {SENSOR_NPZ_EXPECTED}",
            name=missing[0],
        )
    t = arrays["t"]
    body = arrays.get("body", np.zeros(np.shape(t)))
    fmt = arrays.get("format")
    return SensorRecording(
        arrays["sensor"],
        t,
        body,
        arrays["joints"],
        arrays["state"],
        DEFAULT_FORMAT if fmt is None else str(np.asarray(fmt).reshape(-1)[0]),
    )


def _load_csv(path: Path) -> SensorRecording:
    header = _csv_first_row(path)
    fmt = read_csv_format(path)
    names = _names(len(header) > 2 and header[2] == "body", fmt)
    data, words = read_csv_columns(path, names, SENSOR_CSV_EXPECTED, text=("sensor",))
    first = names.index(joint_columns(fmt)[0])  # the first joint's first column
    per_joint = data[:, first:].reshape(-1, fmt.n_joints, len(CSV_JOINT_FIELDS))
    body = data[:, 2] if "body" in names else np.zeros(len(data))
    return SensorRecording(
        np.array(words["sensor"], dtype=str),
        data[:, 0],
        body,
        per_joint[:, :, :3],
        per_joint[:, :, 3],
        fmt.name,
    )


def save_sensor_npz(path: str | Path, rec: SensorRecording) -> None:
    """Write ``rec`` as a per-sensor NPZ (``sensor`` as a string array, ``body`` as int,
    and ``format`` unless it is the default ``"kinect_v2"``: a Kinect v2 file is as
    before)."""
    arrays = {
        "t": rec.t,
        "sensor": rec.sensor,
        "body": rec.body,
        "joints": rec.joints,
        "state": rec.state,
    }
    if rec.format != DEFAULT_FORMAT:
        arrays["format"] = np.array(rec.format)
    with Path(path).open("wb") as handle:
        np.savez(handle, **arrays)  # type: ignore[arg-type]  # numpy's stub: allow_pickle


def save_sensor_csv(path: str | Path, rec: SensorRecording) -> None:
    """Write ``rec`` as a per-sensor CSV (``t,sensor,body,...``; exact float round trip)."""
    with Path(path).open("w", encoding="utf-8", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(_names(True, known_formats()[rec.format]))
        for k in range(rec.n_rows):
            cells = [repr(float(rec.t[k])), str(rec.sensor[k]), str(int(rec.body[k]))]
            for xyz, s in zip(rec.joints[k], rec.state[k], strict=True):
                cells += [repr(float(v)) for v in xyz] + [str(int(s))]
            writer.writerow(cells)
