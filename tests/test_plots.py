"""The figures: which files each scenario gets, and what a reader sees in them."""

from __future__ import annotations

import numpy as np
import pytest

import qpavoid
from qpavoid.output import plots
from qpavoid.scenarios.generated import make_scenario

pytest.importorskip("matplotlib")

EXPECTED = {
    "test1": {
        "fig06_f_vs_distance.png",
        "fig07_snapshots.png",
        "fig08_distance_L2.png",
        "fig09_vrep_L2.png",
        "fig10_distance_EE.png",
        "fig11_vrep_EE.png",
    },
    "test2": {"fig06_f_vs_distance.png", "fig12_snapshots.png", "fig13_f_and_L1.png"},
    "other": {"fig06_f_vs_distance.png", "timeline.png", "snapshots.png"},
}


@pytest.fixture(scope="module")
def log(robot):
    """4 s of test2 at 100 Hz: the hand comes in and the robot stops at about 3 s."""
    cfg = qpavoid.ControllerConfig(distance="spheres", control_period_s=0.01)
    ctrl = qpavoid.AnalyticController(robot, config=cfg)
    sim = qpavoid.SimConfig(control_rate_hz=100, max_time_s=4)
    result = qpavoid.simulate(ctrl, make_scenario("test2", robot), sim)
    assert result.log["stopped"].any() and not result.log["stopped"].all()
    return result.log


def _legend(ax) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


@pytest.mark.parametrize(
    "scenario, kind",
    [
        ("test1", "test1"),
        ("test2", "test2"),
        ("free", "other"),
        pytest.param("random:3", "other", marks=pytest.mark.slow),  # as free's: with the slow
        pytest.param("", "other", marks=pytest.mark.slow),
    ],
)
def test_each_scenario_writes_its_figures(tmp_path, log, robot, scenario, kind):
    paths = plots.write_figures(
        tmp_path, log, robot, None, "spheres", scenario=scenario, controller="analytic"
    )
    assert {p.name for p in paths} == EXPECTED[kind] and len(paths) == len(EXPECTED[kind])
    assert paths == [tmp_path / n for n in plots.figures_for(scenario, robot)]
    assert {p.name for p in tmp_path.iterdir()} == EXPECTED[kind]
    assert all(p.stat().st_size > 10_000 for p in paths)


def test_old_positional_call_still_works(tmp_path, log, robot):
    paths = plots.write_figures(tmp_path, log, robot, qpavoid.AvoidanceConfig(), "capsules")
    assert {p.name for p in paths} == EXPECTED["other"]


def test_titles_name_scenario_controller_and_method(log, robot):
    figs = plots.build_figures(log, robot, None, "capsules", scenario="test1", controller="qp")
    for name, fig in figs.items():
        assert "Test 1 · qp controller · capsules" in fig.get_suptitle(), name
    figs = plots.build_figures(log, robot, None, "spheres", scenario="free")
    for name, fig in figs.items():
        title = fig.get_suptitle()
        assert title.endswith("\nfree · spheres") and "controller" not in title, name


def test_thresholds_and_stop_shading_have_legend_entries(log, robot):
    figs = plots.build_figures(log, robot, None, "spheres", scenario="test1")
    legend = _legend(figs["fig08_distance_L2.png"].axes[0])
    assert {"stop distance 0.05 m", "repulsion starts (ρ = 0.2 m)", "robot stopped"} <= set(legend)
    assert any("30 Hz" in text for text in legend)
    f_axes, d_axes = plots.build_figures(log, robot, scenario="test2")["fig13_f_and_L1.png"].axes
    assert {"stop: f > 0.8", "robot stopped"} <= set(_legend(f_axes))
    assert "f = 0.8 at 0.042 m" in _legend(d_axes)
    fig6 = _legend(figs["fig06_f_vs_distance.png"].axes[0])
    assert {"this run", "robot stops: f > 0.8", "f = 0.8 at d = 0.042 m"} <= set(fig6)


def test_fig6_says_when_the_run_never_came_near(log, robot):
    far = dict(log, distance=log["distance"] + 1.0)
    ax = plots.build_figures(far, robot, scenario="test2")["fig06_f_vs_distance.png"].axes[0]
    legend = _legend(ax)
    assert "this run" not in legend
    assert any(t.startswith("this run: all d > 0.25 m") for t in legend)
    # The legend sits outside the axes: it cannot hide the curve or the samples.
    fig = ax.figure
    fig.canvas.draw()
    box = ax.get_legend().get_window_extent()
    assert box.x0 >= ax.get_window_extent().x1


def test_snapshots_label_every_axis_and_share_one_legend(log, robot):
    figs = plots.build_figures(log, robot, scenario="test2", controller="analytic")
    fig = figs["fig12_snapshots.png"]
    assert len(fig.axes) == 3
    for ax in fig.axes:
        assert (ax.get_xlabel(), ax.get_ylabel(), ax.get_zlabel()) == ("x (m)", "y (m)", "z (m)")
        assert (ax.elev, ax.azim) == plots.VIEWS["test2"]
    titles = [ax.get_title() for ax in fig.axes]
    assert titles[0].startswith("a) start") and titles[1].startswith("b) first stop")
    assert titles[2].startswith("c) end")
    (legend,) = fig.legends
    texts = [t.get_text() for t in legend.get_texts()]
    assert texts == [
        "robot links",
        "robot spheres (eq. 1)",
        "operator (Kinect skeleton)",
        "planned path",
        "end-effector trace",
    ]
    assert plots.snapshot_ticks(log)[1] == int(np.flatnonzero(log["stopped"])[0])
