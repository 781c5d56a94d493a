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


def check_output_dir(path: str | Path) -> Path:
    """``path`` if it is a folder that can be written or created there; else :class:`InputError`.

    Nothing is left behind (a temporary folder is made and removed in the deepest existing
    folder, the one test that holds everywhere): the check runs before a job starts, so
    that a bad ``--out`` fails in a second, not after the simulation.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError(
            f"--out {str(out)!r} is a file, not a folder", name="--out", value=str(out)
        )
    probe = out
    while not probe.exists():  # the deepest folder that exists
        probe = probe.parent
    if not probe.is_dir():
        raise InputError(
            f"--out {str(out)!r}: {str(probe)!r} is a file, not a folder",
            name="--out",
            value=str(out),
        )
    try:  # os.access trusts permission bits; /proc, read-only mounts... only a try tells
        tempfile.TemporaryDirectory(prefix=".qpavoid-check.", dir=probe).cleanup()
    except OSError as exc:
        raise InputError(
            f"--out {str(out)!r}: cannot write in {str(probe)!r} "
            f"({exc.strerror or 'permission denied'})",
            name="--out",
            value=str(out),
        ) from None
    return out


@contextmanager
def staged_output(path: str | Path) -> Iterator[Path]:
    """Write a job's files into a staging folder; move them into ``path`` only on success.

    Yields the staging folder (beside ``path``, so the final move is a rename). If the
    ``with`` block raises, the staging folder is removed and ``path`` is left as it was.
    Files already in ``path`` with other names are kept; files of the same name are
    replaced.
    """
    out = check_output_dir(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        yield stage
        out.mkdir(exist_ok=True)
        for item in stage.iterdir():
            os.replace(item, out / item.name)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
