"""A run's log: one row per control tick, as :func:`~qpavoid.loop.simulation.simulate` writes it
(its docstring says what each array holds; ``log.npz`` keeps them as they are)."""

from __future__ import annotations

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.human.frames import N_KINECT_JOINTS

__all__ = ["TEXT_KEYS", "finished", "new_log"]

#: The arrays of text, one string a tick: why the robot stops ("" while it moves) and why
#: the input is suspect ("" while it is not: a live source's flagged people).
TEXT_KEYS = ("stop_reason", "input_alert")


def new_log(n_max: int, robot: Robot) -> dict[str, np.ndarray]:
    """Room for ``n_max`` ticks of every numeric array (the text ones are lists meanwhile)."""
    sets = (n_max, 3)
    return {
        "t": np.empty(n_max),
        "q": np.empty((n_max, robot.nq)),
        "dq": np.empty((n_max, robot.nv)),
        "dq_command": np.empty((n_max, robot.nv)),
        "joints": np.empty((n_max, N_KINECT_JOINTS, 3)),
        "state": np.empty((n_max, N_KINECT_JOINTS), dtype=np.int8),
        "stopped": np.empty(n_max, dtype=bool),
        "f": np.empty(n_max),
        "distance": np.empty(sets),
        "distance_other": np.empty(sets),
        "v_rep_L2": np.empty((n_max, 3)),
        "v_rep_EE": np.empty((n_max, 3)),
        "ee_pos": np.empty((n_max, 3)),
        "ee_ref": np.empty((n_max, 3)),
        "tau": np.empty(n_max),
        "tick_us": np.empty(n_max),
        "frame_age_s": np.empty(n_max),
        "true_distance": np.full(sets, np.nan),
        "robot_point": np.empty((n_max, 3, 3)),
        "human_point": np.empty((n_max, 3, 3)),
    }


def finished(
    log: dict[str, np.ndarray], n: int, texts: dict[str, list[str]]
) -> dict[str, np.ndarray]:
    """The first ``n`` ticks of ``log``, with the text arrays of ``texts``."""
    out = {key: value[:n] for key, value in log.items()}
    for key in TEXT_KEYS:
        out[key] = np.array(texts[key][:n], dtype=str)
    return out
