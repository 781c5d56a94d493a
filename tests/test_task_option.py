"""``qpavoid run --task FILE``: the robot follows a task file of the user's, and the person
sits where it says (issue 46, item 6.4; the format: docs/tasks.md).

The run's log shows the file's path (its start, its middle, its goal, its duration) and
its operator's seat; a bad file, a joint the arm lacks or a waypoint out of reach is
refused when the run's spec is made: one line, exit 2, nothing written.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from qpavoid.cli.commands import main
from qpavoid.core.errors import InputError
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.human.kinect_v2 import KINECT_V2

#: The paper's start pose A_in (the iiwa reaches it), and a goal 0.1 m towards -x and
#: 0.05 m up, the orientation held.
START = (0.3524, 0.6105, 0.5779)
GOAL = (0.2524, 0.6105, 0.6279)
ROTATION = "[[0.25, -0.866, 0.433], [0.433, 0.5, 0.75], [-0.866, 0.0, 0.5]]"
FIRST = f"[[waypoints]]\nposition_m = {list(START)}\nrotation = {ROTATION}\n"
SECOND = f"[[waypoints]]\nposition_m = {list(GOAL)}\nrotation = {ROTATION}\nduration_s = 3.0\n"
#: The operator's seat: 0.35 m along x, 1.2 m in front of the base (the iiwa's: 0.15, 1.05).
SEAT = "[operator]\nx_m = 0.35\ndistance_m = 1.2\n"


def test_the_run_follows_the_task_file_and_seats_the_operator_there(tmp_path, monkeypatch):
    """On the ideal bench (the true skeleton, an arm that follows at once): the reference
    starts at the file's start, is at the chord's middle at half the file's 3 s (the
    quintic law's s(1/2) = 1/2, no sagitta), ends at its goal, which the arm reaches
    after 3 s, not the robot's own task's 15 s; the person's chest is at the seat,
    (x_m, distance_m, 0.32 m) (qpavoid.human.posture.Operator.rest)."""
    task = tmp_path / "mytask.toml"
    task.write_text(FIRST + "\n" + SECOND + "\n" + SEAT)
    out = tmp_path / "out"
    monkeypatch.chdir(tmp_path)
    args = ["run", "free", "--task", task.name, "--bench", "ideal", "--max-time", "6"]
    args += ["--rate", "100", "--no-plots", "--no-view", "--out", str(out), "-q"]
    assert main(args) == 0
    log = np.load(out / "log.npz")
    metrics = json.loads((out / "metrics.json").read_text())
    np.testing.assert_allclose(log["ee_ref"][0], START, atol=1e-12)
    np.testing.assert_allclose(log["ee_pos"][0], START, atol=1e-9)  # the IK of the start
    half = int(np.argmin(np.abs(log["t"] - 1.5)))
    assert log["t"][half] == pytest.approx(1.5) and log["tau"][half] == pytest.approx(1.5)
    np.testing.assert_allclose(log["ee_ref"][half], np.add(START, GOAL) / 2, atol=1e-9)
    np.testing.assert_allclose(log["ee_ref"][-1], GOAL, atol=1e-12)
    assert np.linalg.norm(log["ee_pos"][-1] - GOAL) < 1e-3
    assert metrics["reached_goal"] and 3.0 <= metrics["duration_s"] < 3.2
    chest = KINECT_V2.joints.index("SpineShoulder")
    np.testing.assert_allclose(
        log["joints"][:, chest], np.tile([0.35, 1.2, 0.32], (len(log["t"]), 1))
    )


def _refused(status: object, err: str, out: str, word: str) -> None:
    assert status == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("qpavoid: error: --task "), err
    assert word in lines[0] and "Traceback" not in err + out and out == ""


#: A task file's text (None: no file) and a word its one-line refusal must hold.
BAD_TASKS = [
    (None, "cannot read the task file"),
    ("waypoints = [\n", "not TOML"),
    (FIRST, "give at least two [[waypoints]]"),
    (FIRST + SECOND + "[operator]\nseat_m = 1.0\n", "operator has unknown key(s) ['seat_m']"),
    (
        FIRST + "[[waypoints]]\njoints_rad = { A1 = 0.5, A2 = 0.6, A4 = -1.4, A5 = 0.0, "
        "A6 = -1.0, A7 = 0.0, A9 = 0.1 }\nduration_s = 2.0\n",
        "waypoints[1].joints_rad.A9: no joint 'A9'",
    ),
    (
        FIRST + SECOND.replace(str(list(GOAL)), "[2.0, 0.6105, 0.5779]"),
        "waypoints[1]: the arm cannot reach this pose",
    ),
]


@pytest.mark.parametrize("text, word", BAD_TASKS, ids=[w for _, w in BAD_TASKS])
def test_a_bad_task_file_is_one_line_exit_2_and_nothing_written(
    tmp_path, monkeypatch, capsys, text, word
):
    if text is not None:
        (tmp_path / "task.toml").write_text(text)
    before = sorted(p.name for p in tmp_path.iterdir())
    monkeypatch.chdir(tmp_path)
    status = main(["run", "free", "--task", "task.toml", "--out", "o"])
    captured = capsys.readouterr()
    _refused(status, captured.err, captured.out, word)
    assert captured.err.startswith("qpavoid: error: --task task.toml: ")  # the file named
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no o/, no runs/


def test_the_spec_checks_the_task_against_the_runs_robot(tmp_path):
    """When the spec is made, with the robot the run will drive: A3, locked at 0 on the
    iiwa, may be named at another angle only when --redundant frees it."""
    task = tmp_path / "a3.toml"
    seven = "A1 = 0.5, A2 = 0.6, A3 = 0.3, A4 = -1.4, A5 = 0.0, A6 = -1.0, A7 = 0.0"
    task.write_text(FIRST + f"[[waypoints]]\njoints_rad = {{ {seven} }}\nduration_s = 2.0\n")
    with pytest.raises(InputError, match=r"joints_rad.A3: the joint is locked at 0 rad") as info:
        RunSpec(scenario="free", task=str(task))
    assert info.value.name == "--task" and info.value.value == str(task)
    spec = RunSpec(scenario="free", task=str(task), controller="qp", redundant=True)
    assert spec.task == str(task)
