"""The 3D snapshots (paper Figs. 7 and 12): the robot, its volumes, the operator, the path."""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from qpavoid.arm.model import Robot
from qpavoid.core.geometry import unit
from qpavoid.output.plot_base import PATH, TRACE, Run, set_title

#: Snapshot viewpoint (elevation, azimuth), degrees: Fig. 12 is an upper side view.
VIEWS = {"test1": (25.0, -60.0), "test2": (40.0, 150.0), "other": (25.0, -60.0)}
#: Bones of the Kinect skeleton drawn in the snapshots (upper body).
BONES = (
    (0, 1),
    (1, 20),
    (20, 2),
    (2, 3),
    (20, 4),
    (4, 5),
    (5, 6),
    (6, 7),
    (20, 8),
    (8, 9),
    (9, 10),
    (10, 11),
)


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
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    joints = [data.oMi[i].translation for i in range(1, robot.model.njoints)]
    return np.array([np.zeros(3), *joints, data.oMf[robot.ee_frame].translation])


def _ball(p: np.ndarray, r: float) -> np.ndarray:
    """Wireframe grid (3, 13, 7) of a sphere."""
    u, v = np.mgrid[0 : 2 * np.pi : 13j, 0 : np.pi : 7j]
    sphere = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)])
    return p[:, None, None] + r * sphere


def _tube(a: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    """Wireframe grid (3, 13, 2) of the cylinder of radius ``r`` around segment ab."""
    axis = unit(b - a, floor=1e-9)
    e1 = unit(np.cross(axis, [1.0, 0, 0] if abs(axis[0]) < 0.9 else [0, 1.0, 0]))
    th = np.linspace(0, 2 * np.pi, 13)
    ring = r * (np.outer(e1, np.cos(th)) + np.outer(np.cross(axis, e1), np.sin(th)))
    return np.stack([a[:, None] + ring, b[:, None] + ring], axis=2)


def _volumes(run: Run, q: np.ndarray) -> list[np.ndarray]:
    """Wireframe grids of the robot's spheres (eq. 1) or capsules at ``q``."""
    if run.method != "capsules":
        return [
            _ball(p, r)
            for p, r in zip(run.robot.control_points(q), run.robot.sphere_radii, strict=True)
        ]
    return [
        g
        for (a, b), r in zip(run.robot.capsules(q), run.robot.capsule_radii, strict=True)
        for g in (_tube(a, b, r), _ball(a, r), _ball(b, r))
    ]


def _skeleton(log: dict, k: int) -> list[np.ndarray]:
    """The operator's bones (2, 3) at tick ``k``, tracked joints only."""
    joints, state = log["joints"][k], log["state"][k]
    usable = np.isfinite(joints).all(axis=1) & (state > 0)
    return [joints[[a, b]] for a, b in BONES if usable[a] and usable[b]]


def _draw_scene(ax: Any, run: Run, k: int) -> None:
    log = run.log
    ax.plot(*log["ee_ref"].T, **PATH)
    ax.plot(*log["ee_pos"][: k + 1].T, **TRACE)
    ax.plot(*_chain(run.robot, log["q"][k]).T, "-o", color="C0", lw=3, ms=3)
    for grid in _volumes(run, log["q"][k]):
        ax.plot_wireframe(*grid, color="C0", lw=0.3, alpha=0.45)
    for bone in _skeleton(log, k):
        ax.plot(*bone.T, color="C3", lw=2)


def _scene_limits(run: Run, ticks: list[int]) -> np.ndarray:
    """Axis limits (3, 2) holding the robot, the operator and the path at ``ticks``."""
    parts = [run.log["ee_ref"], *(_chain(run.robot, run.log["q"][k]) for k in ticks)]
    pts = np.vstack(parts + [b for k in ticks for b in _skeleton(run.log, k)])
    return np.stack([pts.min(axis=0) - 0.12, pts.max(axis=0) + 0.12], axis=1)


def _scene_legend(run: Run) -> list[Any]:
    from matplotlib.lines import Line2D

    volumes = "capsules" if run.method == "capsules" else "spheres (eq. 1)"
    return [
        Line2D([], [], color="C0", lw=3, marker="o", ms=3, label="robot links"),
        Line2D([], [], color="C0", lw=0.6, alpha=0.6, label=f"robot {volumes}"),
        Line2D([], [], color="C3", lw=2, label="operator (Kinect skeleton)"),
        Line2D([], [], **PATH, label="planned path"),
        Line2D([], [], **TRACE, label="end-effector trace"),
    ]


def _panel_title(run: Run, k: int, n: int) -> str:
    log = run.log
    what = ("start", "first stop" if log["stopped"].any() else "closest approach", "end")[n]
    status = "stopped" if log["stopped"][k] else "moving"
    return (
        f"{'abc'[n]}) {what}, t = {log['t'][k]:.2f} s\n{status}, min distance "
        f"{_min_distance(log)[k]:.3f} m, f = {log['f'][k]:.2f}"
    )


def fig_snapshots(number: int | None, run: Run) -> Any:
    """Figs. 7 and 12: three 3D snapshots of the robot, the operator and the path."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MultipleLocator

    fig = Figure(figsize=(14, 5.8))  # 3D axes: explicit margins, not constrained layout
    fig.subplots_adjust(left=0.0, right=0.96, bottom=0.1, top=0.82, wspace=0.08)
    ticks = snapshot_ticks(run.log)
    lim = _scene_limits(run, ticks)
    for n, k in enumerate(ticks):
        ax = fig.add_subplot(1, 3, n + 1, projection="3d")
        _draw_scene(ax, run, k)
        ax.set(
            xlim=lim[0], ylim=lim[1], zlim=lim[2], xlabel="x (m)", ylabel="y (m)", zlabel="z (m)"
        )
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_major_locator(MultipleLocator(0.2))
        ax.set_box_aspect(np.ptp(lim, axis=1), zoom=0.9)  # equal scale on x, y, z
        ax.set_proj_type("ortho")
        ax.view_init(*VIEWS.get(run.scenario, VIEWS["other"]))
        ax.set_title(_panel_title(run, k, n), fontsize=10)
    fig.legend(handles=_scene_legend(run), loc="lower center", ncol=5, fontsize=9)
    text = f"the robot, its {run.method} and the operator"
    set_title(fig, run, f"Fig. {number}: {text}" if number else text.capitalize())
    return fig
