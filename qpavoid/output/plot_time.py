"""The figures against time (paper Figs. 6, 8-11, 13 and the timeline of other runs).

The sets are taken by the part they play (the robot description's roles: ``"scaled"``,
``"repelled"``, ``"end_effector"``) and labelled with their names (L1, L2, EE for the iiwa).
Every stop threshold says whose rule it is, by role (the scaled set stops on f > 0.8, the
repelled and end-effector sets within 0.05 m: the paper's rules, Sect. 5.4), and the
figures that show one carry all the rules as a caption
(:func:`~qpavoid.output.plot_base.stop_rules_note`).
Repulsive speeds below 1e-6 m/s are drawn as 0 on an axis at least 0-0.01 m/s
(:func:`~qpavoid.output.plot_base.speed_axis`): numerical noise never looks like repulsion.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from qpavoid.arm.roles import ROLE_NAMES
from qpavoid.laws.avoidance import l1_factor, stop_distances
from qpavoid.loop.run_log import repulsion_keys
from qpavoid.output.plot_base import (
    STOP,
    Run,
    finish,
    role_label,
    set_caption,
    set_colours,
    set_title,
    speed_axis,
    speed_for_axis,
    stop_rules_note,
)

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


def _distance_lines(ax: Any, run: Run, roles: tuple[str, ...]) -> None:
    """Stop distances and the repulsion range of the sets playing ``roles`` (the repelled
    and/or the end-effector set)."""
    by_role = dict(zip(ROLE_NAMES, stop_distances(run.cfg).tolist(), strict=True))
    for d in sorted({by_role[r] for r in roles}):
        who = " and\n".join(role_label(run.robot, r) for r in roles if by_role[r] == d)
        ax.axhline(
            d, color="r", ls="--", lw=0.9, label=f"stop distance {d:g} m\n(rule of the {who})"
        )
    ax.axhline(
        run.cfg.rho_rep_m,
        color="0.4",
        ls=":",
        lw=1.0,
        label=f"repulsion starts (ρ = {run.cfg.rho_rep_m:g} m)",
    )
    lowest = min(np.nanmin(run.role_column(r), initial=np.inf) for r in roles)
    ax.set_ylim(bottom=min(0.0, lowest - 0.01))


def _speed(run: Run, role: str) -> np.ndarray:
    """|v_rep| over time of the repelled set or the end effector (``role``), m/s, values
    below :data:`~qpavoid.output.plot_base.SPEED_FLOOR_MPS` as 0."""
    keys = dict(zip(("repelled", "end_effector"), repulsion_keys(run.robot), strict=True))
    return speed_for_axis(np.linalg.norm(run.log[keys[role]], axis=1))


def _plot_f(ax: Any, run: Run) -> None:
    ax.plot(run.log["t"], run.log["f"], color="C0", lw=1.2, label="f (eq. 2)")
    rule = f"stop: f > {run.cfg.f_stop:g}\n(rule of the {role_label(run.robot, 'scaled')})"
    ax.axhline(run.cfg.f_stop, color="r", ls="--", lw=0.9, label=rule)
    ax.set_ylim(-0.03, 1.03)


def _f_stop_label(run: Run, at: str) -> str:
    """The scaled set's stop threshold as a distance: ``f = 0.8 at <at>0.042 m`` and whose
    rule it is."""
    cfg = run.cfg
    return (
        f"f = {cfg.f_stop:g} at {at}{cfg.d_stop_L1_m():.3f} m\n"
        f"(rule of the {role_label(run.robot, 'scaled')})"
    )


def fig_f_vs_distance(run: Run) -> Any:
    """Fig. 6: f of eq. (2) against the scaled set's (L1's) distance, the run's samples on it."""
    from matplotlib.figure import Figure

    cfg, d_max = run.cfg, F6_D_MAX_M
    name = run.robot.role_name("scaled")
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
    dl, f = run.column(name), run.log["f"]
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
        ax.plot([], [], ls="none", label=f"this run: {name} never measured")
    ax.axhspan(cfg.f_stop, 1.05, **STOP, label=f"robot stops: f > {cfg.f_stop:g}")
    ax.axvline(cfg.d_stop_L1_m(), color="r", ls="--", lw=0.9, label=_f_stop_label(run, "d = "))
    xlabel = f"{name} distance ‖d_{name},H‖ (m, {run.method})"
    ax.set(xlim=(d[0], d_max), ylim=(-0.03, 1.05), xlabel=xlabel)
    finish(ax, "f")
    set_title(fig, run, f"Fig. 6: the factor f of eq. (2) against the {name} distance")
    set_caption(fig, stop_rules_note(run))
    return fig


def fig_distance(role: str, number: int, run: Run) -> Any:
    """Figs. 8 and 10: distance between the operator and the set playing ``role`` (the
    repelled set, the end-effector set) against time."""
    fig, (ax,), stop = _time_axes(run, 1, 3.4)
    name = run.robot.role_name(role)
    ax.plot(run.log["t"], run.column(name), color="C0", lw=1.2, label=f"distance to {name}")
    _distance_lines(ax, run, (role,))
    finish(ax, "distance (m)", stop, _frames_note())
    set_title(fig, run, f"Fig. {number}: distance between the operator and {name}")
    set_caption(fig, stop_rules_note(run))
    return fig


def fig_vrep(role: str, number: int, run: Run) -> Any:
    """Figs. 9 and 11: norm of the repulsive velocity of the set playing ``role`` (the
    repelled set, the end effector) against time."""
    fig, (ax,), stop = _time_axes(run, 1, 3.4)
    name = run.robot.role_name(role)
    speed = _speed(run, role)
    ax.plot(run.log["t"], speed, color="C2", lw=1.2, label=f"|v_rep| of {name}")
    finish(ax, "speed (m/s)", stop, _frames_note(), speed_axis(ax, speed))
    set_title(fig, run, f"Fig. {number}: repulsive velocity of {name} (eqs. 4-5, norm)")
    return fig


def fig_f_and_l1(run: Run) -> Any:
    """Fig. 13: f and the scaled set's (L1's) distance against time."""
    fig, (a1, a2), stop = _time_axes(run, 2, 4.8)
    _plot_f(a1, run)
    name = run.robot.role_name("scaled")
    a2.plot(run.log["t"], run.column(name), color="C1", lw=1.2, label=f"distance to {name}")
    a2.axhline(run.cfg.d_stop_L1_m(), color="r", ls=":", lw=0.9, label=_f_stop_label(run, ""))
    finish(a1, "f", stop)
    finish(a2, f"{name} distance (m)", stop)
    set_title(fig, run, f"Fig. 13: the factor f and the {name} distance")
    set_caption(fig, stop_rules_note(run))
    return fig


def fig_timeline(run: Run) -> Any:
    """Distances per set, repulsive speeds and f against time, stacked (0.2 inch taller for
    each set beyond three: room for the legend of every set)."""
    n_sets = len(run.robot.sets)
    fig, (a1, a2, a3), stop = _time_axes(run, 3, 7.0 + 0.2 * max(0, n_sets - 3))
    colours = set_colours(n_sets)
    for k, name in enumerate(run.robot.set_names):
        a1.plot(run.log["t"], run.column(name), color=colours[k], lw=1.1, label=name)
    roles = ("repelled", "end_effector")
    _distance_lines(a1, run, roles)
    speeds = [_speed(run, role) for role in roles]
    for role, speed in zip(roles, speeds, strict=True):
        a2.plot(
            run.log["t"],
            speed,
            lw=1.1,
            label=f"|v_rep| of {run.robot.role_name(role)}",
            color=colours[getattr(run.robot.roles, role)],
        )
    _plot_f(a3, run)
    finish(a1, "distance (m)", stop, _frames_note())
    finish(a2, "speed (m/s)", stop, speed_axis(a2, *speeds))
    finish(a3, "f", stop)
    set_title(fig, run, "Distances, repulsive speeds and f over time")
    set_caption(fig, stop_rules_note(run))
    return fig
