"""`qpavoid bench`: the documented keys are there (the numbers themselves are timing)."""

from __future__ import annotations

import json
import subprocess

import pytest
from conftest import PYTHON


@pytest.mark.slow
def test_bench_writes_every_documented_key(tmp_path):
    out = tmp_path / "bench.json"
    r = subprocess.run(
        [*PYTHON, "-m", "qpavoid", "bench", "--quick", "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    data = json.loads(out.read_text())
    for key in (
        "kinematics",
        "human_geometry",
        "sphere_table",
        "capsule_table",
        "perception",
        "fusion",
        "prelude",
        "analytic_law",
        "qp_assembly",
        "qp_assembly/one_pass",
        "qp_solve/persistent_osqp",
        "qp_solve/daqp_direct",
    ):
        assert data["stages"][key]["median_us"] > 0, key
    assert len(data["ticks"]) == 18 and "qp/capsules/ssm" in data["ticks"]
    assert "qp/capsules/pfl" in data["ticks"]
    assert "qp_daqp/spheres/paper" in data["ticks"]
    for key in ("robot_points/9", "robot_points/1000", "people/1", "people/6"):
        assert data["scaling"][key]["p99_us"] >= data["scaling"][key]["median_us"] > 0
    assert data["paper_budget_us"]["distances"] == 9000
    assert "paper's budget" in r.stdout and f"wrote {out}" in r.stdout
