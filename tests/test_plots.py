"""The figures: which files each scenario gets, and what a reader sees in them."""

from __future__ import annotations

import shutil
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import qpavoid
from qpavoid.human.body import KinectHuman
from qpavoid.loop.run_log import repulsion_keys
from qpavoid.output import plots
from qpavoid.output.arm_shapes import arm_parts, base_extent
from qpavoid.output.plot_base import (
    SPEED_AXIS_MIN_MPS,
    SPEED_FLOOR_MPS,
    set_colours,
)
from qpavoid.output.plot_snapshots import capsule_grid, tick_step_m
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
        pytest.param("test2", "test2", marks=pytest.mark.slow),  # test1's figures, by kind
        pytest.param("free", "other", marks=pytest.mark.slow),
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


#: The caption of every figure with a stop threshold, for the iiwa (by hand: the scaled
#: set stops where f = 0.8, d = ρ/2 (1 + ln(1/0.8 − 1)/α) = 0.05 (1 − 0.154) = 0.0423 m).
IIWA_RULES = (
    "Stop rules by role: scaled set L1: f > 0.8 (d < 0.042 m); "
    "repelled set L2 and end-effector set EE: d ≤ 0.05 m."
)


def _caption(fig: Any) -> str:
    """The figure's caption (its ``supxlabel``) on one line; "" if it has none."""
    label = fig._supxlabel
    return "" if label is None else label.get_text().replace("\n", " ")


def test_thresholds_and_stop_shading_have_legend_entries(log, robot):
    figs = plots.build_figures(log, robot, None, "spheres", scenario="test1")
    legend = _legend(figs["fig08_distance_L2.png"].axes[0])
    assert {"repulsion starts (ρ = 0.2 m)", "robot stopped"} <= set(legend)
    assert any("30 Hz" in text for text in legend)
    f_axes, d_axes = plots.build_figures(log, robot, scenario="test2")["fig13_f_and_L1.png"].axes
    assert {"stop: f > 0.8\n(rule of the scaled set L1)", "robot stopped"} <= set(_legend(f_axes))
    assert "f = 0.8 at 0.042 m\n(rule of the scaled set L1)" in _legend(d_axes)
    fig6 = _legend(figs["fig06_f_vs_distance.png"].axes[0])
    assert {"this run", "robot stops: f > 0.8"} <= set(fig6)
    assert "f = 0.8 at d = 0.042 m\n(rule of the scaled set L1)" in fig6


def test_each_stop_threshold_names_the_rule_of_its_role(log: dict, robot: Any) -> None:
    """Figs. 8/10 stop at 0.05 m and Figs. 6/13 at f > 0.8 (0.042 m): each line says whose
    rule it is, and every figure with one carries all the rules as its caption."""
    figs = plots.build_figures(log, robot, scenario="test1") | plots.build_figures(
        log, robot, scenario="test2"
    )
    assert "stop distance 0.05 m\n(rule of the repelled set L2)" in _legend(
        figs["fig08_distance_L2.png"].axes[0]
    )
    assert "stop distance 0.05 m\n(rule of the end-effector set EE)" in _legend(
        figs["fig10_distance_EE.png"].axes[0]
    )
    for name in ("fig06_f_vs_distance.png", "fig08_distance_L2.png", "fig10_distance_EE.png"):
        assert _caption(figs[name]) == IIWA_RULES, name
    assert _caption(figs["fig13_f_and_L1.png"]) == IIWA_RULES
    assert _caption(figs["fig09_vrep_L2.png"]) == ""  # no threshold: no caption
    # other stop distances: two lines and the rules apart, by role, not by the iiwa's names
    cfg = qpavoid.AvoidanceConfig(d_stop_L2_m=0.06, d_stop_EE_m=0.04)
    timeline = plots.build_figures(log, robot, cfg, scenario="free")["timeline.png"]
    legend = _legend(timeline.axes[0])
    assert "stop distance 0.06 m\n(rule of the repelled set L2)" in legend
    assert "stop distance 0.04 m\n(rule of the end-effector set EE)" in legend
    assert _caption(timeline) == (
        "Stop rules by role: scaled set L1: f > 0.8 (d < 0.042 m); "
        "repelled set L2: d ≤ 0.06 m; end-effector set EE: d ≤ 0.04 m."
    )


def test_the_repulsive_speed_axis_shows_noise_as_zero_and_keeps_a_floor(
    log: dict, robot: Any
) -> None:
    """|v_rep| of 1e-9 m/s (the logistic's numerical noise far from the person) once filled
    an autoscaled axis as if the robot were being pushed."""
    rng = np.random.default_rng(1)
    keys = repulsion_keys(robot)
    n = len(log["t"])
    noise = {k: rng.uniform(0, 5e-9, (n, 3)) for k in keys}
    quiet = dict(log, **noise)
    figs = plots.build_figures(quiet, robot, scenario="free")
    speed_axes = figs["timeline.png"].axes[1]
    for line in speed_axes.get_lines():
        assert np.all(line.get_ydata() == 0.0), line.get_label()
    assert speed_axes.get_ylim() == (0.0, SPEED_AXIS_MIN_MPS)
    assert f"below {SPEED_FLOOR_MPS:g} m/s drawn as 0;\naxis at least 0-0.01 m/s" in _legend(
        speed_axes
    )
    # a real repulsion is drawn as it is, on an axis that holds it
    loud = dict(quiet)
    loud[keys[1]] = quiet[keys[1]].copy()
    loud[keys[1]][n // 2] = [0.03, 0.0, 0.04]  # 0.05 m/s
    fig = plots.build_figures(loud, robot, scenario="test1")["fig11_vrep_EE.png"]
    (line,) = fig.axes[0].get_lines()
    assert line.get_ydata()[n // 2] == pytest.approx(0.05)
    assert np.count_nonzero(line.get_ydata()) == 1
    assert fig.axes[0].get_ylim() == pytest.approx((0.0, 1.05 * 0.05))


def test_compare_says_what_a_sphere_distance_below_zero_is(
    tmp_path: Path, log: dict, robot: Any
) -> None:
    t = log["t"]
    below = np.minimum(log["distance"].min(axis=1), 0.5) - 0.03  # reaches below −0.02 m
    series = {
        (c, d): {"t": t, "min_distance": below, "path_error": np.zeros_like(t)}
        for c in ("analytic", "qp")
        for d in ("spheres", "capsules")
    }
    made = [plots.comparison_figure("test2", series, r) for r in (robot, None)]
    with_robot, by_role = (_legend(f.axes[0]) for f in made)
    overlap = "spheres (eq. 1) below 0: the conservative\nspheres overlap the person, not contact"
    assert overlap + "\n(spheres 0.09 m around capsules 0.06-0.07 m)" in with_robot
    assert "stop distance 0.05 m\n(rule of the repelled set L2 and end-effector set EE)" in (
        with_robot
    )
    assert overlap in by_role
    assert "stop distance 0.05 m\n(rule of the repelled sets and end-effector sets)" in by_role
    ax = made[0].axes[0]
    band = [p for p in ax.patches if p.get_y() < 0]  # the grey band under 0
    assert len(band) == 1 and band[0].get_y() == pytest.approx(1.1 * below.min())
    plots.write_comparison(tmp_path / "c.png", "test2", series, robot)
    assert (tmp_path / "c.png").stat().st_size > 10_000


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
        "operator: body-model spheres (eq. 1)",
        "operator joints",
        "robot base",
        "table (z = 0)",
        "planned path",
        "end-effector trace",
    ]
    assert plots.snapshot_ticks(log)[1] == int(np.flatnonzero(log["stopped"])[0])


def test_snapshots_draw_the_distances_solids_the_base_and_the_table(log: dict, robot: Any) -> None:
    """Each panel: the table, the base, a solid per robot capsule and one per body part in
    view (the head's among them: the body model's, not a stick skeleton), and the joints."""
    from mpl_toolkits.mplot3d.art3d import Path3DCollection, Poly3DCollection

    human = KinectHuman()
    fig = plots.build_figures(log, robot, None, "capsules", scenario="test2")["fig12_snapshots.png"]
    for ax, k in zip(fig.axes, plots.snapshot_ticks(log), strict=True):
        geo = human.geometry(log["joints"][k], log["state"][k])
        solids = [c for c in ax.collections if isinstance(c, Poly3DCollection)]
        assert geo.segment_valid[human.part_names.index("head")]
        assert len(solids) == 2 + len(robot.sets) + int(geo.segment_valid.sum())
        (joints,) = [c for c in ax.collections if isinstance(c, Path3DCollection)]
        used = human.part_joints().any(axis=0) & np.isfinite(log["joints"][k]).all(axis=1)
        assert len(joints.get_offsets()) == int(used.sum())
    # the spheres method: a solid per control point instead
    fig = plots.build_figures(log, robot, None, "spheres", scenario="test2")["fig12_snapshots.png"]
    solids = [c for c in fig.axes[0].collections if isinstance(c, Poly3DCollection)]
    geo = human.geometry(log["joints"][0], log["state"][0])
    assert len(solids) == 2 + len(robot.sphere_radii) + int(geo.point_valid.sum())


def test_a_capsule_grid_lies_on_its_capsule() -> None:
    """Every point of the drawn surface is r from the segment (brute force over the
    segment), and the surface reaches r beyond each end along the axis."""
    rng = np.random.default_rng(3)
    s = np.linspace(0.0, 1.0, 4001)
    for _ in range(20):
        a, b = rng.normal(0, 0.5, (2, 3))
        if rng.random() < 0.2:
            b = a.copy()  # a sphere
        r = rng.uniform(0.01, 0.2)
        grid = capsule_grid(a, b, r).reshape(3, -1).T
        axis = a + s[:, None] * (b - a)
        nearest = np.linalg.norm(grid[:, None, :] - axis[None], axis=2).min(axis=1)
        np.testing.assert_allclose(nearest, r, atol=1e-6 * (1 + np.linalg.norm(b - a)))
        n = (b - a) / np.linalg.norm(b - a) if np.any(b != a) else np.array([0.0, 0.0, 1.0])
        reach = grid @ n
        assert reach.max() == pytest.approx(b @ n + r) and reach.min() == pytest.approx(a @ n - r)


def test_set_colours_are_distinct_for_any_number_of_sets() -> None:
    assert set_colours(3) == ["C0", "C1", "C2"]  # the iiwa's figures keep their colours
    from matplotlib.colors import to_rgb

    for n in (5, 10, 12, 20, 25):
        rgb = {tuple(np.round(to_rgb(c), 6)) for c in set_colours(n)}
        assert len(rgb) == n


def test_the_base_is_the_cylinder_holding_the_urdfs_base_objects(robot: Any) -> None:
    """The iiwa's link_0 is a cylinder of radius 0.11 m from z = 0 to 0.1575 m (its URDF);
    a robot with nothing on its base gets a flat disc (not drawn)."""
    parts = arm_parts(robot)
    assert base_extent(parts, 0.07) == pytest.approx((0.11, 0.1575))
    moving = tuple(p for p in parts if p.joint != 0)
    assert base_extent(moving, 0.07) == (0.07, 0.0)


def test_tick_spacing_follows_the_scene_not_one_arm() -> None:
    assert tick_step_m(np.array([[0, 0.5], [0, 0.6], [0, 0.7]])) == 0.1
    assert tick_step_m(np.array([[-0.4, 1.2], [0, 1.0], [0, 0.9]])) == 0.2
    assert tick_step_m(np.array([[-1.5, 1.5], [0, 1.0], [0, 0.9]])) == 0.5


def five_sets(folder: Path) -> qpavoid.Robot:
    """The iiwa with two more sets that play no part (W1: A4 to A5, W2: A5 to A6): five
    sets, the paper's three roles where they were."""
    src = resources.files("qpavoid.robots") / "iiwa14"
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("iiwa14.urdf", "control_points.toml"):
        shutil.copy(str(src / name), folder / name)
    path = folder / "control_points.toml"
    extra = (
        '[[sets]]\nname = "W1"\nsphere_radius_m = 0.09\npoints = [["A5"]]\n'
        'capsule = { from = "A4", to = "A5", capsule_radius_m = 0.06 }\n\n'
        '[[sets]]\nname = "W2"\nsphere_radius_m = 0.08\npoints = [["A6"]]\n'
        'capsule = { from = "A5", to = "A6", capsule_radius_m = 0.05 }\n\n'
    )
    text = path.read_text()
    path.write_text(text.replace("[roles]", extra + "[roles]", 1))
    return qpavoid.load_robot(str(folder))


def test_a_robot_with_five_sets_gets_every_figure_sized_from_its_description(
    tmp_path: Path, log: dict, robot: Any
) -> None:
    five = five_sets(tmp_path / "five")
    assert five.set_names == ("L1", "L2", "EE", "W1", "W2")
    extra = log["distance"][:, [1, 2]] + [0.05, 0.1]
    log5 = dict(log, distance=np.c_[log["distance"], extra])
    figs: dict[str, Any] = {}
    for scenario in ("test1", "test2", "free"):
        figs |= plots.build_figures(log5, five, None, "capsules", scenario=scenario)
    assert set(figs) == EXPECTED["test1"] | EXPECTED["test2"] | EXPECTED["other"]
    timeline = figs["timeline.png"]
    lines = {ln.get_label(): ln for ln in timeline.axes[0].get_lines()}
    assert set(five.set_names) <= set(lines)
    assert len({lines[n].get_color() for n in five.set_names}) == 5
    np.testing.assert_allclose(lines["W2"].get_ydata(), log5["distance"][:, 4])
    assert _caption(timeline) == IIWA_RULES[:-1] + "; sets with no role (W1, W2): contact, d ≤ 0 m."
    snapshots = figs["snapshots.png"]
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    geo = KinectHuman().geometry(log["joints"][0], log["state"][0])
    solids = [c for c in snapshots.axes[0].collections if isinstance(c, Poly3DCollection)]
    assert len(solids) == 2 + 5 + int(geo.segment_valid.sum())  # five capsules
