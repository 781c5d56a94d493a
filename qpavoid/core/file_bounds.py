"""Files bounded before they are read (a security review: a 52 MB compressed NPZ declaring
a 12 GB array made numpy ask for 11.2 GiB before any check; ``--sensors /dev/zero`` read
until the memory ran out): :func:`read_bounded` reads a small regular file (the
calibration, a key) whole on one descriptor;
:func:`check_file_size` refuses a file over :data:`MAX_NPZ_FILE_BYTES` or
:data:`MAX_CSV_BYTES` unopened, and :func:`check_npy_headers` an NPZ whose members declare
more than :data:`MAX_NPZ_BYTES` in all, or an array whose ``.npy`` header (read with
numpy's own header readers) declares Python objects, more values than :data:`MAX_ROWS` rows
of its columns (:func:`row_values`, for frames of the skeleton format's joints, which the
caller gives: this layer knows no skeleton), or a size its member does not hold.
"""

from __future__ import annotations

import math
import os
import stat
import sys
import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import MappingProxyType
from typing import Literal

import numpy as np
from numpy.lib import format as npy_format

from qpavoid.core.errors import RecordingError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = [
    "MAX_CSV_BYTES",
    "MAX_NPZ_BYTES",
    "MAX_ROWS",
    "NotTOMLError",
    "check_file_size",
    "check_npy_headers",
    "read_bounded",
    "read_toml",
    "row_values",
]


#: Most rows an array of an NPZ file may have. A recording of an hour at 120 Hz (four
#: times a Kinect v2's 30 Hz, room for several sensors) of six bodies (a Kinect v2's most)
#: has 2 592 000 rows; a run log has one row per control tick (an hour at 500 Hz is
#: 1 800 000). Rounded up.
MAX_ROWS = 3_000_000


def row_values(n_joints: int) -> Mapping[str, int]:
    """Values per row of the arrays of recordings (base-frame, per-sensor, fused) and run
    logs, by name, for frames of ``n_joints`` joints: such an array may declare at most
    :data:`MAX_ROWS` times as many values. Any other array (a run log's, or one a recording
    carries along) may have rows as wide as the widest of these, a frame's joints.

    Parameters
    ----------
    n_joints
        Joints per frame of the files' skeleton format (25 for the Kinect v2).

    Returns
    -------
    Mapping of str to int
        ``t``, ``sensor``, ``body``: 1; ``joints``: ``3 n_joints``; ``state``,
        ``confidence``: ``n_joints``.
    """
    return MappingProxyType(
        {
            "t": 1,
            "sensor": 1,
            "body": 1,
            "joints": n_joints * 3,
            "state": n_joints,
            "confidence": n_joints,
        }
    )


#: Most bytes the members of one NPZ may declare in all, uncompressed: what reading it may
#: allocate, however well it compresses. ``MAX_ROWS`` rows of a fused Kinect v2 recording
#: take about 1 kB each (t and body 8 B, joints 600 B, state 25 B, confidence 200 B), 3 GB;
#: a run log of 1.8 M ticks about 1.5 GB.
MAX_NPZ_BYTES = 4 * 2**30

#: Most bytes an NPZ file may have on disk, checked before it is opened: ``np.savez``
#: stores its members uncompressed, so the members' bound plus room for the ZIP headers.
MAX_NPZ_FILE_BYTES = MAX_NPZ_BYTES + 2**20

#: Most bytes a CSV recording may have on disk, checked before it is read. A row is about
#: 1.6 kB of text (101 shortest float texts) and reading holds each value as a Python
#: float, about twice the text: an hour of one person at 120 Hz (432 000 rows, 0.7 GB)
#: fits; longer recordings, or several bodies, belong in NPZ.
MAX_CSV_BYTES = 2**30


#: Access bits that make a private file (a key) refused: any for the group or others (as
#: ssh does).
LOOSE_BITS = 0o077


def read_bounded(path: str | Path, max_bytes: int, *, private: bool = False) -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes``, checked before reading.

    The file is opened once and checked on that descriptor (no race between check and
    read): it must be a regular file (not a device such as ``/dev/zero``, a FIFO or a
    folder), of at most ``max_bytes``, and with ``private``, accessible to its owner only.

    Raises
    ------
    OSError
        If it cannot be opened or read.
    ValueError
        If it is not a regular file, too large, or (``private``) readable by others; the
        message says which.
    """
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):  # a folder, a device, a FIFO: never read
        os.close(fd)
        raise ValueError("not a regular file")
    with os.fdopen(fd, "rb") as handle:
        if info.st_size > max_bytes:
            raise ValueError(f"{info.st_size} bytes, more than the {max_bytes} allowed")
        if private and info.st_mode & LOOSE_BITS:
            raise ValueError(
                f"its mode {stat.S_IMODE(info.st_mode):04o} lets its group or others at it "
                f"(chmod 600 {path})"
            )
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:  # grew while we read
        raise ValueError(f"more than the {max_bytes} bytes allowed")
    return data


class NotTOMLError(ValueError):
    """A file that was read but is not TOML (its parser's message), or nests too deeply."""


def read_toml(path: str | Path, max_bytes: int, *, private: bool = False) -> dict:
    """The TOML file at ``path``, read as :func:`read_bounded` reads it, as a dict.

    The one reader of the package's TOML files (robot descriptions, skeleton formats,
    calibrations, keys); each caller turns the errors into its own, naming the file.

    Raises
    ------
    OSError
        If it cannot be opened or read.
    NotTOMLError
        If it is not TOML (a :class:`ValueError`; caught before the others).
    ValueError
        If it is not a regular file, too large, not private (``private``) or not UTF-8.
    """
    text = read_bounded(path, max_bytes, private=private).decode("utf-8")
    try:
        return tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise NotTOMLError(str(exc)) from None


def check_file_size(path: Path, fmt: Literal["npz", "csv"]) -> None:
    """Refuse the file at ``path`` if it is larger than its format allows, unopened.

    Parameters
    ----------
    path
        The file.
    fmt
        Its format: ``"npz"`` (at most :data:`MAX_NPZ_FILE_BYTES`) or ``"csv"`` (at most
        :data:`MAX_CSV_BYTES`).

    Raises
    ------
    RecordingError
        Without the path (the reader adds it); ``value`` is the size.
    """
    limit, what = (
        (MAX_CSV_BYTES, "a CSV recording") if fmt == "csv" else (MAX_NPZ_FILE_BYTES, "an NPZ file")
    )
    info = os.stat(path)  # a link is followed
    if not stat.S_ISREG(info.st_mode):  # a device such as /dev/zero, a FIFO: never read
        raise RecordingError(f"the file is not a regular file: {what} is read from a file")
    if info.st_size > limit:
        raise RecordingError(
            f"the file is {info.st_size:,} bytes, more than the {limit:,} bytes {what} may have",
            value=info.st_size,
        )


def check_npy_headers(
    archive: zipfile.ZipFile, names: Sequence[str], expected: str, n_joints: int
) -> None:
    """Check an NPZ archive's declared sizes and the headers of its arrays ``names``
    (members ``<name>.npy``), reading no array data: what every NPZ reader checks first.

    Parameters
    ----------
    archive
        The open NPZ archive.
    names
        The arrays that will be read.
    expected
        What the file should be, for format messages.
    n_joints
        Joints per frame of the file's skeleton format (the rows' widths,
        :func:`row_values`).

    Raises
    ------
    RecordingError
        Without the path: the members declare more than :data:`MAX_NPZ_BYTES` in all; or
        an array's member is not a ``.npy`` array, declares Python objects (an object
        dtype, or a structured one with object fields), more values than
        :data:`MAX_ROWS` rows of its columns (:func:`row_values`, else a frame's
        joints'), or a data size its member does not hold. ``name`` is the
        array at fault, ``value`` the shape it declares.
    ValueError, zipfile.BadZipFile
        From numpy's header readers and zipfile on a damaged archive (the reader says so).
    """
    total = sum(info.file_size for info in archive.infolist())
    if total > MAX_NPZ_BYTES:
        raise RecordingError(
            f"the NPZ archive's members declare {total:,} bytes uncompressed, more than "
            f"the {MAX_NPZ_BYTES:,} bytes an NPZ file may hold",
            value=total,
        )
    widths = row_values(n_joints)
    for name in names:
        info = archive.getinfo(f"{name}.npy")
        shape, dtype, data_at = _npy_header(archive, info, name, expected)
        what = f"array {name!r} (shape {shape}, dtype {dtype})"
        if dtype.hasobject:
            raise RecordingError(
                f"array {name!r} holds Python objects (pickled data, never loaded); {expected}",
                name=name,
                value=shape,
            )
        if any(n < 0 for n in shape):
            raise RecordingError(
                f"not a readable NPZ archive (damaged: {what} has a negative size); {expected}",
                name=name,
                value=shape,
            )
        per_row = widths.get(name, widths["joints"])
        limit = MAX_ROWS * per_row
        count = math.prod(shape)
        if count > limit or any(n > limit for n in shape):
            raise RecordingError(
                f"{what} declares {count:,} values, more than the {limit:,} allowed "
                f"({MAX_ROWS:,} rows of {per_row})",
                name=name,
                value=shape,
            )
        size = count * dtype.itemsize
        if data_at + size != info.file_size:
            raise RecordingError(
                f"not a readable NPZ archive (damaged: {what} declares {size:,} bytes of "
                f"data, its member holds {info.file_size - data_at:,}); {expected}",
                name=name,
                value=shape,
            )


def _npy_header(
    archive: zipfile.ZipFile, info: zipfile.ZipInfo, name: str, expected: str
) -> tuple[tuple[int, ...], np.dtype, int]:
    """Shape, dtype and data offset of member ``info`` (array ``name``), by numpy's own
    header readers; RecordingError if the member is not a ``.npy`` array."""
    with archive.open(info) as member:
        if member.read(len(npy_format.MAGIC_PREFIX)) != npy_format.MAGIC_PREFIX:
            raise RecordingError(
                f"member {info.filename!r} is not a .npy array; {expected}", name=name
            )
        member.seek(0)
        version = npy_format.read_magic(member)
        if version == (1, 0):
            shape, _, dtype = npy_format.read_array_header_1_0(member)
        elif version == (2, 0):
            shape, _, dtype = npy_format.read_array_header_2_0(member)
        else:
            raise RecordingError(
                f"array {name!r} is in .npy format version {version[0]}.{version[1]}, "
                f"expected 1.0 or 2.0; {expected}",
                name=name,
            )
        return tuple(shape), dtype, member.tell()
