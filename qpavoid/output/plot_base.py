"""What every figure shares: the run it is drawn from, the styles, titles and legends."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.laws.avoidance import AvoidanceConfig

SCENARIO_TITLES = {"test1": "Test 1", "test2": "Test 2"}
#: Styles: the "robot stopped" shading, the planned path and the end-effector trace.
STOP: dict[str, Any] = {"color": "red", "alpha": 0.12, "lw": 0}
PATH: dict[str, Any] = {"color": "C2", "lw": 4, "alpha": 0.45}
TRACE: dict[str, Any] = {"color": "k", "lw": 1.2}


@dataclass(frozen=True)
class Run:
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


def finish(ax: Any, ylabel: str, *extra: Any) -> None:
    """Label, grid and a legend outside the axes (never over the data)."""
    handles = ax.get_legend_handles_labels()[0] + list(extra)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)


def set_title(fig: Any, run: Run, text: str) -> None:
    """The figure's title, with the scenario, controller and method on a second line."""
    fig.suptitle(f"{text}\n{run.subtitle}" if run.subtitle else text)
