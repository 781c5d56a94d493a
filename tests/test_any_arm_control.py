"""Both controllers on any arm and any number of sets; the posture task of redundant arms.

* In ``free`` (nobody near) the QP and the paper's controller give the same command,
  within 1e-4 rad/s, on each arm whose description loads (as it locks its joints, where
  the paper's roles apply) and on the iiwa with three more sets that play no part.
* The QP takes every set as velocity-damper rows with the full Jacobian (a set with no
  part in the laws down to contact); the paper's controller reads only the sets of the
  roles: on the iiwa with three more sets it commands what it commands on the iiwa.
* A strike at each set of each arm finds the robot stopped or out of the way: never
  moving in true contact.
* A redundant arm's posture task (the QP's redundancy mode) pulls the null space back to
  the start posture and leaves the end effector's tracking as it was.

Each arm's task is its description's (``default_task``); an arm without a task file yet
gets a short arc of its own (:data:`OWN_START`), or is skipped.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import ideal_sim, paper_config
from scipy.linalg import null_space
from test_witness_jacobians import EXTRA_SETS, SIX_SETS, load_arm, six_set_description

import qpavoid
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.control.analytic import AnalyticController
from qpavoid.control.path import ArcPath, PlannedPath
from qpavoid.control.qp import QPController
from qpavoid.control.qp.config import REDUNDANT
from qpavoid.control.qp.limits.velocity_damper import VelocityDamper
from qpavoid.control.qp.tasks.posture import PostureTask
from qpavoid.control.task import default_task
from qpavoid.control.tick import ControllerConfig
from qpavoid.core.errors import IKNotConvergedError
from qpavoid.experiments.runs import RunSpec, build_controller
from qpavoid.human.posture import Operator
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import Working, make_scenario
from qpavoid.scenarios.strikes import StrikeCase, strike_camera, strike_motion

#: The arms: the shipped ones, and the iiwa with six sets (:data:`SIX_SETS`).
ARMS = ("iiwa14", "panda", "ur5", "fr3", "six_sets")
#: An arm with no task file yet: its end effector pointing down at this place in front of
#: the operator (m), the start of a 0.3 m arc to −x rising 0.1 m in 8 s.
OWN_START = {"panda": (0.3, 0.45, 0.45), "fr3": (0.3, 0.45, 0.45)}
#: Agreement of the two controllers where nothing binds (docs/qp.md), rad/s.
SAME_COMMAND = 1e-4


def own_path(robot: qpavoid.Robot) -> ArcPath:
    """The short arc of :data:`OWN_START` (skip if the arm has none)."""
    if robot.name not in OWN_START:
        pytest.skip(f"{robot.name} has no task file (robots/{robot.name}/task.toml) yet")
    start = np.eye(4)
    start[:3, :3] = np.diag([1.0, -1.0, -1.0])  # the tool's z axis down
    start[:3, 3] = OWN_START[robot.name]
    goal = start.copy()
    goal[:3, 3] += (-0.3, 0.0, 0.1)
    return ArcPath(start, goal, duration_s=8.0, sagitta_m=0.04)


def arm_path(robot: qpavoid.Robot) -> PlannedPath:
    """The arm's task's path, if its start is in reach, else :func:`own_path`."""
    task = default_task(robot)
    try:
        inverse_kinematics(robot, task.path.reference(0.0)[0])
    except IKNotConvergedError:
        return own_path(robot)
    return task.path


@pytest.fixture(scope="module")
def six_sets(tmp_path_factory) -> qpavoid.Robot:
    return qpavoid.load_robot(six_set_description(tmp_path_factory.mktemp("arms") / "six_sets"))


def arm(name: str, six_sets: qpavoid.Robot) -> qpavoid.Robot:
    return six_sets if name == "six_sets" else load_arm(name)


def free_run(robot: qpavoid.Robot, controller, path: PlannedPath, q0=None, max_time_s=None):
    """``controller`` on ``robot`` along ``path`` in ``free``, on the paper's bench at 100 Hz,
    to the goal (or for ``max_time_s``)."""
    duration = path.duration_s + 1.0 if max_time_s is None else max_time_s
    return simulate(
        controller,
        Working(default_task(robot).operator),
        ideal_sim(control_rate_hz=100.0, max_time_s=duration, measure_truth=False),
        q0=q0,
    )


@pytest.mark.parametrize(
    "name",
    [
        # the Panda by default (the iiwa's twin is test_qp's); the other arms slow
        pytest.param(name, marks=pytest.mark.slow)
        if name in ("iiwa14", "fr3", "ur5", "six_sets")
        else name
        for name in ARMS
    ],
)
def test_nobody_near_qp_equals_analytic_on_each_arm(name, six_sets):
    """test_qp's iiwa test on every arm: at each tick of the QP's free run, the paper's
    controller at the same state commands the same (capsules, the default method)."""
    robot = arm(name, six_sets)
    path = arm_path(robot)
    cfg = paper_config(distance="capsules", control_period_s=0.01)
    result = free_run(robot, QPController(robot, path=path, config=cfg), path)
    log = result.log
    analytic = AnalyticController(robot, path=path, config=cfg)
    worst = 0.0
    for k in range(len(log["t"])):
        cmd = analytic.step(log["q"][k], log["joints"][k], log["state"][k], log["tau"][k])
        worst = max(worst, float(np.abs(cmd.dq - log["dq"][k]).max()))
    assert worst < SAME_COMMAND
    m = result.metrics
    assert m["reached_goal"] and m["rms_path_error_m"] < 1e-3 and m["stop_events"] == []
    assert np.abs(log["dq"]).max() > 0.05  # it did move


def test_every_set_gets_damper_rows_with_the_full_jacobian(six_sets):
    """With a person near all six sets, the QP has a damper row for every set × part: its
    row −nᵀ J_p over every joint, and its bound ξ (d − d_s)/(d_i − d_s) with d_s the
    set's stop distance by role, 0 (contact) for the three sets with none."""
    robot = six_sets
    ctrl = QPController(robot, config=ControllerConfig(distance="capsules"))
    damper = next(p for p in ctrl.assembler.pieces if p.name == VelocityDamper.name)
    K = len(ctrl.human.parts)
    d_stop = damper.d_stop[::K]
    cfg = ctrl.config.avoidance
    expected = {name: 0.0 for name in EXTRA_SETS}
    expected |= {"L1": cfg.d_stop_L1_m(), "L2": cfg.d_stop_L2_m, "EE": cfg.d_stop_EE_m}
    np.testing.assert_array_equal(d_stop, [expected[n] for n in SIX_SETS])
    q = inverse_kinematics(robot, ctrl.path.reference(3.0)[0])
    kin = robot.kinematics(q)
    rng = np.random.default_rng(4)
    seen = set()
    for _ in range(30):
        # the right hand and forearm through random points 0.05-0.12 m off random sets
        i = int(rng.integers(len(robot.sets)))
        a, b = kin.segments[i]
        side = rng.normal(size=3)
        side /= np.linalg.norm(side)
        hand = a + rng.uniform() * (b - a) + (robot.capsule_radii[i] + 0.1) * side
        joints = Operator().reach(Operator().rest(), "right", hand)
        tick = ctrl.measure(q, joints, None, 3.0)
        prob = ctrl.problem(tick)
        rows = prob.rows[VelocityDamper.name]
        G, h = prob.G[rows], prob.h[rows]
        assert G.shape[0] == len(robot.sets) * K
        table = tick.table
        sets, parts = np.divmod(np.arange(G.shape[0]), K)
        J = table.robot_jacobians(kin, sets, parts)
        d = table.distance.ravel()
        active = d < damper.influence_m
        np.testing.assert_allclose(
            G[active, : robot.nv],
            -np.einsum("ak,akv->av", table.vector.reshape(-1, 3), J)[active],
            rtol=0,
            atol=1e-14,
        )
        gap = damper.gain * (d - damper.d_stop) / (damper.influence_m - damper.d_stop)
        np.testing.assert_allclose(h[active], gap[active], rtol=0, atol=1e-14)
        assert np.all(np.isinf(h[~active]))
        seen |= {robot.set_names[s] for s in sets[active]}
    assert seen == set(SIX_SETS)


def test_the_paper_s_controller_reads_only_the_sets_of_the_roles(robot, six_sets):
    """At every tick of an iiwa test1 run (the paper's rules), the paper's controller on
    the iiwa with three more sets commands what it commands on the iiwa: the sets with no
    part change nothing until they touch the person."""
    cfg = paper_config(control_period_s=0.01)
    log = simulate(
        AnalyticController(robot, config=cfg),
        make_scenario("test1", robot),
        ideal_sim(control_rate_hz=100.0, max_time_s=15.0, measure_truth=False),
    ).log
    three, six = AnalyticController(robot, config=cfg), AnalyticController(six_sets, config=cfg)
    rows = [six_sets.set_names.index(n) for n in robot.set_names]
    repelled = 0
    for k in range(0, len(log["t"]), 3):
        step = (log["q"][k], log["joints"][k], log["state"][k], log["tau"][k])
        a, b = three.step(*step), six.step(*step)
        assert b.distance.min() > 0.0  # no set touches
        np.testing.assert_array_equal(b.distance[rows], a.distance)
        np.testing.assert_array_equal(b.dq, a.dq)
        assert b.reason == a.reason
        repelled += bool(np.any(a.v_repelled))
    assert repelled > 10  # the laws acted


def strike(robot: qpavoid.Robot, target: str, controller: str) -> None:
    """A clean strike at ``target`` (1.5 m/s, the right hand, arriving at 2 s) with speed
    and separation monitoring, seen by a Kinect, the arm braking as it does: the robot
    moved before, the hand got to the robot, and no tick moves in true contact."""
    path = arm_path(robot)
    case = StrikeCase(0, target, 1.5, "right", False, 2.0, "none")
    spec = RunSpec(scenario="free", controller=controller, safety="ssm", rate_hz=100.0)
    ctrl = build_controller(spec, robot)
    ctrl.path = path
    sim = simulate(
        ctrl,
        strike_motion(case, robot, path),
        SimConfig(
            control_rate_hz=100.0,
            camera=strike_camera(case),
            max_time_s=case.duration_s,
            measure_truth=True,
        ),
    )
    log = sim.log
    assert np.any(log["dq"][log["t"] < 1.0] != 0.0)  # it worked before the strike
    # the hand got there: within 5 cm of the set's surface (the UR5's shoulder turret, 9 cm
    # above the table, is as near as a seated person's hand gets to it: 4 cm)
    assert np.nanmin(log["true_distance"]) < 0.05
    assert sim.metrics["ticks_moving_in_true_contact"] == 0


# the QP at the tool in the default suite; the paper's controller and the other sets slow
@pytest.mark.parametrize("controller", ["qp", pytest.param("analytic", marks=pytest.mark.slow)])
@pytest.mark.parametrize(
    "target", ["tool", *(pytest.param(s, marks=pytest.mark.slow) for s in ("column", "elbow_pad"))]
)
def test_a_strike_at_a_set_with_no_part_finds_the_robot_still(six_sets, target, controller):
    strike(six_sets, target, controller)


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["qp", "analytic"])
@pytest.mark.parametrize("name", ARMS[:-1])
def test_a_strike_at_each_set_of_each_arm_finds_the_robot_still(name, controller):
    robot = load_arm(name)
    for target in robot.set_names:
        strike(robot, target, controller)


def displaced_start(robot: qpavoid.Robot, rest: np.ndarray, path: PlannedPath) -> np.ndarray:
    """The start pose reached 0.4 rad along the end effector's null space from ``rest``."""
    Z = null_space(robot.kinematics(rest).ee_jacobian)
    assert Z.shape[1] == 1  # one redundant joint
    return inverse_kinematics(robot, path.reference(0.0)[0], q0=rest + 0.4 * Z[:, 0])


@pytest.mark.parametrize(
    "name", ["iiwa14", *(pytest.param(n, marks=pytest.mark.slow) for n in ("panda", "fr3"))]
)
def test_the_posture_task_pulls_the_null_space_home_keeping_the_end_effector(name):
    """A redundant arm starts 0.4 rad along its self-motion from the start posture. Over
    the first 5 s of its path, with the posture task it returns (its distance to the
    rest posture halves by 4 s, while without it grows), and the end effector tracks the
    path as it does without: 1e-5 m apart at every tick (measured 3e-6 m at 100 Hz, the
    second-order term of the null-space motion's Euler steps, which the task's feedback
    removes; the QP's own answer moves the end effector the same to the solver's
    tolerance, test_qp_pieces)."""
    robot = load_arm(name, redundant=True)
    path = arm_path(robot)
    rest = inverse_kinematics(robot, path.reference(0.0)[0])
    q0 = displaced_start(robot, rest, path)
    cfg = paper_config(distance="capsules", control_period_s=0.01)
    runs = {}
    for weight in (0.0, REDUNDANT.posture_weight):
        qp = replace(REDUNDANT, elbow_weight=0.0, posture_weight=weight)
        result = free_run(robot, QPController(robot, path=path, config=cfg, qp=qp), path, q0, 5.0)
        assert result.metrics["stop_events"] == []
        log = result.log
        runs[weight] = (
            np.linalg.norm(log["ee_pos"] - log["ee_ref"], axis=1),
            np.linalg.norm(log["q"] - rest, axis=1),
            log["t"],
        )
    (track_off, post_off, t), (track_on, post_on, _) = runs.values()
    assert np.abs(track_on - track_off).max() < 1e-5
    assert post_on[0] == post_off[0] > 0.39
    assert post_on[np.searchsorted(t, 4.0)] < post_on[0] / 2
    assert post_off[np.searchsorted(t, 4.0)] > 0.9 * post_off[0]  # nothing pulls it home
    assert np.all(post_on[t > 1.0] < post_off[t > 1.0])


def test_the_posture_task_is_nothing_on_a_six_joint_arm(robot):
    """The iiwa with A3 locked has no null space: the posture cost is 0, the QP's answer
    that of eq. (8)."""
    ctrl = QPController(robot, qp=replace(REDUNDANT, posture_weight=1.0, elbow_weight=0.0))
    posture = next(p for p in ctrl.assembler.pieces if isinstance(p, PostureTask))
    q = inverse_kinematics(robot, ctrl.path.reference(2.0)[0]) + 0.01
    tick = ctrl.measure(q, Operator().rest(), None, 2.0)
    obj = posture.compute_qp_objective(tick, 0.01)
    assert obj is not None and not obj.H.any() and not obj.c.any()
    assert np.abs(posture.target(tick)).max() > 0.0
