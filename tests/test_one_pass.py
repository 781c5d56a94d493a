"""The standard pieces' QP in one compiled call (:mod:`qpavoid.control.qp.one_pass`)
against the assembler visiting each piece, bit for bit, on the ticks of real runs; the
kernels the pieces now call against the numpy they replaced."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from qpavoid.arm.model import load_robot
from qpavoid.control.qp import QPConfig, QPController
from qpavoid.control.qp.config import REDUNDANT
from qpavoid.control.qp.kernels import (
    MIN_SPEED_MPS,
    box_bounds,
    position_bounds,
    raise_rows,
    repulsion_row,
    velocity_bounds,
)
from qpavoid.control.qp.one_pass import OnePass
from qpavoid.control.tick import ControllerConfig
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario

ARRAYS = ("H", "c", "G", "h", "lb", "ub")


def _ticks(arm: str, safety: str, distance: str, every: int = 3):
    """A probe controller with ``safety`` and the ticks it measures on the states of a
    test1 run under the paper's rules (close approaches: the dampers' and the
    repulsions' rows active), its first 11 s at 100 Hz (the iiwa's repulsions act from
    8 s on), measured from 3 s."""
    robot = load_robot(arm)
    cfg = ControllerConfig(control_period_s=0.01, distance=distance)
    log = simulate(
        QPController(robot, config=cfg),
        make_scenario("test1", robot),
        SimConfig(control_rate_hz=100, max_time_s=11.0),
    ).log
    probe = QPController(robot, config=replace(cfg, safety=safety))
    ticks = []
    for k in range(300, len(log["t"]), every):
        tick = probe.measure(log["q"][k], log["joints"][k], log["state"][k], log["tau"][k])
        probe.act(tick)  # the ramp moves on (its box: the reach of each next command)
        ticks.append(tick)
    return probe, ticks


@pytest.mark.parametrize(
    "arm, safety, distance",
    [
        ("iiwa14", "paper", "spheres"),
        ("fr3", "ssm", "capsules"),
        ("ur5", "pfl", "capsules"),
        pytest.param("panda", "ssm", "spheres", marks=pytest.mark.slow),
        pytest.param("iiwa14", "pfl", "spheres", marks=pytest.mark.slow),
        pytest.param("ur5", "paper", "capsules", marks=pytest.mark.slow),
        pytest.param("fr3", "pfl", "spheres", marks=pytest.mark.slow),
    ],
)
def test_the_pass_writes_the_assemblers_problem_bit_for_bit(arm, safety, distance):
    probe, ticks = _ticks(arm, safety, distance)
    assert probe.one_pass is not None  # the standard pieces
    rows = probe.assembler.rows
    active = {"repulsion": 0, "damper": 0, "separation or contact": 0}
    for tick in ticks:
        reference = probe.assembler(tick, 0.01)  # piece by piece, arrays of its own
        filled = probe.one_pass.fill(tick, 0.01)
        for name in ARRAYS:
            np.testing.assert_array_equal(getattr(filled, name), getattr(reference, name))
        h = reference.h
        repulsions = [rows[n].start for n in ("repulsion_repelled", "repulsion_end_effector")]
        active["repulsion"] += int(np.isfinite(h[repulsions]).sum())
        active["damper"] += int(np.isfinite(h[rows["velocity_damper"]]).sum())
        if safety == "ssm":
            active["separation or contact"] += int((tick.approach_limit < 10.0).sum())
        if safety == "pfl":
            active["separation or contact"] += int(np.isfinite(tick.contact_limit).sum())
        assert tick.command_box is not None  # the box's projection too
    assert active["repulsion"] > 5 and active["damper"] > 20, active
    if safety != "paper":
        assert active["separation or contact"] > 20, active


def test_any_other_set_of_pieces_is_written_by_the_assembler(robot):
    """The elbow's and the posture's tasks (the redundancy mode) are not in the pass: the
    controller keeps the assembler's path."""
    assert QPController(robot).one_pass is not None
    redundant = QPController(load_robot("iiwa14", locked=()), qp=REDUNDANT)
    assert redundant.one_pass is None
    assert OnePass.of(redundant.assembler) is None


def test_a_table_of_another_size_is_refused_not_written():
    probe, ticks = _ticks("iiwa14", "ssm", "capsules", every=50)
    tick = ticks[-1]
    before = {n: getattr(probe.assembler._filled, n).copy() for n in ARRAYS}
    bad = replace(tick, human_approach=np.zeros(tick.human_approach.size + 1))
    with pytest.raises(ValueError, match="set × part pairs"):
        probe.one_pass.fill(bad, 0.01)
    for wrong in (  # a joint too many anywhere: refused before any write
        replace(tick, limits=np.ones(tick.q.size + 1)),
        replace(tick, q=np.zeros(tick.q.size + 1)),
        replace(tick, command_box=(np.zeros(tick.q.size + 1), np.ones(tick.q.size + 1))),
    ):
        with pytest.raises(ValueError, match="joints for a problem of"):
            probe.one_pass.fill(wrong, 0.01)
    for n in ARRAYS:
        np.testing.assert_array_equal(getattr(probe.assembler._filled, n), before[n])


def test_the_repulsion_row_is_the_numpy_formula():
    """``−uᵀ J_p q̇ − s ≤ −(uᵀ ṗ + |v|)``, u = v/|v|, as the piece wrote it in numpy; no
    bound below :data:`MIN_SPEED_MPS`."""
    rng = np.random.default_rng(8)
    nv, n = 7, 9
    for trial in range(300):
        v = rng.normal(size=3) * (1e-5 if trial % 10 == 0 else rng.uniform(0.01, 2.0))
        Jp, nominal = rng.normal(size=(3, nv)), rng.normal(size=3)
        G, h = np.full((2, n), 7.0), np.zeros(2)
        repulsion_row(v, Jp, nominal, 8, G, h, 1)
        speed = np.linalg.norm(v)
        assert G[1, 8] == -1.0 and not G[1, nv:8].any() and (G[0] == 7.0).all()
        if speed < MIN_SPEED_MPS:
            assert h[1] == np.inf and not G[1, :nv].any()
            continue
        u = v / speed
        np.testing.assert_allclose(G[1, :nv], -(u @ Jp), rtol=1e-14, atol=1e-15)
        assert h[1] == pytest.approx(-(u @ nominal + speed), rel=1e-14, abs=1e-15)


def test_the_bound_kernels_are_numpys_and_keep_a_nan():
    """The velocity, position and box bounds and the contact floor as numpy's maximum,
    minimum and clip gave them, a NaN anywhere kept (the solver's checks refuse it)."""
    rng = np.random.default_rng(9)
    nv = 6
    for trial in range(300):
        lb, ub = rng.normal(size=nv) - 1.0, rng.normal(size=nv) + 1.0
        limits, q = rng.uniform(0.1, 2.0, nv), rng.normal(size=nv)
        q_min, q_max = q - rng.uniform(0, 1, nv), q + rng.uniform(0, 1, nv)
        lo, hi = rng.normal(size=nv) - 0.5, rng.normal(size=nv) + 0.5
        lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
        floor, rows = rng.normal(size=nv), rng.normal(size=nv)
        if trial % 3 == 0:  # a NaN in one input
            [limits, q, lo, floor, lb][trial % 5][rng.integers(nv)] = np.nan
        want_lb = np.clip(np.maximum(np.maximum(lb, -limits), 5.0 * (q_min - q)), lo, hi)
        want_ub = np.clip(np.minimum(np.minimum(ub, limits), 5.0 * (q_max - q)), lo, hi)
        want_rows = np.maximum(rows, floor)
        velocity_bounds(limits, lb, ub)
        position_bounds(q, q_min, q_max, 5.0, lb, ub)
        box_bounds(lo, hi, lb, ub)
        raise_rows(rows, floor)
        np.testing.assert_array_equal(lb, want_lb)
        np.testing.assert_array_equal(ub, want_ub)
        np.testing.assert_array_equal(rows, want_rows)


def test_a_daqp_controller_takes_the_pass_too(robot):
    """The pass feeds every backend: the same commands through the assembler's path."""
    pytest.importorskip("daqp")
    probe, ticks = _ticks("iiwa14", "ssm", "capsules", every=25)
    fast = QPController(robot, config=probe.config, qp=QPConfig(backend="daqp"))
    slow = QPController(robot, config=probe.config, qp=QPConfig(backend="daqp"))
    slow.one_pass = None
    for tick in ticks:
        a, b = fast.act(tick), slow.act(tick)
        np.testing.assert_array_equal(a.dq, b.dq)
