"""The QP controller's commands, tick by tick, equal those recorded before the restructure.

``tests/data/qp_commands_{100,500}hz.npz`` hold the commanded joint velocities (key
``SCENARIO/METHOD/dq``, (T, 6) rad/s) of the QP controller in closed loop on ``free``,
``test1`` and ``test2``, recorded with the code of commit 41fe3c2 (before issue 8's
restructure), on the paper's bench (``bench="ideal"``: perfect sensor, exact arm) with the
paper's rules. Refactoring and speed work must keep every tick within 1e-7 rad/s.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from qpavoid.experiments.runs import RunSpec, simulate_one

DATA = Path(__file__).parent / "data"
#: Allowed difference from the recorded commands, rad/s.
TOL = 1e-7


def assert_same_commands(scenario: str, distance: str, rate_hz: float) -> None:
    recorded = np.load(DATA / f"qp_commands_{rate_hz:.0f}hz.npz")[f"{scenario}/{distance}/dq"]
    run = simulate_one(
        RunSpec(
            scenario=scenario,
            controller="qp",
            distance=distance,
            rate_hz=rate_hz,
            max_time_s=40.0,
            bench="ideal",  # the bench the fixtures were recorded on
            measure_truth=False,
        )
    )
    dq = run.sim.log["dq"]
    assert dq.shape == recorded.shape
    worst = float(np.abs(dq - recorded).max())
    assert worst <= TOL, f"{scenario}/{distance}: {worst:.3e} rad/s"


@pytest.mark.parametrize("scenario", ["free", "test1", "test2"])
def test_qp_commands_unchanged_100hz_spheres(scenario):
    assert_same_commands(scenario, "spheres", 100.0)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["free", "test1", "test2"])
def test_qp_commands_unchanged_100hz_capsules(scenario):
    assert_same_commands(scenario, "capsules", 100.0)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["free", "test1", "test2"])
def test_qp_commands_unchanged_500hz_spheres(scenario):
    assert_same_commands(scenario, "spheres", 500.0)
