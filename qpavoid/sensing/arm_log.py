"""The arm's log for a latency measurement: its joint angles over time, and the flange's path.

An arm log (:class:`ArmLog`) is the arm's active joints sampled on the clock the camera's
recording is stamped on: a run's ``log.npz``, an NPZ or CSV file (:func:`read_arm_log`,
:func:`save_arm_log`). The flange's path follows from it by the arm's forward kinematics
(:func:`flange_positions`); :mod:`qpavoid.sensing.latency` aligns the hand a camera filmed
on the flange with it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.core.checks import as_array
from qpavoid.core.errors import InputError, RecordingError
from qpavoid.sensing.recording_files import read_by_suffix, read_csv_table, read_npz

__all__ = ["ArmLog", "flange_positions", "increasing_times", "read_arm_log", "save_arm_log"]


@dataclass(frozen=True, eq=False)
class ArmLog:
    """The arm's joint angles over time: ``t`` (M,) strictly increasing, s; ``q`` (M, nq),
    rad, the description's active joints (a run's ``log.npz`` has both). Checked, copied
    and read-only.

    Raises
    ------
    InputError
        For times that are not finite and strictly increasing, or joint angles that are
        not (M, nq) finite numbers (``nq`` from ``q`` itself: :func:`read_arm_log` checks
        it against the arm).
    """

    t: np.ndarray
    q: np.ndarray

    def __post_init__(self) -> None:
        t = increasing_times(self.t, "t (arm log times, s)")
        q = np.asarray(self.q)
        q = as_array(q, (t.size, q.shape[-1] if q.ndim == 2 else None), "q (joint angles, rad)")
        for name, arr in (("t", t), ("q", q)):
            arr = np.array(arr, copy=True)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)


#: What an arm log file must be, for error messages.
_ARM_LOG_EXPECTED = (
    "expected an arm log: NPZ arrays t (M,) s and q (M, nq) rad (a run's log.npz), or a CSV "
    "file whose header is t then the robot's active joints"
)


def read_arm_log(path: str | Path, robot: Robot) -> ArmLog:
    """Read an arm log (NPZ or CSV, by suffix) of ``robot``'s active joints.

    * NPZ: ``t`` (M,) s and ``q`` (M, nq) rad (other arrays ignored: a run's ``log.npz``);
      an optional ``joint_names`` (nq,) must be ``robot.joint_names``.
    * CSV: the header ``t,<joint>,...`` with ``robot.joint_names`` in order, then one row a
      sample.

    Raises
    ------
    RecordingError
        One line naming the file, the array or column at fault and its value: a missing or
        unreadable file, a wrong header, ``q`` of another width than the arm's joints,
        times that do not increase.
    """

    def npz(file: Path) -> ArmLog:
        arrays = read_npz(file, None, _ARM_LOG_EXPECTED)
        missing = [k for k in ("t", "q") if k not in arrays]
        if missing:
            raise RecordingError(
                f"NPZ file has no array {missing[0]!r}; {_ARM_LOG_EXPECTED}", name=missing[0]
            )
        names = arrays.get("joint_names")
        if names is not None and tuple(np.asarray(names).astype(str)) != robot.joint_names:
            raise RecordingError(
                f"joint_names are {', '.join(np.asarray(names).astype(str))}, not the joints "
                f"of {robot.name} ({', '.join(robot.joint_names)}): a log of another arm",
                name="joint_names",
                value=tuple(np.asarray(names).astype(str)),
            )
        return _checked_log(arrays["t"], arrays["q"], robot)

    def csv(file: Path) -> ArmLog:
        names = ["t", *robot.joint_names]
        try:
            data = read_csv_table(file, names, _ARM_LOG_EXPECTED)
        except RecordingError as exc:
            if exc.name != "header":
                raise
            found = exc.value if isinstance(exc.value, list) else []
            raise RecordingError(
                f"CSV header must be {','.join(names)} (t, then the active joints of "
                f"{robot.name} in order), got {','.join(found)[:200]!r}",
                name="header",
                value=found,
            ) from None
        return _checked_log(data[:, 0], data[:, 1:], robot)

    return read_by_suffix(path, {".npz": npz, ".csv": csv}, "arm log")


def _checked_log(t: np.ndarray, q: np.ndarray, robot: Robot) -> ArmLog:
    """An :class:`ArmLog` whose ``q`` has ``robot``'s active joints."""
    width = np.shape(q)[-1] if np.ndim(q) == 2 else None
    if width != robot.nq:
        raise InputError(
            f"q has shape {np.shape(q)}: expected (M, {robot.nq}), the active joints of "
            f"{robot.name} ({', '.join(robot.joint_names)}); a log of another arm, or of a "
            "run with --redundant?",
            name="q",
            value=np.shape(q),
        )
    return ArmLog(t, q)


def save_arm_log(path: str | Path, log: ArmLog, robot: Robot) -> None:
    """Write ``log`` as an NPZ arm log: ``t``, ``q`` and ``joint_names`` (the arm's active
    joints, which :func:`read_arm_log` checks)."""
    if log.q.shape[1] != robot.nq:
        raise InputError(
            f"q has {log.q.shape[1]} joints, {robot.name} {robot.nq}",
            name="q",
            value=log.q.shape,
        )
    with Path(path).open("wb") as handle:
        np.savez(handle, t=log.t, q=log.q, joint_names=np.array(robot.joint_names))


def flange_positions(robot: Robot, q: np.ndarray) -> np.ndarray:
    """(M, 3) the end-effector frame's origin at each row of ``q`` (M, nq), base frame, m
    (Pinocchio's forward kinematics: :meth:`~qpavoid.arm.model.Robot.end_effector`)."""
    return np.array([robot.end_effector(row)[:3, 3] for row in np.asarray(q, dtype=float)])


def increasing_times(t: object, label: str, least: int = 2) -> np.ndarray:
    """``t`` as (N,) finite floats, N >= ``least``, strictly increasing; else
    :class:`InputError` naming ``label`` and the first sample that does not increase."""
    arr = as_array(t, (None,), label)
    name = label.split(" (", 1)[0]
    if arr.size < least:
        raise InputError(
            f"{label} has {arr.size} sample(s): at least {least}", name=name, value=arr
        )
    steps = np.flatnonzero(np.diff(arr) <= 0)
    if steps.size:
        i = int(steps[0]) + 1
        raise InputError(
            f"{label} must increase strictly: [{i}] = {float(arr[i])!r} is not after "
            f"[{i - 1}] = {float(arr[i - 1])!r}",
            name=name,
            value=arr,
        )
    return arr
