"""Safety campaigns (`qpavoid sweep`): reproducible whatever runs them, summed up right."""

from __future__ import annotations

import importlib.util
import json
import shlex
from pathlib import Path

import numpy as np
import pytest
from conftest import PYTHON

from qpavoid.cli.commands import build_parser
from qpavoid.core.errors import InputError
from qpavoid.experiments.campaign import (
    CAMPAIGN_MAX_TIME_S,
    RayExecutor,
    campaign_spec,
    run_campaign,
    worst_runs,
    write_campaign,
)
from qpavoid.experiments.runs import RunSpec, simulate_one
from qpavoid.experiments.sweep_checks import StrikeCheck
from qpavoid.experiments.sweep_summary import summarize
from qpavoid.sensing.recording import load_recording


def check(seed, contact=0, clearance=0.1, goal=True, **kw) -> StrikeCheck:
    fields = dict(
        seed=seed,
        controller="qp",
        safety="ssm",
        target="L2",
        speed_mps=1.0,
        side="right",
        both_hands=False,
        fault="none",
        ticks_moving_in_true_contact=contact,
        min_true_clearance_moving_m=clearance,
        moving_s=1.0,
        stopped_s=2.0,
        max_stop_speed_mps=0.1,
        reached_goal=goal,
        duration_s=17.0,
    )
    fields.update(kw)
    return StrikeCheck(**fields)


def test_the_summary_counts_what_it_says():
    runs = [
        check(0, clearance=0.30),
        check(1, contact=3, clearance=-0.02, goal=False),
        check(2, clearance=float("inf"), ticks_moving_below_stop_distance=4),
        check(3, clearance=0.10, limit_violations=1),
    ]
    s = summarize(runs)
    assert s["runs"] == 4 and s["runs_moving_in_true_contact"] == 1
    assert s["runs_moving_below_stop_distance"] == 1 and s["runs_with_limit_violations"] == 1
    assert s["fraction_reaching_goal"] == 0.75
    clear = s["true_clearance_moving_mm"]  # over the runs that moved: -20, 100, 300 mm
    assert clear["min"] == -20.0 and clear["median"] == 100.0
    assert clear["p01"] == pytest.approx(np.percentile([-20.0, 100.0, 300.0], 1))
    assert [r.seed for r in worst_runs(runs, 2)] == [1, 3]


def strip(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k != "timing"}


def test_a_campaign_is_the_same_on_one_or_two_workers_and_its_worst_runs_replay(tmp_path):
    spec = campaign_spec("qp", "spheres", max_time_s=2.5)
    one = run_campaign(spec, 3, seed=11, workers=1)
    two = run_campaign(spec, 3, seed=11, workers=2)
    assert [r.seed for r in one] == [11, 12, 13]
    assert strip(summarize(one)) == strip(summarize(two))
    summary = write_campaign(tmp_path / "c", spec, 3, 11, one)
    assert summary["settings"] == {
        "n": 3,
        "robot": "iiwa14",
        "controller": "qp",
        "distance": "spheres",
        "safety": "ssm",
        "seed": 11,
        "max_speed_mps": 2.0,
        "rate_hz": 100.0,
        "camera": "kinect_v2",
        "latency_s": 0.06,
        "motion": "strikes",
        "payload_kg": 0.0,
    }
    on_disk = json.loads((tmp_path / "c" / "summary.json").read_text())
    assert strip(on_disk) == strip(json.loads(json.dumps(summary)))
    worst = sorted((tmp_path / "c" / "worst").glob("*.npz"))
    assert len(worst) == 3
    rec = load_recording(worst[0])
    assert rec.duration_s >= 2.0
    run = simulate_one(RunSpec(human_file=str(worst[0]), rate_hz=100.0, max_time_s=1.0))
    assert run.metrics["ticks_moving_in_true_contact"] == 0
    # each worst run says how to replay it, with the campaign's controller and rate
    case = json.loads(worst[0].with_suffix(".json").read_text())
    line = shlex.split(case["replay"])
    assert line[:2] == ["qpavoid", "run"]
    args = build_parser().parse_args(line[1:])
    assert (args.human, args.controller, args.distance, args.safety) == (
        [worst[0].name],
        "qp",
        "spheres",
        "ssm",
    )
    assert (args.rate, args.max_time, args.bench) == (100.0, CAMPAIGN_MAX_TIME_S, "real")


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason='needs "qpavoid[cluster]"')
def test_ray_gives_the_same_summary_as_local_processes():
    spec = campaign_spec("analytic", max_time_s=3.0)
    local = run_campaign(spec, 4, seed=3, workers=2)
    executor = RayExecutor(2)
    on_ray = run_campaign(spec, 4, seed=3, executor=executor)
    assert strip(summarize(local)) == strip(summarize(on_ray))
    executor.shutdown()  # the local Ray it started goes (a Ctrl-C left its agents running)
    assert not executor.ray.is_initialized()


@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason='needs "qpavoid[cluster]"')
@pytest.mark.parametrize(
    "address", ["not a host", "ray://", "127.0.0.1:1", ":6379", "localhost:1 ", "127.0.0.1:"]
)
def test_a_ray_that_cannot_be_reached_is_an_input_error(monkeypatch, address):
    """Ray's own errors (a ValueError) were reported as qpavoid's bugs, and Ray waited for
    minutes on an address where nothing listens."""
    monkeypatch.setenv("RAY_ADDRESS", address)
    with pytest.raises(InputError, match="cannot start or reach the Ray cluster") as caught:
        RayExecutor(2)
    assert (caught.value.name, caught.value.value) == ("RAY_ADDRESS", address)


@pytest.mark.slow  # the default suite's time; a CLI sweep runs there too (SIGTERM's test)
def test_qpavoid_sweep_from_the_command_line(tmp_path):
    import subprocess

    out = tmp_path / "c"
    cmd = [*PYTHON, "-m", "qpavoid", "sweep", "--n", "1", "--controller", "analytic"]
    r = subprocess.run([*cmd, "--seed", "4", "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["controller"] == "analytic" and summary["runs"] == 1
    assert summary["runs_moving_in_true_contact"] == 0
    assert (out / "worst" / "seed4.npz").is_file() and (out / "runs.json").is_file()
    assert r.stdout.strip().endswith(f"wrote summary.json, runs.json and worst/ to {out}/")


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason='needs "qpavoid[cluster]"')
@pytest.mark.parametrize(
    "when",
    [
        "starting",
        pytest.param(
            "running",
            marks=pytest.mark.xfail(
                reason="known, left open (issue 24's note): a SIGTERM that lands in ray.get "
                "runs Ray's own C++ failure handler too, which aborts (status -6) after "
                "ours has printed its line",
                strict=False,
            ),
        ),
    ],
)
def test_sigterm_during_a_ray_sweep_is_one_line_and_status_143(tmp_path, when):
    """ray.init sets its own SIGTERM handler (a silent exit 15), and Ray's ``get``
    handed ours on as a plain Ctrl-C. "running": once Ray's workers run the tasks (the
    fixed 5 s this test waited fell sometimes in ray.init, sometimes in ray.get, where it
    fails: found in this session's CI runs, 1 of 3)."""
    import subprocess
    import time

    def ray_workers(pid: int) -> bool:
        """True once a descendant of ``pid`` is a Ray worker running a task (``ray::``)."""
        parent, workers = {}, []
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit():
                try:
                    stat = (entry / "stat").read_text()
                    parent[int(entry.name)] = int(stat.rsplit(")", 1)[1].split()[1])
                    if (entry / "cmdline").read_bytes().startswith(b"ray::"):
                        workers.append(int(entry.name))
                except (OSError, ValueError, IndexError):
                    continue
        for p in workers:
            while p in parent and p not in (pid, 0, 1):
                p = parent[p]
            if p == pid:
                return True
        return False

    out = tmp_path / "c"
    cmd = [*PYTHON, "-m", "qpavoid", "sweep", "--n", "6", "--controller", "qp"]
    proc = subprocess.Popen(
        [*cmd, "--executor", "ray", "-q", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    if when == "starting":
        time.sleep(1.5)
    else:
        deadline = time.time() + 120.0
        while not ray_workers(proc.pid) and time.time() < deadline and proc.poll() is None:
            time.sleep(0.2)
        time.sleep(0.5)
    proc.terminate()
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert err.strip().splitlines()[-1] == "qpavoid: terminated; nothing written"
    assert not out.exists()
