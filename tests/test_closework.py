"""Close work (issue 29): the seated operator working within reach of the path, never at
the robot; the cases, their scenario names, their sweep and ``qpavoid sweep --motion``."""

from __future__ import annotations

import json
import shlex
from dataclasses import replace

import numpy as np
import pytest

from qpavoid.arm.fit import segment_distances
from qpavoid.arm.model import load_robot
from qpavoid.cli.commands import build_parser, main
from qpavoid.control.task import default_task
from qpavoid.core.errors import InputError
from qpavoid.distance.methods import distance_method
from qpavoid.experiments import campaign, sweep
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.sweep import SweepSpec
from qpavoid.experiments.sweep_checks import CloseWorkCheck
from qpavoid.experiments.sweep_summary import summarize
from qpavoid.human.body import KinectHuman
from qpavoid.scenarios import closework as cw
from qpavoid.scenarios.generated import (
    SCENARIOS,
    check_scenario_name,
    make_scenario,
    nominal_configurations,
)

#: Two seeds of each variant: its fixed case and the next one.
SEEDS = {"rest_near": (1, 2), "work_near": (5, 8), "reach_across": (3, 9), "handover": (0, 4)}
#: The arms the cases are checked on: the iiwa and one whose task is scaled (its meshes
#: come from example-robot-data: the UR5's).
ARMS = ("iiwa14", pytest.param("ur5", marks=pytest.mark.slow))  # (the UR5's: slow suite)


class Arm:
    """An arm, its task and its nominal motion, measured once."""

    def __init__(self, name: str):
        self.robot = load_robot(name)
        self.task = default_task(self.robot)
        self.capsules = cw.nominal_capsules(self.robot, self.task.path)
        self.radii = self.robot.capsule_radii
        self.exact = distance_method("capsules", self.robot, KinectHuman())

    def swept(self, joints: np.ndarray, parts: tuple[str, ...] | None = None) -> float:
        """The person's clearance to the whole nominal motion, m."""
        return cw.swept_clearance_m(joints, self.capsules, self.radii, parts)

    def in_step(self, motion, times: np.ndarray) -> np.ndarray:
        """The exact capsule clearance (coal) to the robot on its nominal path at the same
        times, m."""
        path = self.task.path
        qs = nominal_configurations(self.robot, path, np.minimum(times, path.duration_s))
        human = KinectHuman()
        return np.array(
            [
                self.exact(
                    self.robot.kinematics(q, False), human.geometry(motion.frame_at(t)[0])
                ).distance.min()
                for q, t in zip(qs, times, strict=True)
            ]
        )


@pytest.fixture(scope="module", params=ARMS)
def arm(request) -> Arm:
    return Arm(request.param)


#: Each variant's first seed in the default suite, its second with the slow one.
VARIANT_SEEDS = [
    (variant, seed) if k == 0 else pytest.param(variant, seed, marks=pytest.mark.slow)
    for variant in cw.VARIANTS
    for k, seed in enumerate(SEEDS[variant])
]


@pytest.mark.parametrize(("variant", "seed"), VARIANT_SEEDS)
def test_each_variant_stays_in_its_band_and_out_of_the_robot(arm, variant, seed):
    case = cw.closework_case(seed, arm.robot)
    assert case.variant == variant
    motion = cw.closework_motion(case, arm.robot)
    times = np.arange(0.0, case.duration_s, 0.25)
    if variant == "reach_across":
        check_reach_across(arm, case, motion, times)
        return
    # never touching the robot on its nominal path, nor anywhere it sweeps
    assert arm.in_step(motion, times).min() > 0.0, seed
    assert min(arm.swept(motion.frame_at(t)[0]) for t in times) > 0.0, seed
    if variant == "handover":
        (hand, _) = motion.hands
        point = hand.keyframes[1][1]
        flange = arm.task.path.reference(case.path_time_s)[0][:3, 3]
        assert 0.10 <= np.linalg.norm(point - flange) <= 0.30
        assert case.hold_s >= 1.0 and hand.keyframes[2][0] - hand.keyframes[1][0] >= 1.0
        return
    near = [h for h in motion.hands if h.radius_m > 0.0]
    assert len(near) == (2 if case.both_hands else 1) and near[0].side == case.side
    for hand in near:
        parts = cw.arm_parts(hand.side)
        clearance = [arm.swept(motion.frame_at(t)[0], parts) for t in times[::4]]
        assert cw.NEAR_BAND_M[0] <= min(clearance) and max(clearance) <= cw.NEAR_BAND_M[1]


def check_reach_across(arm: Arm, case, motion, times) -> None:
    """The hand goes through the end effector's corridor to a point beside the robot."""
    (hand, _) = motion.hands
    near, far = hand.keyframes[1][1], hand.keyframes[2][1]
    # the far point is clear of every swept capsule: the hand never aims at the robot
    hand_radius = KinectHuman().capsule_radii[-1]
    axes = arm.capsules.reshape(-1, 2, 3)
    radii = np.resize(arm.radii, len(axes))
    gap = [segment_distances(far, a, b)[0] - r for (a, b), r in zip(axes, radii, strict=True)]
    assert min(gap) - hand_radius >= cw.ACROSS_CLEARANCE_M - 1e-9
    # the way across goes through the end effector's capsule at the case's path time
    k = round(case.path_time_s / arm.task.path.duration_s * (len(arm.capsules) - 1))
    a, b = arm.capsules[k, arm.robot.roles.end_effector]
    across = np.linspace(near, far, 201)
    assert segment_distances(across, a, b).min() < arm.radii[arm.robot.roles.end_effector]
    # so the arm does cross the corridor: contact if the robot did not slow
    assert min(arm.swept(motion.frame_at(t)[0]) for t in times) < 0.0
    # at an ordinary working speed, and when the robot comes by
    dt = 0.01
    track = np.array([hand.position(t) for t in np.arange(0.0, case.duration_s, dt)])
    peak = np.linalg.norm(np.diff(track, axis=0), axis=1).max() / dt
    assert 0.3 * 0.99 <= peak <= 1.0 * 1.01 and peak == pytest.approx(case.speed_mps, rel=0.01)
    assert -2.0 <= hand.keyframes[2][0] - case.path_time_s <= 0.5 + 1e-9


def test_the_nominal_capsules_are_those_of_the_nominal_configurations():
    robot = load_robot("iiwa14")
    path = default_task(robot).path
    qs = nominal_configurations(robot, path, np.linspace(0.0, path.duration_s, 7))
    expected = np.array([robot.capsules(q) for q in qs])
    assert np.array_equal(cw.nominal_capsules(robot, path, 7), expected)


def test_a_seed_is_one_case_whatever_asks_for_it():
    iiwa, ur5 = load_robot("iiwa14"), load_robot("ur5")
    for seed in range(12):
        case = cw.closework_case(seed, iiwa)
        assert case == cw.closework_case(seed, iiwa)
        assert case.variant == cw.closework_case(seed, ur5).variant  # drawn first
        assert case.duration_s == default_task(iiwa).path.duration_s + cw.SLACK_S
    one, two = (cw.closework_motion(cw.closework_case(3, iiwa), iiwa) for _ in range(2))
    for t in (0.0, 4.0, 6.5):
        assert np.array_equal(one.frame_at(t)[0], two.frame_at(t)[0])
    # the fixed cases are the first seeds of their variants
    for variant, seed in cw.FIXED_SEEDS.items():
        drawn = [cw.closework_case(s, iiwa).variant for s in range(seed + 1)]
        assert drawn.index(variant) == seed
    with pytest.raises(InputError, match="seed"):
        cw.closework_case(-1, iiwa)
    with pytest.raises(InputError, match="variant"):
        replace(cw.closework_case(0, iiwa), variant="strike")


def test_the_scenario_names_are_the_cases():
    robot = load_robot("iiwa14")
    assert set(cw.VARIANTS) <= set(SCENARIOS)
    assert check_scenario_name("closework:12") == 12 and check_scenario_name("random:3") == 3
    for name in (*cw.VARIANTS, "closework:7"):
        RunSpec(scenario=name)  # accepted by a run
    seed = cw.FIXED_SEEDS["handover"]
    fixed, seeded = make_scenario("handover", robot), make_scenario(f"closework:{seed}", robot)
    expected = cw.closework_motion(cw.closework_case(seed, robot), robot)
    for t in (0.0, 5.0):
        assert np.array_equal(fixed.frame_at(t)[0], expected.frame_at(t)[0])
        assert np.array_equal(seeded.frame_at(t)[0], expected.frame_at(t)[0])
    for bad in ("closework:abc", "closework:-1", "closework:", "rest_far"):
        with pytest.raises(InputError, match="closework:SEED"):
            check_scenario_name(bad)


def test_a_bad_close_work_seed_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "closework:abc", "--out", "r"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("qpavoid: error: unknown scenario")
    assert "closework:SEED" in err and not (tmp_path / "r").exists()


def test_a_close_work_sweep_sums_up_safety_and_productivity():
    spec = SweepSpec("closework", "qp", safety="paper", max_time_s=2.0)
    assert spec.run_spec(4).scenario == "closework:4" and spec.run_spec(4).measure_truth
    assert SweepSpec("closework").run_spec(4, 30.0).max_time_s == 30.0  # the case's own
    checks = sweep.sweep(spec, [0, 1], workers=1)
    assert [type(c) for c in checks] == [CloseWorkCheck] * 2
    assert [(c.seed, c.variant) for c in checks] == [(0, "handover"), (1, "rest_near")]
    assert all(not c.reached_goal and c.time_to_goal_s is None for c in checks)  # 2 s only
    summary = summarize(checks)
    assert set(summary) == {
        "runs",
        "runs_moving_in_true_contact",
        "true_clearance_moving_mm",
        "fraction_reaching_goal",
        "time_to_goal_s",
        "mean_time_stopped_s",
        "mean_duration_s",
        "per_variant",
        "runs_with_limit_violations",
        "runs_with_command_limit_violations",
        "contacts",
        "timing",
    }
    assert set(summary["contacts"]) == {
        "runs_touching_protected_regions",
        "runs_touching_above_limit",
        "runs_touching_within_limit",
        "runs_clamping",
        "runs_pushing",
        "ticks_touching_within_limit",
        "contact_speed_mps",
        "contact_speed_ratio",
        "contact_advance_mm",
        "contact_force_n",
    }
    assert summary["runs"] == 2 and summary["runs_moving_in_true_contact"] == 0
    assert summary["time_to_goal_s"] == {"median": None, "mean": None}
    assert set(summary["per_variant"]) == {"handover", "rest_near"}
    assert set(summary["per_variant"]["handover"]) == {
        "runs",
        "fraction_reaching_goal",
        "time_to_goal_s_median",
        "mean_time_stopped_s",
        "runs_moving_in_true_contact",
    }
    json.dumps(summary)  # plain JSON


def close_check(seed: int, variant: str, goal_s: float | None, stopped_s: float, **kw):
    fields = dict(
        seed=seed,
        controller="qp",
        safety="ssm",
        variant=variant,
        side="right",
        ticks_moving_in_true_contact=0,
        min_true_clearance_moving_m=0.1,
        moving_s=10.0,
        stopped_s=stopped_s,
        reached_goal=goal_s is not None,
        time_to_goal_s=goal_s,
        duration_s=30.0 if goal_s is None else goal_s,
    )
    return CloseWorkCheck(**(fields | kw))


def test_the_close_work_summary_counts_what_it_says():
    runs = [
        close_check(0, "handover", 16.0, 1.0),
        close_check(1, "rest_near", None, 15.0, ticks_moving_in_true_contact=2),
        close_check(2, "rest_near", 20.0, 5.0),
        close_check(3, "handover", 18.0, 3.0, min_true_clearance_moving_m=float("inf")),
    ]
    s = summarize(runs)
    assert s["fraction_reaching_goal"] == 0.75 and s["runs_moving_in_true_contact"] == 1
    assert s["time_to_goal_s"] == {"median": 18.0, "mean": 18.0}
    assert s["mean_time_stopped_s"] == 6.0 and s["mean_duration_s"] == 21.0
    assert s["true_clearance_moving_mm"]["median"] == 100.0  # over the runs that moved
    assert list(s["per_variant"]) == ["rest_near", "handover"]  # in VARIANTS' order
    assert s["per_variant"]["rest_near"] == {
        "runs": 2,
        "fraction_reaching_goal": 0.5,
        "time_to_goal_s_median": 20.0,
        "mean_time_stopped_s": 10.0,
        "runs_moving_in_true_contact": 1,
    }
    assert campaign.worst_runs(runs, 1)[0].seed == 1


def test_the_campaign_motion_chooses_the_kind_and_the_replay(tmp_path):
    strikes, close = campaign.campaign_spec("qp"), campaign.campaign_spec("qp", motion="closework")
    assert (strikes.kind, strikes.max_time_s) == ("strike", campaign.CAMPAIGN_MAX_TIME_S)
    assert (close.kind, close.max_time_s) == ("closework", None)  # the case's own duration
    assert campaign.campaign_settings(strikes, 3, 0)["motion"] == "strikes"
    settings = campaign.campaign_settings(close, 3, 0)
    assert settings["motion"] == "closework" and settings["max_speed_mps"] is None
    with pytest.raises(InputError, match="--motion"):
        campaign.campaign_spec("qp", motion="walks")
    with pytest.raises(InputError, match="campaign"):
        campaign.run_campaign(SweepSpec("approach"), 1)
    spec = campaign.campaign_spec("qp", safety="paper", motion="closework", latency_s=0.1)
    line = shlex.split(campaign.rerun_command(close_check(7, "handover", 16.0, 0.0), spec))
    args = build_parser().parse_args(line[1:])
    assert (args.scenario, args.controller, args.safety, args.bench) == (
        "closework:7",
        "qp",
        "paper",
        "real",
    )
    assert (args.max_time, args.latency, args.human) == (30.0, 0.1, None)


@pytest.mark.slow
def test_qpavoid_sweep_motion_closework(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", "--n", "2", "--controller", "qp", "--motion", "closework",
                 "--out", "c", "--quiet"]) == 0  # fmt: skip
    summary = json.loads((tmp_path / "c" / "summary.json").read_text())
    assert summary["settings"]["motion"] == "closework" and summary["runs"] == 2
    assert "per_variant" in summary and "time_to_goal_s" in summary
    case = json.loads((tmp_path / "c" / "worst" / "seed0.json").read_text())
    assert case["variant"] == "handover"
    assert case["replay"].startswith("qpavoid run closework:0 --controller qp")


@pytest.mark.slow  # two 4 s runs
def test_a_close_work_sweep_s_run_is_the_run_of_its_scenario():
    # the replay line of a sweep's worst run (qpavoid run closework:SEED) repeats it: the
    # camera draws its noise from the case's seed in both
    from qpavoid.experiments.run_spec import RunSpec
    from qpavoid.experiments.runs import simulate_one

    check = sweep.run_case(SweepSpec("closework", "qp", safety="pfl", max_time_s=4.0), 3)
    run = simulate_one(
        RunSpec(
            scenario="closework:3", controller="qp", safety="pfl", rate_hz=100.0, max_time_s=4.0
        )
    )
    assert run.metrics["stopped_s"] == check.stopped_s
    assert run.metrics["ticks_moving_in_true_contact"] == check.ticks_moving_in_true_contact
    assert run.metrics["duration_s"] == check.duration_s
