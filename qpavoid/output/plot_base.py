"""What every figure shares: the run it is drawn from, the styles, titles, legends, the
colours of any number of sets and the words for the stop rules of each role."""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.arm.roles import ROLE_NAMES
from qpavoid.human.body import BodyModel, KinectHuman
from qpavoid.laws.avoidance import AvoidanceConfig, set_stop_distances, stop_distances

SCENARIO_TITLES = {"test1": "Test 1", "test2": "Test 2"}
#: Styles: the "robot stopped" shading, the planned path and the end-effector trace.
STOP: dict[str, Any] = {"color": "red", "alpha": 0.12, "lw": 0}
PATH: dict[str, Any] = {"color": "C2", "lw": 4, "alpha": 0.45}
TRACE: dict[str, Any] = {"color": "k", "lw": 1.2}
#: What each role's set is called in labels (the description's roles, docs/robot.md).
ROLE_WORDS = {
    "scaled": "scaled set",
    "repelled": "repelled set",
    "end_effector": "end-effector set",
}
#: A repulsive speed below this is drawn as 0, m/s: the laws' logistic is never exactly 0,
#: and far from the person its 1e-9 m/s of numerical noise would fill an autoscaled axis
#: as if the robot were being pushed (a micrometre a second moves nothing visibly).
SPEED_FLOOR_MPS = 1e-6
#: The repulsive-speed axes reach at least this high, m/s (1 cm/s: what is below it reads
#: as the flat line it is).
SPEED_AXIS_MIN_MPS = 0.01


@dataclass(frozen=True)
class Run:
    """What every figure needs: the log and how it was produced (``human``: the body model
    whose parts the snapshots draw, the paper's on the Kinect v2 unless the run had
    another)."""

    log: dict
    robot: Robot
    cfg: AvoidanceConfig
    method: str
    scenario: str
    controller: str
    human: BodyModel = field(default_factory=KinectHuman)

    @property
    def subtitle(self) -> str:
        """E.g. ``"Test 1 · analytic controller · spheres"``."""
        parts = (
            SCENARIO_TITLES.get(self.scenario, self.scenario),
            f"{self.controller} controller" if self.controller else "",
            self.method,
        )
        return " · ".join(p for p in parts if p)

    def column(self, name: str) -> np.ndarray:
        """Distance of control set ``name`` over time, NaN where it was not measured."""
        d = self.log["distance"][:, self.robot.set_index(name)]
        return np.where(np.isfinite(d), d, np.nan)

    def role_column(self, role: str) -> np.ndarray:
        """:meth:`column` of the set playing ``role`` (``"scaled"``, ``"repelled"``, ...)."""
        return self.column(self.robot.role_name(role))


def set_colours(n: int) -> list[Any]:
    """A colour for each of ``n`` sets: matplotlib's default cycle (tab10: ``C0``, ``C1``,
    ... as every other figure of a set) for up to ten, tab20 for up to twenty, evenly
    spaced hues of ``turbo`` beyond (no two sets alike, however many)."""
    from matplotlib import colormaps

    if n <= 10:
        return [f"C{k}" for k in range(n)]
    if n <= 20:
        return [colormaps["tab20"](k) for k in range(n)]
    return [colormaps["turbo"](x) for x in np.linspace(0.05, 0.95, n)]


def role_label(robot: Robot, role: str) -> str:
    """``"repelled set L2"``: the part a set plays and its name in the description."""
    return f"{ROLE_WORDS[role]} {robot.role_name(role)}"


def stop_rules_note(run: Run) -> str:
    """The stop rules of every set, by the role it plays (paper Sect. 5.4), as one caption:
    the scaled set stops on f > f_stop (its distance below ``d_stop_L1_m()``, eq. 2
    inverted), the repelled and end-effector sets within their stop distances, a set
    with no role at contact (:func:`~qpavoid.laws.avoidance.set_stop_distances`)."""
    cfg, robot = run.cfg, run.robot
    by_role = dict(zip(ROLE_NAMES, stop_distances(cfg).tolist(), strict=True))
    scaled = f"{role_label(robot, 'scaled')}: f > {cfg.f_stop:g} (d < {cfg.d_stop_L1_m():.3f} m)"
    groups: dict[float, list[str]] = {}
    for role in ("repelled", "end_effector"):
        groups.setdefault(by_role[role], []).append(role_label(robot, role))
    rules = [scaled] + [f"{' and '.join(who)}: d ≤ {d:g} m" for d, who in groups.items()]
    stops = set_stop_distances(cfg, robot.roles, len(robot.sets))
    idle = [n for k, n in enumerate(robot.set_names) if k not in robot.roles.rows]
    if idle:
        contact = min(stops[robot.set_index(n)] for n in idle)
        rules.append(f"sets with no role ({', '.join(idle)}): contact, d ≤ {contact:g} m")
    return "Stop rules by role: " + "; ".join(rules) + "."


def speed_for_axis(v: np.ndarray) -> np.ndarray:
    """``v`` (m/s) with values below :data:`SPEED_FLOOR_MPS` set to 0 (NaN kept)."""
    v = np.asarray(v, dtype=float)
    return np.where(v < SPEED_FLOOR_MPS, 0.0, v)


def speed_axis(ax: Any, *speeds: np.ndarray) -> Any:
    """Put the speed axis at 0..max(:data:`SPEED_AXIS_MIN_MPS`, 1.05 × the largest of
    ``speeds``); return the legend entry that says so."""
    from matplotlib.lines import Line2D

    top = max((np.nanmax(s, initial=0.0) for s in speeds), default=0.0)
    ax.set_ylim(0.0, max(SPEED_AXIS_MIN_MPS, 1.05 * float(top)))
    return Line2D(
        [],
        [],
        ls="none",
        label=f"below {SPEED_FLOOR_MPS:g} m/s drawn as 0;\n"
        f"axis at least 0-{SPEED_AXIS_MIN_MPS:g} m/s",
    )


def finish(ax: Any, ylabel: str, *extra: Any) -> None:
    """Label, grid and a legend outside the axes (never over the data)."""
    handles = ax.get_legend_handles_labels()[0] + list(extra)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)


def set_title(fig: Any, run: Run, text: str) -> None:
    """The figure's title, with the scenario, controller and method on a second line."""
    fig.suptitle(f"{text}\n{run.subtitle}" if run.subtitle else text)


#: Characters per line of a caption (8 pt on the figures' 8.5 inch width).
CAPTION_WIDTH = 130


def set_caption(fig: Any, text: str) -> None:
    """A caption under the figure, wrapped to :data:`CAPTION_WIDTH` characters a line (the
    constrained layout keeps room for it)."""
    fig.supxlabel(textwrap.fill(text, CAPTION_WIDTH), fontsize=8, color="0.25")
