"""Adversarial checks of the one compiled QP pass (control/qp/one_pass.py), the
unreachable-row check before the solver (solver_kernels.unreachable_row) and the frames'
view over Pinocchio's data (arm/model.py::frame_translations)."""

from __future__ import annotations

import copy
import gc
import pickle
import threading
from dataclasses import replace
from fractions import Fraction

import numpy as np
import pinocchio as pin
import pytest

from qpavoid.arm.model import load_robot
from qpavoid.control.qp import QPConfig, QPController
from qpavoid.control.qp import controller as qp_controller
from qpavoid.control.qp.limits.velocity import VelocityLimit
from qpavoid.control.qp.limits.velocity_damper import VelocityDamper
from qpavoid.control.qp.one_pass import OnePass
from qpavoid.control.qp.problem import Assembler
from qpavoid.control.qp.solver_kernels import unreachable_row
from qpavoid.control.tick import ControllerConfig
from qpavoid.human.frames import HumanFrame
from qpavoid.human.people import People
from qpavoid.human.posture import Operator
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario

ARRAYS = ("H", "c", "G", "h", "lb", "ub")
TOL = 1e-5


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def _same_bits(pass_problem, reference) -> None:
    for name in ARRAYS:
        got, want = getattr(pass_problem, name), getattr(reference, name)
        assert got.shape == want.shape, name
        assert np.array_equal(_bits(got), _bits(want)), name


def _person(rng, robot, q):
    """A seated operator moved so that one joint lies near a random control point, with
    jitter (a velocity), and sometimes lost or inferred joints."""
    rest = Operator().rest()
    target = robot.control_points(q)[rng.integers(robot.point_set.size)]
    k = rng.integers(len(rest))
    shift = target - rest[k] + rng.normal(size=3) * rng.choice([0.03, 0.1, 0.2])
    joints = rest + shift + rng.normal(size=rest.shape) * 0.005
    state = np.full(len(joints), 2, dtype=np.int8)
    if rng.random() < 0.3:
        lost = rng.random(len(joints)) < 0.3
        joints[lost], state[lost] = np.nan, 0
    return HumanFrame.check(joints, state)


@pytest.mark.parametrize(
    "arm, safety, distance, smooth",
    [("iiwa14", "ssm", "capsules", True), ("ur5", "pfl", "spheres", False)],
)
def test_the_pass_is_the_assembler_on_fuzzed_ticks_and_mutated_inputs(
    arm, safety, distance, smooth
):
    """Several people near random control points, lost joints, stale frames, odd control
    periods; then each tick's bounds and rows poisoned with NaN, ±inf, −0.0 and a crossed
    box: the pass writes the assembler's problem bit for bit every time."""
    robot = load_robot(arm)
    rng = np.random.default_rng(49)
    cfg = ControllerConfig(control_period_s=0.01, distance=distance, safety=safety, smooth=smooth)
    ctrl = QPController(robot, config=cfg)
    assert ctrl.one_pass is not None
    q, damped = robot.neutral(), 0
    poisons = (np.nan, np.inf, -np.inf, -0.0, 1e308, -1e308, 5e-324)
    for k in range(40):
        q = np.clip(q + rng.normal(size=robot.nq) * 0.03, robot.q_min, robot.q_max)
        n = int(rng.integers(0, 4))
        people = People(tuple(range(n)), tuple(_person(rng, robot, q) for _ in range(n)))
        age = [0.0, 0.03, 0.3, None][k % 4]
        tick = ctrl.measure(q, people, None, 0.01 * k, frame_age_s=age)
        dt = float(rng.choice([0.01, 0.002, 1e-9]))
        _same_bits(ctrl.one_pass.fill(tick, dt), ctrl.assembler(tick, dt))
        damped += int(np.isfinite(ctrl.assembler(tick, dt).h).sum())
        rows = tick.human_approach.shape
        mutated = [
            replace(tick, human_approach=rng.choice(poisons, rows)),
            replace(tick, approach_limit=rng.choice(poisons, rows)),
            replace(tick, contact_limit=rng.choice(poisons, rows)),
            replace(tick, limits=rng.choice(poisons, robot.nv)),
            replace(tick, command_box=(np.full(robot.nv, 0.3), np.full(robot.nv, -0.3))),
            replace(tick, command_box=(rng.choice(poisons, robot.nv), np.zeros(robot.nv))),
            replace(tick, v_end_effector=rng.choice(poisons, 3)),
            replace(tick, v_repelled=np.array([1e200, 0.0, 0.0])),
        ]
        for bad in mutated:
            with np.errstate(all="ignore"):
                _same_bits(ctrl.one_pass.fill(bad, 0.01), ctrl.assembler(bad, 0.01))
        ctrl.act(tick)
    assert damped > 20  # the dampers' rows were active


def _exact_low(g, lb, ub):
    low = Fraction(0)
    for gj, lo, hi in zip(g, lb, ub, strict=True):
        if gj > 0:
            low += Fraction(gj) * Fraction(lo)
        elif gj < 0:
            low += Fraction(gj) * Fraction(hi)
    return low


def test_unreachable_row_on_adversarial_numbers():
    """Flagged exactly when the row's exact minimum over a finite box exceeds h + tol
    (tiny, subnormal, huge and signed-zero coefficients, h at the tolerance's edge); never
    for a NaN anywhere it reads, h = +inf or NaN, or a slack column (−1 under ub = +inf)."""
    rng = np.random.default_rng(5)
    odd = np.array([0.0, -0.0, 5e-324, -5e-324, 1e-300, 1e-12, -1e-12, 1.0, -1.0, 1e6])
    mismatch = flagged = 0
    for trial in range(2000):
        n = int(rng.integers(1, 9))
        g = rng.normal(size=n) * 10.0 ** rng.integers(-8, 3, n)
        mask = rng.random(n) < 0.3
        g[mask] = rng.choice(odd, mask.sum())
        lb = -rng.uniform(0, 3, n)
        ub = rng.uniform(0, 3, n)
        if trial % 5 == 0:
            ub = lb + rng.choice([0.0, 1e-12, 1e-5], n)  # a ramp's narrow box
        low = _exact_low(g, lb, ub)
        h0 = float(low) - TOL
        h = h0 + rng.choice([-1e-9, -1e-12, 0.0, 1e-12, 1e-9, 0.5, -0.5])
        want = low > Fraction(h) + Fraction(TOL)
        got = unreachable_row(g[None, :], np.array([h]), lb, ub, TOL) == 0
        flagged += got
        # within rounding of the edge, float and exact may differ; beyond it never
        if got != want:
            assert abs(float(low - Fraction(h) - Fraction(TOL))) < 1e-14 * max(1.0, abs(float(low)))
            mismatch += 1
        # a slack column: never flagged, whatever h
        gs, lbs, ubs = np.r_[g, -1.0], np.r_[lb, 0.0], np.r_[ub, np.inf]
        assert unreachable_row(gs[None, :], np.array([h - 1e3]), lbs, ubs, TOL) == -1
        # h = +inf or NaN: never judged
        for hh in (np.inf, np.nan):
            assert unreachable_row(g[None, :], np.array([hh]), lb, ub, TOL) == -1
        # a NaN in a coefficient or in a bound the row reads: never judged
        j = int(rng.integers(n))
        g_nan = g.copy()
        g_nan[j] = np.nan
        assert unreachable_row(g_nan[None, :], np.array([h]), lb, ub, TOL) == -1
        if g[j] != 0:
            b = (lb if g[j] > 0 else ub).copy()
            b[j] = np.nan
            args = (b, ub) if g[j] > 0 else (lb, b)
            assert unreachable_row(g[None, :], np.array([h]), *args, TOL) == -1
    assert flagged > 300  # and every disagreement with exact arithmetic was a rounding at the edge


def test_unreachable_row_with_infinite_bounds():
    """−inf/+inf bounds under a coefficient of either sign make the row reachable; inf
    times a zero coefficient (0 or −0.0) is never read; a +inf coefficient on a zero bound
    (inf·0) is NaN: not judged."""
    G = np.array([[1.0, 0.0, -0.0, 1.0]])
    lb = np.array([-np.inf, -np.inf, -np.inf, 1.0])
    ub = np.array([np.inf, np.inf, np.inf, 2.0])
    assert unreachable_row(G, np.array([-1e300]), lb, ub, TOL) == -1
    G2 = np.array([[0.0, -0.0, 5e-324, 1.0]])  # only the last column is bounded below
    lb2 = np.array([-np.inf, -np.inf, 0.0, 1.0])
    assert unreachable_row(G2, np.array([1.0 - 2 * TOL]), lb2, ub, TOL) == 0
    assert unreachable_row(G2, np.array([1.0 - 0.5 * TOL]), lb2, ub, TOL) == -1
    G3 = np.array([[np.inf, 1.0]])
    assert (
        unreachable_row(G3, np.array([-5.0]), np.array([0.0, 0.0]), np.array([1.0, 1.0]), TOL) == -1
    )


def test_every_flagged_tick_is_one_daqp_cannot_solve():
    """Test 1 on the FR3 with speed and separation (a third of its ticks holds): at every
    tick, solved by daqp alone, a problem the check flags is never one the solver solves
    (and then the check changes no command: the run is bit for bit the solver's)."""
    pytest.importorskip("daqp")
    robot = load_robot("fr3")
    cfg = ControllerConfig(control_period_s=0.01, safety="ssm", distance="spheres")
    ctrl = QPController(robot, config=cfg, qp=QPConfig(backend="daqp"))
    solve, seen = ctrl.backend.solve, {"flagged": 0, "solved": 0}

    def judged(prob):
        sol = solve(prob)
        if unreachable_row(prob.G, prob.h, prob.lb, prob.ub, TOL) >= 0:
            seen["flagged"] += 1
            seen["solved"] += bool(sol.found)
        return sol

    ctrl.backend.solve = judged
    original = qp_controller.unreachable_row
    qp_controller.unreachable_row = lambda *args: -1
    try:
        simulate(
            ctrl, make_scenario("test1", robot), SimConfig(control_rate_hz=100, max_time_s=3.5)
        )
    finally:
        qp_controller.unreachable_row = original
    assert seen["flagged"] > 20 and seen["solved"] == 0, seen


class _SlowJoints(VelocityLimit):
    """A site's stricter joint speed limit under the standard piece's name."""

    def tighten_qp_bounds(self, tick, dt, lb, ub):
        super().tighten_qp_bounds(tick, dt, lb, ub)
        dq = self.variables.dq
        np.maximum(lb[dq], -0.05, out=lb[dq])
        np.minimum(ub[dq], 0.05, out=ub[dq])


class _CloserDamper(VelocityDamper):
    """A damper that allows no approach at all, under the standard piece's name."""

    def write_qp_inequalities(self, tick, dt, G, h):
        super().write_qp_inequalities(tick, dt, G, h)
        np.minimum(h, 0.0, out=h)


@pytest.mark.parametrize(
    "swap", [("velocity_limits", _SlowJoints), ("velocity_damper", _CloserDamper)]
)
def test_a_custom_piece_under_a_standard_name_is_never_bypassed(swap):
    """Either OnePass.of refuses the set (the assembler writes it), or it writes what the
    assembler writes."""
    robot = load_robot("iiwa14")
    ctrl = QPController(robot, config=ControllerConfig(control_period_s=0.01, smooth=False))
    name, cls = swap
    pieces = []
    for p in ctrl.assembler.pieces:
        if p.name == name:
            custom = cls.__new__(cls)
            custom.__dict__.update(p.__dict__)
            p = custom
        pieces.append(p)
    assembler = Assembler(ctrl.assembler.n, pieces)
    one_pass = OnePass.of(assembler)
    tick = ctrl.measure(robot.neutral(), Operator().rest(), None, 5.0)
    if one_pass is not None:
        _same_bits(one_pass.fill(tick, 0.01), assembler(tick, 0.01))


def _truth(robot, q):
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    pos = np.array([data.oMf[f].translation for f in robot._frames])
    return pos[: robot._n_points], pos[robot._segment_index], data.oMf[robot.ee_frame].homogeneous


def _agrees(robot, q, jacobians=True) -> bool:
    kin = robot.kinematics(q, jacobians=jacobians)
    points, segments, ee = _truth(robot, q)
    return (
        np.array_equal(kin.points, points)
        and np.array_equal(kin.segments, segments)
        and np.array_equal(kin.ee_placement, ee)
    )


@pytest.mark.parametrize("arm, locked", [("fr3", None), ("iiwa14", ())])
def test_frame_positions_survive_new_data_copies_pickles_and_collection(arm, locked):
    """Data assigned anew (old data collected), for_thread, copy, deepcopy and pickle:
    positions always a fresh framesForwardKinematics's; a kept Kinematics outlives its
    robot unchanged and shares no memory with any data."""
    robot = load_robot(arm, locked=locked)
    rng = np.random.default_rng(3)
    q = lambda: rng.uniform(robot.q_min, robot.q_max)  # noqa: E731
    for k in range(10):
        robot.data = robot.model.createData()
        gc.collect()
        assert _agrees(robot, q(), jacobians=bool(k % 2))
    for other in (
        robot.for_thread(),
        copy.copy(robot),
        copy.deepcopy(robot),
        pickle.loads(pickle.dumps(robot)),
    ):
        q1 = q()
        kin1 = robot.kinematics(q1)
        assert _agrees(other, q())
        assert _agrees(robot, q1)
        del other
        gc.collect()
        assert _agrees(robot, q())
        assert not np.shares_memory(kin1.points, robot._held[3])
    lone = load_robot(arm, locked=locked)
    qk = q()
    kin = lone.kinematics(qk)
    want = _truth(lone, qk)
    del lone
    gc.collect()
    [np.ones((200, 200)) for _ in range(10)]  # reuse what was freed
    assert np.array_equal(kin.points, want[0]) and np.array_equal(kin.segments, want[1])


def test_frame_positions_from_threads_on_their_own_copies():
    robot = load_robot("panda")
    errors = []

    def work(r, seed):
        g = np.random.default_rng(seed)
        for k in range(150):
            if k == 75:
                r.data = r.model.createData()
            if not _agrees(r, g.uniform(r.q_min, r.q_max)):
                errors.append(seed)

    threads = [threading.Thread(target=work, args=(robot.for_thread(), s)) for s in range(3)]
    threads.append(threading.Thread(target=work, args=(copy.deepcopy(robot), 9)))
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors


def test_an_assembler_swapped_in_after_construction_is_the_one_that_writes():
    """``act`` takes the pass only for the assembler it was made for: a stricter joint
    speed limit in an assembler assigned later bounds the command (as ``problem()`` shows)."""
    robot = load_robot("iiwa14")
    cfg = ControllerConfig(control_period_s=0.01, smooth=False)
    ctrl = QPController(robot, config=cfg)
    slow = _SlowJoints.__new__(_SlowJoints)
    pieces = []
    for p in ctrl.assembler.pieces:
        if p.name == "velocity_limits":
            slow.__dict__.update(p.__dict__)
            p = slow
        pieces.append(p)
    ctrl.assembler = Assembler(ctrl.assembler.n, pieces)
    tick = ctrl.measure(robot.neutral(), Operator().rest(), None, 5.0)
    assert ctrl.problem(tick).ub[: robot.nv].max() <= 0.05 + 1e-12
    cmd = ctrl.act(tick)
    assert np.abs(cmd.dq).max() <= 0.05 + 1e-6
