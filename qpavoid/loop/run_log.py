"""A run's log: one row per control tick, as :func:`~qpavoid.loop.simulation.simulate` writes it
(its docstring says what each array holds; ``log.npz`` keeps them as they are).

Its shapes and the names of its repulsion arrays come from the robot description: one
column per robot set, and ``v_rep_<set>`` named after the sets playing the repelled and
end-effector parts (``v_rep_L2`` and ``v_rep_EE`` for the iiwa); the person's rows from the
body model's skeleton format (one per joint).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from qpavoid.arm.model import Kinematics, Robot
from qpavoid.control.controller import Controller
from qpavoid.control.tick import Command
from qpavoid.distance.methods import distance_method
from qpavoid.human.frames import HumanFrame
from qpavoid.human.people import People
from qpavoid.human.skeleton import SkeletonFormat

__all__ = ["TEXT_KEYS", "RunLogger", "finished", "new_log", "repulsion_keys"]

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


class RunLogger:
    """A run's log beside its loop: a row a tick (:meth:`row`), the stop events, the last
    guard on what the arm did (:meth:`guard`), a live view's rows (``watch``).

    Parameters
    ----------
    n_max
        Most ticks of the run.
    controller
        The run's controller (its robot, body model, distance method and closest frame).
    watch
        Called with the tick just logged (its row of every log key, copied, and its
        ``stop_reason``), at most 30 times a second of run time; None for none.
    """

    def __init__(
        self,
        n_max: int,
        controller: Controller,
        watch: Callable[[dict[str, Any]], None] | None = None,
    ):
        self.controller = controller
        self.robot = robot = controller.robot
        self.log = new_log(n_max, robot, controller.human.skeleton)
        self.repulsion = repulsion_keys(robot)
        self.texts: dict[str, list[str]] = {key: [] for key in TEXT_KEYS}
        self.stop_events: list[dict[str, Any]] = []
        other = "capsules" if controller.config.distance == "spheres" else "spheres"
        self.other = distance_method(other, robot, controller.human)  # distance_other
        self.watch, self.last_watch = watch, -1.0
        self.vel_violations = self.pos_violations = 0
        self.n = 0  # the ticks logged
        self._was_stopped = False

    def guard(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """The last guard: ``dq`` saturated at the joints' velocity limits (a tick that
        needed it counted), and a tick out of the joint limits counted."""
        robot = self.robot
        if np.any(np.abs(dq) > robot.dq_max * (1 + 1e-9)):
            self.vel_violations += 1
            dq = np.clip(dq, -robot.dq_max, robot.dq_max)
        if np.any(q > robot.q_max + 1e-12) or np.any(q < robot.q_min - 1e-12):
            self.pos_violations += 1
        return dq

    def row(
        self,
        k: int,
        t: float,
        kin: Kinematics,
        dq: np.ndarray,
        cmd: Command,
        human: HumanFrame | People,
        tau: float,
        tick_us: float,
        frame_age_s: float,
        alert: str,
    ) -> None:
        """Tick ``k``: at ``t`` (s), the arm at ``kin`` moving at ``dq`` (rad/s), the
        command, the frame given, the path clock, the tick's time (µs), the frame's age (s)
        and the source's alert."""
        log, texts = self.log, self.texts
        if cmd.stopped and not self._was_stopped:
            self.stop_events.append({"t": round(t, 6), "reason": cmd.reason})
        self._was_stopped = cmd.stopped
        other_table = self.other.closest(kin, self.controller.geometry(human))[0]
        v_repelled, v_end_effector = self.repulsion
        log["t"][k], log["q"][k], log["dq"][k], log["dq_command"][k] = t, kin.q, dq, cmd.dq
        closest = self.controller.closest_frame
        assert closest is not None  # the closest person's frame: set by the tick just measured
        log["joints"][k], log["state"][k] = closest
        log["stopped"][k], log["f"][k] = cmd.stopped, cmd.f
        log["distance"][k], log["distance_other"][k] = cmd.distance, other_table.min_per_set()
        log[v_repelled][k], log[v_end_effector][k] = cmd.v_repelled, cmd.v_end_effector
        log["ee_pos"][k], log["ee_ref"][k] = cmd.ee_pos, cmd.ee_ref
        log["tau"][k], log["tick_us"][k], log["frame_age_s"][k] = tau, tick_us, frame_age_s
        closest = np.argmin(cmd.table.distance, axis=1)  # each set's closest pair
        sets = np.arange(len(closest))
        log["robot_point"][k] = cmd.table.robot_point[sets, closest]
        log["human_point"][k] = cmd.table.human_point[sets, closest]
        texts["stop_reason"].append(cmd.reason if cmd.stopped else "")
        texts["input_alert"].append(alert)
        if self.watch is not None and t - self.last_watch >= 1.0 / 30.0:
            self.watch(
                {key: v[k].copy() for key, v in log.items()} | {x: texts[x][k] for x in texts}
            )
            self.last_watch = t
        self.n = k + 1

    def finished(self) -> dict[str, np.ndarray]:
        """The log of the ticks logged (and the live view's last row, whenever it came)."""
        log = finished(self.log, self.n, self.texts)
        if self.watch is not None and self.n:
            self.watch({key: v[self.n - 1].copy() for key, v in log.items()})
        return log
