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
(``fig08_distance_L2.png`` for the iiwa). The snapshots show
the robot (links and its spheres or capsules), the operator's skeleton, the planned path
and the end-effector trace at the start, the first stop (or closest approach) and the end.

Every title names the scenario, controller and distance method; every threshold line and
the red "robot stopped" shading has a legend entry, and legends sit outside the axes. The
steps in the curves are the 30 Hz camera frames, held while the robot moves at the control
rate (see docs/analytic.md).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from qpavoid.arm.description import ROLE_NAMES
from qpavoid.arm.model import Robot
from qpavoid.laws.avoidance import AvoidanceConfig
from qpavoid.output.plot_base import PATH, SCENARIO_TITLES, STOP, TRACE, Run, finish
from qpavoid.output.plot_snapshots import BONES, VIEWS, fig_snapshots, snapshot_ticks
from qpavoid.output.plot_time import (
    F6_D_MAX_M,
    fig_distance,
    fig_f_and_l1,
    fig_f_vs_distance,
    fig_timeline,
    fig_vrep,
)

__all__ = [
    "BONES",
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
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figures = build_figures(log, robot, avoidance, method, scenario=scenario, controller=controller)
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
) -> dict:
    """The matplotlib Figures of :func:`write_figures`, by file name, not saved."""
    run = Run(log, robot, avoidance or AvoidanceConfig(), method, scenario, controller)
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


def write_comparison(path: Path, label: str, series: dict) -> None:
    """Minimum distance and path error over time of every (controller, distance) run."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 6), layout="constrained")
    a1, a2 = fig.subplots(2, 1, sharex=True)
    styles = {"analytic": "-", "qp": "--"}
    colors = {"spheres": "C0", "capsules": "C1"}
    for (ctrl, dist), s in series.items():
        kw = {
            "ls": styles.get(ctrl, "-"),
            "color": colors.get(dist, "k"),
            "lw": 1.3,
            "label": f"{ctrl} controller, {dist}",
        }
        a1.plot(s["t"], s["min_distance"], **kw)
        a2.plot(s["t"], np.asarray(s["path_error"]) * 1e3, **kw)
    stop = AvoidanceConfig().d_stop_L2_m
    a1.axhline(stop, color="r", lw=0.9, ls=":", label=f"stop distance {stop:g} m (L2, EE)")
    finish(a1, "min distance (m)\n(each run's own method)")
    a2.set(ylabel="path error (mm)", xlabel="time (s)")
    a2.grid(alpha=0.3)
    fig.suptitle(
        f"{SCENARIO_TITLES.get(label, label)}: analytic (solid) vs QP (dashed) "
        "controller, spheres (blue) vs capsules (orange)"
    )
    fig.savefig(path, dpi=DPI)
