"""The paper's figures from a run's log (needs the ``plot`` extra: matplotlib).

Each scenario gets the figures that belong to it (:data:`FIGURES_BY_SCENARIO`):

* ``test1`` (paper Sect. 6.1): Fig. 6, Fig. 7 snapshots, Figs. 8-11 (distance and
  repulsive speed |v_rep| of the repelled and end-effector sets, L2 and EE, against time);
* ``test2`` (paper Sect. 6.2): Fig. 6, Fig. 12 snapshots (the paper's upper side view),
  Fig. 13 (f and the scaled set's, L1's, distance against time);
* any other run (``free``, ``random:SEED``, a recording, ""): Fig. 6, ``timeline.png``
  (distances per set, |v_rep| and f against time, stacked) and ``snapshots.png``.

Fig. 6 is f of eq. (2) against the scaled set's distance with the run's samples. The
figures' file names and labels name the sets as the robot description does
(``fig08_distance_L2.png`` for the iiwa), for any number of sets. The snapshots show the
robot (links, and its capsules or spheres as solids), its base on the table, the operator
as the run's body model covers it (its parts' capsules or spheres, the head's among them,
and its joints), the planned path and the end-effector trace at the start, the first stop
(or closest approach) and the end.

Every title names the scenario, controller and distance method; every threshold line and
the red "robot stopped" shading has a legend entry, each stop threshold names the role
whose rule it is (scaled set: f > 0.8; repelled and end-effector sets: 0.05 m), and the
figures with one carry all the rules as a caption; legends sit outside the axes.
Repulsive speeds below 1e-6 m/s are drawn as 0, on an axis at least 0-0.01 m/s. The steps
in the curves are the 30 Hz camera frames, held while the robot moves at the control rate
(see docs/analytic.md). ``compare_<input>.png`` says what a sphere distance below 0 is
(the spheres of eq. 1 overlapping the person, not contact). docs/figures.md describes each.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.arm.roles import ROLE_NAMES
from qpavoid.human.body import BodyModel, KinectHuman
from qpavoid.laws.avoidance import AvoidanceConfig
from qpavoid.output.plot_base import (
    PATH,
    ROLE_WORDS,
    SCENARIO_TITLES,
    STOP,
    TRACE,
    Run,
    finish,
    role_label,
)
from qpavoid.output.plot_snapshots import VIEWS, fig_snapshots, snapshot_ticks
from qpavoid.output.plot_time import (
    F6_D_MAX_M,
    fig_distance,
    fig_f_and_l1,
    fig_f_vs_distance,
    fig_timeline,
    fig_vrep,
)

__all__ = [
    "BUILDERS",
    "DPI",
    "F6_D_MAX_M",
    "FIGURES_BY_SCENARIO",
    "PATH",
    "SCENARIO_TITLES",
    "STOP",
    "TRACE",
    "VIEWS",
    "available",
    "build_figures",
    "comparison_figure",
    "fig_distance",
    "fig_f_and_l1",
    "fig_f_vs_distance",
    "fig_snapshots",
    "fig_timeline",
    "fig_vrep",
    "figures_for",
    "snapshot_ticks",
    "write_comparison",
    "write_figures",
]

#: Figure files written per scenario; any scenario not listed gets those of "other". A
#: ``{role}`` in a name is the name of the set playing that part (:func:`figures_for`).
FIGURES_BY_SCENARIO: dict[str, tuple[str, ...]] = {
    "test1": (
        "fig06_f_vs_distance.png",
        "fig07_snapshots.png",
        "fig08_distance_{repelled}.png",
        "fig09_vrep_{repelled}.png",
        "fig10_distance_{end_effector}.png",
        "fig11_vrep_{end_effector}.png",
    ),
    "test2": ("fig06_f_vs_distance.png", "fig12_snapshots.png", "fig13_f_and_{scaled}.png"),
    "other": ("fig06_f_vs_distance.png", "timeline.png", "snapshots.png"),
}
DPI = 110
#: The band below 0 of ``compare_<input>.png`` reaches at least this far down, m (where a
#: sphere distance would fall, labelled even when none did).
OVERLAP_BAND_M = 0.02


def available() -> bool:
    """True if matplotlib can be imported."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def _templates(scenario: str) -> tuple[str, ...]:
    return FIGURES_BY_SCENARIO.get(scenario, FIGURES_BY_SCENARIO["other"])


def _file_name(template: str, robot: Robot) -> str:
    """A figure's file name for ``robot``: each ``{role}`` is the name of its set."""
    return template.format(**dict(zip(ROLE_NAMES, robot.role_names, strict=True)))


def figures_for(scenario: str, robot: Robot) -> tuple[str, ...]:
    """File names that :func:`write_figures` writes for ``scenario`` and ``robot``."""
    return tuple(_file_name(t, robot) for t in _templates(scenario))


def write_figures(
    out_dir: str | Path,
    log: dict,
    robot: Robot,
    avoidance: AvoidanceConfig | None = None,
    method: str = "spheres",
    *,
    scenario: str = "",
    controller: str = "",
    human: BodyModel | None = None,
) -> list[Path]:
    """Write the figures of a run into ``out_dir``; return their paths.

    Parameters
    ----------
    out_dir
        Folder (created if missing).
    log
        The run's log (:func:`qpavoid.loop.simulation.simulate`).
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
    human
        The run's body model (the operator's parts in the snapshots; default: the
        paper's on the Kinect v2, :class:`~qpavoid.human.body.KinectHuman`).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figures = build_figures(
        log, robot, avoidance, method, scenario=scenario, controller=controller, human=human
    )
    for name, fig in figures.items():
        fig.savefig(out / name, dpi=DPI)
    return [out / name for name in figures]


def build_figures(
    log: dict,
    robot: Robot,
    avoidance: AvoidanceConfig | None = None,
    method: str = "spheres",
    *,
    scenario: str = "",
    controller: str = "",
    human: BodyModel | None = None,
) -> dict:
    """The matplotlib Figures of :func:`write_figures`, by file name, not saved."""
    cfg = avoidance or AvoidanceConfig()
    run = Run(log, robot, cfg, method, scenario, controller, human or KinectHuman())
    return {_file_name(t, robot): BUILDERS[t](run) for t in _templates(scenario)}


#: Builder of each figure file (by its name's template) from a run.
BUILDERS: dict[str, Callable[[Run], Any]] = {
    "fig06_f_vs_distance.png": fig_f_vs_distance,
    "fig07_snapshots.png": partial(fig_snapshots, 7),
    "fig08_distance_{repelled}.png": partial(fig_distance, "repelled", 8),
    "fig09_vrep_{repelled}.png": partial(fig_vrep, "repelled", 9),
    "fig10_distance_{end_effector}.png": partial(fig_distance, "end_effector", 10),
    "fig11_vrep_{end_effector}.png": partial(fig_vrep, "end_effector", 11),
    "fig12_snapshots.png": partial(fig_snapshots, 12),
    "fig13_f_and_{scaled}.png": fig_f_and_l1,
    "timeline.png": fig_timeline,
    "snapshots.png": partial(fig_snapshots, None),
}


def write_comparison(path: Path, label: str, series: dict, robot: Robot | None = None) -> None:
    """Write :func:`comparison_figure` to ``path``."""
    comparison_figure(label, series, robot).savefig(path, dpi=DPI)


def comparison_figure(label: str, series: dict, robot: Robot | None = None) -> Any:
    """Minimum distance and path error over time of every (controller, distance) run.

    Each run's minimum distance is by its own method. The spheres of eq. (1) are larger
    than the arm's links (the iiwa's: 0.09 m around links of 0.06-0.07 m), so they reach
    the person first: a sphere distance below 0 is the spheres overlapping the person,
    not contact; the grey band below 0 says so. ``robot`` names the sets of the stop rule and
    gives the radii (without it, the rule is named by role).
    """
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    fig = Figure(figsize=(9, 6.4), layout="constrained")
    a1, a2 = fig.subplots(2, 1, sharex=True)
    styles = {"analytic": "-", "qp": "--"}
    colors = {"spheres": "C0", "capsules": "C1"}
    lowest = 0.0
    for (ctrl, dist), s in series.items():
        kw = {
            "ls": styles.get(ctrl, "-"),
            "color": colors.get(dist, "k"),
            "lw": 1.3,
            "label": f"{ctrl} controller, {dist}",
        }
        a1.plot(s["t"], s["min_distance"], **kw)
        a2.plot(s["t"], np.asarray(s["path_error"]) * 1e3, **kw)
        lowest = min(lowest, float(np.nanmin(s["min_distance"], initial=0.0)))
    cfg = AvoidanceConfig()
    if robot is None:
        who = f"{ROLE_WORDS['repelled']}s and {ROLE_WORDS['end_effector']}s"
    else:
        who = f"{role_label(robot, 'repelled')} and {role_label(robot, 'end_effector')}"
    for stop in sorted({cfg.d_stop_L2_m, cfg.d_stop_EE_m}):
        rule = f"stop distance {stop:g} m\n(rule of the {who})"
        a1.axhline(stop, color="r", lw=0.9, ls=":", label=rule)
    overlap = "spheres (eq. 1) below 0: the conservative\nspheres overlap the person, not contact"
    if robot is not None:
        spheres = np.unique(np.round(robot.sphere_radii, 3))
        links = np.round(robot.capsule_radii, 3)
        overlap += (
            f"\n(spheres {'/'.join(f'{r:g}' for r in spheres)} m around capsules "
            f"{links.min():g}-{links.max():g} m)"
        )
    band = Patch(color="0.5", alpha=0.15, label=overlap)
    a1.axhspan(min(1.1 * lowest, -OVERLAP_BAND_M), 0.0, color="0.5", alpha=0.15, lw=0)
    a1.axhline(0.0, color="0.3", lw=0.8)
    finish(a1, "min distance (m)\n(each run's own method)", band)
    a2.set(ylabel="path error (mm)", xlabel="time (s)")
    a2.grid(alpha=0.3)
    fig.suptitle(
        f"{SCENARIO_TITLES.get(label, label)}: analytic (solid) vs QP (dashed) "
        "controller, spheres (blue) vs capsules (orange)"
    )
    return fig
