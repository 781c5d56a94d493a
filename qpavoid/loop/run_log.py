"""A run's log: one row per control tick, as :func:`~qpavoid.loop.simulation.simulate` writes it
(its docstring says what each array holds; ``log.npz`` keeps them as they are).

Its shapes and the names of its repulsion arrays come from the robot description: one
column per robot set, and ``v_rep_<set>`` named after the sets playing the repelled and
end-effector parts (``v_rep_L2`` and ``v_rep_EE`` for the iiwa); the person's rows from the
body model's skeleton format (one per joint).
"""

from __future__ import annotations

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.human.skeleton import SkeletonFormat

__all__ = ["TEXT_KEYS", "finished", "new_log", "repulsion_keys"]

#: The arrays of text, one string a tick: why the robot stops ("" while it moves) and why
#: the input is suspect ("" while it is not: a live source's flagged people).
TEXT_KEYS = ("stop_reason", "input_alert")


def repulsion_keys(robot: Robot) -> tuple[str, str]:
    """The log's keys of the repulsive velocities of the repelled set (eq. 5) and of the end
    effector (eq. 7): ``v_rep_`` and the name of the set playing each part."""
    return f"v_rep_{robot.role_name('repelled')}", f"v_rep_{robot.role_name('end_effector')}"


def new_log(n_max: int, robot: Robot, skeleton: SkeletonFormat) -> dict[str, np.ndarray]:
    """Room for ``n_max`` ticks of every numeric array (the text ones are lists meanwhile).

    Parameters
    ----------
    n_max
        Most ticks of the run.
    robot
        The run's robot (the sets' columns, the joint angles).
    skeleton
        The skeleton format of the frames the controller is given (``joints`` and
        ``state`` have a row per joint).
    """
    n_sets, n_joints = len(robot.sets), skeleton.n_joints
    sets = (n_max, n_sets)
    v_repelled, v_end_effector = repulsion_keys(robot)
    return {
        "t": np.empty(n_max),
        "q": np.empty((n_max, robot.nq)),
        "dq": np.empty((n_max, robot.nv)),
        "dq_command": np.empty((n_max, robot.nv)),
        "joints": np.empty((n_max, n_joints, 3)),
        "state": np.empty((n_max, n_joints), dtype=np.int8),
        "stopped": np.empty(n_max, dtype=bool),
        "f": np.empty(n_max),
        "distance": np.empty(sets),
        "distance_other": np.empty(sets),
        v_repelled: np.empty((n_max, 3)),
        v_end_effector: np.empty((n_max, 3)),
        "ee_pos": np.empty((n_max, 3)),
        "ee_ref": np.empty((n_max, 3)),
        "tau": np.empty(n_max),
        "tick_us": np.empty(n_max),
        "frame_age_s": np.empty(n_max),
        "true_distance": np.full(sets, np.nan),
        "robot_point": np.empty((n_max, n_sets, 3)),
        "human_point": np.empty((n_max, n_sets, 3)),
    }


def finished(
    log: dict[str, np.ndarray], n: int, texts: dict[str, list[str]]
) -> dict[str, np.ndarray]:
    """The first ``n`` ticks of ``log``, with the text arrays of ``texts``."""
    out = {key: value[:n] for key, value in log.items()}
    for key in TEXT_KEYS:
        out[key] = np.array(texts[key][:n], dtype=str)
    return out
