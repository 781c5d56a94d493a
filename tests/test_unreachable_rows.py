"""A row no joint velocity within the bounds can meet: the QP is infeasible, said before any
solver runs (:func:`~qpavoid.control.qp.solver_kernels.unreachable_row`), with the stop
the solver's infeasibility gave."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

from qpavoid.arm.model import load_robot
from qpavoid.control.qp import QPConfig, QPController
from qpavoid.control.qp import controller as qp_controller
from qpavoid.control.qp.solver_kernels import unreachable_row
from qpavoid.control.tick import ControllerConfig
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario

TOL = 1e-5


def test_a_row_is_unreachable_exactly_when_a_linear_program_finds_it_so():
    """Each row alone against the box, by scipy's linear programming: flagged iff its
    minimum over the bounds exceeds h by the tolerance; a slack's +inf bound frees it."""
    rng = np.random.default_rng(4)
    flagged = 0
    for _ in range(300):
        n = int(rng.integers(2, 9))
        lb, ub = -rng.uniform(0.1, 2.0, n), rng.uniform(0.1, 2.0, n)
        if rng.random() < 0.3:  # a slack: s ≥ 0, unbounded above, with −1 in the row
            lb[-1], ub[-1] = 0.0, np.inf
        G = rng.normal(size=(1, n)) * (rng.random(n) < 0.8)
        if ub[-1] == np.inf:
            G[0, -1] = -1.0
        lp = linprog(G[0], bounds=list(zip(lb, ub, strict=True)))
        assert lp.status in (0, 3)  # solved, or unbounded below (a slack)
        low = lp.fun if lp.status == 0 else -np.inf
        h = np.array([low + rng.choice([-0.1, -2 * TOL, 0.5 * TOL, 2 * TOL, 0.3])])
        if not np.isfinite(low):  # a slack: always reachable
            h = np.array([rng.normal()])
        want = 0 if np.isfinite(low) and low > h[0] + TOL else -1
        assert unreachable_row(G, h, lb, ub, TOL) == want
        flagged += want == 0
    assert flagged > 50


def test_inactive_rows_and_nan_flag_nothing_and_the_first_unreachable_row_is_named():
    G = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [-1.0, 0.0]])
    lb, ub = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    h = np.array([np.inf, 0.0, -2.5, -1.5])  # rows 2 and 3 beyond the box
    assert unreachable_row(G, h, lb, ub, TOL) == 2
    h[2] = np.nan
    assert unreachable_row(G, h, lb, ub, TOL) == 3
    G[3, 0] = np.nan
    assert unreachable_row(G, h, lb, ub, TOL) == -1


@pytest.mark.parametrize("backend", ["persistent", "daqp"])
def test_a_hold_said_before_the_solver_commands_what_the_solver_gave(backend):
    """Test 1 with speed and separation on the UR5 (half its ticks a hold: the person
    inside the protective distance): the same commands with the check as with the solver
    alone (daqp, cold: bit for bit; OSQP, warm started from other ticks: within its
    tolerance on this run, whose holds are far from their limits: other closed-loop runs
    can drift apart, docs/qp.md), and every stop said as speed and separation's hold."""
    pytest.importorskip("daqp") if backend == "daqp" else None
    robot = load_robot("ur5")
    cfg = ControllerConfig(control_period_s=0.01, safety="ssm")
    runs, original, found = {}, qp_controller.unreachable_row, []

    def counted(*args):
        row = original(*args)
        found.append(row)
        return row

    for check in (True, False):
        ctrl = QPController(robot, config=cfg, qp=QPConfig(backend=backend))
        qp_controller.unreachable_row = counted if check else (lambda *args: -1)
        try:
            runs[check] = simulate(
                ctrl, make_scenario("test1", robot), SimConfig(control_rate_hz=100, max_time_s=8)
            ).log
        finally:
            qp_controller.unreachable_row = original
    assert sum(row >= 0 for row in found) > 50  # the check said them
    with_check, solver_only = runs[True], runs[False]
    held = [r for r in with_check["stop_reason"] if r]
    assert len(held) > 50  # the holds happened
    assert all(r.startswith("speed and separation:") and r.endswith("holding") for r in held)
    tol = 0.0 if backend == "daqp" else 1e-6
    np.testing.assert_allclose(
        with_check["dq_command"], solver_only["dq_command"], atol=tol, rtol=0
    )
