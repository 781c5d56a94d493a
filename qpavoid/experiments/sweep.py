"""Safety sweeps: many random hand approaches, each run checked for the safety invariants.

Every approach is an independent closed-loop run (:func:`check_approach`), so a sweep is a
map over seeds: here over a local process pool; on a cluster, the same function over
another executor (anything with ``map``).

Each run is checked, tick by tick, for what must never happen:

* a joint outside its position limits, or faster than its (eq. 3 scaled) velocity limit;
* a non-zero command while one of the paper's stop rules holds;
* the robot moving while the *exact capsule* distance of a set is below that set's stop
  threshold (0.05 m for L2 and EE; for L1 the distance where f = 0.8), whichever distance
  method the controller itself uses.

The adversarial sweep, judged against the true motion, is :mod:`qpavoid.experiments.strike_sweep`.
"""

from __future__ import annotations

from collections.abc import Iterable
from concurrent.futures import Executor
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot, joint_columns
from qpavoid.control.tick import ControllerConfig
from qpavoid.experiments.jobs import map_jobs
from qpavoid.experiments.runs import RunSpec, simulate_one
from qpavoid.laws.avoidance import scaled_velocity_limits, stop_distances, stop_rule_holds


@dataclass(frozen=True)
class ApproachCheck:
    """The outcome of one random approach (counts are ticks).

    Attributes
    ----------
    seed, controller, distance
        What was run.
    ticks
        Number of control ticks simulated.
    position_violations, velocity_violations
        Ticks with a joint outside its position limits / over its scaled velocity limit.
    moving_under_stop_rule
        Ticks with a non-zero command while a stop rule held.
    moving_below_capsule_threshold
        Ticks with a non-zero command while a set's capsule distance was below its
        threshold.
    min_capsule_distance_moving_m
        (L1, L2, EE) smallest capsule distance over the ticks where the robot moved, m.
    stopped_s, reached_goal
        Time spent stopped, and whether the goal was reached.
    """

    seed: int
    controller: str
    distance: str
    ticks: int
    position_violations: int
    velocity_violations: int
    moving_under_stop_rule: int
    moving_below_capsule_threshold: int
    min_capsule_distance_moving_m: tuple[float, float, float]
    stopped_s: float
    reached_goal: bool

    @property
    def safe(self) -> bool:
        """True if no invariant was broken."""
        return not (
            self.position_violations
            or self.velocity_violations
            or self.moving_under_stop_rule
            or self.moving_below_capsule_threshold
        )


def check_log(
    log: dict[str, np.ndarray], robot: Robot, config: ControllerConfig, distance: str
) -> dict[str, Any]:
    """Tick counts of every broken invariant in a simulation log (see the module docstring).

    Returns a dict with ``position_violations``, ``velocity_violations``,
    ``moving_under_stop_rule``, ``moving_below_capsule_threshold`` (tick counts) and
    ``min_capsule_distance_moving_m`` (per set, m).
    """
    avo = config.avoidance
    sets = [robot.set_index(name) for name in ("L1", "L2", "EE")]  # the paper's three sets
    capsule = (log["distance"] if distance == "capsules" else log["distance_other"])[:, sets]
    threshold = stop_distances(avo)
    moving = np.any(log["dq_command"] != 0.0, axis=1)  # the controller's decisions
    seen = log["distance"][:, sets]
    rule = stop_rule_holds(log["f"], seen[:, 1], seen[:, 2], avo)
    cols = joint_columns(robot, config.scaled_joints, "scaled_joints")
    limits = scaled_velocity_limits(robot.dq_max, log["f"], cols)  # eq. (3)
    over = np.any(np.abs(log["dq_command"]) > limits * (1 + 1e-9) + 1e-12, axis=1)
    outside = np.any((log["q"] > robot.q_max) | (log["q"] < robot.q_min), axis=1)
    below = np.any(capsule < threshold, axis=1)
    return {
        "position_violations": int(outside.sum()),
        "velocity_violations": int(over.sum()),
        "moving_under_stop_rule": int((moving & rule).sum()),
        "moving_below_capsule_threshold": int((moving & below).sum()),
        "min_capsule_distance_moving_m": tuple(
            float(x) for x in (capsule[moving].min(axis=0) if moving.any() else np.full(3, np.inf))
        ),
    }


def check_approach(
    seed: int,
    controller: str = "qp",
    distance: str = "spheres",
    rate_hz: float = 50.0,
    max_time_s: float = 25.0,
) -> ApproachCheck:
    """Simulate the random approach ``seed`` and check the invariants of every tick."""
    run = simulate_one(
        RunSpec(
            scenario=f"random:{seed}",
            controller=controller,
            distance=distance,
            max_time_s=max_time_s,
            rate_hz=rate_hz,
            measure_truth=False,  # the checks here use the seen frames' capsule table
        )
    )
    return ApproachCheck(
        seed,
        controller,
        distance,
        len(run.sim.log["t"]),
        **check_log(run.sim.log, run.robot, run.config, distance),
        stopped_s=run.metrics["stopped_s"],
        reached_goal=run.metrics["reached_goal"],
    )


def _check(args: tuple[int, str, str, float, float]) -> ApproachCheck:
    return check_approach(*args)


def safety_sweep(
    seeds: Iterable[int],
    controller: str = "qp",
    distance: str = "spheres",
    rate_hz: float = 50.0,
    max_time_s: float = 25.0,
    workers: int | None = None,
    executor: Executor | None = None,
    progress: bool = False,
) -> list[ApproachCheck]:
    """Check every seed's random approach; in parallel over ``workers`` processes.

    Parameters
    ----------
    seeds
        Seeds of :func:`qpavoid.scenarios.generated.random_approach`.
    controller, distance
        ``"analytic"`` or ``"qp"``; ``"spheres"`` or ``"capsules"``.
    rate_hz, max_time_s
        Control rate and cap of each run.
    workers
        Local processes (default: all cores).
    executor
        Any object with ``map`` (e.g. a cluster's executor) to use instead of a local pool.
    progress
        Show a progress bar (on a terminal only).

    Returns
    -------
    list of ApproachCheck
        In the order of ``seeds``, whatever the number of workers.
    """
    jobs = [(int(s), controller, distance, rate_hz, max_time_s) for s in seeds]
    RunSpec(
        scenario="free",
        controller=controller,
        distance=distance,
        max_time_s=max_time_s,
        rate_hz=rate_hz,
    )  # check the settings before any job starts
    return map_jobs(
        _check,
        jobs,
        workers=workers,
        executor=executor,
        progress=progress,
        desc="safety sweep",
        unit="approach",
    )


def summarize(checks: list[ApproachCheck]) -> dict:
    """Totals over a sweep (for reports and docs)."""
    mins = np.array([c.min_capsule_distance_moving_m for c in checks])
    return {
        "approaches": len(checks),
        "unsafe": sum(not c.safe for c in checks),
        "position_violations": sum(c.position_violations for c in checks),
        "velocity_violations": sum(c.velocity_violations for c in checks),
        "moving_under_stop_rule": sum(c.moving_under_stop_rule for c in checks),
        "moving_below_capsule_threshold": sum(c.moving_below_capsule_threshold for c in checks),
        "min_capsule_distance_moving_m": dict(
            zip(("L1", "L2", "EE"), mins.min(axis=0).tolist(), strict=True)
        ),
        "reached_goal": sum(c.reached_goal for c in checks),
        "mean_stopped_s": float(np.mean([c.stopped_s for c in checks])),
    }


def as_dicts(checks: list[ApproachCheck]) -> list[dict]:
    """The checks as plain dicts (JSON)."""
    return [asdict(c) for c in checks]
