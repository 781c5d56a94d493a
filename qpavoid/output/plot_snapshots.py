"""The 3D snapshots (paper Figs. 7 and 12): the robot, its volumes, the operator, the path.

Each panel draws what the distances used at that tick, as solids: the robot's capsules
(or spheres, eq. 1) around its links, the operator's body parts as the run's body model
covers them (:mod:`qpavoid.human.body`: a capsule per part, the head's among them, or
the parts' spheres) with the joints they hang on, the robot's base (the URDF's collision
objects on the base, as the smallest upright cylinder holding them) on the table (the
plane z = 0 of the base, translucent: the seated operator's hips are below it), the
planned path and the end-effector trace. Nothing is sized from a particular arm: the
axes hold what is drawn, with ticks spaced for its size.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from qpavoid.arm.model import Robot
from qpavoid.core.geometry import unit
from qpavoid.output.arm_shapes import arm_parts, base_extent
from qpavoid.output.plot_base import PATH, TRACE, Run, set_title

#: Snapshot viewpoint (elevation, azimuth), degrees: Fig. 12 is an upper side view.
VIEWS = {"test1": (25.0, -60.0), "test2": (40.0, 150.0), "other": (25.0, -60.0)}
#: Colours and opacities of the solids: the robot's volumes, the operator's parts, the
#: base and the table.
ROBOT: dict[str, Any] = {"color": "C0", "alpha": 0.35}
PERSON: dict[str, Any] = {"color": "C3", "alpha": 0.45}
BASE: dict[str, Any] = {"color": "0.35", "alpha": 0.8}
TABLE: dict[str, Any] = {"color": "tan", "alpha": 0.18}
#: Points around a circle and along a half circle of a drawn capsule or sphere.
AROUND, ALONG = 16, 6
#: Room around what is drawn, m.
MARGIN_M = 0.05


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


def capsule_grid(a: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    """Surface grid (3, AROUND, 2 ALONG) of the capsule of radius ``r`` about segment ab
    (a sphere if a = b): the circles of its profile, from the cap beyond a to the cap
    beyond b. With axis n = (b − a)/‖b − a‖ and e1, e2 completing it, the point at angle φ
    on the circle at latitude θ is

        c + r sin θ n + r cos θ (cos φ e1 + sin φ e2),

    c = a for θ ∈ [−π/2, 0] and c = b for θ ∈ [0, π/2].
    """
    axis = unit(b - a, fallback=np.array([0.0, 0.0, 1.0]))
    e1 = unit(np.cross(axis, [1.0, 0, 0] if abs(axis[0]) < 0.9 else [0, 1.0, 0]))
    e2 = np.cross(axis, e1)
    phi = np.linspace(0.0, 2.0 * np.pi, AROUND)
    ring = np.outer(e1, np.cos(phi)) + np.outer(e2, np.sin(phi))  # (3, AROUND)
    theta = np.r_[np.linspace(-np.pi / 2, 0.0, ALONG), np.linspace(0.0, np.pi / 2, ALONG)]
    centre = np.where((np.arange(2 * ALONG) < ALONG)[:, None], a, b)  # (2 ALONG, 3)
    along = centre + r * np.sin(theta)[:, None] * axis  # (2 ALONG, 3)
    return along.T[:, None, :] + r * np.cos(theta)[None, None, :] * ring[:, :, None]


def _cylinder_grid(radius: float, height: float) -> np.ndarray:
    """Surface grid (3, AROUND, 4) of the upright cylinder on the table about the base's
    z axis, closed at the top (its rim shrinks to the axis)."""
    phi = np.linspace(0.0, 2.0 * np.pi, AROUND)
    rho = np.array([radius, radius, radius, 0.0])
    z = np.array([0.0, 0.0, height, height])
    return np.stack(
        [np.outer(np.cos(phi), rho), np.outer(np.sin(phi), rho), np.tile(z, (AROUND, 1))]
    )


def _robot_volumes(run: Run, q: np.ndarray) -> list[np.ndarray]:
    """Surface grids of the robot's spheres (eq. 1) or capsules at ``q``."""
    robot = run.robot
    if run.method == "spheres":
        return [
            capsule_grid(p, p, r)
            for p, r in zip(robot.control_points(q), robot.sphere_radii, strict=True)
        ]
    return [
        capsule_grid(a, b, r)
        for (a, b), r in zip(robot.capsules(q), robot.capsule_radii, strict=True)
    ]


def _person(run: Run, k: int) -> tuple[list[np.ndarray], np.ndarray]:
    """The operator at tick ``k`` as the run's body model covers it: surface grids of its
    parts (capsules, or the parts' spheres with the spheres method) and (N, 3) the usable
    joints its parts hang on."""
    human = run.human
    joints, state = run.log["joints"][k], run.log["state"][k]
    geo = human.geometry(joints, state)
    if run.method != "spheres":
        grids = [
            capsule_grid(a, b, r)
            for (a, b), r, ok in zip(
                geo.segments, human.capsule_radii, geo.segment_valid, strict=True
            )
            if ok
        ]
    else:
        radii = human.sphere_radii[np.argmax(human.point_part, axis=1)]
        grids = [
            capsule_grid(p, p, r)
            for p, r, ok in zip(geo.points, radii, geo.point_valid, strict=True)
            if ok
        ]
    used = human.part_joints().any(axis=0)
    shown = np.asarray(joints, dtype=float)[used]
    return grids, shown[np.isfinite(shown).all(axis=1)]


def _person_extent(run: Run, ticks: list[int]) -> np.ndarray:
    """(N, 3) the ends of the operator's usable parts at ``ticks``, widened by the largest
    radius of the model along every axis (what the panels must hold)."""
    human = run.human
    r = float(max(human.capsule_radii.max(), human.sphere_radii.max()))
    ends = []
    for k in ticks:
        geo = human.geometry(run.log["joints"][k], run.log["state"][k])
        ends.append(geo.segments[geo.segment_valid].reshape(-1, 3))
    points = np.vstack([np.zeros((0, 3)), *ends])
    cube = np.array([[x, y, z] for x in (-r, r) for y in (-r, r) for z in (-r, r)])
    return (points[:, None, :] + cube[None]).reshape(-1, 3)


def _draw_scene(ax: Any, run: Run, k: int, lim: np.ndarray, base: tuple[float, float]) -> None:
    log = run.log
    (x0, x1), (y0, y1) = lim[0], lim[1]
    ax.plot_surface(*np.meshgrid([x0, x1], [y0, y1]), np.zeros((2, 2)), **TABLE, shade=False)
    if base[1] > 0:
        ax.plot_surface(*_cylinder_grid(*base), **BASE, shade=True)
    ax.plot(*log["ee_ref"].T, **PATH)
    ax.plot(*log["ee_pos"][: k + 1].T, **TRACE)
    ax.plot(*_chain(run.robot, log["q"][k]).T, "-o", color="C0", lw=2, ms=2.5)
    for grid in _robot_volumes(run, log["q"][k]):
        ax.plot_surface(*grid, **ROBOT, lw=0, shade=True)
    grids, joints = _person(run, k)
    for grid in grids:
        ax.plot_surface(*grid, **PERSON, lw=0, shade=True)
    ax.scatter(*joints.T, color="k", s=5, depthshade=False)


def _scene_limits(run: Run, ticks: list[int], base: tuple[float, float]) -> np.ndarray:
    """Axis limits (3, 2) holding the robot with its volumes, the operator's parts, the
    base and the path at ``ticks``."""
    reach = float(max(run.robot.capsule_radii.max(), run.robot.sphere_radii.max()))
    arm = [_chain(run.robot, run.log["q"][k]) for k in ticks]
    arm_box = np.vstack(arm)[:, None, :] + reach * np.array(
        [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    )
    radius, height = base
    base_box = np.array([[-radius, -radius, 0.0], [radius, radius, height]])
    pts = np.vstack(
        [run.log["ee_ref"], arm_box.reshape(-1, 3), _person_extent(run, ticks), base_box]
    )
    pts = pts[np.isfinite(pts).all(axis=1)]
    return np.stack([pts.min(axis=0) - MARGIN_M, pts.max(axis=0) + MARGIN_M], axis=1)


def tick_step_m(lim: np.ndarray) -> float:
    """Spacing of the axis ticks, m: 0.1 for a scene under 0.8 m across, 0.2 under 2 m,
    0.5 beyond (about four to ten ticks an axis, whatever the arm's size)."""
    span = float(np.ptp(lim, axis=1).max())
    return 0.1 if span < 0.8 else 0.2 if span < 2.0 else 0.5


def _scene_legend(run: Run, base: tuple[float, float]) -> list[Any]:
    """The snapshots' legend (the base's entry where the URDF puts something on it)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    volumes = "spheres (eq. 1)" if run.method == "spheres" else "capsules"
    return [
        Line2D([], [], color="C0", lw=2, marker="o", ms=2.5, label="robot links"),
        Patch(**ROBOT, label=f"robot {volumes}"),
        Patch(**PERSON, label=f"operator: body-model {volumes}"),
        Line2D([], [], color="k", ls="none", marker="o", ms=2.5, label="operator joints"),
        *([Patch(**BASE, label="robot base")] if base[1] > 0 else []),
        Patch(color=TABLE["color"], alpha=0.5, label="table (z = 0)"),
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

    fig = Figure(figsize=(14, 6.2))  # 3D axes: explicit margins, not constrained layout
    fig.subplots_adjust(left=0.0, right=0.96, bottom=0.13, top=0.82, wspace=0.08)
    ticks = snapshot_ticks(run.log)
    largest = float(max(run.robot.capsule_radii.max(), run.robot.sphere_radii.max()))
    base = base_extent(arm_parts(run.robot), largest)
    lim = _scene_limits(run, ticks, base)
    step = tick_step_m(lim)
    for n, k in enumerate(ticks):
        ax = fig.add_subplot(1, 3, n + 1, projection="3d")
        _draw_scene(ax, run, k, lim, base)
        ax.set(
            xlim=lim[0], ylim=lim[1], zlim=lim[2], xlabel="x (m)", ylabel="y (m)", zlabel="z (m)"
        )
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_major_locator(MultipleLocator(step))
        ax.set_box_aspect(np.ptp(lim, axis=1), zoom=0.9)  # equal scale on x, y, z
        ax.set_proj_type("ortho")
        ax.view_init(*VIEWS.get(run.scenario, VIEWS["other"]))
        ax.set_title(_panel_title(run, k, n), fontsize=10)
    fig.legend(handles=_scene_legend(run, base), loc="lower center", ncol=4, fontsize=9)
    text = f"the robot, its {run.method} and the operator"
    set_title(fig, run, f"Fig. {number}: {text}" if number else text.capitalize())
    return fig
