"""The QP's pieces, row by row, against independent references: finite differences of the
robot points, the rows' formulas by hand, numpy for the compiled cost, and the in-place
assembly against the pieces' own ``compute_qp_*``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import random_q

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.control.path import ArcPath
from qpavoid.control.qp import QPConfig, QPController, QPProblem
from qpavoid.control.qp.barriers.separation import SeparationLimit
from qpavoid.control.qp.config import REDUNDANT
from qpavoid.control.qp.limits.velocity_damper import VelocityDamper
from qpavoid.control.qp.problem import Assembler
from qpavoid.control.qp.solver_kernels import hard_excess, problem_defect
from qpavoid.control.qp.tasks.posture import PostureTask
from qpavoid.control.tick import ControllerConfig
from qpavoid.core.errors import InputError
from qpavoid.human.posture import Operator
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario

EPS = 1e-6  # central differences: error ~ EPS² · |q̈-terms|, far below the tolerance


# capsules (the default method) in the default suite; the paper's spheres with the slow ones
@pytest.fixture(
    scope="module", params=[pytest.param("spheres", marks=pytest.mark.slow), "capsules"]
)
def ticks(robot, request):
    """The states of a test1 run under the paper's rules (close approaches: active damper
    rows), measured again by a probe controller with SSM (active separation rows)."""
    cfg = ControllerConfig(control_period_s=0.01, distance=request.param)
    log = simulate(
        QPController(robot, config=cfg),
        make_scenario("test1", robot),
        SimConfig(control_rate_hz=100),
    ).log
    probe = QPController(robot, config=replace(cfg, safety="ssm"))
    out = [
        probe.measure(log["q"][k], log["joints"][k], log["state"][k], log["tau"][k])
        for k in range(0, len(log["t"]), 7)
    ]
    return probe, [t for t in out if not t.reason]


def _material_point(robot, q, table, i, k):
    """The robot point of pair (i, k) as a point fixed on the arm, at joint angles q."""
    kin = robot.kinematics(q, jacobians=False)
    p = table.robot_index[i, k]
    if p >= 0:
        return kin.points[p]
    s = table.robot_s[i, k]
    return (1.0 - s) * kin.segments[i, 0] + s * kin.segments[i, 1]


def _approach_row(robot, tick, i, k):
    """−nᵀ ∂p/∂q by central differences (p the pair's robot point)."""
    J = np.empty((3, robot.nv))
    for j in range(robot.nv):
        e = np.zeros(robot.nq)
        e[j] = EPS
        J[:, j] = (
            _material_point(robot, tick.q + e, tick.table, i, k)
            - _material_point(robot, tick.q - e, tick.table, i, k)
        ) / (2 * EPS)
    return -tick.table.vector[i, k] @ J


def test_damper_and_separation_rows_by_finite_differences(robot, ticks):
    ctrl, recorded = ticks
    pieces = {p.name: p for p in ctrl.assembler.pieces}
    damper, separation = pieces[VelocityDamper.name], pieces[SeparationLimit.name]
    nv, n_parts = robot.nv, len(ctrl.human.parts)
    np.testing.assert_allclose(damper.d_stop[::n_parts], [0.0423, 0.05, 0.05], atol=1e-4)
    checked = {"damper": 0, "separation": 0}
    for tick in recorded:
        d = tick.table.distance
        for piece, active, bound in (
            (
                damper,
                d < damper.influence_m,
                damper.gain * (d.ravel() - damper.d_stop) / (damper.influence_m - damper.d_stop)
                - tick.human_approach.ravel(),
            ),
            (
                separation,
                tick.approach_limit < separation.inactive_above_mps,
                tick.approach_limit.ravel(),
            ),
        ):
            con = piece.compute_qp_inequalities(tick, 0.01)
            assert con.G.shape == (d.size, ctrl.variables.n)
            np.testing.assert_array_equal(con.G[:, nv:], 0.0)  # no slack in a hard row
            for r in range(d.size):
                i, k = divmod(r, n_parts)
                if not active[i, k]:
                    assert con.h[r] == np.inf and not con.G[r].any()
                    continue
                assert con.h[r] == pytest.approx(bound[r], abs=1e-12)
                np.testing.assert_allclose(
                    con.G[r, :nv], _approach_row(robot, tick, i, k), atol=1e-7
                )
                checked["damper" if piece is damper else "separation"] += 1
    assert checked["damper"] > 20 and checked["separation"] > 20, checked


def test_compiled_end_effector_cost_equals_numpy(ticks):
    ctrl, recorded = ticks
    n, nv = ctrl.variables.n, ctrl.variables.nv
    for tick in recorded[::3]:
        obj = ctrl.ee_task.compute_qp_objective(tick, 0.01)
        J, W2 = tick.kin.ee_jacobian, np.diag(ctrl.ee_task.w2)
        np.testing.assert_allclose(obj.H[:nv, :nv], 2 * J.T @ W2 @ J, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(
            obj.c[:nv], -2 * J.T @ W2 @ ctrl.ee_task.target(tick), rtol=1e-12, atol=1e-12
        )
        assert not obj.H[nv:].any() and not obj.H[:, nv:].any() and not obj.c[nv:].any()
        assert obj.H.shape == (n, n)


def test_in_place_assembly_equals_the_pieces_own_blocks(ticks):
    """What the loop solves (Assembler.fill, in place) is the sum, stack and intersection
    of each piece's compute_qp_* (allocated fresh), the rows of a piece that tightens
    another's merged into them (the same left side where both bound a pair: the smaller
    bound), and problem() outlives the next tick."""
    ctrl, recorded = ticks
    asm: Assembler = ctrl.assembler
    n, first = asm.n, ctrl.problem(recorded[0])
    kept = {k: getattr(first, k).copy() for k in ("H", "c", "G", "h", "lb", "ub")}
    merged = 0
    for tick in recorded:
        H, c = np.zeros((n, n)), np.zeros(n)
        G, h, own = [], [], {}
        lb, ub = np.full(n, -np.inf), np.full(n, np.inf)
        for p in asm.pieces:
            if (obj := p.compute_qp_objective(tick, 0.01)) is not None:
                H, c = H + obj.H, c + obj.c
            if p.rows:
                con = p.compute_qp_inequalities(tick, 0.01)
                if p.tightens is None:
                    G.append(con.G)
                    h.append(con.h)
                    own[p.name] = len(G) - 1
                else:  # into the rows it tightens
                    k = own[p.tightens]
                    both = np.isfinite(con.h) & np.isfinite(h[k])
                    np.testing.assert_allclose(con.G[both], G[k][both], rtol=0, atol=0)
                    merged += int(both.sum())
                    G[k] = np.where(np.isfinite(con.h)[:, None], con.G, G[k])
                    h[k] = np.minimum(h[k], con.h)
            if (b := p.compute_qp_bounds(tick, 0.01)) is not None:
                lb, ub = np.maximum(lb, b.lb), np.minimum(ub, b.ub)
        prob = asm.fill(tick, 0.01)
        for name, ref in zip(
            ("H", "c", "G", "h", "lb", "ub"), (H, c, np.vstack(G), np.concatenate(h), lb, ub)
        ):
            np.testing.assert_allclose(getattr(prob, name), ref, rtol=1e-13, atol=1e-13)
    for k, v in kept.items():  # the first problem() is untouched by every fill since
        np.testing.assert_array_equal(getattr(first, k), v)
    assert merged > 20  # pairs bounded by both the damper and speed and separation


def test_problem_defect_finds_every_nan_and_infinity():
    rng = np.random.default_rng(5)
    shapes = {"H": (4, 4), "c": (4,), "G": (3, 4), "h": (3,), "lb": (4,), "ub": (4,)}
    codes = {"H": 1, "c": 1, "G": 1, "h": 2, "lb": 3, "ub": 4}
    for _ in range(200):
        arrays = {k: rng.normal(size=s) for k, s in shapes.items()}
        arrays["h"][0], arrays["lb"][1], arrays["ub"][2] = np.inf, -np.inf, np.inf  # free
        assert problem_defect(*arrays.values()) == 0
        name = rng.choice(list(shapes))
        arrays[name].flat[rng.integers(arrays[name].size)] = (
            np.nan if name in ("h", "lb", "ub") else rng.choice([np.nan, np.inf, -np.inf])
        )
        assert problem_defect(*arrays.values()) == codes[name]


def test_hard_excess_is_numpys_max_and_nan_aware():
    rng = np.random.default_rng(6)
    nv, n, m = 3, 5, 6
    for _ in range(300):
        x, lb, ub = rng.normal(size=n), rng.normal(size=n) - 1, rng.normal(size=n) + 1
        G, h = rng.normal(size=(m, n)), rng.normal(size=m)
        start, stop = sorted(rng.integers(0, m + 1, size=2))
        ref = max(
            np.max(lb[:nv] - x[:nv]),
            np.max(x[:nv] - ub[:nv]),
            np.max(G[start:stop] @ x - h[start:stop], initial=-np.inf),
        )
        assert hard_excess(x, nv, lb, ub, G, h, start, stop) == pytest.approx(ref, abs=1e-12)
        x[rng.integers(n if stop > start else nv)] = np.nan  # a slack only counts via a row
        assert np.isnan(hard_excess(x, nv, lb, ub, G, h, start, stop))


def test_problem_never_touches_the_problem_being_solved(ticks):
    """``problem()`` (inspection, any thread) builds in arrays of its own: the arrays the
    loop's ``fill`` handed to the solver keep their tick's numbers."""
    ctrl, recorded = ticks
    filled = ctrl.assembler.fill(recorded[0], 0.01)
    before = {k: getattr(filled, k).copy() for k in ("H", "c", "G", "h", "lb", "ub")}
    other = ctrl.problem(recorded[-1])
    assert not np.array_equal(other.c, before["c"])  # a different tick indeed
    for k, v in before.items():
        np.testing.assert_array_equal(getattr(filled, k), v)


def test_rows_of_the_wrong_size_are_refused_not_written(ticks):
    """The compiled kernels write unchecked: a table or a problem of another size is a
    ValueError (as numpy's broadcasting gave), never a write past an array's end."""
    ctrl, recorded = ticks
    damper = next(p for p in ctrl.assembler.pieces if p.name == VelocityDamper.name)
    n = ctrl.variables.n
    with pytest.raises(ValueError, match="pairs"):
        damper.write_qp_inequalities(recorded[0], 0.01, np.zeros((3, n)), np.zeros(3))
    prob = ctrl.problem(recorded[0])
    small = QPProblem(prob.H, prob.c, prob.G[:5], prob.h[:5], prob.lb, prob.ub)
    with pytest.raises(ValueError, match="shapes"):
        ctrl.backend.solve(small)


def test_a_damper_that_would_divide_by_zero_is_refused(robot):
    with pytest.raises(InputError, match="damper_influence_m"):
        QPController(robot, qp=QPConfig(damper_influence_m=0.05))  # = L2's stop distance
    ctrl = QPController(robot, qp=QPConfig(damper_gain_mps=1, weight_position=2))  # ints
    damper = next(p for p in ctrl.assembler.pieces if p.name == VelocityDamper.name)
    assert isinstance(damper.gain, float) and ctrl.ee_task.w2.dtype == np.float64


def test_the_posture_cost_is_its_formula_and_lives_in_the_null_space(robot7):
    """PostureTask on the iiwa with A3 free, at random configurations: H = 2wN and
    c = −2wN q̇* with N the projector onto the end effector's null space (JN = 0, N² = N,
    rank 1, built here from numpy's SVD), and ½xᵀHx + cᵀx = w‖N(q̇ − q̇*)‖² − w‖Nq̇*‖²."""
    w, k = 0.3, 0.7
    ctrl = QPController(robot7, qp=replace(REDUNDANT, posture_weight=w, posture_gain_per_s=k))
    posture = next(p for p in ctrl.assembler.pieces if isinstance(p, PostureTask))
    assert posture.name in {p.name for p in ctrl.assembler.pieces}
    rng = np.random.default_rng(2)
    n, nv = ctrl.variables.n, robot7.nv
    for _ in range(10):
        q = random_q(rng, robot7)
        tick = ctrl.measure(q, Operator().rest(), None, 0.0)
        J = tick.kin.ee_jacobian
        v = np.linalg.svd(J)[2][-1]  # the right singular vector of the smallest: σ = 0
        N = np.outer(v, v)
        np.testing.assert_allclose(posture.projector(tick), N, atol=1e-12)
        assert np.abs(J @ N).max() < 1e-12
        target = k * (posture.rest - q)
        obj = posture.compute_qp_objective(tick, 0.01)
        np.testing.assert_allclose(obj.H[:nv, :nv], 2 * w * N, atol=1e-12)
        np.testing.assert_allclose(obj.c[:nv], -2 * w * N @ target, atol=1e-12)
        assert not obj.H[nv:].any() and not obj.H[:, nv:].any() and not obj.c[nv:].any()
        x = rng.normal(size=n)
        cost = 0.5 * x @ obj.H @ x + obj.c @ x
        by_hand = w * np.sum((N @ (x[:nv] - target)) ** 2) - w * np.sum((N @ target) ** 2)
        assert cost == pytest.approx(by_hand, rel=1e-12, abs=1e-12)


def test_the_posture_task_moves_only_the_null_space(robot7):
    """One tick, nobody near, 0.3 rad off the rest posture: with the posture task the QP's
    command moves the end effector as without it (within 1e-6 m/s, rad/s: the solver's
    tolerance), and its component along the null space is w/(w + ε) of the pull's (the QP's
    own command: one tick from rest, not yet bounded by the arm's acceleration)."""
    path = ArcPath()
    rest = inverse_kinematics(robot7, path.reference(0.0)[0])
    q = inverse_kinematics(robot7, path.reference(4.0)[0], q0=rest)
    v = np.linalg.svd(robot7.kinematics(q).ee_jacobian)[2][-1]
    q = inverse_kinematics(robot7, path.reference(4.0)[0], q0=q + 0.3 * v)
    cfg = ControllerConfig(distance="capsules", smooth=False)
    cmds = {}
    for w in (0.0, REDUNDANT.posture_weight):
        qp = replace(REDUNDANT, elbow_weight=0.0, posture_weight=w)
        ctrl = QPController(robot7, path=path, config=cfg, qp=qp, rest_posture=rest)
        cmd = ctrl.step(q, Operator().rest(), None, 4.0)
        assert not cmd.stopped
        cmds[w] = cmd.dq
    off, on = cmds.values()
    J = robot7.kinematics(q).ee_jacobian
    assert np.abs(J @ (on - off)).max() < 1e-6
    v = np.linalg.svd(J)[2][-1]
    w, eps = REDUNDANT.posture_weight, REDUNDANT.regularization
    pull = REDUNDANT.posture_gain_per_s * (rest - q)
    assert abs(v @ pull) > 0.1  # rad/s: a real pull
    assert v @ (on - off) == pytest.approx(w / (w + eps) * (v @ pull), rel=1e-4, abs=1e-6)


def test_a_piece_tightens_only_rows_before_it_of_its_own_size():
    """The separation's bounds tighten the dampers' rows: with the dampers first, the
    problem has the dampers' rows alone (both pieces' slices are theirs); without them, or
    with the separation first, or with another count of rows, the assembler refuses."""
    from qpavoid.control.qp.variables import Variables

    x = Variables(3)
    damper = VelocityDamper(x, np.zeros(2), 0.2, 0.5, 3)  # 2 sets × 3 parts
    separation = SeparationLimit(x, 6, 3.0)
    asm = Assembler(x.n, [damper, separation])
    assert asm.m == 6 and asm.rows[SeparationLimit.name] == asm.rows[VelocityDamper.name]
    for pieces in ([separation], [separation, damper], [damper, SeparationLimit(x, 4, 3.0)]):
        with pytest.raises(ValueError, match="tightens the rows of 'velocity_damper'"):
            Assembler(x.n, pieces)
