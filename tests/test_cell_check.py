"""The cell check (``qpavoid check``, issue 48): where the arm stops beside its seated
operator, said before the first motion, and what a ``free`` run then does."""

from __future__ import annotations

import dataclasses
import json
import subprocess

import numpy as np
import pytest
from conftest import PYTHON

from qpavoid.cli.commands import main
from qpavoid.experiments.cell_check import check_cell
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.runs import simulate_one
from qpavoid.laws.ssm import SSMConfig, hold_distance

ARMS = ("iiwa14", "panda", "fr3", "ur5")
CAMERAS = ("kinect_v2", "k4abt", "mediapipe_pose", "zed_body_34", "zed_body_38")


def _spec(robot: str, camera: str, latency: float | None) -> RunSpec:
    return RunSpec(
        scenario="free",
        robot=robot,
        camera=camera,
        latency_s=latency,
        safety="ssm",
        rate_hz=100.0,
        max_time_s=40.0,
    )


def _agrees(spec: RunSpec, whole_run: bool = True) -> tuple[bool, bool]:
    """(the check says the arm stops, the ``free`` run held it for speed and separation);
    where both, the run's first hold is on the check's first stretch (from 0.5 s of path
    time before it: the arm slows to it). Without ``whole_run``, where the check says the
    arm stops the run ends a second after the check's first stretch (its first hold must
    come by then; a run held from the start to its 40 s cap spends the rest holding
    still)."""
    check = check_cell(spec)
    if check.stops and not whole_run:
        end = check.stretches[0].end_s + 1.0  # a second more: the path clock may lag
        spec = dataclasses.replace(spec, max_time_s=min(spec.max_time_s, end))
    run = simulate_one(spec)
    reasons = run.sim.log["stop_reason"]
    held = [k for k, r in enumerate(reasons) if str(r).startswith("speed and separation")]
    if check.stops and held:
        tau = float(run.sim.log["tau"][held[0]])
        first = check.stretches[0]
        assert first.start_s - 0.5 <= tau <= first.end_s, (tau, first)
    if not held:
        assert run.metrics["reached_goal"], run.metrics["end_reason"]
    return check.stops, bool(held)


@pytest.mark.parametrize(
    ("robot", "camera", "latency", "stops"),
    [  # the run at the passing latency (to its goal, 15 s) with the slow ones
        ("panda", "k4abt", None, True),
        pytest.param("panda", "k4abt", 0.06, False, marks=pytest.mark.slow),
    ],
)
def test_the_check_says_where_a_free_run_stops(robot, camera, latency, stops):
    """The Panda's task beside its operator, an Azure Kinect at its own 0.10 s: held from
    the start (the left hand 0.31 m from the hand, 0.35 m needed); at 0.06 s it passes,
    and so does the run. (The slow suite runs every arm and camera to the cap.)"""
    assert _agrees(_spec(robot, camera, latency), whole_run=False) == (stops, stops)


@pytest.mark.slow
@pytest.mark.parametrize("latency", [None, 0.06])
@pytest.mark.parametrize("camera", CAMERAS)
@pytest.mark.parametrize("robot", ARMS)
def test_the_check_agrees_with_a_free_run_on_every_arm_and_camera(robot, camera, latency):
    says, does = _agrees(_spec(robot, camera, latency))
    assert says == does


def test_a_stretchs_numbers_are_the_protective_distance_at_the_oldest_frame():
    """The worst sample's needed clearance is S_p(0) at T_f = latency + a frame period (the
    ISO 13855 speed of its zone); at the passing latency the stretch's tightest sample
    keeps exactly its clearance."""
    check = check_cell(_spec("panda", "zed_body_34", None))
    assert check.frame_age_s == pytest.approx(0.12 + 1 / 30)
    (s,) = check.stretches
    hands = ("left_hand", "right_hand")
    ssm = SSMConfig(reaction_time_s=0.1, stop_time_s=0.2)  # only its v_h and zones compared
    assert s.part in hands and s.link == "hand" and s.shortfall_m > 0.05
    assert s.needed_m > s.clearance_m
    spare = check.clearance_m - check.needed_m
    assert np.nanmin(spare) == pytest.approx(-s.shortfall_m)
    # S_p(0) grows with T_f at the part's speed: between two ages, v_h × their difference
    grow = hold_distance(s.clearance_m, 1.0, ssm, False) - hold_distance(
        s.clearance_m, 0.0, ssm, False
    )
    assert grow == pytest.approx(2.0, rel=1e-9) or grow == pytest.approx(1.6, rel=1e-9)
    assert s.passing_latency_s is not None and 0.0 < s.passing_latency_s < 0.12


def test_bad_inputs_are_one_line_and_exit_2(tmp_path, capsys):
    """In this process: the installed program's own exit statuses are the next test's."""
    bad_task = tmp_path / "task.toml"
    bad_task.write_text(
        "[[waypoints]]\njoints_rad = { no_such_joint = 0.1 }\n"
        "[[waypoints]]\nposition_m = [0.4, 0.0, 0.5]\nrpy_rad = [0.0, 3.14, 0.0]\n"
        "duration_s = 5.0\n"
    )
    far = tmp_path / "far.toml"
    far.write_text(
        "[[waypoints]]\nposition_m = [0.5, 0.0, 0.5]\nrpy_rad = [0.0, 3.14, 0.0]\n"
        "[[waypoints]]\nposition_m = [3.0, 0.0, 0.5]\nrpy_rad = [0.0, 3.14, 0.0]\n"
        "duration_s = 5.0\n"
    )
    for args, words in (
        (["--task", str(bad_task)], "no_such_joint"),
        (["--task", str(far)], "waypoints[1]: the arm cannot reach this pose"),
        (["--latency", "-0.1"], "latency"),
    ):
        status = main(["check", "--robot", "panda", *args, "--out", str(tmp_path / "o")])
        out, err = capsys.readouterr()
        assert status == 2, (args, out, err)
        assert words in err and err.count("\n") == 1, err


def test_the_command_line_exits_1_where_the_arm_stops_and_writes_the_figure(tmp_path, capsys):
    done = subprocess.run(
        [
            *PYTHON,
            "-m",
            "qpavoid",
            "check",
            "--robot",
            "panda",
            "--camera",
            "k4abt",
            "--out",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 1, done.stderr
    assert "checking panda's task beside its seated operator, 8 phases" in done.stderr
    assert "the arm will stop for the still operator on 1 stretch(es)" in done.stdout
    assert "passes at a latency of 0.0" in done.stdout
    result = json.loads((tmp_path / "check.json").read_text())
    assert result["stops"] and result["stretches"][0]["part"] == "left_hand"
    assert (tmp_path / "check.png").stat().st_size > 10_000
    status = main(["check", "--robot", "panda", "--out", str(tmp_path)])  # in this process
    out, err = capsys.readouterr()
    assert status == 0 and "will not stop" in out, err
