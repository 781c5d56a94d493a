"""Fused recordings: per-sensor recordings merged offline into base-frame ones.

:func:`fuse_recordings` plays per-sensor recordings through a
:class:`~qpavoid.fusion.fuser.Fuser` in the order of their capture times (on the controller's
clock, after each sensor's ``time_offset_s``) and fuses at every capture time, as a live
cell would: each fused frame uses only frames captured by then. The result is a
:class:`FusedRecording`: one row per person per fused time, in the base frame, with a
per-joint ``confidence``; saved as NPZ (docs/formats.md): ``t``, ``joints``, ``state``,
``confidence`` (N, J) and, where several people are present, ``body`` (N,) (the
person's stable id). One person's rows are an ordinary base-frame recording. The rows
are the body's landmarks whatever the sensors' skeleton formats (a mixed cell's frames
are mapped onto them as they enter the fusion).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from qpavoid.core.errors import InputError, RecordingError
from qpavoid.fusion.fuser import Fuser, FusionConfig
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.per_sensor import SensorRecording
from qpavoid.sensing.recording import Recording
from qpavoid.sensing.recording_files import read_file, read_npz

__all__ = ["FusedRecording", "fuse_recordings", "load_people", "save_fused_npz"]


@dataclass(frozen=True, eq=False)
class FusedRecording:
    """Fused people over time: one row per person per fused time.

    Attributes
    ----------
    t
        (N,) fusion times, s (controller clock), non-decreasing.
    body
        (N,) the person's stable id.
    joints, state
        (N, J, 3) base-frame joints, m (NaN where no sensor saw the joint), and (N, J)
        tracking states.
    confidence
        (N, J) per-joint confidence in [0, 1].
    """

    t: np.ndarray
    body: np.ndarray
    joints: np.ndarray
    state: np.ndarray
    confidence: np.ndarray

    @property
    def ids(self) -> tuple[int, ...]:
        """The people's ids, in order of first appearance."""
        return tuple(int(b) for b in dict.fromkeys(self.body.tolist()))

    def people(self) -> dict[int, Recording]:
        """Each person's rows as a base-frame :class:`Recording`, by id."""
        out = {}
        for pid in self.ids:
            rows = self.body == pid
            out[pid] = Recording(self.t[rows], self.joints[rows], self.state[rows])
        return out


def fuse_recordings(
    recordings: Sequence[SensorRecording],
    calibration: Calibration,
    config: FusionConfig | None = None,
) -> FusedRecording:
    """Fuse per-sensor recordings (module docstring).

    Raises
    ------
    CalibrationError
        If a recording names a sensor that the calibration does not have, or holds frames
        of another skeleton format than its sensor's calibrated one (before any work).
    InputError
        If no person is ever seen.
    """
    for rec in recordings:
        calibration.check_names(rec.sensors)
        for sensor in rec.sensors:
            calibration.check_format(sensor, rec.format)
    fuser = Fuser(calibration, config)
    n = fuser.skeleton.n_joints
    frames = [f for rec in recordings for f in rec.frames()]
    clock = [f.t + calibration[f.sensor].time_offset_s for f in frames]
    order = np.argsort(clock, kind="stable")
    rows: list[tuple[float, int, np.ndarray, np.ndarray, np.ndarray]] = []
    k = 0
    while k < len(order):
        now = clock[order[k]]
        while k < len(order) and clock[order[k]] <= now:
            fuser.add(frames[order[k]])
            k += 1
        for person in fuser.fuse(now).people:
            rows.append((now, person.id, *person.frame, person.confidence))
    if not rows:
        raise InputError("no person was seen in the recordings", name="recordings")
    return FusedRecording(
        np.array([r[0] for r in rows]),
        np.array([r[1] for r in rows], dtype=np.int64),
        np.array([r[2] for r in rows]).reshape(-1, n, 3),
        np.array([r[3] for r in rows], dtype=np.int8).reshape(-1, n),
        np.array([r[4] for r in rows]).reshape(-1, n),
    )


def save_fused_npz(path: str | Path, fused: FusedRecording) -> None:
    """Write ``fused`` as NPZ: ``t``, ``joints``, ``state``, ``confidence``, and ``body``
    when several people are present."""
    arrays = {
        "t": fused.t,
        "joints": fused.joints,
        "state": fused.state,
        "confidence": fused.confidence,
    }
    if len(fused.ids) > 1:
        arrays["body"] = fused.body
    with Path(path).open("wb") as handle:
        np.savez(handle, **arrays)  # type: ignore[arg-type]  # numpy's stub: allow_pickle


def load_people(path: str | Path) -> dict[int, Recording] | None:
    """The people of a base-frame NPZ with a ``body`` array (a fused recording of several
    people), by id; None for a file without ``body`` (one person: use ``load_recording``).

    Raises
    ------
    RecordingError
        On an unreadable file or invalid content.
    """
    p = Path(path)
    if p.suffix.lower() != ".npz":
        return None

    def read(q: Path) -> dict[int, Recording] | None:
        arrays = read_npz(q, None, "expected a base-frame NPZ recording")
        if "body" not in arrays:
            return None
        for name in ("t", "joints", "state"):
            if name not in arrays:
                raise RecordingError(f"NPZ file has no array {name!r}", name=name)
        body = np.asarray(arrays["body"])
        if body.shape != np.shape(arrays["t"]):
            raise RecordingError(
                f"body must have one id per frame, shape {np.shape(arrays['t'])}, got {body.shape}",
                name="body",
                value=body,
            )
        out = {}
        for pid in dict.fromkeys(body.tolist()):
            rows = body == pid
            out[int(pid)] = Recording(
                arrays["t"][rows], arrays["joints"][rows], arrays["state"][rows]
            )
        return out

    return read_file(p, read, "recording", "see docs/formats.md")
