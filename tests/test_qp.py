"""The QP controller: agreement with eq. (8), safety over random approaches, solver paths."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import qpsolvers
from conftest import ideal_sim, paper_config

import qpavoid
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.cli.commands import main
from qpavoid.control.analytic import AnalyticController
from qpavoid.control.path import ArcPath
from qpavoid.control.qp import (
    DirectDAQP,
    PersistentOSQP,
    QPConfig,
    QPController,
    QPProblem,
    QPSolversBackend,
)
from qpavoid.control.qp.limits.velocity import VelocityLimit
from qpavoid.control.qp.tasks.elbow import ElbowClearanceTask
from qpavoid.control.tick import ControllerConfig
from qpavoid.distance.methods import PointDistance
from qpavoid.experiments.run_spec import CONTROLLERS, DISTANCES
from qpavoid.experiments.runs import RunSpec, simulate_one
from qpavoid.experiments.sweep import safety_sweep
from qpavoid.experiments.sweep_checks import check_log
from qpavoid.experiments.sweep_summary import summarize
from qpavoid.human.kinect_v2 import JointType
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario

#: Documented agreement between the solve paths (docs/qp.md), rad/s.
SOLVER_TOL = 1e-5


@pytest.mark.parametrize(
    "rate_hz", [100.0, pytest.param(500.0, marks=pytest.mark.slow)], ids=["100Hz", "500Hz"]
)
# DAQP's answers are the persistent backend's on recorded problems in the default suite
# (test_solve_paths_agree); its closed loop here with the slow ones
@pytest.mark.parametrize("backend", ["persistent", pytest.param("daqp", marks=pytest.mark.slow)])
def test_nobody_near_qp_equals_analytic_at_every_tick(robot, rate_hz, backend):
    """In `free` both controllers solve eq. (8): same command within 1e-4 rad/s."""
    cfg = paper_config(control_period_s=1.0 / rate_hz)
    result = simulate(
        QPController(robot, config=cfg, qp=QPConfig(backend=backend)),
        make_scenario("free", robot),
        ideal_sim(control_rate_hz=rate_hz),
    )
    log = result.log
    analytic = AnalyticController(robot, config=cfg)
    worst = 0.0
    for k in range(len(log["t"])):
        cmd = analytic.step(log["q"][k], log["joints"][k], log["state"][k], log["tau"][k])
        worst = max(worst, float(np.abs(cmd.dq - log["dq"][k]).max()))
    assert worst < 1e-4
    m = result.metrics
    assert m["reached_goal"] and m["rms_path_error_m"] < 1e-3 and m["stop_events"] == []


# test2 (the hand comes near, the robot stops, then goes on) in the default suite; test1 and
# free (nobody near: tracked above) with the slow ones
@pytest.mark.parametrize(
    "name",
    [
        pytest.param("test1", marks=pytest.mark.slow),
        "test2",
        pytest.param("free", marks=pytest.mark.slow),
    ],
)
@pytest.mark.parametrize(  # capsules, the default method, here; the paper's spheres slow
    "distance", [pytest.param("spheres", marks=pytest.mark.slow), "capsules"]
)
def test_scenarios_are_safe(name, distance):
    """Every scenario, both distance methods: the sweep's invariants hold."""
    run = simulate_one(
        RunSpec(
            scenario=name,
            controller="qp",
            distance=distance,
            max_time_s=40.0,
            rate_hz=100.0,
            measure_truth=False,
        )
    )
    result, robot, config = run.sim, run.robot, run.config
    checks = check_log(result.log, robot, config, distance)
    assert checks["position_violations"] == checks["velocity_violations"] == 0
    assert checks["moving_under_stop_rule"] == 0
    assert checks["moving_below_capsule_threshold"] == 0
    assert result.metrics["joint_velocity_limit_violations"] == 0
    assert result.metrics["reached_goal"]
    if name == "test2":
        assert result.metrics["stop_events"][0]["reason"].startswith("f = ")


def _assert_sweep_safe(n: int, distance: str, min_stopping: int) -> None:
    """Random part, direction and timing, hand speeds up to 1.6 m/s (scenarios.random_approach)."""
    checks = safety_sweep(range(n), "qp", distance, rate_hz=50.0)
    s = summarize(checks)
    assert s["approaches"] == n
    assert s["position_violations"] == 0
    assert s["velocity_violations"] == 0
    assert s["moving_under_stop_rule"] == 0
    assert s["command_limit_violations"] == 0  # every command within the arm's limits
    assert s["moving_below_capsule_threshold"] == 0, [c for c in checks if not c.safe][:3]
    assert sum(c.stopped_s > 0 for c in checks) >= min_stopping  # the approaches reach the robot


@pytest.mark.slow  # 5.5 s; the strikes of tests/test_strikes.py hold the QP in the default suite
@pytest.mark.parametrize("distance", ["spheres", "capsules"])
def test_safety_over_5_random_approaches(distance):
    """The first 5 seeds (5 stop the robot with spheres, 4 with capsules, the EE coming
    within 0.5 mm of its capsule threshold): capsules, the default method, in the default
    suite; spheres with the slow one (its 200-approach sweep is there too)."""
    _assert_sweep_safe(5, distance, min_stopping=4)


@pytest.mark.slow
@pytest.mark.parametrize("distance", ["spheres", "capsules"])
def test_safety_over_200_random_approaches(distance):
    """The long safety suite: 200 seeds (``pytest -m slow``)."""
    _assert_sweep_safe(200, distance, min_stopping=21)


@pytest.fixture(scope="module")
def recorded_problems(robot):
    """QP problems of every tick of a test1 run (100 Hz), many with active rows."""
    ctrl = QPController(robot, config=ControllerConfig(control_period_s=0.01))
    log = simulate(ctrl, make_scenario("test1", robot), SimConfig(control_rate_hz=100)).log
    probe = QPController(robot, config=ControllerConfig(control_period_s=0.01))
    problems = []
    for k in range(0, len(log["t"]), 3):
        tick = probe.measure(log["q"][k], log["joints"][k], log["state"][k], log["tau"][k])
        if not tick.reason:
            problems.append(probe.problem(tick))
    return problems


def test_solve_paths_agree(recorded_problems):
    n, m = recorded_problems[0].H.shape[0], len(recorded_problems[0].h)
    persistent = PersistentOSQP(n, m, QPConfig())
    direct_daqp = DirectDAQP(n, m)
    through_osqp = QPSolversBackend("osqp", QPConfig())
    daqp = QPSolversBackend("daqp", QPConfig())
    others = [
        QPSolversBackend(s, QPConfig()) for s in ("proxqp",) if s in qpsolvers.available_solvers
    ]
    active = 0
    for prob in recorded_problems:
        ref = daqp.solve(prob)
        assert ref.found
        keep = np.isfinite(prob.h)
        if np.any(prob.G[keep] @ ref.x > prob.h[keep] - 1e-9):
            active += 1
        for backend in (persistent, direct_daqp, through_osqp, *others):
            sol = backend.solve(prob)
            assert sol.found, (backend.name, sol.status)
            np.testing.assert_allclose(sol.x[:-2], ref.x[:-2], atol=SOLVER_TOL)
    assert active > 50  # constraints were really active on many ticks


def test_persistent_paths_agree(recorded_problems):
    """The fast path into osqp's solver object equals osqp's public API."""
    n, m = recorded_problems[0].H.shape[0], len(recorded_problems[0].h)
    fast, public = PersistentOSQP(n, m, QPConfig()), PersistentOSQP(n, m, QPConfig())
    public._native = None
    for prob in recorded_problems[::5]:
        a, b = fast.solve(prob), public.solve(prob)
        assert a.found and b.found
        np.testing.assert_allclose(a.x, b.x, atol=1e-9)


def _problem(n: int, m: int) -> QPProblem:
    """A feasible problem of ``n`` variables and ``m`` rows."""
    return QPProblem(np.eye(n), np.ones(n), np.zeros((m, n)), np.ones(m), -np.ones(n), np.ones(n))


@pytest.mark.parametrize("backend", ["persistent", "daqp"])
def test_a_problem_changed_in_place_is_solved_or_refused(recorded_problems, backend):
    """The same problem object solved again and again (the assembler's, every tick):
    values written into it are solved; a NaN written into it is refused; an array made
    read-only is still taken; an array reshaped in place, arrays of another number of
    dimensions, or a problem of other sizes that would fit the solver's arrays, is a
    ValueError, never a wrong answer or a write past an array's end."""
    n, m = recorded_problems[0].H.shape[0], len(recorded_problems[0].h)
    assert (n, m) == (8, 26)
    solver = PersistentOSQP(n, m, QPConfig()) if backend == "persistent" else DirectDAQP(n, m)
    reference = QPSolversBackend("daqp", QPConfig())

    def fresh() -> QPProblem:
        return QPProblem(
            *(np.array(getattr(recorded_problems[0], k)) for k in ["H", "c", "G", "h", "lb", "ub"])
        )

    mutable = fresh()
    for prob in recorded_problems[::7]:
        for k in ("H", "c", "G", "h", "lb", "ub"):
            getattr(mutable, k)[...] = getattr(prob, k)
        sol, ref = solver.solve(mutable), reference.solve(prob)
        assert sol.found and ref.found
        np.testing.assert_allclose(sol.x[:-2], ref.x[:-2], atol=SOLVER_TOL)
    mutable.c[0] = np.nan
    assert not solver.solve(mutable).found
    mutable.c[0] = 0.0
    mutable.h.setflags(write=False)  # taken again (a copy), still solved
    assert solver.solve(mutable).found and solver.solve(mutable).found
    for reshape in ("G", (n, m)), ("G", (m * n,)), ("h", (m, 1)):
        again = fresh()
        assert solver.solve(again).found
        getattr(again, reshape[0]).shape = reshape[1]  # the same bytes, other sizes
        with pytest.raises(ValueError, match="shapes"):
            solver.solve(again)
    H3 = np.zeros((n, n, 2))  # H.flat would read its first n² entries as an (n, n) H
    H3.reshape(-1)[: n * n] = 5 * np.eye(n).ravel()
    p = fresh()
    with pytest.raises(ValueError, match="shapes"):
        solver.solve(QPProblem(H3, p.c, p.G, p.h, p.lb, p.ub))
    # sizes that fit the solver's arrays: n + m = 34 (and for OSQP n (m + 1) = 216)
    for other in (27, 7), (9, 25), (10, 24):
        with pytest.raises(ValueError, match="shapes"):
            solver.solve(_problem(*other))


def _start(robot):
    path = ArcPath()
    return path, inverse_kinematics(robot, path.reference(1.0)[0])


def test_iteration_limit_stops_the_robot(robot):
    path, q = _start(robot)
    ctrl = QPController(robot, path=path, qp=QPConfig(max_iter=1))
    from qpavoid.human.posture import Operator

    cmd = ctrl.step(q + 0.05, Operator().rest(), None, 1.0)
    assert cmd.stopped and cmd.reason.startswith("QP not solved")
    assert "maximum iterations" in cmd.reason
    np.testing.assert_array_equal(cmd.dq, 0.0)


@pytest.mark.parametrize("backend", ["persistent", "qpsolvers"])
@pytest.mark.parametrize("writer", ["assembler", "one pass"])
def test_infeasible_problem_stops_the_robot(robot, monkeypatch, backend, writer):
    """Crossed bounds (1 ≤ x ≤ −1), written by a piece through the assembler or by the
    standard pieces' one compiled pass: no command but a stop."""
    from qpavoid.control.qp import one_pass

    path, q = _start(robot)

    def crossed(self, tick, dt, lb, ub):  # 1 <= x <= -1
        lb[:], ub[:] = 1.0, -1.0

    def crossed_pass(*args):
        real(*args)
        args[-2][:], args[-1][:] = 1.0, -1.0  # its lb and ub, written last

    real = one_pass.standard_problem
    monkeypatch.setattr(VelocityLimit, "tighten_qp_bounds", crossed)
    monkeypatch.setattr(one_pass, "standard_problem", crossed_pass)
    ctrl = QPController(
        robot,
        path=path,
        qp=QPConfig(backend=backend, solver="daqp" if backend == "qpsolvers" else "osqp"),
    )
    assert ctrl.one_pass is not None  # the standard pieces
    if writer == "assembler":
        ctrl.one_pass = None
    from qpavoid.human.posture import Operator

    cmd = ctrl.step(q, Operator().rest(), None, 1.0)
    assert cmd.stopped and cmd.reason.startswith("QP not solved")
    np.testing.assert_array_equal(cmd.dq, 0.0)


def test_backends_report_infeasibility():
    prob = QPProblem(
        np.eye(2),
        np.zeros(2),
        np.zeros((1, 2)),
        np.array([-1.0]),
        np.full(2, -1.0),
        np.full(2, 1.0),
    )  # 0 <= -1: infeasible
    assert not PersistentOSQP(2, 1, QPConfig()).solve(prob).found
    assert not QPSolversBackend("daqp", QPConfig()).solve(prob).found
    daqp = DirectDAQP(2, 1)
    assert not daqp.solve(prob).found
    # min ½|x|² − x₁ − x₂ with x₁ + x₂ ≤ 1: x = (½, ½), by hand
    feasible = QPProblem(np.eye(2), -np.ones(2), np.ones((1, 2)), np.ones(1), prob.lb, prob.ub)
    np.testing.assert_allclose(daqp.solve(feasible).x, [0.5, 0.5], atol=1e-9)
    nan = QPProblem(
        np.full((2, 2), np.nan), -np.ones(2), np.ones((1, 2)), np.ones(1), prob.lb, prob.ub
    )
    assert not daqp.solve(nan).found  # never a NaN command
    assert daqp.solve(feasible).found  # and the workspace recovers
    concave = QPProblem(-np.eye(2), -np.ones(2), np.ones((1, 2)), np.ones(1), prob.lb, prob.ub)
    assert not daqp.solve(concave).found
    assert not daqp.solve(prob).found
    with pytest.raises(qpavoid.SolverError, match="not installed"):
        QPSolversBackend("nosuchsolver", QPConfig())


def test_redundancy_moves_the_elbow_away_keeping_the_end_effector(robot7):
    """A3 free: the elbow task acts in the null space of the end-effector task (one tick
    from rest: the QP's own command, not yet bounded by the arm's acceleration)."""
    path = ArcPath()
    q = inverse_kinematics(robot7, path.reference(5.0)[0])
    P = robot7.control_points(q)
    elbow = P[3]
    side = np.cross(P[7] - P[3], P[3] - robot7.capsules(q)[0, 0])
    side /= np.linalg.norm(side)
    for sign in (1.0, -1.0):
        # one hand near the elbow, the rest of the person beyond it, away from the arm (a
        # body with only a hand seen is bounded around the hand by its bones: a stop)
        joints = np.repeat((elbow + sign * 1.3 * side)[None], 25, axis=0)
        joints[JointType.ShoulderRight] = elbow + sign * 1.0 * side
        joints[JointType.ElbowRight] = elbow + sign * 0.65 * side
        joints[JointType.WristRight] = elbow + sign * 0.35 * side
        joints[JointType.HandRight] = elbow + sign * 0.33 * side
        # the fingers seen too (unseen, they could be a bone beyond the hand)
        joints[JointType.HandTipRight] = elbow + sign * 0.32 * side
        joints[JointType.ThumbRight] = elbow + sign * 0.33 * side
        speeds = []
        for weight in (0.0, 0.05):
            ctrl = QPController(
                robot7,
                path=path,
                config=ControllerConfig(smooth=False),
                qp=QPConfig(elbow_weight=weight, regularization=1e-4),
            )
            tick = ctrl.measure(q, joints, None, 5.0)
            cmd = ctrl.step(q, joints, None, 5.0)
            assert not cmd.stopped
            assert robot7.roles.elbow == 3  # the description's elbow: A4
            clearance = PointDistance(3, len(P), robot7.sphere_radii[3], ctrl.human)
            _, n = ElbowClearanceTask(ctrl.variables, 3, clearance, 1, 0.4, 0.1).clearance(tick)
            speeds.append(n @ tick.kin.point_jacobians[3] @ cmd.dq)
            residual = tick.kin.ee_jacobian @ cmd.dq - ctrl.ee_task.target(tick)
            assert np.abs(residual).max() < 1e-3  # the end effector keeps its path
        assert speeds[1] > speeds[0] + 0.03  # m/s: the elbow moves away


def test_cli_qp_solver_redundant_and_compare(tmp_path, capsys):
    out = tmp_path / "qp"
    assert (
        main(
            [
                "run",
                "test1",
                "--controller",
                "qp",
                "--solver",
                "daqp",
                "--out",
                str(out),
                "--max-time",
                "1",
                "--rate",
                "100",
                "--no-plots",
            ]
        )
        == 0
    )
    m = json.loads((out / "metrics.json").read_text())
    assert m["controller"] == "qp" and m["solver"] == "daqp"
    out = tmp_path / "red"
    assert (
        main(
            [
                "run",
                "free",
                "--controller",
                "qp",
                "--redundant",
                "--out",
                str(out),
                "--max-time",
                "1",
                "--rate",
                "100",
                "--no-plots",
            ]
        )
        == 0
    )
    assert np.load(out / "log.npz")["q"].shape[1] == 7
    assert main(["view", str(out), "--out", str(tmp_path / "red.html")]) == 0  # 7 joints
    assert (tmp_path / "red.html").read_bytes() == (out / "replay.html").read_bytes()
    assert main(["run", "free", "--redundant", "--out", str(out)]) == 2
    assert "needs --controller qp" in capsys.readouterr().err
    cmp = tmp_path / "cmp"
    assert (
        main(
            [
                "compare",
                "--out",
                str(cmp),
                "--scenarios",
                "free",
                "--random",
                "1",
                "--max-time",
                "2",
                "--rate",
                "50",
            ]
        )
        == 0
    )
    data = json.loads((cmp / "compare.json").read_text())
    assert set(data) == {"free", "random:0"}
    replays = sorted(p.name for p in cmp.glob("replay_*.html"))  # the named input's four
    assert replays == sorted(f"replay_free_{c}_{d}.html" for c in CONTROLLERS for d in DISTANCES)
    for ctrl in ("analytic", "qp"):
        assert set(data["free"][ctrl]) == {"spheres", "capsules"}
        assert "min_distance_m" in data["free"][ctrl]["spheres"]
    table = (cmp / "compare.md").read_text()
    assert table.count("| free |") == 4 and "random ×1" in table


def test_rejected_update_is_never_solved_stale(robot):
    """OSQP keeps the old data when an update is invalid; the backend must not 'solve' it."""
    ok = QPProblem(
        np.eye(2), np.zeros(2), np.zeros((1, 2)), np.array([1.0]), np.full(2, -1.0), np.full(2, 1.0)
    )
    bad = QPProblem(
        np.eye(2), np.zeros(2), np.zeros((1, 2)), np.array([1.0]), np.full(2, 1.0), np.full(2, -1.0)
    )  # lb > ub
    nonconvex = QPProblem(
        -np.eye(2),
        np.zeros(2),
        np.zeros((1, 2)),
        np.array([1.0]),
        np.full(2, -1.0),
        np.full(2, 1.0),
    )
    for native in (True, False):
        b = PersistentOSQP(2, 1, QPConfig())
        if not native:
            b._native = None
        assert b.solve(ok).found
        sol = b.solve(bad)
        assert not sol.found and "infeasible bounds" in sol.status
        assert not b.solve(nonconvex).found
        assert b.solve(ok).found


def _recorded_pair(k: int) -> QPProblem:
    data = np.load(Path(__file__).parent / "data" / "daqp_warm_start_pairs.npz")
    return QPProblem(*(data[f"{name}_{k}"] for name in ("H", "c", "G", "h", "lb", "ub")))


@pytest.mark.parametrize("first, second", [(313, 314), (404, 405)])
def test_daqp_answers_each_tick_as_if_it_were_the_first(first, second):
    """Consecutive QPs of recorded ticks on which daqp 0.11's warm start (Model.update)
    returned a wrong 'optimal' command (A1 at -1.48 rad/s instead of +1.48) or a NaN: the
    daqp backend (cold each tick) answers the second as OSQP does."""
    a, b = _recorded_pair(first), _recorded_pair(second)
    n, m = a.G.shape[1], a.G.shape[0]
    backend = DirectDAQP(n, m)
    assert backend.solve(a).found
    sol = backend.solve(b)
    ref = PersistentOSQP(n, m, QPConfig()).solve(b)
    assert sol.found and ref.found
    np.testing.assert_allclose(sol.x[:-2], ref.x[:-2], atol=SOLVER_TOL)


@pytest.mark.parametrize(
    "field, value",
    [(f, np.nan) for f in ("H", "c", "G", "h", "lb", "ub")]
    + [("h", -np.inf), ("lb", np.inf), ("ub", -np.inf), ("G", np.inf)],
)
def test_a_nan_in_the_problem_is_never_solved_and_leaves_no_trace(field, value):
    """daqp takes a NaN row as no row and says 'solved'; one NaN in OSQP's warm start
    spoiled every later solve: every backend refuses the problem, then solves the next."""
    good = _recorded_pair(313)
    n, m = good.G.shape[1], good.G.shape[0]
    arrays = {k: getattr(good, k).copy() for k in ("H", "c", "G", "h", "lb", "ub")}
    arrays[field].flat[0] = value
    bad = QPProblem(**arrays)
    for backend in (
        PersistentOSQP(n, m, QPConfig()),
        DirectDAQP(n, m),
        QPSolversBackend("daqp", QPConfig()),
    ):
        assert backend.solve(good).found
        sol = backend.solve(bad)
        assert not sol.found
        assert "NaN" in sol.status or "not finite" in sol.status, sol.status
        again = backend.solve(good)
        assert again.found, backend.name


def test_a_solution_the_hard_rows_cannot_judge_is_never_applied(robot, monkeypatch):
    """A 'found' solution whose hard-row check is NaN (Python's max would skip the NaN)."""
    path, q = _start(robot)
    ctrl = QPController(robot, path=path)
    from qpavoid.control.qp.problem import QPSolution
    from qpavoid.human.posture import Operator

    x = np.zeros(ctrl.variables.n)
    x[-1] = np.nan  # a slack: the bounds on q̇ hold, the rows' check is NaN
    monkeypatch.setattr(ctrl.backend, "solve", lambda prob: QPSolution(x, True, "solved"))
    cmd = ctrl.step(q, Operator().rest(), None, 1.0)
    assert cmd.stopped and "breaks a hard constraint by nan" in cmd.reason
    np.testing.assert_array_equal(cmd.dq, 0.0)


def test_warm_start_never_decays_into_subnormal_numbers(recorded_problems):
    """The duals of inactive rows shrink with every warm-started solve until they are
    subnormal, and OSQP's iterations then take twice as long: they are zeroed between
    solves, so no solution of a long run holds one (without it, most did)."""
    n, m = recorded_problems[0].H.shape[0], len(recorded_problems[0].h)
    backend = PersistentOSQP(n, m, QPConfig())
    tiny = np.finfo(float).tiny
    subnormal = 0
    for prob in recorded_problems * 3:
        assert backend.solve(prob).found
        sol = backend._native.solution
        v = np.r_[np.array(sol.x), np.array(sol.y)]
        subnormal += int(((v != 0) & (np.abs(v) < tiny)).any())
    assert subnormal == 0
