"""The paper's figures from a run's log (needs the ``plot`` extra: matplotlib).

Each scenario gets the figures that belong to it (:data:`FIGURES_BY_SCENARIO`):

* ``test1`` (paper Sect. 6.1): Fig. 6, Fig. 7 snapshots, Figs. 8-11 (distance and
  repulsive speed |v_rep| of L2 and EE against time);
* ``test2`` (paper Sect. 6.2): Fig. 6, Fig. 12 snapshots (the paper's upper side view),
  Fig. 13 (f and the L1 distance against time);
* any other run (``free``, ``random:SEED``, a recording, ""): Fig. 6, ``timeline.png``
  (distances per set, |v_rep| and f against time, stacked) and ``snapshots.png``.

Fig. 6 is f of eq. (2) against the L1 distance with the run's samples. The snapshots show
the robot (links and its spheres or capsules), the operator's skeleton, the planned path
and the end-effector trace at the start, the first stop (or closest approach) and the end.

Every title names the scenario, controller and distance method; every threshold line and
the red "robot stopped" shading has a legend entry, and legends sit outside the axes. The
steps in the curves are the 30 Hz camera frames, held while the robot moves at the control
rate (see docs/analytic.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from .laws import AvoidanceConfig, l1_factor
from .robot import Robot

#: Figure files written per scenario; any scenario not listed gets those of "other".
FIGURES_BY_SCENARIO: dict[str, tuple[str, ...]] = {
    "test1": ("fig06_f_vs_distance.png", "fig07_snapshots.png", "fig08_distance_L2.png",
              "fig09_vrep_L2.png", "fig10_distance_EE.png", "fig11_vrep_EE.png"),
    "test2": ("fig06_f_vs_distance.png", "fig12_snapshots.png", "fig13_f_and_L1.png"),
    "other": ("fig06_f_vs_distance.png", "timeline.png", "snapshots.png"),
}
#: Snapshot viewpoint (elevation, azimuth), degrees: Fig. 12 is an upper side view.
VIEWS = {"test1": (25.0, -60.0), "test2": (40.0, 150.0), "other": (25.0, -60.0)}
SCENARIO_TITLES = {"test1": "Test 1", "test2": "Test 2"}
#: Bones of the Kinect skeleton drawn in the snapshots (upper body).
BONES = ((0, 1), (1, 20), (20, 2), (2, 3), (20, 4), (4, 5), (5, 6), (6, 7),
         (20, 8), (8, 9), (9, 10), (10, 11))
F6_D_MAX_M = 0.25                     # right end of Fig. 6's distance axis
STOP = {"color": "red", "alpha": 0.12, "lw": 0}
PATH = {"color": "C2", "lw": 4, "alpha": 0.45}
TRACE = {"color": "k", "lw": 1.2}
DPI = 110


def available() -> bool:
    """True if matplotlib can be imported."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def figures_for(scenario: str) -> tuple[str, ...]:
    """File names that :func:`write_figures` writes for ``scenario``."""
    return FIGURES_BY_SCENARIO.get(scenario, FIGURES_BY_SCENARIO["other"])


@dataclass(frozen=True)
class _Run:
    """What every figure needs: the log and how it was produced."""

    log: dict
    robot: Robot
    cfg: AvoidanceConfig
    method: str
    scenario: str
    controller: str

    @property
    def subtitle(self) -> str:
        """E.g. ``"Test 1 · analytic controller · spheres"``."""
        parts = (SCENARIO_TITLES.get(self.scenario, self.scenario),
                 f"{self.controller} controller" if self.controller else "", self.method)
        return " · ".join(p for p in parts if p)

    def column(self, name: str) -> np.ndarray:
        """Distance of control set ``name`` over time, NaN where it was not measured."""
        d = self.log["distance"][:, self.robot.set_index(name)]
        return np.where(np.isfinite(d), d, np.nan)


def write_figures(out_dir: str | Path, log: dict, robot: Robot,
                  avoidance: AvoidanceConfig | None = None, method: str = "spheres", *,
                  scenario: str = "", controller: str = "") -> list[Path]:
    """Write the figures of a run into ``out_dir``; return their paths.

    Parameters
    ----------
    out_dir
        Folder (created if missing).
    log
        The run's log (:func:`qpavoid.simulation.simulate`).
    robot
        The arm of the run.
    avoidance
        Constants of the run's avoidance laws (thresholds drawn; default: the paper's).
    method
        Distance method of the run, ``"spheres"`` or ``"capsules"``.
    scenario
        Selects the figures (:data:`FIGURES_BY_SCENARIO`) and names the run in the titles.
    controller
        Controller name for the titles (``"analytic"``, ``"qp"``); omitted if empty.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figures = build_figures(log, robot, avoidance, method, scenario=scenario,
                            controller=controller)
    for name, fig in figures.items():
        fig.savefig(out / name, dpi=DPI)
    return [out / name for name in figures]


def build_figures(log: dict, robot: Robot, avoidance: AvoidanceConfig | None = None,
                  method: str = "spheres", *, scenario: str = "", controller: str = ""
                  ) -> dict:
    """The matplotlib Figures of :func:`write_figures`, by file name, not saved."""
    run = _Run(log, robot, avoidance or AvoidanceConfig(), method, scenario, controller)
    return {name: BUILDERS[name](run) for name in figures_for(scenario)}


# --------------------------------------------------------------------------- helpers

def _time_axes(run: _Run, rows: int, height: float):
    """Stacked axes sharing time, shaded where the robot stopped; and the shading's entry."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch
    fig = Figure(figsize=(8.5, height), layout="constrained")
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    axes[-1].set_xlabel("time (s)")
    t, stopped = run.log["t"], np.asarray(run.log["stopped"], dtype=int)
    edges = np.flatnonzero(np.diff(np.r_[0, stopped, 0]))
    for ax in axes:
        for a, b in zip(edges[::2], edges[1::2]):
            ax.axvspan(t[a], t[min(b, len(t) - 1)], **STOP)
    label = "robot stopped" if len(edges) else "robot stopped (never)"
    return fig, axes, Patch(**STOP, label=label)


def _finish(ax, ylabel: str, *extra) -> None:
    """Label, grid and a legend outside the axes (never over the data)."""
    handles = ax.get_legend_handles_labels()[0] + list(extra)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)


def _title(fig, run: _Run, text: str) -> None:
    """The figure's title, with the scenario, controller and method on a second line."""
    fig.suptitle(f"{text}\n{run.subtitle}" if run.subtitle else text)


def _frames_note():
    """Legend entry explaining the steps of the curves (docs/analytic.md)."""
    from matplotlib.lines import Line2D
    return Line2D([], [], ls="none", label="steps: 30 Hz camera frames,\nheld between ticks")


def _distance_lines(ax, run: _Run, sets: tuple[str, ...]) -> None:
    """Stop distances and the repulsion range of ``sets`` (L2 and/or EE)."""
    stops = {n: getattr(run.cfg, f"d_stop_{n}_m") for n in sets}
    for d in sorted(set(stops.values())):
        who = ", ".join(n for n in sets if stops[n] == d)
        ax.axhline(d, color="r", ls="--", lw=0.9, label=f"stop distance {d:g} m"
                   + (f" ({who})" if len(sets) > 1 else ""))
    ax.axhline(run.cfg.rho_rep_m, color="0.4", ls=":", lw=1.0,
               label=f"repulsion starts (ρ = {run.cfg.rho_rep_m:g} m)")
    lowest = min(np.nanmin(run.column(n), initial=np.inf) for n in sets)
    ax.set_ylim(bottom=min(0.0, lowest - 0.01))


def _speed(run: _Run, name: str) -> np.ndarray:
    return np.linalg.norm(run.log[f"v_rep_{name}"], axis=1)


def _plot_f(ax, run: _Run) -> None:
    ax.plot(run.log["t"], run.log["f"], color="C0", lw=1.2, label="f (eq. 2)")
    ax.axhline(run.cfg.f_stop, color="r", ls="--", lw=0.9, label=f"stop: f > {run.cfg.f_stop:g}")
    ax.set_ylim(-0.03, 1.03)


# --------------------------------------------------------------------------- figures

def fig_f_vs_distance(run: _Run):
    """Fig. 6: f of eq. (2) against the L1 distance, the run's samples on it."""
    from matplotlib.figure import Figure
    cfg, d_max = run.cfg, F6_D_MAX_M
    fig = Figure(figsize=(8.5, 3.6), layout="constrained")
    ax = fig.subplots()
    d = np.linspace(-0.02, d_max, 500)
    ax.plot(d, l1_factor(d, cfg), color="C0", lw=1.5, zorder=3,
            label=f"eq. (2): ρ = {cfg.rho_L1_m:g} m, α = {cfg.alpha_L1:g}")
    dl, f = run.column("L1"), run.log["f"]
    near, far = dl <= d_max, dl > d_max
    if near.any():
        step = max(1, int(near.sum()) // 1500)
        ax.scatter(dl[near][::step], f[near][::step], s=22, facecolors="none",
                   edgecolors="C1", lw=0.8, label="this run")
    if far.any():
        label = (f"this run, d > {d_max:g} m (at the edge)" if near.any() else
                 f"this run: all d > {d_max:g} m\n(closest {np.nanmin(dl):.3f} m; at the edge)")
        ax.scatter([d_max], [f[far].max()], marker=">", s=60, color="C1", clip_on=False,
                   zorder=4, label=label)
    if not (near | far).any():
        ax.plot([], [], ls="none", label="this run: L1 never measured")
    ax.axhspan(cfg.f_stop, 1.05, **STOP, label=f"robot stops: f > {cfg.f_stop:g}")
    ax.axvline(cfg.d_stop_L1_m(), color="r", ls="--", lw=0.9,
               label=f"f = {cfg.f_stop:g} at d = {cfg.d_stop_L1_m():.3f} m")
    ax.set(xlim=(d[0], d_max), ylim=(-0.03, 1.05),
           xlabel=f"L1 distance ‖d_L1,H‖ (m, {run.method})")
    _finish(ax, "f")
    _title(fig, run, "Fig. 6: the factor f of eq. (2) against the L1 distance")
    return fig


def fig_distance(name: str, number: int, run: _Run):
    """Figs. 8 and 10: distance between the operator and set ``name`` against time."""
    fig, (ax,), stop = _time_axes(run, 1, 3.4)
    ax.plot(run.log["t"], run.column(name), color="C0", lw=1.2, label=f"distance to {name}")
    _distance_lines(ax, run, (name,))
    _finish(ax, "distance (m)", stop, _frames_note())
    _title(fig, run, f"Fig. {number}: distance between the operator and {name}")
    return fig


def fig_vrep(name: str, number: int, run: _Run):
    """Figs. 9 and 11: norm of the repulsive velocity of set ``name`` against time."""
    fig, (ax,), stop = _time_axes(run, 1, 3.4)
    ax.plot(run.log["t"], _speed(run, name), color="C2", lw=1.2, label=f"|v_rep| of {name}")
    ax.set_ylim(bottom=0.0)
    _finish(ax, "speed (m/s)", stop, _frames_note())
    _title(fig, run, f"Fig. {number}: repulsive velocity of {name} (eqs. 4-5, norm)")
    return fig


def fig_f_and_l1(run: _Run):
    """Fig. 13: f and the L1 distance against time."""
    fig, (a1, a2), stop = _time_axes(run, 2, 4.8)
    _plot_f(a1, run)
    a2.plot(run.log["t"], run.column("L1"), color="C1", lw=1.2, label="distance to L1")
    a2.axhline(run.cfg.d_stop_L1_m(), color="r", ls=":", lw=0.9,
               label=f"f = {run.cfg.f_stop:g} at {run.cfg.d_stop_L1_m():.3f} m")
    _finish(a1, "f", stop)
    _finish(a2, "L1 distance (m)", stop)
    _title(fig, run, "Fig. 13: the factor f and the L1 distance")
    return fig


def fig_timeline(run: _Run):
    """Distances per set, repulsive speeds and f against time, stacked."""
    fig, (a1, a2, a3), stop = _time_axes(run, 3, 7.0)
    for k, name in enumerate(run.robot.set_names):
        a1.plot(run.log["t"], run.column(name), color=f"C{k}", lw=1.1, label=name)
    _distance_lines(a1, run, ("L2", "EE"))
    for name in ("L2", "EE"):
        a2.plot(run.log["t"], _speed(run, name), lw=1.1, label=f"|v_rep| of {name}",
                color=f"C{run.robot.set_index(name)}")
    a2.set_ylim(bottom=0.0)
    _plot_f(a3, run)
    _finish(a1, "distance (m)", stop, _frames_note())
    _finish(a2, "speed (m/s)", stop)
    _finish(a3, "f", stop)
    _title(fig, run, "Distances, repulsive speeds and f over time")
    return fig


# --------------------------------------------------------------------------- snapshots

def snapshot_ticks(log: dict) -> list[int]:
    """Three telling ticks: the start, the first stop (or closest approach), the end."""
    stops = np.flatnonzero(log["stopped"])
    middle = int(stops[0]) if len(stops) else int(np.argmin(_min_distance(log)))
    return [0, middle, len(log["t"]) - 1]


def _min_distance(log: dict) -> np.ndarray:
    """Smallest distance of any set per tick, inf where nothing was measured."""
    d = np.asarray(log["distance"], dtype=float)
    return np.where(np.isfinite(d), d, np.inf).min(axis=1)


def _chain(robot: Robot, q: np.ndarray) -> np.ndarray:
    """Joint origins from the base to the end effector (the stick diagram), (n, 3)."""
    import pinocchio as pin
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    joints = [data.oMi[i].translation for i in range(1, robot.model.njoints)]
    return np.array([np.zeros(3), *joints, data.oMf[robot.ee_frame].translation])


def _ball(p: np.ndarray, r: float) -> np.ndarray:
    """Wireframe grid (3, 13, 7) of a sphere."""
    u, v = np.mgrid[0:2 * np.pi:13j, 0:np.pi:7j]
    unit = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)])
    return p[:, None, None] + r * unit


def _tube(a: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    """Wireframe grid (3, 13, 2) of the cylinder of radius ``r`` around segment ab."""
    axis = (b - a) / max(np.linalg.norm(b - a), 1e-9)
    e1 = np.cross(axis, [1.0, 0, 0] if abs(axis[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    th = np.linspace(0, 2 * np.pi, 13)
    ring = r * (np.outer(e1, np.cos(th)) + np.outer(np.cross(axis, e1), np.sin(th)))
    return np.stack([a[:, None] + ring, b[:, None] + ring], axis=2)


def _volumes(run: _Run, q: np.ndarray) -> list[np.ndarray]:
    """Wireframe grids of the robot's spheres (eq. 1) or capsules at ``q``."""
    if run.method != "capsules":
        return [_ball(p, r) for p, r in zip(run.robot.control_points(q), run.robot.sphere_radii)]
    return [g for (a, b), r in zip(run.robot.capsules(q), run.robot.capsule_radii)
            for g in (_tube(a, b, r), _ball(a, r), _ball(b, r))]


def _skeleton(log: dict, k: int) -> list[np.ndarray]:
    """The operator's bones (2, 3) at tick ``k``, tracked joints only."""
    joints, state = log["joints"][k], log["state"][k]
    usable = np.isfinite(joints).all(axis=1) & (state > 0)
    return [joints[[a, b]] for a, b in BONES if usable[a] and usable[b]]


def _draw_scene(ax, run: _Run, k: int) -> None:
    log = run.log
    ax.plot(*log["ee_ref"].T, **PATH)
    ax.plot(*log["ee_pos"][:k + 1].T, **TRACE)
    ax.plot(*_chain(run.robot, log["q"][k]).T, "-o", color="C0", lw=3, ms=3)
    for grid in _volumes(run, log["q"][k]):
        ax.plot_wireframe(*grid, color="C0", lw=0.3, alpha=0.45)
    for bone in _skeleton(log, k):
        ax.plot(*bone.T, color="C3", lw=2)


def _scene_limits(run: _Run, ticks: list[int]) -> np.ndarray:
    """Axis limits (3, 2) holding the robot, the operator and the path at ``ticks``."""
    pts = [run.log["ee_ref"], *(_chain(run.robot, run.log["q"][k]) for k in ticks)]
    pts = np.vstack(pts + [b for k in ticks for b in _skeleton(run.log, k)])
    return np.stack([pts.min(axis=0) - 0.12, pts.max(axis=0) + 0.12], axis=1)


def _scene_legend(run: _Run) -> list:
    from matplotlib.lines import Line2D
    volumes = "capsules" if run.method == "capsules" else "spheres (eq. 1)"
    return [Line2D([], [], color="C0", lw=3, marker="o", ms=3, label="robot links"),
            Line2D([], [], color="C0", lw=0.6, alpha=0.6, label=f"robot {volumes}"),
            Line2D([], [], color="C3", lw=2, label="operator (Kinect skeleton)"),
            Line2D([], [], **PATH, label="planned path"),
            Line2D([], [], **TRACE, label="end-effector trace")]


def _panel_title(run: _Run, k: int, n: int) -> str:
    log = run.log
    what = ("start", "first stop" if log["stopped"].any() else "closest approach", "end")[n]
    status = "stopped" if log["stopped"][k] else "moving"
    return (f"{'abc'[n]}) {what}, t = {log['t'][k]:.2f} s\n{status}, min distance "
            f"{_min_distance(log)[k]:.3f} m, f = {log['f'][k]:.2f}")


def fig_snapshots(number: int | None, run: _Run):
    """Figs. 7 and 12: three 3D snapshots of the robot, the operator and the path."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MultipleLocator
    fig = Figure(figsize=(14, 5.8))   # 3D axes: explicit margins, not constrained layout
    fig.subplots_adjust(left=0.0, right=0.96, bottom=0.1, top=0.82, wspace=0.08)
    ticks = snapshot_ticks(run.log)
    lim = _scene_limits(run, ticks)
    for n, k in enumerate(ticks):
        ax = fig.add_subplot(1, 3, n + 1, projection="3d")
        _draw_scene(ax, run, k)
        ax.set(xlim=lim[0], ylim=lim[1], zlim=lim[2], xlabel="x (m)", ylabel="y (m)",
               zlabel="z (m)")
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_major_locator(MultipleLocator(0.2))
        ax.set_box_aspect(np.ptp(lim, axis=1), zoom=0.9)      # equal scale on x, y, z
        ax.set_proj_type("ortho")
        ax.view_init(*VIEWS.get(run.scenario, VIEWS["other"]))
        ax.set_title(_panel_title(run, k, n), fontsize=10)
    fig.legend(handles=_scene_legend(run), loc="lower center", ncol=5, fontsize=9)
    text = f"the robot, its {run.method} and the operator"
    _title(fig, run, f"Fig. {number}: {text}" if number else text.capitalize())
    return fig


#: Builder of each figure file from a run.
BUILDERS = {
    "fig06_f_vs_distance.png": fig_f_vs_distance,
    "fig07_snapshots.png": partial(fig_snapshots, 7),
    "fig08_distance_L2.png": partial(fig_distance, "L2", 8),
    "fig09_vrep_L2.png": partial(fig_vrep, "L2", 9),
    "fig10_distance_EE.png": partial(fig_distance, "EE", 10),
    "fig11_vrep_EE.png": partial(fig_vrep, "EE", 11),
    "fig12_snapshots.png": partial(fig_snapshots, 12),
    "fig13_f_and_L1.png": fig_f_and_l1,
    "timeline.png": fig_timeline,
    "snapshots.png": partial(fig_snapshots, None),
}


# --------------------------------------------------------------------------- comparison

def write_comparison(path: Path, label: str, series: dict) -> None:
    """Minimum distance and path error over time of every (controller, distance) run."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(9, 6), layout="constrained")
    a1, a2 = fig.subplots(2, 1, sharex=True)
    styles = {"analytic": "-", "qp": "--"}
    colors = {"spheres": "C0", "capsules": "C1"}
    for (ctrl, dist), s in series.items():
        kw = {"ls": styles.get(ctrl, "-"), "color": colors.get(dist, "k"), "lw": 1.3,
              "label": f"{ctrl} controller, {dist}"}
        a1.plot(s["t"], s["min_distance"], **kw)
        a2.plot(s["t"], np.asarray(s["path_error"]) * 1e3, **kw)
    stop = AvoidanceConfig().d_stop_L2_m
    a1.axhline(stop, color="r", lw=0.9, ls=":", label=f"stop distance {stop:g} m (L2, EE)")
    a1.set_ylabel("min distance (m)\n(each run's own method)")
    a2.set(ylabel="path error (mm)", xlabel="time (s)")
    a1.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    for a in (a1, a2):
        a.grid(alpha=0.3)
    fig.suptitle(f"{SCENARIO_TITLES.get(label, label)}: analytic (solid) vs QP (dashed) "
                 "controller, spheres (blue) vs capsules (orange)")
    fig.savefig(path, dpi=DPI)
