"""A sweep's totals: its checks summed up, per kind (the ``qpavoid sweep`` summary).

Everything but a strike or close-work sweep's ``timing`` is reproducible from the seeds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict
from typing import Any, cast

import numpy as np

from qpavoid.core.errors import InputError
from qpavoid.experiments.sweep_checks import ApproachCheck, Check, CloseWorkCheck, StrikeCheck
from qpavoid.scenarios.closework import VARIANTS

__all__ = ["as_dicts", "summarize"]


def summarize(checks: Sequence[Check]) -> dict[str, Any]:
    """A sweep's totals (the ``qpavoid sweep`` summary for strikes and close work);
    everything but a strike or close-work sweep's ``timing`` is reproducible from the
    seeds.

    Raises
    ------
    InputError
        If there is nothing to sum up.
    """
    if not checks:
        raise InputError("a sweep's summary needs at least one run", name="checks", value=[])
    if checks[0].kind == "approach":
        return _approach_totals(cast(Sequence[ApproachCheck], checks))
    if checks[0].kind == "closework":
        return _closework_totals(cast(Sequence[CloseWorkCheck], checks))
    return _strike_totals(cast(Sequence[StrikeCheck], checks))


def _approach_totals(checks: Sequence[ApproachCheck]) -> dict[str, Any]:
    return {
        "approaches": len(checks),
        "unsafe": sum(not c.safe for c in checks),
        "position_violations": sum(c.position_violations for c in checks),
        "velocity_violations": sum(c.velocity_violations for c in checks),
        "moving_under_stop_rule": sum(c.moving_under_stop_rule for c in checks),
        "command_limit_violations": sum(c.command_limit_violations for c in checks),
        "moving_below_capsule_threshold": sum(c.moving_below_capsule_threshold for c in checks),
        "min_capsule_distance_moving_m": {
            name: min(c.min_capsule_distance_moving_m[name] for c in checks)
            for name in checks[0].min_capsule_distance_moving_m
        },
        "reached_goal": sum(c.reached_goal for c in checks),
        "mean_stopped_s": float(np.mean([c.stopped_s for c in checks])),
    }


def _mm(x: float) -> float:
    """``x`` m in mm, to the µm."""
    return round(float(x) * 1e3, 3)


def _clearance_totals(runs: Sequence[StrikeCheck | CloseWorkCheck]) -> dict[str, float | None]:
    """The true clearance while moving over the runs that moved, mm: min, p01, median."""
    clear = np.array([r.min_true_clearance_moving_m for r in runs])
    moved = np.isfinite(clear)
    return {
        "min": _mm(clear[moved].min()) if moved.any() else None,
        "p01": _mm(np.percentile(clear[moved], 1)) if moved.any() else None,
        "median": _mm(np.median(clear[moved])) if moved.any() else None,
    }


def _timing(runs: Sequence[StrikeCheck | CloseWorkCheck]) -> dict[str, float]:
    """The controller's tick times over the runs, µs: the median of the runs' medians,
    the 99th percentile of their p99s."""
    return {
        "tick_us_median": float(np.median([r.tick_us_median for r in runs])),
        "tick_us_p99": float(np.percentile([r.tick_us_p99 for r in runs], 99)),
    }


def _contact_totals(runs: Sequence[StrikeCheck | CloseWorkCheck]) -> dict[str, Any]:
    """Power and force limiting over the runs: runs whose arm moved while
    touching the head, face, neck or trunk, runs touching an arm or hand region above its
    limit (both must be zero), runs touching one within it (allowed with ``pfl``), runs
    clamping, the contact ticks within limit, and the fastest touch, its ratio to its
    limit, the deepest advance into a part (mm) and the largest force, with the medians
    over the runs that touched."""
    touched = [r for r in runs if r.ticks_contact_within_limit or r.ticks_contact_above_limit]

    def spread(values: list[float]) -> dict[str, float | None]:
        return {
            "max": round(float(np.max(values)), 6) if values else None,
            "median": round(float(np.median(values)), 6) if values else None,
        }

    return {
        "runs_touching_protected_regions": sum(r.ticks_moving_protected_contact > 0 for r in runs),
        "runs_touching_above_limit": sum(r.ticks_contact_above_limit > 0 for r in runs),
        "runs_touching_within_limit": sum(r.ticks_contact_within_limit > 0 for r in runs),
        "runs_clamping": sum(r.ticks_clamped > 0 for r in runs),
        "runs_pushing": sum(r.ticks_pushed > 0 for r in runs),
        "ticks_touching_within_limit": sum(r.ticks_contact_within_limit for r in runs),
        "contact_speed_mps": spread([r.max_contact_speed_mps for r in touched]),
        "contact_speed_ratio": spread([r.max_contact_speed_ratio for r in touched]),
        "contact_advance_mm": spread([1e3 * r.max_contact_advance_m for r in touched]),
        "contact_force_n": spread([r.max_contact_force_n for r in touched]),
    }


def _strike_totals(runs: Sequence[StrikeCheck]) -> dict[str, Any]:
    return {
        "runs": len(runs),
        "runs_moving_in_true_contact": sum(r.ticks_moving_in_true_contact > 0 for r in runs),
        "runs_moving_below_stop_distance": sum(
            r.ticks_moving_below_stop_distance > 0 for r in runs
        ),
        "true_clearance_moving_mm": _clearance_totals(runs),
        "fraction_reaching_goal": sum(r.reached_goal for r in runs) / len(runs),
        "mean_time_stopped_s": round(float(np.mean([r.stopped_s for r in runs])), 6),
        "mean_duration_s": round(float(np.mean([r.duration_s for r in runs])), 6),
        "runs_with_limit_violations": sum(r.limit_violations > 0 for r in runs),
        "runs_with_command_limit_violations": sum(r.command_limit_violations > 0 for r in runs),
        "contacts": _contact_totals(runs),
        "timing": _timing(runs),
    }


def _goal_times(runs: Sequence[CloseWorkCheck]) -> list[float]:
    """The times to goal of the runs that reached it, s."""
    return [r.time_to_goal_s for r in runs if r.time_to_goal_s is not None]


def _closework_totals(runs: Sequence[CloseWorkCheck]) -> dict[str, Any]:
    """Safety as strikes' (true contact, clearance), then productivity: the fraction of
    runs reaching the goal, the time to it over those that did (None if none did), the
    time stopped, per variant too."""
    times = _goal_times(runs)
    per_variant = {}
    for variant in VARIANTS:
        these = [r for r in runs if r.variant == variant]
        if not these:
            continue
        reached = _goal_times(these)
        per_variant[variant] = {
            "runs": len(these),
            "fraction_reaching_goal": sum(r.reached_goal for r in these) / len(these),
            "time_to_goal_s_median": round(float(np.median(reached)), 6) if reached else None,
            "mean_time_stopped_s": round(float(np.mean([r.stopped_s for r in these])), 6),
            "runs_moving_in_true_contact": sum(r.ticks_moving_in_true_contact > 0 for r in these),
        }
    return {
        "runs": len(runs),
        "runs_moving_in_true_contact": sum(r.ticks_moving_in_true_contact > 0 for r in runs),
        "true_clearance_moving_mm": _clearance_totals(runs),
        "fraction_reaching_goal": sum(r.reached_goal for r in runs) / len(runs),
        "time_to_goal_s": {
            "median": round(float(np.median(times)), 6) if times else None,
            "mean": round(float(np.mean(times)), 6) if times else None,
        },
        "mean_time_stopped_s": round(float(np.mean([r.stopped_s for r in runs])), 6),
        "mean_duration_s": round(float(np.mean([r.duration_s for r in runs])), 6),
        "per_variant": per_variant,
        "runs_with_limit_violations": sum(r.limit_violations > 0 for r in runs),
        "runs_with_command_limit_violations": sum(r.command_limit_violations > 0 for r in runs),
        "contacts": _contact_totals(runs),
        "timing": _timing(runs),
    }


def as_dicts(checks: Sequence[Check]) -> list[dict[str, Any]]:
    """The checks as plain dicts (JSON)."""
    return [asdict(c) for c in checks]
