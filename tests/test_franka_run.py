"""The FR3 in franky-sim driven by the loop while a person strikes it at 1.5 m/s (issue 27).

The simulator (MuJoCo, libfranka's protocol) is started headless on a loopback address of
this process's own; the run is a real-time one through the same loop as every run
(:func:`~qpavoid.loop.simulation.simulate` with ``arm=``), built as the command line builds it
(``qpavoid run ... --robot fr3 --arm franka:HOST``). The truth is measured from the joint
angles the simulator reports, its physics' lag included, against the collision meshes.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.runs import simulate_one, spec_robot
from qpavoid.scenarios.strikes import StrikeCase, strike_camera, strike_motion

pytest.importorskip("franky")
pytest.importorskip("franky_sim")
FrankySim = pytest.importorskip("qpavoid.drive.franka_sim").FrankySim

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
