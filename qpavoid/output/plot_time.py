"""The figures against time (paper Figs. 6, 8-11, 13 and the timeline of other runs)."""

from __future__ import annotations

from typing import Any

import numpy as np

from qpavoid.laws.avoidance import l1_factor
from qpavoid.output.plot_base import STOP, Run, finish, set_title

F6_D_MAX_M = 0.25  # right end of Fig. 6's distance axis


def _time_axes(run: Run, rows: int, height: float) -> Any:
    """Stacked axes sharing time, shaded where the robot stopped; and the shading's entry."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    fig = Figure(figsize=(8.5, height), layout="constrained")
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    axes[-1].set_xlabel("time (s)")
    t, stopped = run.log["t"], np.asarray(run.log["stopped"], dtype=int)
    edges = np.flatnonzero(np.diff(np.r_[0, stopped, 0]))
    for ax in axes:
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            ax.axvspan(t[a], t[min(b, len(t) - 1)], **STOP)
    label = "robot stopped" if len(edges) else "robot stopped (never)"
    return fig, axes, Patch(**STOP, label=label)


def _frames_note() -> Any:
    """Legend entry explaining the steps of the curves (docs/analytic.md)."""
    from matplotlib.lines import Line2D

    return Line2D([], [], ls="none", label="steps: 30 Hz camera frames,\nheld between ticks")


def _distance_lines(ax: Any, run: Run, sets: tuple[str, ...]) -> None:
    """Stop distances and the repulsion range of ``sets`` (L2 and/or EE)."""
    stops = {n: getattr(run.cfg, f"d_stop_{n}_m") for n in sets}
    for d in sorted(set(stops.values())):
        who = ", ".join(n for n in sets if stops[n] == d)
        ax.axhline(
            d,
            color="r",
            ls="--",
            lw=0.9,
            label=f"stop distance {d:g} m" + (f" ({who})" if len(sets) > 1 else ""),
        )
    ax.axhline(
        run.cfg.rho_rep_m,
        color="0.4",
        ls=":",
        lw=1.0,
        label=f"repulsion starts (ρ = {run.cfg.rho_rep_m:g} m)",
    )
    lowest = min(np.nanmin(run.column(n), initial=np.inf) for n in sets)
    ax.set_ylim(bottom=min(0.0, lowest - 0.01))


def _speed(run: Run, name: str) -> np.ndarray:
    return np.linalg.norm(run.log[f"v_rep_{name}"], axis=1)


def _plot_f(ax: Any, run: Run) -> None:
    ax.plot(run.log["t"], run.log["f"], color="C0", lw=1.2, label="f (eq. 2)")
    ax.axhline(run.cfg.f_stop, color="r", ls="--", lw=0.9, label=f"stop: f > {run.cfg.f_stop:g}")
    ax.set_ylim(-0.03, 1.03)


def fig_f_vs_distance(run: Run) -> Any:
    """Fig. 6: f of eq. (2) against the L1 distance, the run's samples on it."""
    from matplotlib.figure import Figure

    cfg, d_max = run.cfg, F6_D_MAX_M
    fig = Figure(figsize=(8.5, 3.6), layout="constrained")
    ax = fig.subplots()
    d = np.linspace(-0.02, d_max, 500)
    ax.plot(
        d,
        l1_factor(d, cfg),
        color="C0",
        lw=1.5,
        zorder=3,
        label=f"eq. (2): ρ = {cfg.rho_L1_m:g} m, α = {cfg.alpha_L1:g}",
    )
    dl, f = run.column("L1"), run.log["f"]
    near, far = dl <= d_max, dl > d_max
    if near.any():
        step = max(1, int(near.sum()) // 1500)
        ax.scatter(
            dl[near][::step],
            f[near][::step],
            s=22,
            facecolors="none",
            edgecolors="C1",
            lw=0.8,
            label="this run",
        )
    if far.any():
        label = (
            f"this run, d > {d_max:g} m (at the edge)"
            if near.any()
            else f"this run: all d > {d_max:g} m\n(closest {np.nanmin(dl):.3f} m; at the edge)"
        )
        ax.scatter(
            [d_max],
            [f[far].max()],
            marker=">",
            s=60,
            color="C1",
            clip_on=False,
            zorder=4,
            label=label,
        )
    if not (near | far).any():
        ax.plot([], [], ls="none", label="this run: L1 never measured")
    ax.axhspan(cfg.f_stop, 1.05, **STOP, label=f"robot stops: f > {cfg.f_stop:g}")
    ax.axvline(
        cfg.d_stop_L1_m(),
        color="r",
        ls="--",
        lw=0.9,
        label=f"f = {cfg.f_stop:g} at d = {cfg.d_stop_L1_m():.3f} m",
    )
    ax.set(xlim=(d[0], d_max), ylim=(-0.03, 1.05), xlabel=f"L1 distance ‖d_L1,H‖ (m, {run.method})")
    finish(ax, "f")
    set_title(fig, run, "Fig. 6: the factor f of eq. (2) against the L1 distance")
    return fig


def fig_distance(name: str, number: int, run: Run) -> Any:
    """Figs. 8 and 10: distance between the operator and set ``name`` against time."""
    fig, (ax,), stop = _time_axes(run, 1, 3.4)
    ax.plot(run.log["t"], run.column(name), color="C0", lw=1.2, label=f"distance to {name}")
    _distance_lines(ax, run, (name,))
    finish(ax, "distance (m)", stop, _frames_note())
    set_title(fig, run, f"Fig. {number}: distance between the operator and {name}")
    return fig


def fig_vrep(name: str, number: int, run: Run) -> Any:
    """Figs. 9 and 11: norm of the repulsive velocity of set ``name`` against time."""
    fig, (ax,), stop = _time_axes(run, 1, 3.4)
    ax.plot(run.log["t"], _speed(run, name), color="C2", lw=1.2, label=f"|v_rep| of {name}")
    ax.set_ylim(bottom=0.0)
    finish(ax, "speed (m/s)", stop, _frames_note())
    set_title(fig, run, f"Fig. {number}: repulsive velocity of {name} (eqs. 4-5, norm)")
    return fig


def fig_f_and_l1(run: Run) -> Any:
    """Fig. 13: f and the L1 distance against time."""
    fig, (a1, a2), stop = _time_axes(run, 2, 4.8)
    _plot_f(a1, run)
    a2.plot(run.log["t"], run.column("L1"), color="C1", lw=1.2, label="distance to L1")
    a2.axhline(
        run.cfg.d_stop_L1_m(),
        color="r",
        ls=":",
        lw=0.9,
        label=f"f = {run.cfg.f_stop:g} at {run.cfg.d_stop_L1_m():.3f} m",
    )
    finish(a1, "f", stop)
    finish(a2, "L1 distance (m)", stop)
    set_title(fig, run, "Fig. 13: the factor f and the L1 distance")
    return fig


def fig_timeline(run: Run) -> Any:
    """Distances per set, repulsive speeds and f against time, stacked."""
    fig, (a1, a2, a3), stop = _time_axes(run, 3, 7.0)
    for k, name in enumerate(run.robot.set_names):
        a1.plot(run.log["t"], run.column(name), color=f"C{k}", lw=1.1, label=name)
    _distance_lines(a1, run, ("L2", "EE"))
    for name in ("L2", "EE"):
        a2.plot(
            run.log["t"],
            _speed(run, name),
            lw=1.1,
            label=f"|v_rep| of {name}",
            color=f"C{run.robot.set_index(name)}",
        )
    a2.set_ylim(bottom=0.0)
    _plot_f(a3, run)
    finish(a1, "distance (m)", stop, _frames_note())
    finish(a2, "speed (m/s)", stop)
    finish(a3, "f", stop)
    set_title(fig, run, "Distances, repulsive speeds and f over time")
    return fig
