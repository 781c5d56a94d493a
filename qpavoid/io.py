"""Writing a run to disk: ``metrics.json`` and ``log.npz`` (the figures: :mod:`qpavoid.plots`).

``log.npz`` holds the per-tick arrays of :func:`qpavoid.simulation.simulate` (row k is
the state at ``t[k]`` and the command computed from it). ``metrics.json`` holds the
run's summary (:func:`qpavoid.simulation.run_metrics`). Recorded human motion is read by
:mod:`qpavoid.recording`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .recording import Recording, load_recording, save_csv, save_npz
from .simulation import SimResult

__all__ = ["LOG_KEYS", "Recording", "load_log", "load_recording", "save_csv", "save_npz",
           "write_run"]

#: The arrays every ``log.npz`` contains.
LOG_KEYS = ("t", "q", "dq", "joints", "state", "stopped", "f", "distance", "v_rep_L2",
            "v_rep_EE", "ee_pos", "ee_ref")


def write_run(out_dir: str | Path, result: SimResult, extra: dict | None = None) -> Path:
    """Write ``metrics.json`` (with ``extra`` merged in) and ``log.npz`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    metrics = dict(result.metrics)
    metrics.update(extra or {})
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    np.savez_compressed(out / "log.npz", **result.log)
    return out


def load_log(path: str | Path) -> dict[str, np.ndarray]:
    """The arrays of a ``log.npz`` (a run directory or the file itself)."""
    p = Path(path)
    if p.is_dir():
        p = p / "log.npz"
    with np.load(p) as data:
        return {k: data[k] for k in data.files}
