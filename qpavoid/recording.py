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

import codecs
import csv
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np

from ._checks import as_array, finite_number, one_line
from .errors import InputError, RecordingError
from .frames import N_KINECT_JOINTS, HumanFrame, JointType, check_joints, check_states

T = TypeVar("T")

#: Names of the arrays of an NPZ recording.
NPZ_ARRAYS: tuple[str, ...] = ("t", "joints", "state")

#: Column suffixes of one joint in a CSV recording, in column order.
CSV_JOINT_FIELDS: tuple[str, ...] = ("x", "y", "z", "state")

#: Valid tracking states: 0 not tracked, 1 inferred, 2 tracked.

#: Where the file formats are described (named by every file-format error).
FORMATS_DOC = "docs/formats.md"

#: What an NPZ recording must be, for error messages.
NPZ_EXPECTED = ("expected a NumPy .npz archive with arrays t (N,), joints (N, 25, 3) and "
                "state (N, 25)")

#: What a CSV recording must be, for error messages.
CSV_EXPECTED = ("expected a UTF-8 CSV file: the header row t,SpineBase_x,SpineBase_y,"
                "SpineBase_z,SpineBase_state,...,ThumbRight_state (101 columns), then one row "
                "of numbers per frame")


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
            raise InputError(f"no frame yet at t={time_s!r} s: the recording starts at "
                             f"t[0]={float(self.t[0])!r} s", name="time_s", value=time_s)
        return index

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


def _check_times(t) -> np.ndarray:
    """(N,) finite, strictly increasing frame times with N >= 1, s."""
    arr = as_array(t, (None,), "t (frame times, s)", finite=False)
    if arr.shape[0] == 0:
        raise InputError("the recording has no frame: t (frame times, s) is empty", name="t",
                         value=arr)
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise InputError(f"t (frame times, s) has a non-finite value at index {bad}: "
                         f"{float(arr[bad])!r}", name="t", value=arr)
    steps = np.diff(arr)
    if np.any(steps <= 0):
        i = int(np.flatnonzero(steps <= 0)[0]) + 1
        kind = "duplicate frame time" if steps[i - 1] == 0 else "frames out of order"
        raise InputError(f"t (frame times, s) must be strictly increasing ({kind}): "
                         f"t[{i}]={float(arr[i])!r} s is not after t[{i - 1}]="
                         f"{float(arr[i - 1])!r} s", name="t", value=arr)
    return arr


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
    RecordingError
        On an unknown suffix, a missing file or a folder, a file that is not in the
        format of its suffix (text named ``.npz``, a ZIP without the arrays, binary data
        named ``.csv``, a wrong CSV header...), or invalid data. The message is one line
        naming the path, the problem and what was expected; ``path`` is set, and
        ``name`` and ``value`` name the array or column at fault when there is one.
    """
    path = Path(path)
    readers = {".npz": _load_npz, ".csv": _load_csv}
    reader = readers.get(path.suffix.lower())
    if reader is None:
        raise RecordingError(f"unknown recording format {path.suffix!r} for {str(path)!r}: "
                             "expected a .npz or .csv file", path=path)
    return read_file(path, reader, "recording", f"see {FORMATS_DOC}")


def read_file(path: Path, reader: Callable[[Path], T], what: str, hint: str = "") -> T:
    """``reader(path)``, with every failure to read ``path`` as a :class:`RecordingError`.

    Parameters
    ----------
    path
        The file.
    reader
        Reads and validates it; raises :class:`InputError` (without the path) on bad
        content.
    what
        What the file is, for messages (``"recording"``).
    hint
        Appended to content errors (e.g. where the format is described).
    """
    if not path.exists():
        raise RecordingError(f"{what} file not found: {str(path)!r}", path=path)
    if path.is_dir():
        raise RecordingError(f"{str(path)!r} is a folder, not a {what} file", path=path)
    if not path.is_file():
        raise RecordingError(f"{str(path)!r} is not a regular file (expected a {what} file)",
                             path=path)
    try:
        return reader(path)
    except InputError as exc:      # bad content (RecordingError included): name the file
        tail = f"; {hint}" if hint else ""
        raise RecordingError(f"{path}: {exc}{tail}", path=path, name=exc.name,
                             value=exc.value) from exc
    except OSError as exc:         # permission denied, vanished, a special file...
        raise RecordingError(f"{path}: cannot read the {what} file "
                             f"({exc.strerror or one_line(exc)})", path=path) from exc


def _file_kind(path: Path) -> str:
    """What the first bytes of ``path`` look like: ``"empty"``, ``"zip"``, ``"npy"``,
    ``"text"`` or ``"binary"``."""
    with path.open("rb") as handle:
        head = handle.read(4096)
    if not head:
        return "empty"
    if head.startswith((b"PK\x03\x04", b"PK\x05\x06")):
        return "zip"
    if head.startswith(b"\x93NUMPY"):
        return "npy"
    try:                           # a multi-byte character may be cut at the end: not final
        codecs.getincrementaldecoder("utf-8")().decode(head, final=False)
    except UnicodeDecodeError:
        return "binary"
    return "binary" if b"\x00" in head else "text"


#: How :func:`_file_kind`'s answers read in messages.
_KIND_TEXT = {"empty": "the file is empty", "zip": "it is a ZIP archive",
              "npy": "it is a single .npy array", "text": "it is a text file",
              "binary": "it is binary data"}


def _load_npz(path: Path) -> Recording:
    """Read an NPZ recording (arrays ``t``, ``joints``, ``state``; others are ignored)."""
    arrays = read_npz(path, NPZ_ARRAYS, NPZ_EXPECTED)
    return Recording(**arrays)


def read_npz(path: Path, names: Sequence[str] | None, expected: str) -> dict[str, np.ndarray]:
    """Arrays of an NPZ file by name (``names``, or all if None); no pickled objects.

    Raises
    ------
    RecordingError
        Without the path (:func:`read_file` adds it): the file is not an NPZ archive, an
        array is missing, holds Python objects or cannot be read. ``expected`` (what the
        file should be) ends the message.
    """
    kind = _file_kind(path)
    if kind != "zip":
        raise RecordingError(f"not a readable NPZ archive ({_KIND_TEXT[kind]}); {expected}")
    try:
        # Our own handle: numpy leaks the one it opens when the archive is damaged.
        with path.open("rb") as handle, np.load(handle, allow_pickle=False) as data:
            members = set(data.zip.namelist())
            found = [name for name in data.files if f"{name}.npy" in members]
            if not found:
                others = ", ".join(data.files[:5]) or "none"
                raise RecordingError(f"not a readable NPZ archive (a ZIP archive without .npy "
                                     f"arrays; members: {others}); {expected}")
            missing = [name for name in names or () if name not in found]
            if missing:
                raise RecordingError(
                    f"NPZ file has no array {', '.join(map(repr, missing))} (found: "
                    f"{', '.join(map(repr, found))}); {expected}", name=missing[0])
            return {name: _npz_array(data, name, expected) for name in names or found}
    except RecordingError:
        raise
    except Exception as exc:       # zipfile, zlib, numpy's format parser: a damaged file
        raise RecordingError(f"not a readable NPZ archive (damaged: {one_line(exc)}); "
                             f"{expected}") from exc


def _npz_array(data, name: str, expected: str) -> np.ndarray:
    """Member ``name`` of an open NPZ file, refusing pickled objects with a clear message."""
    try:
        arr = data[name]
    except ValueError as exc:
        if "allow_pickle" not in str(exc):
            raise
        raise RecordingError(f"array {name!r} holds Python objects (pickled data, never "
                             f"loaded); {expected}", name=name) from None
    if not isinstance(arr, np.ndarray):        # a member named .npy that is not one
        raise RecordingError(f"member {name + '.npy'!r} is not a .npy array; {expected}",
                             name=name)
    return arr


def _load_csv(path: Path) -> Recording:
    """Read a CSV recording (header row, then one row of 101 numbers per frame)."""
    kind = _file_kind(path)
    if kind != "text":
        raise RecordingError(f"not a CSV text file ({_KIND_TEXT[kind]}); {CSV_EXPECTED}")
    names = csv_header()
    try:
        with path.open("r", encoding="utf-8-sig", newline="") as handle:
            rows = csv.reader(handle)
            _check_csv_header(next(rows, None), names)
            values = [_parse_csv_row(row, line, names) for line, row in enumerate(rows, start=2)
                      if any(cell.strip() for cell in row)]
    except UnicodeDecodeError as exc:      # past the first 4 kB that _file_kind looked at
        raise RecordingError(f"not a CSV text file (invalid UTF-8: {one_line(exc)}); "
                             f"{CSV_EXPECTED}") from exc
    except csv.Error as exc:               # a NUL byte, a field too long...
        raise RecordingError(f"not a readable CSV file ({one_line(exc)}); {CSV_EXPECTED}") from exc
    data = np.array(values, dtype=float).reshape(len(values), len(names))
    per_joint = data[:, 1:].reshape(-1, N_KINECT_JOINTS, len(CSV_JOINT_FIELDS))
    return Recording(t=data[:, 0], joints=per_joint[:, :, :3], state=per_joint[:, :, 3])


def _check_csv_header(header: list[str] | None, expected: list[str]) -> None:
    """Raise RecordingError unless ``header`` is exactly ``expected`` (:func:`csv_header`)."""
    if header is None:
        raise RecordingError(f"the CSV file has no header row; {CSV_EXPECTED}", name="header")
    found = [cell.strip() for cell in header]
    if found == expected:
        return

    def fail(problem: str) -> RecordingError:
        return RecordingError(f"CSV header {problem}", name="header", value=found)

    missing = [name for name in expected if name not in found]
    if len(missing) == len(expected):
        shown = ",".join(found[:3]) + (",..." if len(found) > 3 else "")
        count = f"{len(found)} column" + ("s" if len(found) != 1 else "")
        raise fail(f"not found: the first row is {shown!r} ({count}); {CSV_EXPECTED}")
    if missing:
        more = len(missing) - 5
        shown = ", ".join(missing[:5]) + (f" and {more} more" if more > 0 else "")
        raise fail(f"is missing column(s) {shown}")
    unknown = [name for name in found if name not in expected]
    if unknown:
        raise fail(f"has unknown column(s) {', '.join(map(repr, unknown))}")
    for i, (got, want) in enumerate(zip(found, expected)):
        if got != want:
            raise fail(f"column {i} is {got!r}, expected {want!r} (columns must be t then "
                       "<Joint>_x,_y,_z,_state in JointType order)")
    raise fail(f"has {len(found)} columns, expected {len(expected)} (a column is repeated)")


def _parse_csv_row(row: list[str], line: int, names: list[str]) -> list[float]:
    """Floats of one CSV data row; ``line`` is its 1-based line number for messages."""
    if len(row) != len(names):
        raise RecordingError(f"CSV line {line} has {len(row)} values, expected {len(names)}",
                             name="line", value=line)
    try:
        return [float(cell) for cell in row]
    except ValueError:
        col = next(i for i, cell in enumerate(row) if not _is_float(cell))
        raise RecordingError(f"CSV line {line}, column {names[col]!r}: {row[col]!r} is not a "
                             "number", name=names[col], value=row[col]) from None


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
        raise InputError(f"rec must be a Recording, got {type(rec).__name__}", name="rec",
                         value=rec)
