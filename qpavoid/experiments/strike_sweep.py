"""The adversarial sweep: hands driven into the robot, judged against where they really are.

Each run is a :mod:`qpavoid.scenarios.strikes` case (every set, the shoulder and the base, up to
2.0 m/s or beyond, both hands, lost, inferred and frozen limbs, frame gaps and jitter)
on the real bench (Kinect latency and noise, the arm's reaction and braking). What counts
is the truth: ticks in which the arm moved while a robot capsule touched the true person,
and the true clearance while moving. Like :mod:`qpavoid.experiments.sweep`, a sweep is a map over
seeds, on a local process pool or any executor.
"""

from __future__ import annotations

from collections.abc import Iterable
from concurrent.futures import Executor
from dataclasses import asdict, dataclass

import numpy as np

from qpavoid.arm.model import load_robot
from qpavoid.experiments.jobs import map_jobs
from qpavoid.experiments.runs import RunSpec, build_controller
from qpavoid.loop.camera import KINECT_V2_LATENCY_S, SensorConfig
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.strikes import strike_case, strike_motion, strike_sensor

__all__ = ["StrikeCheck", "as_dicts", "check_strike", "strike_sweep", "summarize_strikes"]


@dataclass(frozen=True)
class StrikeCheck:
    """One strike (:func:`~qpavoid.scenarios.strikes.strike_case`) judged against the truth.

    Attributes
    ----------
    seed, controller, safety
        What was run.
    target, speed_mps, side, both_hands, fault
        The strike.
    ticks_moving_in_true_contact
        Ticks in which the arm moved (its real velocity, braking included) while a robot
        capsule touched the true person.
    min_true_clearance_moving_m
        Smallest true capsule distance over the ticks in which the arm moved, m (+inf if
        it never moved).
    moving_s, stopped_s
        Time the arm moved / the controller held a stop, s.
    max_stop_speed_mps
        The fastest robot point when a stop began, m/s (0 if none).
    ticks_moving_below_stop_distance
        Ticks in which the arm moved while a set was truly closer than its stop distance.
    reached_goal, duration_s
        Whether the path's goal was reached, and when the run ended, s.
    limit_violations
        Ticks over a joint's velocity or position limit.
    tick_us_median, tick_us_p99
        The controller's time per tick, µs (measured: not reproducible).
    """

    seed: int
    controller: str
    safety: str
    target: str
    speed_mps: float
    side: str
    both_hands: bool
    fault: str
    ticks_moving_in_true_contact: int
    min_true_clearance_moving_m: float
    moving_s: float
    stopped_s: float
    max_stop_speed_mps: float
    ticks_moving_below_stop_distance: int = 0
    reached_goal: bool = False
    duration_s: float = 0.0
    limit_violations: int = 0
    tick_us_median: float = 0.0
    tick_us_p99: float = 0.0


def check_strike(
    seed: int,
    controller: str = "qp",
    safety: str = "ssm",
    rate_hz: float = 100.0,
    max_speed_mps: float = 2.0,
    latency_s: float = KINECT_V2_LATENCY_S,
    distance: str = "capsules",
    max_time_s: float | None = None,
) -> StrikeCheck:
    """Simulate the strike of ``seed`` on the real bench and judge it against the truth.

    The run lasts the strike (``max_time_s=None``) or until the goal, capped at
    ``max_time_s`` (s).
    """
    case = strike_case(seed, max_speed_mps)
    max_time_s = case.duration_s if max_time_s is None else max_time_s
    spec = RunSpec(
        scenario="free",
        controller=controller,
        distance=distance,
        safety=safety,
        rate_hz=rate_hz,
        max_time_s=max_time_s,
        latency_s=latency_s,
    )
    robot = load_robot(spec.robot)
    sim = simulate(
        build_controller(spec, robot),
        strike_motion(case, robot),
        SimConfig(
            control_rate_hz=rate_hz,
            sensor=strike_sensor(case, SensorConfig(latency_s=latency_s, seed=case.seed)),
            max_time_s=max_time_s,
            measure_truth=True,
        ),
    )
    m, log = sim.metrics, sim.log
    moving = np.any(log["dq"] != 0.0, axis=1)
    clearance = m["min_true_clearance_moving_m"]
    return StrikeCheck(
        seed,
        controller,
        safety,
        case.target,
        case.speed_mps,
        case.side,
        case.both_hands,
        case.fault,
        int(m["ticks_moving_in_true_contact"]),
        float("inf") if clearance is None else float(clearance),
        float(moving.sum() / rate_hz),
        float(m["stopped_s"]),
        max((e.get("robot_speed_mps", 0.0) for e in m["stop_events"]), default=0.0),
        int(m["ticks_moving_below_stop_distance"] or 0),
        bool(m["reached_goal"]),
        float(m["duration_s"]),
        int(m["joint_velocity_limit_violations"] + m["joint_position_limit_violations"]),
        float(m["tick_us"]["median"]),
        float(m["tick_us"]["p99"]),
    )


def _check_strike(args: tuple) -> StrikeCheck:
    return check_strike(*args)


def strike_sweep(
    seeds: Iterable[int],
    controller: str = "qp",
    safety: str = "ssm",
    rate_hz: float = 100.0,
    max_speed_mps: float = 2.0,
    latency_s: float = KINECT_V2_LATENCY_S,
    workers: int | None = None,
    executor: Executor | None = None,
    progress: bool = False,
    distance: str = "capsules",
    max_time_s: float | None = None,
) -> list[StrikeCheck]:
    """:func:`check_strike` over ``seeds`` (in parallel; results in the order of ``seeds``)."""
    RunSpec(  # checks the names before any work
        scenario="free", controller=controller, distance=distance, safety=safety, rate_hz=rate_hz
    )
    jobs = [
        (int(s), controller, safety, rate_hz, max_speed_mps, latency_s, distance, max_time_s)
        for s in seeds
    ]
    return map_jobs(
        _check_strike,
        jobs,
        workers=workers,
        executor=executor,
        progress=progress,
        desc="strike sweep",
        unit="strike",
    )


def summarize_strikes(checks: list[StrikeCheck]) -> dict:
    """Totals of a strike sweep: runs in true contact, clearance percentiles, time moving."""
    clear = np.array([c.min_true_clearance_moving_m for c in checks])
    moved = np.isfinite(clear)
    return {
        "strikes": len(checks),
        "runs_moving_in_true_contact": sum(c.ticks_moving_in_true_contact > 0 for c in checks),
        "ticks_moving_in_true_contact": sum(c.ticks_moving_in_true_contact for c in checks),
        "runs_that_moved": int(moved.sum()),
        "min_true_clearance_moving_m": float(clear[moved].min()) if moved.any() else None,
        "p01_true_clearance_moving_m": (
            float(np.percentile(clear[moved], 1)) if moved.any() else None
        ),
        "mean_moving_s": float(np.mean([c.moving_s for c in checks])),
        "mean_stopped_s": float(np.mean([c.stopped_s for c in checks])),
    }


def as_dicts(checks: list[StrikeCheck]) -> list[dict]:
    """The checks as plain dicts (JSON)."""
    return [asdict(c) for c in checks]
