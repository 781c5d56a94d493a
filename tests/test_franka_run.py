"""The FR3 in franky-sim driven by the loop while a person strikes it at 1.5 m/s (issue 27).

The simulator (MuJoCo, libfranka's protocol) is started headless on a loopback address of
this process's own; the run is a real-time one through the same loop as every run
(:func:`~qpavoid.loop.simulation.simulate` with ``arm=``), built as the command line builds it
(``qpavoid run ... --robot fr3 --arm franka:HOST``). The truth is measured from the joint
angles the simulator reports, its physics' lag included, against the collision meshes.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import PYTHON

from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.runs import build_controller, simulate_one, spec_robot
from qpavoid.scenarios.strikes import StrikeCase, strike_camera, strike_motion

pytest.importorskip("franky")
pytest.importorskip("franky_sim")
FrankySim = pytest.importorskip("qpavoid.drive.franka_sim").FrankySim
FrankaArm = pytest.importorskip("qpavoid.drive.franka").FrankaArm

pytestmark = pytest.mark.slow


def host(k: int) -> str:
    """A loopback address of this process's own (Linux routes all of 127/8 to lo)."""
    pid = os.getpid()
    return f"127.{(pid >> 8) % 256}.{pid % 256}.{100 + k}"


@pytest.mark.parametrize("controller", ["analytic", "qp"])
def test_fr3_in_franky_sim_keeps_clear_of_a_strike_and_reaches_its_goal(controller):
    address = host(["analytic", "qp"].index(controller))
    case = StrikeCase(
        seed=1,
        target="link5",  # the repelled set, on the capsule's axis
        speed_mps=1.5,
        side="right",
        both_hands=False,
        arrival_s=4.0,
        fault="none",
    )
    spec = RunSpec(
        scenario="free",
        robot="fr3",
        controller=controller,
        safety="ssm",
        max_time_s=40.0,
        arm=f"franka:{address}",
    )
    robot = spec_robot(spec)
    with FrankySim(address):
        run = simulate_one(
            spec, strike_motion(case, robot), robot=robot, camera=strike_camera(case)
        )
    m, log = run.metrics, run.sim.log
    # the person did come: into the arm's capsules (the arm had stepped aside or stopped)
    assert np.nanmin(log["true_distance"]) < 0.05
    assert m["ticks_moving_in_true_contact"] == 0
    assert m["min_true_clearance_moving_m"] > 0.0
    assert m["end_reason"] == "goal reached" and m["reached_goal"]
    assert m["command_limit_violations"] == {"velocity": 0, "acceleration": 0, "jerk": 0}
    assert m["arm"] == f"franka:{address}"
    loop = m["loop"]
    assert loop["commands_sent"] >= len(log["t"]) - 1
    assert np.isfinite(loop["frame_to_command_s"]["median"])
    assert {"deadline_misses", "longest_gap_s", "command_period_s"} <= set(loop)
    # speed and separation stopped (or slowed) the arm for the strike
    stops = [e["reason"] for e in m["stop_events"]]
    assert any(r.startswith("speed and separation") for r in stops), stops


def test_sigterm_mid_motion_ramps_the_fr3_to_rest_and_writes_the_run(tmp_path):
    """SIGTERM 3 s into the path (on the tick whose path clock τ reaches 3 s of the path's
    15, not a timer nor a tick count: a loaded machine ticks slower while τ follows the
    wall clock, so the 1500th tick came after the goal there): the controller's ramp brings
    the FR3 to rest within its limits, and the run ends as "interrupted"."""
    address = host(2)
    spec = RunSpec(scenario="free", robot="fr3", max_time_s=40.0, arm=f"franka:{address}")
    robot = spec_robot(spec)
    controller = build_controller(spec, robot)
    step, sent = controller.step, []
    assert controller.path.duration_s > 6.0  # τ = 3 s is mid-motion

    def step_then_term(q, joints, state=None, t=0.0, *args, **kwargs):
        if t >= 3.0 and not sent:  # t: the path clock τ
            sent.append(t)
            os.kill(os.getpid(), signal.SIGTERM)
        return step(q, joints, state, t, *args, **kwargs)

    controller.step = step_then_term
    with FrankySim(address):
        run = simulate_one(spec, robot=robot, controller=controller)
        log, m = run.sim.log, run.metrics
        after = joint_angles_for(robot, address, 0.5)  # the simulator's arm, after the run
    assert m["end_reason"] == "interrupted" and sent
    assert log["tau"][-1] < controller.path.duration_s
    moving = np.abs(log["dq_command"]).max(axis=1)
    assert moving[-1] > 0.01, (moving[-10:], log["stop_reason"][-10:])  # moving at the signal
    assert m["command_limit_violations"] == {"velocity": 0, "acceleration": 0, "jerk": 0}
    assert np.ptp(after, axis=0).max() < 0.01  # at rest (the wrist's creep: < 2 mrad/0.1 s)


def test_the_command_line_on_franky_sim_ends_cleanly_on_sigterm(tmp_path):
    """`qpavoid run test1 --robot fr3 --arm franka:HOST`, SIGTERM while it runs: one line,
    no traceback, the run written (or, before the loop began, nothing), no process left."""
    address, out = host(3), tmp_path / "run"
    cmd = [*PYTHON, "-m", "qpavoid", "run", "test1", "--robot", "fr3"]
    cmd += ["--arm", f"franka:{address}", "--out", str(out), "--no-plots", "--no-view", "-q"]
    with FrankySim(address):
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(15.0)  # startup, the slow move to the start, then some of the path
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=60)
        assert not psutil_children(proc.pid)
        after = joint_angles_for(spec_robot(RunSpec(scenario="free", robot="fr3")), address, 0.5)
    assert "Traceback" not in stderr and len(stderr.strip().splitlines()) <= 1, stderr
    assert np.ptp(after, axis=0).max() < 0.01
    if proc.returncode == 0:  # the loop was running: the run is written
        m = json.loads((out / "metrics.json").read_text())
        assert m["end_reason"] in ("interrupted", "goal reached"), m["end_reason"]
        assert "loop on franka:" in stdout
    else:  # it came before the loop: nothing written
        assert proc.returncode == 143 and not out.exists(), (proc.returncode, stderr)


def joint_angles_for(robot, address: str, seconds: float) -> np.ndarray:
    """(N, nv) the arm's joint angles read every 10 ms for ``seconds`` s (a new client)."""
    with FrankaArm(robot, address) as arm:
        angles = []
        for _ in range(round(seconds / 0.01)):
            angles.append(arm.read().q)
            time.sleep(0.01)
    return np.array(angles)


def psutil_children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (from /proc)."""
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            kids.append(int(stat.parent.name))
    return kids
