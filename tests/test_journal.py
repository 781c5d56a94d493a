"""What a controller was handed, kept call by call, gives its commands again
(qpavoid.control.journal; a run's bag reproduced by ``qpavoid run --human RUN.mcap``)."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
from conftest import PYTHON

from qpavoid.arm.model import load_robot
from qpavoid.cli.commands import main
from qpavoid.control.journal import KINDS, Journal, _frame_entry, _frame_of, reproduce
from qpavoid.control.qp import QPController
from qpavoid.control.tick import ControllerConfig
from qpavoid.core.errors import InputError
from qpavoid.experiments.runs import RunSpec, build_controller, simulate_one, spec_robot
from qpavoid.human.frames import HumanFrame
from qpavoid.human.people import People
from qpavoid.scenarios.generated import make_scenario


def _entries(journal: dict[str, np.ndarray]) -> list[np.ndarray]:
    return Journal.split(journal["journal_data"], journal["journal_offsets"])


def test_a_frame_entry_gives_the_frame_back():
    """People with lags, an inferred joint and one lost; a bare frame; nobody seen."""
    rng = np.random.default_rng(1)
    frames = []
    for _ in range(2):
        joints = rng.normal(size=(25, 3))
        joints[4] = np.nan
        state = np.full(25, 2, np.int8)
        state[4], state[7] = 0, 1
        frames.append(HumanFrame(joints, state))
    people = People((3, 11), tuple(frames), (0.0, 0.033))
    back = _frame_of(_frame_entry(people))
    assert isinstance(back, People) and back.ids == (3, 11) and back.lag_s == (0.0, 0.033)
    for a, b in zip(back.frames, frames, strict=True):
        np.testing.assert_array_equal(a.joints, b.joints)
        np.testing.assert_array_equal(a.state, b.state)
        assert a.state.dtype == np.int8
    bare = _frame_of(_frame_entry(frames[0]))
    assert isinstance(bare, HumanFrame)
    np.testing.assert_array_equal(bare.joints, frames[0].joints)
    nobody = _frame_of(_frame_entry(People((), ())))
    assert isinstance(nobody, People) and nobody.ids == () and nobody.frames == ()


def test_the_same_frame_handed_anew_is_kept_once():
    """A live source hands a new People each tick; kept again only when its content (ids,
    lags, joints, states) changes."""
    rng = np.random.default_rng(2)
    joints = rng.normal(size=(25, 3))

    def people(dx: float, lag: float = 0.01) -> People:
        return People((4,), (HumanFrame(joints + dx, np.full(25, 2, np.int8)),), (lag,))

    journal = Journal()
    for frame in (people(0.0), people(0.0), people(0.0), people(0.001), people(0.001, 0.02)):
        journal.step(np.zeros(7), frame, 0.0, 0.05, None, 1)
    kinds = [e[0] for e in journal.entries]
    assert kinds.count(KINDS["frame"]) == 3 and kinds.count(KINDS["step"]) == 5
    assert [int(e[1]) for e in journal.entries if e[0] == KINDS["step"]] == [0, 0, 0, 1, 2]


def test_a_run_is_reproduced_to_the_bit_and_its_journal_keeps_each_frame_once():
    spec = RunSpec(scenario="test1", controller="qp", safety="ssm", max_time_s=3.0, rate_hz=100)
    run = simulate_one(spec)
    assert run.metrics["reproducible"] is True
    entries = _entries(run.sim.journal)
    kinds = [e[0] for e in entries]
    ticks = len(run.sim.log["t"])
    assert kinds.count(KINDS["step"]) == kinds.count(KINDS["logged"]) == ticks
    # 30 Hz frames over 3 s at 100 Hz ticks: each kept once (not once per tick)
    assert 85 <= kinds.count(KINDS["frame"]) <= 95
    again = reproduce(build_controller(spec, spec_robot(spec)), entries)
    np.testing.assert_array_equal(again, run.sim.log["dq_command"])
    assert np.abs(again).max() > 0.01  # a run that moved


def test_brakes_rests_and_interface_limits_are_replayed_in_their_order():
    """A missed deadline's brake in place of a tick's command, an arm that came to rest on
    its own, an interface's tighter limits: each changes the commands after it, and the
    journal gives them again."""
    robot = load_robot("panda")
    motion = make_scenario("test1", robot)

    def drive(controller: QPController) -> list[np.ndarray]:
        out = []
        v = np.array(robot.dq_max) * 0.5
        controller.accept_limits(v, np.full(robot.nv, 5.0), np.full(robot.nv, 4000.0))
        q = robot.neutral()
        for k in range(60):
            frame = HumanFrame(*motion.frame_at(k * 0.01))
            cmd = controller.step(q, frame, None, k * 0.01, 0.01)
            if k % 7 == 3:
                cmd = controller.brake("missed deadline", instead=True)
            if k == 30:
                controller.at_rest()
                cmd = controller.brake("stalled")
            out.append(cmd.dq.copy())
            if controller.journal is not None:
                controller.journal.logged()
            q = q + cmd.dq * 0.01
        return out

    config = ControllerConfig(control_period_s=0.01)
    first = QPController(robot, config=config)
    first.journal = journal = Journal()
    sent = drive(first)
    again = reproduce(QPController(robot, config=config), journal.entries)
    np.testing.assert_array_equal(again, np.array(sent))
    without = [e for e in journal.entries if e[0] != KINDS["brake"]]  # the brakes matter
    assert np.abs(reproduce(QPController(robot, config=config), without) - sent).max() > 1e-6


def test_an_entry_of_no_known_kind_is_one_input_error():
    robot = load_robot("iiwa14")
    with pytest.raises(InputError, match="journal entry 1 is of no known kind"):
        reproduce(QPController(robot), [np.array([KINDS["rest"]]), np.array([42.0])])


def test_the_command_line_reproduces_a_runs_bag_and_refuses_a_tampered_one(tmp_path, capsys):
    pytest.importorskip("mcap")
    pytest.importorskip("rosbags")
    from qpavoid.output.bag_writer import write_bag
    from qpavoid.output.run_files import load_log

    # the bag written by the installed program, in a process of its own; reproduced here,
    # in another (the command line's main in this process, as the console script calls it)
    bag = tmp_path / "run.mcap"
    run = [*PYTHON, "-m", "qpavoid", "run", "test1", "--max-time", "1.5", "--rate", "100"]
    run += ["--no-plots", "--no-view", "-q", "--out", str(tmp_path / "r"), "--bag", str(bag)]
    subprocess.run(run, check=True, capture_output=True)
    status = main(["run", "--human", str(bag)])
    out, err = capsys.readouterr()
    assert status == 0, err
    assert "reproduced the 151 commands of" in out
    assert "largest difference 0 rad/s" in out
    # one joint angle of tick 40 changed in the journal: the commands differ from there
    log = load_log(tmp_path / "r")
    entries = _entries(log)
    steps = [k for k, e in enumerate(entries) if e[0] == KINDS["step"]]
    entries[steps[40]][6] += 0.01
    log["journal_data"] = np.concatenate(entries)
    import json

    spec = json.loads((tmp_path / "r" / "metrics.json").read_text())["run_spec"]
    robot = load_robot("iiwa14")
    write_bag(tmp_path / "bad.mcap", log, robot.joint_names, run_spec=json.dumps(spec))
    status = main(["run", "--human", str(tmp_path / "bad.mcap")])
    out, err = capsys.readouterr()
    assert status == 2 and out == ""
    assert "the run's commands are not reproduced (tick 40 differs first" in err
    assert err.count("\n") == 1
