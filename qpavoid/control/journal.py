"""What a controller was handed, call by call, and the commands it gives when handed it again.

A live run cannot be run again (the arm, the cameras and the wall clock are gone), but its
controller reads no clock: its commands are a function of what it was handed. A
:class:`Journal` keeps that, in order:

=========== ================================================================================
entry       what it holds
=========== ================================================================================
``frame``   a frame the next ticks are handed (kept once, however many ticks hold it): each
            person's id, lag behind the newest capture (s) and joints (J, 3) with states
``step``    a tick: the frame's index, the path clock τ, the frame's age and capture time,
            its id, the joint angles q
``brake``   a stop decided outside the controller (a missed deadline, the end of a run);
            whether it replaced the tick's command
``rest``    the arm came to rest on its own (its hold of a command ran out)
``limits``  the arm's interface limits (velocity, acceleration, jerk), tighter than the
            description's
``logged``  the tick's command is the controller's last (row k of the run's log)
=========== ================================================================================

Each entry is one float64 vector (its kind's code first), so the journal is stored as one
array and its offsets (``log.npz``: ``journal_data``, ``journal_offsets``) and as one
``std_msgs/Float64MultiArray`` per entry in a run's bag (``/qpavoid/journal``).
:func:`reproduce` hands a fresh controller built the same way the same entries and
returns the command of each logged tick: a run's own commands, to the last bit on the
same machine (QP warm starts included), which the ROS 2 cell's test checks within
1e-9 rad/s.
"""

from __future__ import annotations

import itertools
from collections.abc import Hashable, Iterator, Sequence
from typing import Any, Protocol

import numpy as np

from qpavoid.core.errors import InputError
from qpavoid.human.frames import HumanFrame
from qpavoid.human.people import People

__all__ = ["KINDS", "Journal", "reproduce"]

#: Each entry's code (its vector's first element).
KINDS = {"frame": 1.0, "step": 2.0, "brake": 3.0, "rest": 4.0, "limits": 5.0, "logged": 6.0}
_NAMES = {code: name for name, code in KINDS.items()}


class Journal:
    """What a controller is handed, appended call by call (module docstring).

    Attributes
    ----------
    entries
        The entries so far, each a float64 vector.
    unsupported
        Why the journal cannot reproduce the run ("" while it can): a frame id that is
        neither an integer nor None, a call with its own tracking states or format.
    """

    def __init__(self) -> None:
        self.entries: list[np.ndarray] = []
        self.unsupported = ""
        self._frame: object = None  # the frame last kept (by identity)
        self._frames = 0

    def step(
        self,
        q: np.ndarray,
        joints: object,
        tau: float,
        frame_age_s: float | None,
        frame_time_s: float | None,
        frame_id: Hashable | None,
    ) -> None:
        """A tick handed ``joints`` (a :class:`HumanFrame` or :class:`People`)."""
        if frame_id is not None and not isinstance(frame_id, (int, np.integer)):
            self.unsupported = f"a frame id of type {type(frame_id).__name__}"
        if joints is not self._frame:
            if not _same(joints, self._frame):  # a live source hands a new object a tick
                self.entries.append(_frame_entry(joints))
                self._frames += 1
            self._frame = joints
        q = np.asarray(q, dtype=float)
        entry = np.empty(6 + len(q))  # filled in place: np.r_ costs 3.5 times more
        entry[0], entry[1], entry[2] = KINDS["step"], self._frames - 1, tau
        entry[3] = np.nan if frame_age_s is None else frame_age_s
        entry[4] = np.nan if frame_time_s is None else frame_time_s
        entry[5] = float(frame_id) if isinstance(frame_id, (int, np.integer)) else np.nan
        entry[6:] = q
        self.entries.append(entry)

    def brake(self, instead: bool) -> None:
        self.entries.append(np.array([KINDS["brake"], float(instead)]))

    def rest(self) -> None:
        self.entries.append(np.array([KINDS["rest"]]))

    def limits(self, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray) -> None:
        self.entries.append(np.r_[KINDS["limits"], velocity, acceleration, jerk])

    def logged(self) -> None:
        self.entries.append(np.array([KINDS["logged"]]))

    def arrays(self) -> dict[str, np.ndarray]:
        """``journal_data`` (all entries end to end) and ``journal_offsets`` (C + 1,)."""
        sizes = [len(e) for e in self.entries]
        data = np.concatenate(self.entries) if self.entries else np.zeros(0)
        return {"journal_data": data, "journal_offsets": np.r_[0, np.cumsum(sizes)]}

    @staticmethod
    def split(data: np.ndarray, offsets: np.ndarray) -> list[np.ndarray]:
        """The entries of :meth:`arrays`' two arrays."""
        return [data[a:b] for a, b in itertools.pairwise(offsets)]


class Replayable(Protocol):
    """What :func:`reproduce` calls (a :class:`~qpavoid.control.controller.Controller`)."""

    robot: Any

    @property
    def last_command(self) -> Any: ...

    def step(self, q: np.ndarray, joints: object, state: object, t: float, *args: Any) -> Any: ...

    def brake(self, reason: str, instead: bool = False) -> Any: ...

    def at_rest(self) -> None: ...

    def accept_limits(self, v: np.ndarray, a: np.ndarray, j: np.ndarray) -> None: ...


def _same(a: object, b: object) -> bool:
    """``a`` and ``b`` are the same frame: both People (or both HumanFrame) with equal
    ids, lags, joints (NaN equal to NaN) and states."""
    if isinstance(a, People) and isinstance(b, People):
        if a.ids != b.ids or a.lag_s != b.lag_s:
            return False
        pairs = list(zip(a.frames, b.frames, strict=True))
    elif isinstance(a, HumanFrame) and isinstance(b, HumanFrame):
        pairs = [(a, b)]
    else:
        return False
    return all(
        np.array_equal(f.joints, g.joints, equal_nan=True) and np.array_equal(f.state, g.state)
        for f, g in pairs
    )


def _frame_entry(joints: object) -> np.ndarray:
    """``[1, is_people, persons, J, (id, lag, J × (x, y, z, state)) per person]``; lag NaN
    where the frame gives none."""
    if isinstance(joints, People):
        people, is_people = joints, 1.0
    elif isinstance(joints, HumanFrame):
        people, is_people = People((0,), (joints,)), 0.0
    else:  # raw arrays (a caller's own): kept as given, a frame of one
        frame = HumanFrame(np.asarray(joints, dtype=float), np.full(len(joints), 2, np.int8))  # type: ignore[arg-type]
        people, is_people = People((0,), (frame,)), 0.0
    n_joints = len(people.frames[0].joints) if people.frames else 0
    parts: list[np.ndarray] = [np.array([KINDS["frame"], is_people, len(people.ids), n_joints])]
    for k, (pid, frame) in enumerate(zip(people.ids, people.frames, strict=True)):
        lag = people.lag_s[k] if people.lag_s else np.nan
        body = np.c_[np.asarray(frame.joints, float), np.asarray(frame.state, float)]
        parts.append(np.r_[float(pid), lag, body.ravel()])
    return np.concatenate(parts)


def _frame_of(entry: np.ndarray) -> HumanFrame | People:
    is_people, persons, n_joints = bool(entry[1]), int(entry[2]), int(entry[3])
    size = 2 + 4 * n_joints
    ids, frames, lags = [], [], []
    for k in range(persons):
        part = entry[4 + k * size : 4 + (k + 1) * size]
        body = part[2:].reshape(n_joints, 4)
        ids.append(int(part[0]))
        lags.append(float(part[1]))
        frames.append(HumanFrame(body[:, :3].copy(), body[:, 3].astype(np.int8)))
    if not is_people:
        return frames[0]
    lag = () if all(np.isnan(v) for v in lags) else tuple(lags)
    return People(tuple(ids), tuple(frames), lag)


def _nan_none(v: float) -> float | None:
    return None if np.isnan(v) else float(v)


def reproduce(controller: Replayable, entries: Sequence[np.ndarray]) -> np.ndarray:
    """The commands (T, nv), rad/s, of each logged tick when ``controller`` (fresh, built
    as the run's was) is handed the journal's ``entries`` again.

    Raises
    ------
    InputError
        For an entry of an unknown kind or a malformed one (a journal from elsewhere).
    """
    frames: list[HumanFrame | People] = []
    commands: list[np.ndarray] = []
    for entry in _checked(entries):
        kind = _NAMES[entry[0]]
        if kind == "frame":
            frames.append(_frame_of(entry))
        elif kind == "step":
            frame_id = None if np.isnan(entry[5]) else int(entry[5])
            controller.step(
                entry[6:],
                frames[int(entry[1])],
                None,
                float(entry[2]),
                _nan_none(entry[3]),
                _nan_none(entry[4]),
                frame_id,
            )
        elif kind == "brake":
            controller.brake("replayed", instead=bool(entry[1]))
        elif kind == "rest":
            controller.at_rest()
        elif kind == "limits":
            v, a, j = np.split(entry[1:], 3)
            controller.accept_limits(v, a, j)
        else:
            last = controller.last_command
            assert last is not None
            commands.append(last.dq.copy())
    return np.array(commands).reshape(len(commands), controller.robot.nv)


def _checked(entries: Sequence[np.ndarray]) -> Iterator[np.ndarray]:
    for k, entry in enumerate(entries):
        if not len(entry) or entry[0] not in _NAMES:
            raise InputError(
                f"journal entry {k} is of no known kind (codes {sorted(_NAMES)})",
                name="journal",
                value=entry[:1].tolist(),
            )
        yield entry
