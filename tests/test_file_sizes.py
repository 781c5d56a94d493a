"""Recording files are bounded before they are read (security review: "a 52 MB compressed
NPZ holding a 12 GB array asks for 11.2 GiB before any check").

Every NPZ reader (base-frame, per-sensor and fused recordings, run logs) checks the file's
size, the archive's declared size and each array's ``.npy`` header before reading any
array; a CSV recording's size is checked before it is read. The refusals are one-line
:class:`~qpavoid.core.errors.RecordingError` naming the file and the array, and allocate
nothing of the size declared.
"""

from __future__ import annotations

import io
import pickle
import subprocess
import tracemalloc
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from conftest import PYTHON
from numpy.lib import format as npy_format

from qpavoid.core import file_bounds
from qpavoid.core.checks import one_line
from qpavoid.core.errors import RecordingError
from qpavoid.fusion.offline import FusedRecording, load_people, save_fused_npz
from qpavoid.human.posture import Operator
from qpavoid.output.run_files import load_log
from qpavoid.sensing import recording_files
from qpavoid.sensing.per_sensor import (
    SensorRecording,
    is_sensor_recording,
    load_sensor_recording,
    save_sensor_csv,
    save_sensor_npz,
)
from qpavoid.sensing.recording import Recording, load_recording, save_csv, save_npz

#: Peak Python + numpy allocation allowed while a file is refused, bytes (numpy reports its
#: array buffers to tracemalloc: an array of the size declared would show).
REFUSAL_PEAK_BYTES = 4 * 2**20

#: The review's case: 20 M frames of 25 joints × 3 float64, 12 GB.
HUGE_JOINTS = (20_000_000, 25, 3)

HINT = "; see docs/formats.md"


def _npy(arr: np.ndarray) -> bytes:
    """``arr`` as a .npy file."""
    buf = io.BytesIO()
    npy_format.write_array(buf, arr, allow_pickle=False)
    return buf.getvalue()


def _header(shape: tuple[int, ...], dtype: str, version: tuple[int, int] = (1, 0)) -> bytes:
    """A .npy header declaring ``shape`` and ``dtype``, written by numpy, with no data."""
    buf = io.BytesIO()
    header = {
        "shape": shape,
        "fortran_order": False,
        "descr": npy_format.dtype_to_descr(np.dtype(dtype)),
    }
    if version == (1, 0):
        npy_format.write_array_header_1_0(buf, header)
    else:
        npy_format.write_array_header_2_0(buf, header)
    return buf.getvalue()


def _zip(path: Path, members: dict[str, bytes]) -> Path:
    """A deflated ZIP at ``path`` with ``members`` (name without .npy: bytes)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():
            archive.writestr(f"{name}.npy", data)
    return path


def _rest(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` frames of an operator at rest: t, joints, state."""
    joints = np.repeat(Operator().rest()[None], n, axis=0)
    return np.arange(n) / 30.0, joints, np.full((n, 25), 2, dtype=np.int8)


def _members(n: int = 3, **replace: bytes) -> dict[str, bytes]:
    """The .npy members of a valid per-sensor, fused-with-body recording of ``n`` frames
    (every loader finds its arrays), with ``replace`` substituted."""
    t, joints, state = _rest(n)
    members = {
        "t": _npy(t),
        "joints": _npy(joints),
        "state": _npy(state),
        "sensor": _npy(np.array("a")),
        "body": _npy(np.zeros(n, dtype=np.int64)),
    }
    return members | replace


#: Every NPZ reader of the library: (loader, the hint its messages end with).
LOADERS: dict[str, tuple[Callable[[Path], object], str]] = {
    "recording": (load_recording, HINT),
    "per-sensor": (load_sensor_recording, HINT),
    "fused": (load_people, HINT),
    "run log": (load_log, ""),
}


def _refusal(load: Callable[[Path], object], path: Path) -> tuple[RecordingError, int]:
    """The error ``load(path)`` raises and the peak allocation while it ran, bytes."""
    tracemalloc.start()
    try:
        with pytest.raises(RecordingError) as info:
            load(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert info.value.path == path
    return info.value, peak


@pytest.mark.parametrize("loader", sorted(LOADERS))
def test_a_header_declaring_a_huge_array_is_refused_without_allocating(tmp_path, loader):
    load, hint = LOADERS[loader]
    path = _zip(tmp_path / "big.npz", _members(joints=_header(HUGE_JOINTS, "<f8") + b"\0" * 64))
    assert path.stat().st_size < 10_000
    err, peak = _refusal(load, path)
    assert one_line(err) == (
        f"{path}: array 'joints' (shape (20000000, 25, 3), dtype float64) declares "
        f"1,500,000,000 values, more than the 225,000,000 allowed (3,000,000 rows of 75){hint}"
    )
    assert (err.name, err.value) == ("joints", HUGE_JOINTS)
    assert peak < REFUSAL_PEAK_BYTES


def test_tracemalloc_sees_numpy_arrays_read(tmp_path):
    """The control of the test above: reading an 8 MB array shows as 8 MB."""
    path = tmp_path / "log.npz"
    with path.open("wb") as handle:
        np.savez_compressed(handle, t=np.zeros(1_000_000))
    tracemalloc.start()
    try:
        assert load_log(path)["t"].nbytes == 8_000_000
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak >= 8_000_000


def test_a_compressed_array_over_a_lowered_row_bound_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(file_bounds, "MAX_ROWS", 1_000)
    path = tmp_path / "long.npz"
    with path.open("wb") as handle:  # zeros compress ~1000 times: 600 kB in a few kB
        np.savez_compressed(handle, t=np.arange(1_001.0), joints=np.zeros((1_001, 25, 3)))
    assert path.stat().st_size < 20_000
    err, peak = _refusal(load_log, path)
    assert one_line(err) == (
        f"{path}: array 't' (shape (1001,), dtype float64) declares 1,001 values, "
        "more than the 1,000 allowed (1,000 rows of 1)"
    )
    assert peak < REFUSAL_PEAK_BYTES
    with path.open("wb") as handle:  # the bound itself is allowed
        np.savez_compressed(handle, t=np.arange(1_000.0), joints=np.zeros((1_000, 25, 3)))
    assert load_log(path)["joints"].shape == (1_000, 25, 3)


def test_each_array_is_bounded_by_its_own_columns(tmp_path, monkeypatch):
    monkeypatch.setattr(file_bounds, "MAX_ROWS", 10)
    path = _zip(tmp_path / "wide.npz", _members(10, state=_npy(np.zeros((10, 26), np.int8))))
    with pytest.raises(RecordingError) as info:
        load_recording(path)
    assert one_line(info.value) == (
        f"{path}: array 'state' (shape (10, 26), dtype int8) declares 260 values, more than "
        f"the 250 allowed (10 rows of 25){HINT}"
    )
    extra = _npy(np.zeros((10, 76)))  # an array of no known format: a frame's 75 at most
    path = _zip(tmp_path / "extra.npz", _members(10, extra=extra))
    with pytest.raises(RecordingError, match=r"'extra' .* more than the 750 allowed"):
        load_people(path)
    assert load_recording(path).n_frames == 10  # not read: a recording ignores it


@pytest.mark.parametrize(
    "data, held",
    [(b"\0" * 10, 10), (_npy(np.zeros((100, 25, 3)))[128:] + b"\0", 60_001)],
    ids=["short", "long"],
)
def test_a_size_the_member_does_not_hold_is_refused(tmp_path, data, held):
    path = _zip(tmp_path / "lie.npz", _members(100, joints=_header((100, 25, 3), "<f8") + data))
    with pytest.raises(RecordingError) as info:
        load_recording(path)
    assert one_line(info.value) == (
        f"{path}: not a readable NPZ archive (damaged: array 'joints' (shape (100, 25, 3), "
        f"dtype float64) declares 60,000 bytes of data, its member holds {held:,}); "
        f"{recording_files.NPZ_EXPECTED}{HINT}"
    )
    assert info.value.name == "joints"


def test_a_negative_dimension_is_refused(tmp_path):
    path = _zip(tmp_path / "neg.npz", _members(joints=_header((-3, -25, 3), "<f8")))
    with pytest.raises(RecordingError, match=r"damaged: array 'joints' .* a negative size"):
        load_recording(path)


def test_npy_version_2_loads_and_3_is_refused(tmp_path):
    t = _rest(3)[0]
    v2 = _header((3,), "<f8", version=(2, 0)) + t.tobytes()
    path = _zip(tmp_path / "v2.npz", _members(t=v2))
    np.testing.assert_array_equal(load_recording(path).t, t)
    v3 = v2[:6] + b"\x03" + v2[7:]  # version 3.0 has version 2.0's layout
    path = _zip(tmp_path / "v3.npz", _members(t=v3))
    with pytest.raises(RecordingError, match=r"array 't' is in \.npy format version 3\.0"):
        load_recording(path)


def test_the_archives_declared_total_is_bounded(tmp_path, monkeypatch):
    monkeypatch.setattr(file_bounds, "MAX_NPZ_BYTES", 10_000)
    path = tmp_path / "total.npz"
    save_npz(path, Recording(*_rest(100)))  # 60 kB of joints
    err, _ = _refusal(load_recording, path)
    total = sum(i.file_size for i in zipfile.ZipFile(path).infolist())
    assert one_line(err) == (
        f"{path}: the NPZ archive's members declare {total:,} bytes uncompressed, more than "
        f"the 10,000 bytes an NPZ file may hold{HINT}"
    )


def test_the_file_size_is_bounded_before_it_is_opened(tmp_path, monkeypatch):
    monkeypatch.setattr(file_bounds, "MAX_NPZ_FILE_BYTES", 100)
    path = tmp_path / "notes.npz"
    path.write_text("x" * 101)  # not an archive: the size is what is checked first
    for load, hint in LOADERS.values():
        with pytest.raises(RecordingError) as info:
            load(path)
        assert one_line(info.value) == (
            f"{path}: the file is 101 bytes, more than the 100 bytes an NPZ file may have{hint}"
        )
        assert info.value.value == 101
    assert not is_sensor_recording(path)


@pytest.mark.parametrize(
    "name, arr",
    [
        ("t", np.array([0.0, "a"], dtype=object)),
        ("t", np.zeros(2, dtype=[("a", "<f8"), ("b", object)])),
        ("sensor", np.array(["a", None], dtype=object)),
    ],
    ids=["object", "void with objects", "sensor names"],
)
def test_python_objects_are_refused_from_the_header(tmp_path, monkeypatch, name, arr):
    def never(*args: object, **kwargs: object) -> object:
        raise AssertionError("unpickled")

    monkeypatch.setattr(pickle, "load", never)
    monkeypatch.setattr(pickle, "loads", never)
    buf = io.BytesIO()
    npy_format.write_array(buf, arr, allow_pickle=True)
    path = _zip(tmp_path / "objects.npz", _members(2, **{name: buf.getvalue()}))
    with pytest.raises(RecordingError) as info:
        load_sensor_recording(path)
    assert one_line(info.value) == (
        f"{path}: array {name!r} holds Python objects (pickled data, never loaded); "
        "expected a per-sensor NPZ recording: arrays t (N,), joints (N, 25, 3) in the camera "
        "frame, state (N, 25), sensor (a name, or N names) and optionally body (N,)" + HINT
    )
    assert (info.value.name, info.value.value) == (name, arr.shape)


def test_valid_recordings_still_load(tmp_path):
    t, joints, state = _rest(5)
    rec = Recording(t, joints, state)
    for path, save in ((tmp_path / "r.npz", save_npz), (tmp_path / "r.csv", save_csv)):
        save(path, rec)
        got = load_recording(path)
        np.testing.assert_array_equal(got.joints, joints)
        np.testing.assert_array_equal(got.state, state)
    compressed = tmp_path / "c.npz"
    with compressed.open("wb") as handle:
        np.savez_compressed(handle, t=t, joints=joints, state=state, notes=np.array("hi"))
    np.testing.assert_array_equal(load_recording(compressed).t, t)
    sensor = SensorRecording(["a"] * 5, t, np.arange(5) % 2, joints, state)
    for path, save in (
        (tmp_path / "s.npz", save_sensor_npz),
        (tmp_path / "s.csv", save_sensor_csv),
    ):
        save(path, sensor)
        assert is_sensor_recording(path)
        np.testing.assert_array_equal(load_sensor_recording(path).body, sensor.body)
    fused = FusedRecording(t, np.arange(5) % 2, joints, state, np.ones((5, 25)))
    save_fused_npz(tmp_path / "f.npz", fused)
    people = load_people(tmp_path / "f.npz")
    assert people is not None and sorted(people) == [0, 1]
    np.testing.assert_array_equal(people[1].t, t[1::2])


def test_an_oversize_csv_is_refused_unread(tmp_path, monkeypatch):
    monkeypatch.setattr(file_bounds, "MAX_CSV_BYTES", 1_000)
    path = tmp_path / "big.csv"
    path.write_bytes(bytes(range(256)) * 4)  # binary: refused for its size, unread
    base = tmp_path / "base.csv"
    save_csv(base, Recording(*_rest(2)))
    sensor = tmp_path / "sensor.csv"
    t, joints, state = _rest(2)
    save_sensor_csv(sensor, SensorRecording(["a", "a"], t, [0, 0], joints, state))
    for file, load in (
        (path, load_recording),
        (base, load_recording),
        (sensor, load_sensor_recording),
    ):
        size = file.stat().st_size
        with pytest.raises(RecordingError) as info:
            load(file)
        assert one_line(info.value) == (
            f"{file}: the file is {size:,} bytes, more than the 1,000 bytes a CSV recording "
            f"may have{HINT}"
        )
    assert not is_sensor_recording(sensor)  # not read: its loader says why


def test_the_command_line_refuses_a_huge_npz_and_writes_nothing(tmp_path):
    base = {k: v for k, v in _members().items() if k in ("t", "joints", "state")}
    _zip(tmp_path / "big.npz", base | {"joints": _header(HUGE_JOINTS, "<f8")})
    r = subprocess.run(
        [
            *PYTHON,
            "-m",
            "qpavoid",
            "run",
            "--human",
            "big.npz",
            "--no-plots",
            "--no-view",
            "--out",
            "out",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("qpavoid: error: "), r.stderr
    assert "big.npz" in lines[0] and "'joints'" in lines[0] and "(20000000, 25, 3)" in lines[0]
    assert "Traceback" not in r.stderr and r.stdout == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.npz"]


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_a_device_named_as_a_recording_is_refused_unread(tmp_path, suffix, capsys):
    """A review's case: a link to /dev/zero named .csv was read for ever (size 0 passed)."""
    from qpavoid.cli.commands import main

    link = tmp_path / f"zero{suffix}"
    link.symlink_to("/dev/zero")
    out = tmp_path / "out"
    assert main(["run", "--human", str(link), "--no-plots", "--no-view", "--out", str(out)]) == 2
    assert "not a regular file" in capsys.readouterr().err and not out.exists()
