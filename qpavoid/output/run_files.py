"""Writing a run to disk: ``metrics.json`` and ``log.npz`` (the figures:
:mod:`qpavoid.output.plots`).

``log.npz`` holds the per-tick arrays of :func:`qpavoid.loop.simulation.simulate` (row k is
the state at ``t[k]`` and the command computed from it). ``metrics.json`` holds the
run's summary (:func:`qpavoid.loop.metrics.run_metrics`). Recorded human motion is read by
:mod:`qpavoid.sensing.recording`.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from qpavoid.core.errors import InputError
from qpavoid.core.signals import held
from qpavoid.loop.simulation import SimResult
from qpavoid.sensing.recording import (
    Recording,
    load_recording,
    read_file,
    read_npz,
    save_csv,
    save_npz,
)

__all__ = [
    "LOG_KEYS",
    "Recording",
    "check_output_dir",
    "check_output_file",
    "load_log",
    "load_recording",
    "save_csv",
    "save_npz",
    "staged_output",
    "strict_json",
    "write_run",
]

#: The arrays every ``log.npz`` of the bundled iiwa contains (another arm's repulsion
#: arrays are named after its sets: :func:`qpavoid.loop.run_log.repulsion_keys`).
LOG_KEYS = (
    "t",
    "q",
    "dq",
    "joints",
    "state",
    "stopped",
    "f",
    "distance",
    "v_rep_L2",
    "v_rep_EE",
    "ee_pos",
    "ee_ref",
)


def strict_json(value: Any, indent: int | None = 2) -> str:
    """``value`` as strict JSON (RFC 8259): every NaN or infinite number written as
    ``null`` (Python's ``json`` would write ``NaN`` and ``Infinity``, which strict parsers
    refuse); numpy scalars and arrays as numbers and lists. Every JSON file a run, a
    comparison or a campaign writes goes through it (docs/formats.md: null means "not
    measured", e.g. the distance to nobody, or no frame taken)."""
    return json.dumps(_finite(value), indent=indent, allow_nan=False)


def _finite(value: Any) -> Any:
    """``value`` with non-finite floats as None, tuples and arrays as lists."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, np.ndarray):
        return [_finite(v) for v in value.tolist()]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def write_run(out_dir: str | Path, result: SimResult, extra: dict | None = None) -> Path:
    """Write ``metrics.json`` (with ``extra`` merged in) and ``log.npz`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    metrics = dict(result.metrics)
    metrics.update(extra or {})
    (out / "metrics.json").write_text(strict_json(metrics) + "\n")
    arrays: dict[str, Any] = dict(result.log) | result.journal
    np.savez_compressed(out / "log.npz", **arrays)
    return out


def load_log(path: str | Path) -> dict[str, np.ndarray]:
    """The arrays of a ``log.npz`` (a run directory or the file itself).

    Raises
    ------
    RecordingError
        If the file is missing or is not an NPZ archive of numeric arrays.
    """
    p = Path(path)
    if p.is_dir():
        p = p / "log.npz"
    named = [k for k in LOG_KEYS if not k.startswith("v_rep_")]  # the iiwa's sets' names
    expected = (
        f"expected the log.npz of a run, with arrays {', '.join(named)} and v_rep_<set> "
        "of the repelled and end-effector sets"
    )
    return read_file(p, lambda f: read_npz(f, None, expected), "run log")


#: The prefix of the staging folders and write probes (short: a long ``--out`` name fits).
STAGE_PREFIX = ".qpavoid-"


def check_output_dir(path: str | Path) -> Path:
    """``path`` if it is a folder that can be written or created there; else :class:`InputError`.

    Nothing is left behind (a temporary folder is made and removed where
    :func:`staged_output` will stage: in ``path`` if it exists, else in the deepest
    existing folder, the one test that holds everywhere): the check runs before a job
    starts, so that a bad ``--out`` fails in a second, not after the simulation.
    """
    new: list[str]
    if str(path) == "":
        raise InputError("--out '' is empty: give a folder", name="--out", value="")
    out = Path(path)

    def refuse(why: str) -> InputError:
        return InputError(f"--out {str(out)!r}: {why}", name="--out", value=str(out))

    if out.exists() and not out.is_dir():
        raise refuse("is a file, not a folder")
    probe, new = out, []  # new: the names to create below probe
    while not probe.exists():  # the deepest folder that exists
        if probe.is_symlink():
            raise refuse(f"{str(probe)!r} is a symbolic link to nothing")
        probe, new = probe.parent, [probe.name, *new]
    if not probe.is_dir():
        raise refuse(f"{str(probe)!r} is a file, not a folder")
    try:  # os.access trusts permission bits; /proc, read-only mounts... only a try tells
        tempfile.TemporaryDirectory(prefix=STAGE_PREFIX, dir=probe).cleanup()
        longest = os.pathconf(probe, "PC_NAME_MAX")
    except OSError as exc:
        raise refuse(f"cannot write in {str(probe)!r} ({exc.strerror or 'denied'})") from None
    if any(len(os.fsencode(name)) > longest for name in new):
        raise refuse(f"a name longer than {longest} bytes")
    return out


def check_output_file(path: str, flag: str) -> Path:
    """``path`` if a regular file can be written there (tried now, left as it was); else
    :class:`InputError` naming ``flag``: so that a long job fails before it starts."""
    target = Path(path)

    def refuse(why: str) -> InputError:
        return InputError(f"{flag} {path!r}: {why}", name=flag, value=path)

    if not path:
        raise refuse("an empty path")
    if path.endswith(os.sep) or target.is_dir():
        raise refuse("a folder, not a file")
    if target.is_symlink() and not target.exists():
        raise refuse("a symbolic link to nothing")
    if target.exists() and not target.is_file():  # a FIFO would block, a device...
        raise refuse("not a regular file")
    existed = target.exists()
    try:
        with open(target, "a"):
            pass
        if not existed:
            target.unlink()
    except OSError as exc:
        raise refuse(f"cannot write this file ({exc.strerror or exc})") from None
    return target


@contextmanager
def staged_output(path: str | Path) -> Iterator[Path]:
    """Write a job's files into a staging folder; move them into ``path`` only on success.

    Yields the staging folder (in ``path`` if it exists, else beside it: so the final
    move is a rename). If the ``with`` block raises, the staging folder and any folder
    made for ``path`` are removed and ``path`` is left as it was. Files and folders
    already in ``path`` with other names are kept; those of the same name are replaced
    (a folder with its contents). The move is all or nothing: Ctrl-C and SIGTERM wait
    for its end, and the ``KeyboardInterrupt`` they raise then carries ``written = path``.
    """
    out = check_output_dir(path)
    made = [p for p in (out, *out.parents) if not p.exists()][::-1]  # outermost first
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        home = out if out.is_dir() else out.parent
        stage = Path(tempfile.mkdtemp(prefix=STAGE_PREFIX, dir=home))
    except BaseException:
        _remove_empty(made)
        raise
    try:
        yield stage
        try:
            with held():
                _move_in(stage, out)
        except KeyboardInterrupt as exc:  # after the move: the files are there
            exc.written = out  # type: ignore[attr-defined]
            raise
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        _remove_empty(made)  # those that stayed empty: all of them, unless the move ended
        raise


def _move_in(stage: Path, out: Path) -> None:
    """Move ``stage``'s items into ``out``: first every item of the same name out of the
    way (a folder with its files, a file a folder replaces), then the renames."""
    out.mkdir(exist_ok=True)
    items = list(stage.iterdir())
    old = stage / f"{STAGE_PREFIX}replaced"
    old.mkdir()
    for item in items:
        if os.path.lexists(out / item.name):
            os.replace(out / item.name, old / item.name)
    try:
        for item in items:
            os.replace(item, out / item.name)
    except BaseException:  # a rename failed (same file system: hardly ever): put back
        for item in old.iterdir():
            if not os.path.lexists(out / item.name):
                os.replace(item, out / item.name)
        raise
    shutil.rmtree(stage)


def _remove_empty(folders: list[Path]) -> None:
    """Remove the ``folders`` a job made (outermost first), where they stayed empty."""
    for folder in reversed(folders):
        with contextlib.suppress(OSError):
            folder.rmdir()
