"""Against the true motion: strikes at every robot set and every sensor fault, with SSM.

Each case simulates the real bench (Kinect latency and noise, the arm's reaction and
braking) and judges the run against where the hand really is.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from qpavoid.arm.model import load_robot
from qpavoid.control.task import BodyTarget, default_task
from qpavoid.core.errors import InputError
from qpavoid.experiments import sweep
from qpavoid.experiments.runs import RunSpec, build_controller
from qpavoid.loop.camera import CameraConfig, CameraFault
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario, nominal_configurations
from qpavoid.scenarios.strikes import StrikeCase, strike_camera, strike_motion, strike_targets


def run_case(robot, case: StrikeCase, controller: str, safety: str = "ssm"):
    spec = RunSpec(scenario="free", controller=controller, safety=safety, rate_hz=100.0)
    return simulate(
        build_controller(spec, robot),
        strike_motion(case, robot),
        SimConfig(
            control_rate_hz=100.0,
            camera=strike_camera(case),
            max_time_s=case.duration_s,
            measure_truth=True,
        ),
    )


def stationary_before_contact(log) -> bool:
    """At every tick in true contact the arm's real velocity is exactly zero."""
    contact = log["true_distance"].min(axis=1) <= 0.0
    return not np.any(log["dq"][contact] != 0.0)


#: The strikes the default suite keeps (the default suite's time): at the end effector
#: and at the base column (not a robot set); `-m slow` runs both controllers at every set
FAST_TARGETS = ("EE", "base")


def _fast_first(targets, fast):
    """``targets`` as parameters, those not in ``fast`` in the slow suite."""
    return [t if t in fast else pytest.param(t, marks=pytest.mark.slow) for t in targets]


# the analytic controller's five with the slow suite (the default suite's time): the sensor
# faults below alternate the controllers, and `-m slow` runs both at every set
@pytest.mark.parametrize("controller", ["qp", pytest.param("analytic", marks=pytest.mark.slow)])
@pytest.mark.parametrize("target", _fast_first(strike_targets(load_robot()), FAST_TARGETS))
def test_a_hand_at_2_mps_aimed_at_each_set_finds_the_robot_stationary(robot, controller, target):
    case = StrikeCase(0, target, 2.0, "right", False, 2.0, "none")
    sim = run_case(robot, case, controller)
    log = sim.log
    assert sim.metrics["ticks_moving_in_true_contact"] == 0
    assert stationary_before_contact(log)
    assert np.any(log["dq"][log["t"] < 1.0] != 0.0)  # it worked before the strike
    reached = log["true_distance"].min(axis=1) < 0.02  # the hand did get there
    assert reached.any() or target == "base"  # (the base column is not a robot set)


@pytest.mark.parametrize(
    "fault, controller",
    [  # two in the default suite, one per controller (a frozen camera: a test below too)
        ("lost", "qp"),
        pytest.param("inferred", "analytic", marks=pytest.mark.slow),
        pytest.param("frozen", "qp", marks=pytest.mark.slow),
        ("gap", "analytic"),
        pytest.param("jitter", "qp", marks=pytest.mark.slow),
    ],
)
def test_every_sensor_fault_during_a_strike_keeps_the_robot_still_in_contact(
    robot, controller, fault
):
    case = StrikeCase(1, "EE", 2.0, "right", False, 2.0, fault)
    sim = run_case(robot, case, controller)
    assert sim.metrics["ticks_moving_in_true_contact"] == 0
    assert stationary_before_contact(sim.log)


def test_the_paper_rules_alone_are_hit_while_moving(robot):
    """The same strike without SSM: latency, braking and 2 m/s defeat the paper's rules."""
    case = StrikeCase(0, "L2", 2.0, "right", False, 2.0, "none")
    assert run_case(robot, case, "qp", "paper").metrics["ticks_moving_in_true_contact"] > 0


def test_frozen_and_stale_frames_stop_the_robot_until_fresh_frames(robot):
    """A hung sensor (the same skeleton from 4.7 s to 5.6 s) and a gap in the frames stop
    the person at work (``free``) with the reason, until fresh frames come."""
    for kind, word in (("freeze", "frozen"), ("gap", "stale")):
        camera = CameraConfig(faults=(CameraFault(kind, 4.7, 5.6),))
        spec = RunSpec(scenario="free", controller="qp", rate_hz=100.0)
        sim = simulate(
            build_controller(spec, robot),
            make_scenario("free", robot),
            SimConfig(control_rate_hz=100.0, camera=camera, max_time_s=8.0),
        )
        log, events = sim.log, sim.metrics["stop_events"]
        # The last fresh frame is captured at 140/30 s. Frozen: frames 141-143 repeat it
        # (3 tolerated), 144 (captured 4.8 s) arrives 60 ms later and stops the robot.
        # Gap: the frame in hand is older than 0.1 s at 140/30 + 0.1 s.
        first = 4.8 + 0.06 if kind == "freeze" else 140 / 30 + 0.1
        (event,) = events
        assert word in event["reason"] and first - 0.04 < event["t"] < first + 0.04
        window = (log["t"] > first + 0.04) & (log["t"] < 5.6)
        assert log["stopped"][window].all()
        assert not log["stopped"][log["t"] > 5.6 + 0.1].any()  # fresh frames: moving again


@pytest.mark.slow
def test_strike_sweep_200_cases_no_contact_while_moving():
    for controller in ("qp", "analytic"):
        for seed in range(100):
            check = sweep.run_case(sweep.SweepSpec("strike", controller, safety="ssm"), seed)
            assert check.ticks_moving_in_true_contact == 0, check


@pytest.mark.parametrize("controller", ["qp", "analytic"])
def test_an_arm_never_seen_that_appears_inside_the_robot_finds_it_stationary(
    robot, tmp_path, controller
):
    """An adversarial tester's case: the right arm NotTracked from the first frame, then
    seen already inside the end effector (7 ticks in true contact before the arm was
    bounded by the reach of the tracked shoulder)."""
    from qpavoid.arm.ik import inverse_kinematics
    from qpavoid.control.path import ArcPath
    from qpavoid.experiments.runs import simulate_one
    from qpavoid.human.kinect_v2 import JointType as J
    from qpavoid.human.posture import Operator

    t = np.arange(0.0, 3.0, 1 / 30)
    joints = np.repeat(Operator().rest()[None], len(t), 0)
    state = np.full((len(t), 25), 2, np.int8)
    # the arm reaching into the flange of the start configuration, from the shoulder
    shoulder = joints[0, J.ShoulderRight]
    flange = robot.end_effector(inverse_kinematics(robot, ArcPath().reference(0.0)[0]))[:3, 3]
    pose = {
        J.ElbowRight: shoulder + 0.45 * (flange - shoulder),
        J.WristRight: shoulder + 0.85 * (flange - shoulder),
        J.HandRight: flange,
        J.HandTipRight: flange + 0.05 * (flange - shoulder),
        J.ThumbRight: flange,
    }
    seen = t >= 1.5
    for j, p in pose.items():
        joints[~seen, j], state[~seen, j] = np.nan, 0
        joints[seen, j] = p
    path = tmp_path / "hidden_arm.npz"
    np.savez(path, t=t, joints=joints, state=state)
    spec = RunSpec(human_file=str(path), controller=controller, safety="ssm", rate_hz=100.0)
    run = simulate_one(RunSpec(**{**spec.__dict__, "max_time_s": 2.5}))
    assert np.nanmin(run.sim.log["true_distance"]) < 0.0  # the arm really is inside
    assert run.metrics["ticks_moving_in_true_contact"] == 0


def test_the_places_a_strike_aims_at_besides_the_sets_are_the_tasks(robot):
    """The iiwa's task file names the shoulder and the base; another task names others,
    and a strike at one of them aims at its frame (here A4, the L1 point ["A4"])."""
    assert strike_targets(robot) == ("L1", "L2", "EE", "shoulder", "base")
    task = replace(default_task(robot), body_targets=(BodyTarget("elbow", "A4"),))
    assert strike_targets(robot, task) == ("L1", "L2", "EE", "elbow")
    case = StrikeCase(2, "elbow", 1.0, "right", False, 2.5, "none")
    aim = strike_motion(case, robot, task=task).keyframes[1][1]
    (q,) = nominal_configurations(robot, task.path, np.array([2.5]))
    np.testing.assert_allclose(aim, robot.control_points(q)[3], atol=1e-12)
    with pytest.raises(InputError, match="strike target 'shoulder' is not one of"):
        strike_motion(StrikeCase(2, "shoulder", 1.0, "right", False, 2.5, "none"), robot, task=task)
