"""The command line and its files (metrics.json, log.npz, figures), recordings replayed."""

from __future__ import annotations

import json
import multiprocessing

import numpy as np
import pytest

import qpavoid
from qpavoid.cli.commands import main
from qpavoid.loop.camera import CameraConfig
from qpavoid.output import plots
from qpavoid.output.run_files import LOG_KEYS, load_log
from qpavoid.scenarios.generated import make_scenario
from qpavoid.sensing.recording import Recording, save_csv, save_npz

METRIC_KEYS = (
    "reached_goal",
    "final_position_error_m",
    "rms_path_error_m",
    "max_path_error_m",
    "duration_s",
    "stopped_s",
    "stop_events",
    "max_f",
    "min_distance_m",
    "joint_velocity_limit_violations",
    "joint_position_limit_violations",
    "tick_us",
)


def test_run_writes_metrics_log_and_figures(tmp_path, capsys):
    out = tmp_path / "run"
    assert (
        main(
            [
                "run",
                "test2",
                "--controller",
                "analytic",
                "--distance",
                "capsules",
                "--out",
                str(out),
                "--max-time",
                "5",
                "--rate",
                "100",
            ]
        )
        == 0
    )
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
    np.testing.assert_allclose(
        log["q"][1:], log["q"][:-1] + log["dq"][:-1] * np.diff(log["t"])[:, None], atol=1e-12
    )
    assert m["duration_s"] == pytest.approx(5.0)
    if plots.available():  # Test 2's figures: Figs. 6, 12 and 13
        figures = {"fig06_f_vs_distance.png", "fig13_f_and_L1.png", "fig12_snapshots.png"}
        assert {p.name for p in out.glob("*.png")} == figures
        assert set(m["plots"]) == figures
        for name in figures:
            assert (out / name).stat().st_size > 1000, name
    printed = capsys.readouterr().out
    assert "reached goal" in printed and f"to {out}/" in printed.splitlines()[-1]


def test_without_matplotlib_plots_are_skipped(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(plots, "available", lambda: False)
    out = tmp_path / "run"
    assert main(["run", "free", "--out", str(out), "--max-time", "1", "--rate", "100"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["plots"] == [] and "matplotlib" in m["plots_skipped"]
    assert not list(out.glob("*.png"))
    assert "figures skipped" in capsys.readouterr().out


# NPZ in the default suite; CSV (its files read back: tests/test_io.py) with the slow ones
@pytest.mark.parametrize("fmt", ["npz", pytest.param("csv", marks=pytest.mark.slow)])
def test_replay_a_recording(robot, tmp_path, fmt):
    motion = make_scenario("test1", robot)
    t = np.arange(0, 6, 1 / 30) + 100.0  # a recording need not start at 0
    frames = [motion.frame_at(x - 100.0) for x in t]
    rec = Recording(t, np.array([f[0] for f in frames]), np.array([f[1] for f in frames]))
    path = tmp_path / f"rec.{fmt}"
    (save_npz if fmt == "npz" else save_csv)(path, rec)
    out = tmp_path / "run"
    assert (
        main(
            [
                "run",
                "--human",
                str(path),
                "--out",
                str(out),
                "--max-time",
                "8",
                "--rate",
                "100",
                "--no-plots",
            ]
        )
        == 0
    )
    m = json.loads((out / "metrics.json").read_text())
    assert m["scenario"] == "rec"
    log = load_log(out)
    # The controller saw the recording's frames through a Kinect (one latency late, with
    # millimetres of noise), sample-and-hold from its first frame, the last held after it.
    k = np.searchsorted(log["t"], 2.0)
    camera = CameraConfig()
    seen = rec.frame_at(100.0 + 2.0 - camera.latency_s)[0]
    np.testing.assert_allclose(log["joints"][k], seen, atol=6 * camera.noise_m)
    np.testing.assert_allclose(log["joints"][-1], rec.joints[-1], atol=6 * camera.noise_m)
    assert m["safety"] == "paper" and m["bench"] == "real" and m["distance_method"] == "capsules"


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
    for name in (
        "load_robot",
        "KinectHuman",
        "sphere_distances",
        "capsule_distances",
        "DistanceTable",
        "AnalyticController",
        "QPController",
    ):
        assert hasattr(qpavoid, name), name


def run_main(*args: str) -> int:
    """``main(args)`` in this process; an argparse exit becomes its status."""
    try:
        return main(list(args))
    except SystemExit as exc:
        return int(exc.code or 0)


def test_version_and_help_show_defaults(tmp_path, capsys):
    assert run_main("run", "--help") == 0
    help_text = " ".join(capsys.readouterr().out.split())
    for option, default in (
        ("--controller", "analytic"),
        ("--distance", "capsules"),
        ("--safety", "paper"),
        ("--bench", "real"),
        ("--max-time", "40.0"),
        ("--rate", "500.0"),
        ("--out", "runs/NAME"),
    ):
        assert option in help_text and f"(default: {default})" in help_text, option
    assert run_main("--help") == 0
    assert "``" not in capsys.readouterr().out


def test_failure_during_a_run_leaves_no_folder(tmp_path, monkeypatch, capsys):
    """An error after the simulation started: one line, exit 2, no --out folder."""
    import qpavoid.experiments.runs

    def fail(*args, **kwargs):
        raise qpavoid.SolverError("the solver gave up")

    monkeypatch.setattr(qpavoid.experiments.runs, "simulate", fail)
    out = tmp_path / "new" / "run"
    assert main(["run", "free", "--out", str(out)]) == 2
    assert capsys.readouterr().err == "qpavoid: error: the solver gave up\n"
    assert not out.exists() and not (tmp_path / "new").exists()


def test_failure_while_writing_leaves_no_folder(tmp_path, monkeypatch, capsys):
    """An error after some files were written: they go too, nothing else is touched."""
    import qpavoid.experiments.runs

    def fail(*args, **kwargs):
        raise OSError(28, "No space left on device", "log.npz")

    monkeypatch.setattr(qpavoid.experiments.runs, "write_run", fail)
    out = tmp_path / "run"
    assert main(["run", "free", "--max-time", "0.5", "--rate", "100", "--out", str(out)]) == 2
    assert capsys.readouterr().err == "qpavoid: error: No space left on device: log.npz\n"
    assert list(tmp_path.iterdir()) == []  # figures were written, then removed


def test_a_bug_is_one_line_too(tmp_path, monkeypatch, capsys):
    import qpavoid.experiments.runs

    def bug(*args, **kwargs):
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(qpavoid.experiments.runs, "simulate", bug)
    assert main(["run", "free", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("qpavoid: error: internal error") and err.count("\n") == 1
    assert "ZeroDivisionError" in err and not (tmp_path / "x").exists()


@pytest.mark.skipif(
    multiprocessing.get_start_method() != "fork",
    reason="the failure is patched into forked workers",
)
def test_worker_errors_are_reported_in_one_line(tmp_path, monkeypatch, capsys):
    """A failure inside a worker process of `compare`: one line, exit 2, nothing written."""
    import qpavoid.experiments.runs

    def fail(*args, **kwargs):
        raise qpavoid.SolverError("the solver gave up in a worker")

    monkeypatch.setattr(qpavoid.experiments.runs, "simulate", fail)
    out = tmp_path / "c"
    assert (
        main(
            [
                "compare",
                "--scenarios",
                "free",
                "test1",
                "--workers",
                "2",
                "--out",
                str(out),
                "--max-time",
                "0.2",
                "--rate",
                "50",
            ]
        )
        == 2
    )
    assert capsys.readouterr().err == "qpavoid: error: the solver gave up in a worker\n"
    assert not out.exists()
