"""Reading recording files safely: NPZ archives and CSV tables, every failure one clear error.

The functions here know file formats, not recordings: :mod:`qpavoid.sensing.recording` builds a
:class:`~qpavoid.sensing.recording.Recording` from what they read, and
:mod:`qpavoid.output.run_files` reads run
logs with the same NPZ reader. Every problem is a :class:`~qpavoid.core.errors.RecordingError`
with a one-line message saying what is wrong and what was expected; no pickled object is
ever loaded.

Sizes are bounded before anything is read (:func:`~qpavoid.core.file_bounds.check_file_size`,
:func:`~qpavoid.core.file_bounds.check_npy_headers`): a file's size on disk, an NPZ's declared
size and each array's ``.npy`` header.
"""

from __future__ import annotations

import codecs
import csv
import zipfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TypeVar

import numpy as np
from numpy.lib import format as npy_format

from qpavoid.core.checks import one_line
from qpavoid.core.errors import InputError, RecordingError
from qpavoid.core.file_bounds import check_file_size, check_npy_headers
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.sensing.calibration import DEFAULT_FORMAT, known_formats

T = TypeVar("T")

#: Names of the arrays of an NPZ recording.
NPZ_ARRAYS: tuple[str, ...] = ("t", "joints", "state")

#: Column suffixes of one joint in a CSV recording, in column order.
CSV_JOINT_FIELDS: tuple[str, ...] = ("x", "y", "z", "state")

#: Where the file formats are described (named by every file-format error).
FORMATS_DOC = "docs/formats.md"

_N = KINECT_V2.n_joints  # recordings hold Kinect v2 skeletons (docs/formats.md)
_FIRST, _LAST = KINECT_V2.joints[0], KINECT_V2.joints[-1]

#: What an NPZ recording must be, for error messages.
NPZ_EXPECTED = (
    f"expected a NumPy .npz archive with arrays t (N,), joints (N, {_N}, 3) and state (N, {_N})"
)

#: What a CSV recording must be, for error messages.
CSV_EXPECTED = (
    f"expected a UTF-8 CSV file: the header row t,{_FIRST}_x,{_FIRST}_y,"
    f"{_FIRST}_z,{_FIRST}_state,...,{_LAST}_state ({1 + _N * len(CSV_JOINT_FIELDS)} columns), "
    "then one row of numbers per frame"
)


def csv_header(skeleton: SkeletonFormat = KINECT_V2) -> list[str]:
    """The column names of a CSV recording of ``skeleton`` (101 for the Kinect v2's 25
    joints).

    Returns
    -------
    list of str
        ``t`` then :func:`joint_columns`.
    """
    return ["t", *joint_columns(skeleton)]


def joint_columns(skeleton: SkeletonFormat = KINECT_V2) -> list[str]:
    """``<Joint>_x, <Joint>_y, <Joint>_z, <Joint>_state`` for each joint of ``skeleton``
    in the format's order (the Kinect v2's: the SDK's
    :class:`~qpavoid.human.kinect_v2.JointType`)."""
    return [f"{joint}_{field}" for joint in skeleton.joints for field in CSV_JOINT_FIELDS]


def csv_format(header: Sequence[str]) -> SkeletonFormat:
    """The skeleton format whose joint columns a CSV header names: of the formats the
    library has, the one the most of whose columns it holds (its reader then says what
    else is wrong with the header, as for a Kinect v2 file); the Kinect v2's if it holds
    none (the reader refuses the header, naming the formats)."""
    cells = set(header)
    best, most = KINECT_V2, 0
    for fmt in known_formats().values():
        found = len(cells.intersection(joint_columns(fmt)))
        if found > most:
            best, most = fmt, found
    return best


def read_csv_format(path: Path) -> SkeletonFormat:
    """:func:`csv_format` of the CSV file's first row (the Kinect v2's for a file that is
    not text or has no row: its reader says what it is). Opens no file over its size
    bound."""
    check_file_size(path, "csv")
    if _file_kind(path) != "text":
        return KINECT_V2
    with path.open("r", encoding="utf-8-sig", errors="replace", newline="") as handle:
        try:
            return csv_format([cell.strip() for cell in next(csv.reader(handle), [])])
        except csv.Error:  # a field over the csv module's limit: the reader says so
            return KINECT_V2


def npz_format(arrays: Mapping[str, np.ndarray]) -> SkeletonFormat:
    """The skeleton format an NPZ recording names in its optional ``format`` array (a
    string; none: the Kinect v2's, as every file before formats were data).

    Raises
    ------
    RecordingError
        For a ``format`` that is not one string naming a format the library has.
    """
    if "format" not in arrays:
        return known_formats()[DEFAULT_FORMAT]
    value = np.asarray(arrays["format"])
    name = str(value.reshape(-1)[0]) if value.dtype.kind == "U" and value.size == 1 else None
    if name is None or name not in known_formats():
        shown = str(value.tolist())[:80]
        raise RecordingError(
            f"array 'format' must be one string naming a skeleton format "
            f"({', '.join(known_formats())}), got {shown}",
            name="format",
            value=shown,
        )
    return known_formats()[name]


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
        raise RecordingError(
            f"{str(path)!r} is not a regular file (expected a {what} file)", path=path
        )
    try:
        return reader(path)
    except InputError as exc:  # bad content (RecordingError included): name the file
        tail = f"; {hint}" if hint else ""
        raise RecordingError(
            f"{path}: {exc}{tail}", path=path, name=exc.name, value=exc.value
        ) from exc
    except OSError as exc:  # permission denied, vanished, a special file...
        raise RecordingError(
            f"{path}: cannot read the {what} file ({exc.strerror or one_line(exc)})", path=path
        ) from exc


def read_by_suffix(path: str | Path, readers: Mapping[str, Callable[[Path], T]], what: str) -> T:
    """``path`` read by the reader of its suffix (``.npz``, ``.csv``; any letter case)
    through :func:`read_file`; an unknown suffix is a :class:`RecordingError`."""
    path = Path(path)
    reader = readers.get(path.suffix.lower())
    if reader is None:
        raise RecordingError(
            f"unknown recording format {path.suffix!r} for {str(path)!r}: "
            f"expected a {' or '.join(readers)} file",
            path=path,
        )
    return read_file(path, reader, what, f"see {FORMATS_DOC}")


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
    try:  # a multi-byte character may be cut at the end: not final
        codecs.getincrementaldecoder("utf-8")().decode(head, final=False)
    except UnicodeDecodeError:
        return "binary"
    return "binary" if b"\x00" in head else "text"


#: How :func:`_file_kind`'s answers read in messages.
_KIND_TEXT = {
    "empty": "the file is empty",
    "zip": "it is a ZIP archive",
    "npy": "it is a single .npy array",
    "text": "it is a text file",
    "binary": "it is binary data",
}


def read_npz(
    path: Path,
    names: Sequence[str] | None,
    expected: str,
    skeleton: SkeletonFormat = KINECT_V2,
    formatted: bool = False,
) -> dict[str, np.ndarray]:
    """Arrays of an NPZ file by name (``names``, or all if None); no pickled objects.

    The file's size, the archive's declared size and every array's ``.npy`` header are
    checked (:func:`~qpavoid.core.file_bounds.check_npy_headers`, rows as wide as frames
    of ``skeleton``'s joints) before any array is read. ``formatted``: the file's optional
    ``format`` array is read first, and returned; the rows are as wide as frames of the
    format it names (:func:`npz_format`), ``skeleton`` is not used.

    Raises
    ------
    RecordingError
        Without the path (:func:`read_file` adds it): the file is too large or not an NPZ
        archive, an array is missing, too large, holds Python objects or cannot be read.
        ``expected`` (what the file should be) ends format messages.
    """
    check_file_size(path, "npz")
    kind = _file_kind(path)
    if kind != "zip":
        raise RecordingError(f"not a readable NPZ archive ({_KIND_TEXT[kind]}); {expected}")
    try:
        with path.open("rb") as handle, zipfile.ZipFile(handle) as archive:
            members = archive.namelist()
            found = list(dict.fromkeys(m[: -len(".npy")] for m in members if m.endswith(".npy")))
            if not found:
                others = ", ".join(members[:5]) or "none"
                raise RecordingError(
                    f"not a readable NPZ archive (a ZIP archive without .npy "
                    f"arrays; members: {others}); {expected}"
                )
            missing = [name for name in names or () if name not in found]
            if missing:
                raise RecordingError(
                    f"NPZ file has no array {', '.join(map(repr, missing))} (found: "
                    f"{', '.join(map(repr, found))}); {expected}",
                    name=missing[0],
                )
            wanted = list(names or found)
            arrays = {}
            if formatted:
                if "format" in found:
                    check_npy_headers(archive, ["format"], expected, KINECT_V2.n_joints)
                    with archive.open("format.npy") as member:
                        arrays["format"] = npy_format.read_array(member, allow_pickle=False)
                skeleton = npz_format(arrays)
                wanted = [name for name in wanted if name != "format"]
            check_npy_headers(archive, wanted, expected, skeleton.n_joints)
            for name in wanted:
                with archive.open(f"{name}.npy") as member:
                    arrays[name] = npy_format.read_array(member, allow_pickle=False)
            return arrays
    except RecordingError:
        raise
    except Exception as exc:  # zipfile, zlib, numpy's format parser: a damaged file
        raise RecordingError(
            f"not a readable NPZ archive (damaged: {one_line(exc)}); {expected}"
        ) from exc


def read_csv_table(path: Path, names: list[str], expected: str) -> np.ndarray:
    """The numbers of a CSV file whose header is exactly ``names``: (rows, len(names)).

    Raises
    ------
    RecordingError
        Without the path (:func:`read_file` adds it): not UTF-8 text, a wrong header, a
        short row or a cell that is not a number. ``expected`` ends format messages.
    """
    return read_csv_columns(path, names, expected)[0]


def read_csv_columns(
    path: Path, names: list[str], expected: str, text: Sequence[str] = ()
) -> tuple[np.ndarray, dict[str, list[str]]]:
    """:func:`read_csv_table` where the columns named in ``text`` hold words, not numbers.

    Returns the numbers (rows, len(names)), NaN in the text columns, and each text
    column's cells (stripped) by name.
    """
    check_file_size(path, "csv")
    kind = _file_kind(path)
    if kind != "text":
        raise RecordingError(f"not a CSV text file ({_KIND_TEXT[kind]}); {expected}")
    try:
        with path.open("r", encoding="utf-8-sig", newline="") as handle:
            rows = csv.reader(handle)
            _check_csv_header(next(rows, None), names)
            text_at = [names.index(name) for name in text]
            words: dict[str, list[str]] = {name: [] for name in text}
            values = []
            for line, row in enumerate(rows, start=2):
                if not any(cell.strip() for cell in row):
                    continue
                if text_at and len(row) == len(names):
                    for name, i in zip(text, text_at, strict=True):
                        words[name].append(row[i].strip())
                        row = [*row[:i], "nan", *row[i + 1 :]]
                values.append(_parse_csv_row(row, line, names))
    except UnicodeDecodeError as exc:  # past the first 4 kB that _file_kind looked at
        raise RecordingError(
            f"not a CSV text file (invalid UTF-8: {one_line(exc)}); {expected}"
        ) from exc
    except csv.Error as exc:  # a NUL byte, a field too long...
        raise RecordingError(f"not a readable CSV file ({one_line(exc)}); {expected}") from exc
    return np.array(values, dtype=float).reshape(len(values), len(names)), words


def _check_csv_header(header: list[str] | None, expected: list[str]) -> None:
    """Raise RecordingError unless ``header`` is exactly ``expected``."""
    if header is None:
        raise RecordingError(f"the CSV file has no header row; {CSV_EXPECTED}", name="header")
    found = [cell.strip() for cell in header]
    if found == expected:
        return

    def fail(problem: str) -> RecordingError:
        return RecordingError(f"CSV header {problem}", name="header", value=found)

    missing = [name for name in expected if name not in found]
    joints = [name for name in expected if name.rpartition("_")[2] in CSV_JOINT_FIELDS]
    if len(missing) == len(expected) or (joints and set(joints) <= set(missing)):
        shown = ",".join(found[:3]) + (",..." if len(found) > 3 else "")
        count = f"{len(found)} column" + ("s" if len(found) != 1 else "")
        raise fail(
            f"not found: the first row is {shown!r} ({count}), the joints of no skeleton "
            f"format ({', '.join(known_formats())}); {CSV_EXPECTED}"
        )
    if missing:
        more = len(missing) - 5
        shown = ", ".join(missing[:5]) + (f" and {more} more" if more > 0 else "")
        raise fail(f"is missing column(s) {shown}")
    unknown = [name for name in found if name not in expected]
    if unknown:
        raise fail(f"has unknown column(s) {', '.join(map(repr, unknown))}")
    for i, (got, want) in enumerate(zip(found, expected, strict=False)):
        if got != want:
            raise fail(
                f"column {i} is {got!r}, expected {want!r} (columns must be t then "
                "<Joint>_x,_y,_z,_state in JointType order)"
            )
    raise fail(f"has {len(found)} columns, expected {len(expected)} (a column is repeated)")


def _parse_csv_row(row: list[str], line: int, names: list[str]) -> list[float]:
    """Floats of one CSV data row; ``line`` is its 1-based line number for messages."""
    if len(row) != len(names):
        raise RecordingError(
            f"CSV line {line} has {len(row)} values, expected {len(names)}", name="line", value=line
        )
    try:
        if any("_" in cell for cell in row):  # float() takes 1_000; a CSV cell may not
            raise ValueError
        return [float(cell) for cell in row]
    except ValueError:
        col = next(i for i, cell in enumerate(row) if not _is_float(cell))
        raise RecordingError(
            f"CSV line {line}, column {names[col]!r}: {row[col]!r} is not a number",
            name=names[col],
            value=row[col],
        ) from None


def _is_float(text: str) -> bool:
    """True if ``float(text)`` succeeds."""
    try:
        float(text)
    except ValueError:
        return False
    return "_" not in text


def recording_format(path: str | Path) -> SkeletonFormat:
    """The skeleton format of the recording at ``path`` (NPZ: its ``format`` array; CSV:
    its header's joint columns), without reading its frames: a file of one person or of
    several, base-frame or per sensor.

    Raises
    ------
    RecordingError
        For a file that cannot be read, an unknown suffix or a ``format`` array naming no
        format.
    """
    return read_by_suffix(
        path,
        {
            ".npz": lambda p: npz_format(read_npz(p, ["t"], "a recording", formatted=True)),
            ".csv": read_csv_format,
        },
        "recording",
    )
