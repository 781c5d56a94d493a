"""The cell check's figure: along the task's path, the tightest clearance to the seated
operator beside the protective distance it needs, the stretches where the arm stops shaded
(``qpavoid check``, :mod:`qpavoid.experiments.cell_check`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from qpavoid.output.plot_base import STOP
from qpavoid.output.plots import DPI

__all__ = ["check_figure"]


def check_figure(
    path: str | Path,
    times_s: np.ndarray,
    clearance_m: np.ndarray,
    needed_m: np.ndarray,
    stretches: Sequence[tuple[float, float]],
    waypoint_times_s: Sequence[float],
    title: str,
) -> Path:
    """Draw and save the figure at ``path`` (PNG); return it.

    Parameters
    ----------
    times_s, clearance_m, needed_m
        (N,) the path times sampled, the tightest pair's clearance there and the
        protective distance it needs (NaN: none, the paper's rules alone), m.
    stretches
        ``(start_s, end_s)`` of each stretch where the arm stops.
    waypoint_times_s
        The task's waypoints, marked on the time axis.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8.0, 3.6))
    ax = fig.add_subplot()
    ax.plot(times_s, clearance_m, color="k", lw=1.4, label="clearance to the operator")
    if np.isfinite(needed_m).any():
        ax.plot(times_s, needed_m, color="C3", lw=1.4, ls="--", label="protective distance")
    for k, (start, end) in enumerate(stretches):
        ax.axvspan(start, end, **STOP, label="the arm stops" if k == 0 else None)
    for t in waypoint_times_s:
        ax.axvline(t, color="0.6", lw=0.8, ls=":")
    ax.set_xlabel("path time, s (dotted: the task's waypoints)")
    ax.set_ylabel("m")
    ax.set_ylim(bottom=0.0)
    ax.set_title(title, fontsize=10)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=DPI)
    return out
