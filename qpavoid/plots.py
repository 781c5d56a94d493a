"""The paper's figures from a run's log (needs the ``plot`` extra: matplotlib).

* ``fig06_f_vs_distance.png``  f of eq. (2) against the L1 distance, and the run's samples;
* ``fig08_distance_L2.png``, ``fig09_vrep_L2.png``, ``fig10_distance_EE.png``,
  ``fig11_vrep_EE.png``  distance and repulsive speed against time for L2 and EE;
* ``fig13_f_and_L1.png``  f and the L1 distance against time;
* ``fig07_12_snapshots.png``  three 3D snapshots: the robot as a stick diagram with its
  spheres and the operator's skeleton, at the start, at the closest approach (or the first
  stop) and at the end.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .laws import AvoidanceConfig, l1_factor
from .robot import Robot

#: Bones of the Kinect skeleton drawn in the snapshots (upper body).
BONES = ((0, 1), (1, 20), (20, 2), (2, 3), (20, 4), (4, 5), (5, 6), (6, 7),
         (20, 8), (8, 9), (9, 10), (10, 11))


def available() -> bool:
    """True if matplotlib can be imported."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _stop_spans(ax, log):
    t, s = log["t"], log["stopped"]
    edges = np.flatnonzero(np.diff(np.r_[0, s.astype(int), 0]))
    for a, b in zip(edges[::2], edges[1::2]):
        ax.axvspan(t[a], t[min(b, len(t)) - 1], color="red", alpha=0.12, lw=0)


def _time_plot(plt, log, y, ylabel, title, path, hline=None):
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.plot(log["t"], y, lw=1.2)
    if hline is not None:
        ax.axhline(hline, color="k", ls="--", lw=0.8)
    _stop_spans(ax, log)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_figures(out_dir: str | Path, log: dict, robot: Robot, avoidance: AvoidanceConfig | None = None, method: str = "spheres") -> list[Path]:
    """Write the figures of a run into ``out_dir``; return their paths."""
    plt = _plt()
    cfg = avoidance or AvoidanceConfig()
    out = Path(out_dir)
    paths = []

    d = np.linspace(-0.02, 0.2, 500)
    fig, ax = plt.subplots(figsize=(6, 3.6))
    ax.plot(d, l1_factor(d, cfg), label=f"eq. (2), ρ = {cfg.rho_L1_m} m, α = {cfg.alpha_L1:g}")
    ax.scatter(log["distance"][::10, 0], log["f"][::10], s=4, color="C1", label="this run")
    ax.axhline(cfg.f_stop, color="r", ls="--", lw=0.8, label=f"stop: f > {cfg.f_stop}")
    ax.set_xlim(d[0], d[-1])
    ax.set_xlabel(f"L1 distance ‖d_L1,H‖ (m, {method})")
    ax.set_ylabel("f")
    ax.set_title("Fig. 6: the factor f against distance")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    paths.append(out / "fig06_f_vs_distance.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    for col, name, fig_d, fig_v, key, stop in ((1, "L2", 8, 9, "v_rep_L2", cfg.d_stop_L2_m),
                                              (2, "EE", 10, 11, "v_rep_EE", cfg.d_stop_EE_m)):
        paths.append(out / f"fig{fig_d:02d}_distance_{name}.png")
        _time_plot(plt, log, log["distance"][:, col], "distance (m)",
                   f"Fig. {fig_d}: distance between the operator and {name} ({method})",
                   paths[-1], hline=stop)
        paths.append(out / f"fig{fig_v:02d}_vrep_{name}.png")
        _time_plot(plt, log, np.linalg.norm(log[key], axis=1), "speed (m/s)",
                   f"Fig. {fig_v}: repulsive velocity of {name} (norm)", paths[-1])

    fig, ax = plt.subplots(figsize=(7, 3.4))
    ax.plot(log["t"], log["f"], color="C0", label="f")
    ax.axhline(cfg.f_stop, color="C0", ls="--", lw=0.8)
    ax.set_ylabel("f", color="C0")
    ax.set_ylim(-0.02, 1.02)
    ax2 = ax.twinx()
    ax2.plot(log["t"], log["distance"][:, 0], color="C1", label="L1 distance")
    ax2.set_ylabel("L1 distance (m)", color="C1")
    _stop_spans(ax, log)
    ax.set_xlabel("time (s)")
    ax.set_title("Fig. 13: f and the L1 distance (shaded: robot stopped)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    paths.append(out / "fig13_f_and_L1.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    paths.append(out / "fig07_12_snapshots.png")
    write_snapshots(paths[-1], log, robot)
    return paths


def snapshot_ticks(log: dict) -> list[int]:
    """Three telling ticks: the start, the closest approach (or first stop), the end."""
    stops = np.flatnonzero(log["stopped"])
    middle = int(stops[0]) if len(stops) else int(np.argmin(log["distance"].min(axis=1)))
    return [0, middle, len(log["t"]) - 1]


def write_snapshots(path: Path, log: dict, robot: Robot) -> None:
    """Robot stick diagram with spheres and the skeleton at :func:`snapshot_ticks`."""
    import pinocchio as pin
    plt = _plt()
    fig = plt.figure(figsize=(13, 4.6))
    u, v = np.mgrid[0:2 * np.pi:12j, 0:np.pi:7j]
    sphere = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)])
    for n, k in enumerate(snapshot_ticks(log)):
        ax = fig.add_subplot(1, 3, n + 1, projection="3d")
        q = log["q"][k]
        data = robot.model.createData()
        pin.forwardKinematics(robot.model, data, q)
        pin.updateFramePlacements(robot.model, data)
        chain = [np.zeros(3)] + [data.oMi[i].translation for i in range(1, robot.model.njoints)]
        chain.append(data.oMf[robot.ee_frame].translation)
        chain = np.array(chain)
        ax.plot(*chain.T, "-o", color="C0", lw=3, ms=3)
        P = robot.control_points(q)
        for p, r in zip(P, robot.sphere_radii):
            ax.plot_wireframe(*(p[:, None, None] + r * sphere), color="C0", lw=0.3, alpha=0.4)
        joints = log["joints"][k]
        usable = np.isfinite(joints).all(axis=1) & (log["state"][k] > 0)
        for a, b in BONES:
            if usable[a] and usable[b]:
                ax.plot(*joints[[a, b]].T, color="C3", lw=2)
        ax.plot(*log["ee_ref"][: k + 1].T, color="C2", lw=1, label="reference so far")
        status = "STOPPED" if log["stopped"][k] else "moving"
        ax.set_title(f"t = {log['t'][k]:.2f} s, {status}\nmin distance "
                     f"{log['distance'][k].min():.3f} m, f = {log['f'][k]:.2f}", fontsize=9)
        ax.set_xlim(-0.5, 0.7)
        ax.set_ylim(-0.2, 1.2)
        ax.set_zlim(-0.2, 1.0)
        ax.set_box_aspect((1.2, 1.4, 1.2))
        ax.view_init(elev=25, azim=-60)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    fig.suptitle("Figs. 7 and 12: robot (spheres of its control points) and operator")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_comparison(path: Path, label: str, series: dict) -> None:
    """Minimum distance and path error over time of every (controller, distance) run."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    styles = {"analytic": "-", "qp": "--"}
    colors = {"spheres": "C0", "capsules": "C1"}
    for (ctrl, dist), s in series.items():
        kw = dict(ls=styles.get(ctrl, "-"), color=colors.get(dist, "k"), lw=1.3,
                  label=f"{ctrl}, {dist}")
        a1.plot(s["t"], s["min_distance"], **kw)
        a2.plot(s["t"], np.asarray(s["path_error"]) * 1e3, **kw)
    a1.axhline(0.05, color="r", lw=0.8, ls=":")
    a1.set_ylabel("min distance (m)\n(own method)")
    a2.set_ylabel("path error (mm)")
    a2.set_xlabel("time (s)")
    a1.set_title(f"{label}: analytic (solid) vs QP (dashed)")
    a1.legend(fontsize=8, ncol=2)
    for a in (a1, a2):
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
