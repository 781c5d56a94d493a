"""Writing a run to disk: ``metrics.json`` and ``log.npz`` (the figures: :mod:`qpavoid.plots`).

``log.npz`` holds the per-tick arrays of :func:`qpavoid.simulation.simulate` (row k is
the state at ``t[k]`` and the command computed from it). ``metrics.json`` holds the
run's summary (:func:`qpavoid.metrics.run_metrics`). Recorded human motion is read by
:mod:`qpavoid.recording`.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError
from .recording import Recording, load_recording, read_file, read_npz, save_csv, save_npz
from .simulation import SimResult

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
    "write_run",
]

#: The arrays every ``log.npz`` contains.
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


def write_run(out_dir: str | Path, result: SimResult, extra: dict | None = None) -> Path:
    """Write ``metrics.json`` (with ``extra`` merged in) and ``log.npz`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    metrics = dict(result.metrics)
    metrics.update(extra or {})
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    arrays: dict[str, Any] = dict(result.log)
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
    expected = f"expected the log.npz of a run, with arrays {', '.join(LOG_KEYS)}"
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
    """``path`` if a file can be written there (tried now, left as it was); else
    :class:`InputError` naming ``flag``: so that a long job fails before it starts."""
    target = Path(path)
    existed = target.exists()
    try:
        if not path or target.is_dir():
            raise IsADirectoryError(0, "a folder, not a file")
        with open(target, "a"):
            pass
        if not existed:
            target.unlink()
    except OSError as exc:
        raise InputError(
            f"{flag} {path!r}: cannot write this file ({exc.strerror or exc})",
            name=flag,
            value=path,
        ) from None
    return target


@contextmanager
def staged_output(path: str | Path) -> Iterator[Path]:
    """Write a job's files into a staging folder; move them into ``path`` only on success.

    Yields the staging folder (in ``path`` if it exists, else beside it: so the final
    move is a rename). If the ``with`` block raises, the staging folder is removed and
    ``path`` is left as it was. Files and folders already in ``path`` with other names
    are kept; those of the same name are replaced (a folder with its contents).
    """
    out = check_output_dir(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    home = out if out.is_dir() else out.parent
    stage = Path(tempfile.mkdtemp(prefix=STAGE_PREFIX, dir=home))
    old = stage / f"{STAGE_PREFIX}replaced"  # what the new files replace, removed with it
    try:
        yield stage
        out.mkdir(exist_ok=True)
        items = [item for item in stage.iterdir() if item != old]
        old.mkdir()
        for item in items:  # first every replaced folder out of the way, then the renames
            if (out / item.name).is_dir() and not (out / item.name).is_symlink():
                os.replace(out / item.name, old / item.name)
        for item in items:
            os.replace(item, out / item.name)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
