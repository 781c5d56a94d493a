"""Recorded human motion: Kinect v2 skeletons over time, stored as NPZ or CSV.

A recording is N camera frames of the 25 Kinect v2 joints, already expressed in the
robot base frame. Two file formats hold it (see ``docs/formats.md``):

* **NPZ**: arrays ``t`` (N,) s, ``joints`` (N, 25, 3) m, ``state`` (N, 25) int.
* **CSV**: a header row ``t`` then ``<Joint>_x,<Joint>_y,<Joint>_z,<Joint>_state`` for
  the 25 joints in :class:`~qpavoid.human.JointType` order (101 columns), one row a frame.

The simulation samples a recording with *sample-and-hold*: at time ``t_s`` it uses the
last frame with ``t <= t_s``, never a frame from the future, and holds the last frame
once the recording has ended (:meth:`Recording.frame_at`).
"""

from __future__ import annotations

import csv
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._checks import as_array
from .errors import InputError
from .human import N_KINECT_JOINTS, JointType

#: Names of the arrays of an NPZ recording.
NPZ_ARRAYS: tuple[str, ...] = ("t", "joints", "state")

#: Column suffixes of one joint in a CSV recording, in column order.
CSV_JOINT_FIELDS: tuple[str, ...] = ("x", "y", "z", "state")

#: Valid tracking states: 0 not tracked, 1 inferred, 2 tracked.
VALID_STATES: tuple[int, ...] = (0, 1, 2)


@dataclass(frozen=True, eq=False)
class Recording:
    """N frames of a Kinect v2 skeleton in the robot base frame.

    The arrays are validated, converted (``t`` and ``joints`` to float64, ``state`` to
    int8), copied and made read-only at construction.

    Parameters
    ----------
    t
        (N,) frame times, s. Finite and strictly increasing (no duplicate frame).
    joints
        (N, 25, 3) joint positions in the robot base frame, m, joints in
        :class:`~qpavoid.human.JointType` order. NaN marks a joint that is not usable;
        infinite values are rejected.
    state
        (N, 25) tracking states: 0 not tracked, 1 inferred, 2 tracked
        (:class:`~qpavoid.human.TrackingState`). A joint in state 0 is not usable
        whatever its coordinates.

    Raises
    ------
    InputError
        On a wrong shape, no frame, a non-finite or non-increasing ``t``, an infinite
        coordinate or a state outside {0, 1, 2}; the message names the bad value.
    """

    t: np.ndarray
    joints: np.ndarray
    state: np.ndarray

    def __post_init__(self) -> None:
        t = _check_times(self.t)
        joints = _check_joints(self.joints, t)
        state = _check_states(self.state, t)
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
        time_s = _check_query_time(time_s)
        index = int(np.searchsorted(self.t, time_s, side="right")) - 1
        if index < 0:
            raise InputError(f"no frame yet at t={time_s!r} s: the recording starts at "
                             f"t[0]={float(self.t[0])!r} s")
        return index

    def frame_at(self, time_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Joints and states shown at ``time_s``: the last frame with ``t <= time_s``.

        Never returns a frame from the future; after the last frame, the last frame is
        held. O(log N).

        Parameters
        ----------
        time_s
            Query time, s, on the clock of ``t``.

        Returns
        -------
        joints : np.ndarray
            (25, 3) joint positions in the robot base frame, m (a copy; NaN = not usable).
        state : np.ndarray
            (25,) int8 tracking states (a copy).

        Raises
        ------
        InputError
            If ``time_s`` is not finite or is before the first frame.
        """
        index = self.index_at(time_s)
        return self.joints[index].copy(), self.state[index].copy()


def _check_times(t) -> np.ndarray:
    """(N,) finite, strictly increasing frame times with N >= 1, s."""
    arr = as_array(t, (None,), "t (frame times, s)", finite=False)
    if arr.shape[0] == 0:
        raise InputError("the recording has no frame: t (frame times, s) is empty")
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise InputError(f"t (frame times, s) has a non-finite value at index {bad}: {float(arr[bad])!r}")
    steps = np.diff(arr)
    if np.any(steps <= 0):
        i = int(np.flatnonzero(steps <= 0)[0]) + 1
        kind = "duplicate frame time" if steps[i - 1] == 0 else "frames out of order"
        raise InputError(f"t (frame times, s) must be strictly increasing ({kind}): "
                         f"t[{i}]={float(arr[i])!r} s is not after t[{i - 1}]={float(arr[i - 1])!r} s")
    return arr


def _check_joints(joints, t: np.ndarray) -> np.ndarray:
    """(N, 25, 3) float joints, m; NaN allowed (not usable), infinite values rejected."""
    n = t.shape[0]
    arr = as_array(joints, (n, N_KINECT_JOINTS, 3), "joints (robot base frame, m)", finite=False)
    if np.any(np.isinf(arr)):
        frame, joint, axis = (int(i) for i in np.argwhere(np.isinf(arr))[0])
        raise InputError(f"joints has an infinite coordinate at frame {frame} (t={float(t[frame])!r} s), "
                         f"joint {JointType(joint).name}, axis {'xyz'[axis]}: {float(arr[frame, joint, axis])!r}")
    return arr


def _check_states(state, t: np.ndarray) -> np.ndarray:
    """(N, 25) int8 tracking states in {0, 1, 2}."""
    n = t.shape[0]
    arr = as_array(state, (n, N_KINECT_JOINTS), "state (tracking states)", finite=False)
    bad_mask = ~np.isin(arr, VALID_STATES)
    if np.any(bad_mask):
        frame, joint = (int(i) for i in np.argwhere(bad_mask)[0])
        raise InputError(f"state[{frame}, {joint}] ({JointType(joint).name} at t={float(t[frame])!r} s) "
                         f"is {_number_text(arr[frame, joint])}, expected 0 (not tracked), 1 (inferred) "
                         "or 2 (tracked)")
    return arr.astype(np.int8)


def _number_text(value: float) -> str:
    """``3`` for an integral value, else the float's repr (``1.5``, ``nan``)."""
    value = float(value)
    return str(int(value)) if value.is_integer() else repr(value)


def _check_query_time(time_s) -> float:
    """A finite query time, s."""
    try:
        value = float(time_s)
    except (TypeError, ValueError) as exc:
        raise InputError(f"time_s must be a number of seconds, got {time_s!r}") from exc
    if not np.isfinite(value):
        raise InputError(f"time_s must be finite, got {value!r}")
    return value


def csv_header() -> list[str]:
    """The 101 column names of a CSV recording.

    Returns
    -------
    list of str
        ``t`` then ``<Joint>_x, <Joint>_y, <Joint>_z, <Joint>_state`` for each Kinect v2
        joint in :class:`~qpavoid.human.JointType` order.
    """
    return ["t"] + [f"{joint.name}_{field}" for joint in JointType for field in CSV_JOINT_FIELDS]


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
    InputError
        On an unknown suffix, a missing file, a missing array or column, a wrong CSV
        header or invalid data; the message names the path and the problem.
    """
    path = Path(path)
    readers = {".npz": _load_npz, ".csv": _load_csv}
    reader = readers.get(path.suffix.lower())
    if reader is None:
        raise InputError(f"unknown recording format {path.suffix!r} for {str(path)!r}: "
                         "expected a .npz or .csv file")
    if not path.is_file():
        raise InputError(f"recording file not found: {str(path)!r}")
    try:
        return reader(path)
    except FileNotFoundError as exc:
        raise InputError(f"recording file not found: {str(path)!r}") from exc
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a UTF-8 text CSV file: {exc}") from exc
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from exc


def _load_npz(path: Path) -> Recording:
    """Read an NPZ recording (arrays ``t``, ``joints``, ``state``; others are ignored)."""
    arrays = _read_npz_arrays(path)
    missing = [name for name in NPZ_ARRAYS if name not in arrays]
    if missing:
        raise InputError(f"NPZ recording has no array {', '.join(map(repr, missing))} "
                         f"(found: {', '.join(map(repr, arrays)) or 'none'}); "
                         f"expected arrays {', '.join(map(repr, NPZ_ARRAYS))}")
    return Recording(**{name: arrays[name] for name in NPZ_ARRAYS})


def _read_npz_arrays(path: Path) -> dict[str, np.ndarray]:
    """All arrays of an NPZ file, by name (no pickled objects)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return {name: data[name] for name in data.files}
    except FileNotFoundError:
        raise
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise InputError(f"not a readable NPZ file: {exc}") from exc


def _load_csv(path: Path) -> Recording:
    """Read a CSV recording (header row, then one row of 101 numbers per frame)."""
    with path.open("r", encoding="utf-8-sig", newline="") as handle:
        rows = csv.reader(handle)
        _check_csv_header(next(rows, None))
        values = [_parse_csv_row(row, line) for line, row in enumerate(rows, start=2)
                  if any(cell.strip() for cell in row)]
    data = np.array(values, dtype=float).reshape(len(values), len(csv_header()))
    per_joint = data[:, 1:].reshape(-1, N_KINECT_JOINTS, len(CSV_JOINT_FIELDS))
    return Recording(t=data[:, 0], joints=per_joint[:, :, :3], state=per_joint[:, :, 3])


def _check_csv_header(header: list[str] | None) -> None:
    """Raise InputError unless ``header`` is exactly :func:`csv_header`."""
    expected = csv_header()
    if header is None:
        raise InputError("CSV recording is empty: expected a header row starting with 't'")
    found = [cell.strip() for cell in header]
    if found == expected:
        return
    missing = [name for name in expected if name not in found]
    if missing:
        shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        raise InputError(f"CSV header is missing column(s) {shown}")
    unknown = [name for name in found if name not in expected]
    if unknown:
        raise InputError(f"CSV header has unknown column(s) {', '.join(map(repr, unknown))}")
    for i, (got, want) in enumerate(zip(found, expected)):
        if got != want:
            raise InputError(f"CSV header column {i} is {got!r}, expected {want!r} "
                             "(columns must be t then <Joint>_x,_y,_z,_state in JointType order)")
    raise InputError(f"CSV header has {len(found)} columns, expected {len(expected)} "
                     "(a column is repeated)")


def _parse_csv_row(row: list[str], line: int) -> list[float]:
    """Floats of one CSV data row; ``line`` is its 1-based line number for messages."""
    names = csv_header()
    if len(row) != len(names):
        raise InputError(f"CSV line {line} has {len(row)} values, expected {len(names)}")
    try:
        return [float(cell) for cell in row]
    except ValueError:
        col = next(i for i, cell in enumerate(row) if not _is_float(cell))
        raise InputError(f"CSV line {line}, column {names[col]!r}: {row[col]!r} is not a number") from None


def _is_float(text: str) -> bool:
    """True if ``float(text)`` succeeds."""
    try:
        float(text)
    except ValueError:
        return False
    return True


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
    for xyz, s in zip(joints, state):
        cells += [repr(float(v)) for v in xyz] + [str(int(s))]
    return cells


def _check_recording(rec) -> None:
    """Raise InputError unless ``rec`` is a :class:`Recording`."""
    if not isinstance(rec, Recording):
        raise InputError(f"rec must be a Recording, got {type(rec).__name__}")
