"""The command line and its files (metrics.json, log.npz, figures), recordings replayed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from qpavoid import plots
from qpavoid.cli import main
from qpavoid.io import LOG_KEYS, load_log
from qpavoid.recording import Recording, save_csv, save_npz
from qpavoid.scenarios import make_scenario

METRIC_KEYS = ("reached_goal", "final_position_error_m", "rms_path_error_m", "max_path_error_m",
               "duration_s", "stopped_s", "stop_events", "max_f", "min_distance_m",
               "joint_velocity_limit_violations", "joint_position_limit_violations", "tick_us")


def test_run_writes_metrics_log_and_figures(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "test2", "--controller", "analytic", "--distance", "capsules",
                 "--out", str(out), "--max-time", "5", "--rate", "100"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    for key in METRIC_KEYS:
        assert key in m, key
    assert set(m["min_distance_m"]) == {"spheres", "capsules"}
    assert set(m["tick_us"]) >= {"median", "p99"}
    assert m["distance_method"] == "capsules" and m["scenario"] == "test2"
    assert m["stop_events"] and {"t", "reason"} <= set(m["stop_events"][0])
    log = load_log(out)
    for key in LOG_KEYS:
        assert key in log, key
    T = len(log["t"])
    assert log["q"].shape == (T, 6) and log["dq"].shape == (T, 6)
    assert log["joints"].shape == (T, 25, 3) and log["state"].shape == (T, 25)
    assert log["distance"].shape == (T, 3) and log["f"].shape == (T,)
    # Row k is the state at t[k] and the command computed from it.
    np.testing.assert_allclose(log["q"][1:], log["q"][:-1] + log["dq"][:-1] * np.diff(log["t"])[:, None],
                               atol=1e-12)
    assert m["duration_s"] == pytest.approx(5.0)
    if plots.available():
        for name in ("fig06_f_vs_distance.png", "fig08_distance_L2.png", "fig09_vrep_L2.png",
                     "fig10_distance_EE.png", "fig11_vrep_EE.png", "fig13_f_and_L1.png",
                     "fig07_12_snapshots.png"):
            assert (out / name).stat().st_size > 1000, name
    assert "reached goal" in capsys.readouterr().out


def test_without_matplotlib_plots_are_skipped(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(plots, "available", lambda: False)
    out = tmp_path / "run"
    assert main(["run", "free", "--out", str(out), "--max-time", "1", "--rate", "100"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["plots"] == [] and "matplotlib" in m["plots_skipped"]
    assert not list(out.glob("*.png"))
    assert "plots skipped" in capsys.readouterr().out


@pytest.mark.parametrize("fmt", ["npz", "csv"])
def test_replay_a_recording(robot, tmp_path, fmt):
    motion = make_scenario("test1", robot)
    t = np.arange(0, 6, 1 / 30) + 100.0                      # a recording need not start at 0
    frames = [motion.frame_at(x - 100.0) for x in t]
    rec = Recording(t, np.array([f[0] for f in frames]), np.array([f[1] for f in frames]))
    path = tmp_path / f"rec.{fmt}"
    (save_npz if fmt == "npz" else save_csv)(path, rec)
    out = tmp_path / "run"
    assert main(["run", "--human", str(path), "--out", str(out), "--max-time", "8", "--rate", "100",
                 "--no-plots"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["scenario"] == "rec"
    log = load_log(out)
    # The controller saw the recording's frames, sample-and-hold from its first frame, and
    # the last frame held after it ended.
    k = np.searchsorted(log["t"], 2.0)
    np.testing.assert_allclose(log["joints"][k], rec.frame_at(100.0 + 2.0)[0])
    np.testing.assert_allclose(log["joints"][-1], rec.joints[-1])


def test_errors_are_reported(tmp_path, capsys):
    assert main(["run", "nosuch", "--out", str(tmp_path / "x")]) == 2
    assert "unknown scenario 'nosuch'" in capsys.readouterr().err
    bad = tmp_path / "bad.npz"
    np.savez(bad, t=np.array([0.0, 0.0]), joints=np.zeros((2, 25, 3)), state=np.full((2, 25), 2))
    assert main(["run", "--human", str(bad), "--out", str(tmp_path / "y")]) == 2
    assert "duplicate" in capsys.readouterr().err
    assert main(["run", "--out", str(tmp_path / "z")]) == 2
    with pytest.raises(SystemExit):
        main(["run", "free", "--human", str(bad), "--out", str(tmp_path / "w")])


def test_public_names():
    """The names the issues fix are importable from the package."""
    import qpavoid
    for name in ("load_robot", "KinectHuman", "sphere_distances", "capsule_distances",
                 "DistanceTable", "AnalyticController", "QPController"):
        assert hasattr(qpavoid, name), name
