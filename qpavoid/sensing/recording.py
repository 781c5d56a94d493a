"""Recorded human motion: skeletons over time in the robot base frame, stored as NPZ or CSV.

A recording is N camera frames of one person, already expressed in the robot base frame.
Two file formats hold it (see ``docs/formats.md``), in any skeleton format the library
has (:data:`~qpavoid.human.landmarks.FORMAT_NAMES`; the Kinect v2's by default):

* **NPZ**: arrays ``t`` (N,) s, ``joints`` (N, J, 3) m, ``state`` (N, J) int (J the
  format's joints: 25 for the Kinect v2), and optionally ``format`` (a string: the
  format's name; none is the Kinect v2's).
* **CSV**: a header row ``t`` then ``<Joint>_x,<Joint>_y,<Joint>_z,<Joint>_state`` for
  the format's joints in its order (101 columns for the Kinect v2's 25, in
  :class:`~qpavoid.human.kinect_v2.JointType` order), one row a frame; the joint columns
  name the format.

A file of another format is mapped onto the body's landmarks when it is read
(:func:`~qpavoid.human.landmarks.landmark_map`): a :class:`Recording` always holds the
body's landmarks (the Kinect v2's 25 joints; bit-identical for a Kinect v2 file), and
:attr:`Recording.format` names the format of the file it came from.

The simulation samples a recording with *sample-and-hold*: at time ``t_s`` it uses the
last frame with ``t <= t_s``, never a frame from the future, and holds the last frame
once the recording has ended (:meth:`Recording.frame_at`).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from qpavoid.core.checks import as_array, finite_number
from qpavoid.core.errors import InputError
from qpavoid.human.frames import HumanFrame, check_joints, check_states
from qpavoid.human.landmarks import landmark_map
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.sensing.calibration import DEFAULT_FORMAT, check_format_name
from qpavoid.sensing.recording_files import (
    CSV_EXPECTED,
    CSV_JOINT_FIELDS,
    NPZ_ARRAYS,
    NPZ_EXPECTED,
    csv_header,
    npz_format,
    read_by_suffix,
    read_csv_format,
    read_csv_table,
    read_file,
    read_npz,
)

__all__ = [
    "Recording",
    "csv_header",
    "load_recording",
    "read_file",
    "read_npz",
    "save_csv",
    "save_npz",
]


@dataclass(frozen=True, eq=False)
class Recording:
    """N frames of the body's landmarks (the Kinect v2's 25 joints) in the robot base frame.

    The arrays are validated, converted (``t`` and ``joints`` to float64, ``state`` to
    int8), copied and made read-only at construction.

    Parameters
    ----------
    t
        (N,) frame times, s. Finite and strictly increasing (no duplicate frame).
    joints
        (N, 25, 3) joint positions in the robot base frame, m, joints in
        :class:`~qpavoid.human.kinect_v2.JointType` order. NaN marks a joint that is not usable;
        infinite values are rejected.
    state
        (N, 25) tracking states: 0 not tracked, 1 inferred, 2 tracked
        (:class:`~qpavoid.human.kinect_v2.TrackingState`). A joint in state 0 is not usable
        whatever its coordinates.
    format
        The skeleton format of the camera the frames came from (a name of
        :data:`~qpavoid.human.landmarks.FORMAT_NAMES`; default ``"kinect_v2"``): what the
        file read held, before its frames were mapped onto the body's landmarks. The
        joints are the landmarks whatever it says.

    Raises
    ------
    InputError
        On a wrong shape, no frame, a non-finite or non-increasing ``t``, an infinite
        coordinate, a state outside {0, 1, 2} or an unknown format; the message names
        the bad value.
    """

    t: np.ndarray
    joints: np.ndarray
    state: np.ndarray
    format: str = DEFAULT_FORMAT

    def __post_init__(self) -> None:
        problem = check_format_name(self.format)
        if problem is not None:
            raise InputError(problem, name="format", value=self.format)
        t = _check_times(self.t)
        joints = check_joints(self.joints, t)
        state = check_states(self.state, t)
        for name, arr in (("t", t), ("joints", joints), ("state", state)):
            arr = np.array(arr, copy=True)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def n_frames(self) -> int:
        """Number of frames N."""
        return int(self.t.shape[0])

    @property
    def duration_s(self) -> float:
        """Time from the first to the last frame, s (0 for a single frame)."""
        return float(self.t[-1] - self.t[0])

    def index_at(self, time_s: float) -> int:
        """Index of the frame shown at ``time_s`` (sample-and-hold), in O(log N).

        Parameters
        ----------
        time_s
            Query time, s, on the clock of ``t``.

        Returns
        -------
        int
            Index of the last frame with ``t <= time_s`` (``N - 1`` after the end).

        Raises
        ------
        InputError
            If ``time_s`` is not finite or is before the first frame (no frame yet).
        """
        time_s = finite_number(time_s, "time_s (s)")
        index = int(np.searchsorted(self.t, time_s, side="right")) - 1
        if index < 0:
            raise InputError(
                f"no frame yet at t={time_s!r} s: the recording starts at "
                f"t[0]={float(self.t[0])!r} s",
                name="time_s",
                value=time_s,
            )
        return index

    def capture_time_at(self, time_s: float) -> float:
        """Capture time (s, on the clock of ``t``) of the frame shown at ``time_s``.

        A frame's age is ``time_s`` minus this: after a gap in the recording, or once it
        has ended, the frame shown grows old and a controller stops on it.
        """
        return float(self.t[self.index_at(time_s)])

    def frame_at(self, time_s: float) -> HumanFrame:
        """Joints and states shown at ``time_s``: the last frame with ``t <= time_s``.

        Never returns a frame from the future; after the last frame, the last frame is
        held. O(log N).

        Parameters
        ----------
        time_s
            Query time, s, on the clock of ``t``.

        Returns
        -------
        HumanFrame
            ``joints`` (25, 3) in the robot base frame, m (NaN = not usable) and ``state``
            (25,) int8: copies, checked when the recording was made.

        Raises
        ------
        InputError
            If ``time_s`` is not finite or is before the first frame.
        """
        index = self.index_at(time_s)
        return HumanFrame(self.joints[index].copy(), self.state[index].copy())


def _check_times(t: object) -> np.ndarray:
    """(N,) finite, strictly increasing frame times with N >= 1, s."""
    arr = as_array(t, (None,), "t (frame times, s)", finite=False)
    if arr.shape[0] == 0:
        raise InputError(
            "the recording has no frame: t (frame times, s) is empty", name="t", value=arr
        )
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise InputError(
            f"t (frame times, s) has a non-finite value at index {bad}: {float(arr[bad])!r}",
            name="t",
            value=arr,
        )
    steps = np.diff(arr)
    if np.any(steps <= 0):
        i = int(np.flatnonzero(steps <= 0)[0]) + 1
        kind = "duplicate frame time" if steps[i - 1] == 0 else "frames out of order"
        raise InputError(
            f"t (frame times, s) must be strictly increasing ({kind}): "
            f"t[{i}]={float(arr[i])!r} s is not after t[{i - 1}]="
            f"{float(arr[i - 1])!r} s",
            name="t",
            value=arr,
        )
    return arr


def load_recording(path: str | Path) -> Recording:
    """Read a recording, choosing the format by the file suffix.

    Parameters
    ----------
    path
        A ``.npz`` or ``.csv`` file (suffix case-insensitive).

    Returns
    -------
    Recording
        The validated recording.

    Raises
    ------
    RecordingError
        On an unknown suffix, a missing file or a folder, a file that is not in the
        format of its suffix (text named ``.npz``, a ZIP without the arrays, binary data
        named ``.csv``, a wrong CSV header...), or invalid data. The message is one line
        naming the path, the problem and what was expected; ``path`` is set, and
        ``name`` and ``value`` name the array or column at fault when there is one.
    """
    return read_by_suffix(path, {".npz": _load_npz, ".csv": _load_csv}, "recording")


def _load_npz(path: Path) -> Recording:
    """Read an NPZ recording (arrays ``t``, ``joints``, ``state``, optionally ``format``;
    others are ignored)."""
    arrays = read_npz(path, NPZ_ARRAYS, NPZ_EXPECTED, formatted=True)
    fmt = npz_format(arrays)
    return _on_landmarks(arrays["t"], arrays["joints"], arrays["state"], fmt)


def _load_csv(path: Path) -> Recording:
    """Read a CSV recording (header row, then one row of numbers per frame)."""
    fmt = read_csv_format(path)
    data = read_csv_table(path, csv_header(fmt), CSV_EXPECTED)
    per_joint = data[:, 1:].reshape(-1, fmt.n_joints, len(CSV_JOINT_FIELDS))
    return _on_landmarks(data[:, 0], per_joint[:, :, :3], per_joint[:, :, 3], fmt)


def _on_landmarks(t: object, joints: object, state: object, fmt: SkeletonFormat) -> Recording:
    """A recording of the body's landmarks from frames of ``fmt`` (checked as such first:
    a wrong shape or a coordinate beyond 100 m is named in the format's joints)."""
    times = _check_times(t)
    j = check_joints(joints, times, skeleton=fmt)
    s = check_states(state, times, skeleton=fmt)
    mapped = landmark_map(fmt).map(j, s)
    return Recording(times, mapped.joints, mapped.state, fmt.name)


def save_npz(path: str | Path, rec: Recording) -> None:
    """Write ``rec`` as an NPZ file with arrays ``t``, ``joints`` and ``state`` (int8).

    Parameters
    ----------
    path
        Output file, written exactly at this path (no suffix is added).
    rec
        The recording.
    """
    _check_recording(rec)
    with Path(path).open("wb") as handle:
        np.savez(handle, t=rec.t, joints=rec.joints, state=rec.state)


def save_csv(path: str | Path, rec: Recording) -> None:
    """Write ``rec`` as a CSV file: the :func:`csv_header` row, then one row per frame.

    Floats are written as Python's shortest text that reads back to the same float64
    (exact round trip), NaN is written ``nan`` and states are integers.

    Parameters
    ----------
    path
        Output file.
    rec
        The recording.
    """
    _check_recording(rec)
    with Path(path).open("w", encoding="utf-8", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(csv_header())
        for k in range(rec.n_frames):
            writer.writerow(_csv_row(rec.t[k], rec.joints[k], rec.state[k]))


def _csv_row(t: float, joints: np.ndarray, state: np.ndarray) -> list[str]:
    """Text cells of one frame: shortest exact float text (``nan`` for NaN), int states."""
    cells = [repr(float(t))]
    for xyz, s in zip(joints, state, strict=True):
        cells += [repr(float(v)) for v in xyz] + [str(int(s))]
    return cells


def _check_recording(rec: object) -> None:
    """Raise InputError unless ``rec`` is a :class:`Recording`."""
    if not isinstance(rec, Recording):
        raise InputError(
            f"rec must be a Recording, got {type(rec).__name__}", name="rec", value=rec
        )
