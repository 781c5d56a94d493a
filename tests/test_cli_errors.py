"""The command line as a user types it: every bad input a user tried (issue 7), --version,
the default output folder.

Each bad input must end with exit status 2 and one line ``qpavoid: error: ...`` naming the
problem, no traceback, and nothing written (no ``runs/`` folder, no ``--out`` folder). They
run in-process through :func:`qpavoid.cli.commands.main`, what the console script calls (a
subprocess each cost 0.8 s of start-up, 50 s of the suite); a sample of them and --version
go through the installed entry point in a subprocess.
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import qpsolvers
from conftest import PYTHON

from qpavoid.cli.commands import main
from qpavoid.human.posture import Operator
from qpavoid.sensing.arm_log import ArmLog, save_arm_log
from qpavoid.sensing.per_sensor import SensorRecording, save_sensor_npz
from qpavoid.sensing.recording import Recording, save_npz


def qpavoid_cli(*args: str, cwd) -> subprocess.CompletedProcess:
    """The installed command line in a subprocess (as a user types it)."""
    return subprocess.run(
        [*PYTHON, "-m", "qpavoid", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
    )


#: Bad inputs a user tried (issue 7), and a word the one-line error must contain.
BAD_INPUTS = [
    (["run", "test1", "--out", "afile"], "is a file"),
    (["run", "test1", "--camera", "kinect_v1"], "--camera"),
    (["compare", "--camera", "zed"], "--camera"),
    (["sweep", "--n", "1", "--controller", "qp", "--camera", "femto", "--out", "o"], "--camera"),
    (["run", "test1", "--camera", "k4abt", "--latency", "2"], "--latency"),
    (["sweep", "--n", "1", "--controller", "qp", "--latency", "-1", "--out", "o"], "--latency"),
    (["run", "test1", "--max-time", "-1"], "--max-time"),
    (["run", "test1", "--max-time", "nan"], "--max-time"),
    (["run", "test1", "--max-time", "0"], "--max-time"),
    (["run", "test1", "--max-time", "0.01"], "--max-time"),
    (["run", "test1", "--rate", "0"], "--rate"),
    (["run", "test1", "--rate", "-500"], "--rate"),
    (["run", "test1", "--rate", "inf"], "--rate"),
    (["run", "test1", "--rate", "5"], "--rate"),
    (["run", "test1", "--robot", "fr3", "--arm", "sim", "--rate", "2000"], "up to 1000 Hz"),
    (["compare", "--rate", "0"], "--rate"),
    (["compare", "--random", "-1"], "--random"),
    (["compare", "--scenarios"], "nothing to compare"),
    (["compare", "--seed", "-5"], "--seed"),
    (["compare", "--workers", "0"], "--workers"),
    (["compare", "--scenarios", "test1", "nosuch"], "unknown scenario 'nosuch'"),
    (["run", "--human", "text.npz"], "text.npz"),
    (["compare", "--scenarios", "--human", "text.npz"], "text.npz"),
    (["run", "--human", "missing.csv"], "missing.csv"),
    (["run", "test1", "--human", "text.npz"], "not both"),
    (["run"], "give a SCENARIO"),
    (["run", "nosuch"], "unknown scenario 'nosuch'"),
    (["run", "random:-5"], "random:SEED"),
    (["run", "test1", "--controller", "qp", "--limit-mode", "clip"], "--limit-mode"),
    (["run", "test1", "--limit-mode", "clip", "--solver", "daqp"], "--solver"),
    (["run", "test1", "--redundant"], "--redundant"),
    (["run", "test1", "--controller", "qp", "--solver", "nosuch"], "'nosuch' is not installed"),
    (["run", "test1", "--controller", "nosuch"], "--controller"),
    (["run", "test1", "--robot", "nosuch"], "unknown robot 'nosuch'"),
    (["nosuch"], "invalid choice"),
    # sensors, fusion and live input (issue 10)
    (["fuse", "a.npz"], "--sensors"),
    (["fuse", "a.npz", "--sensors", "bad.toml"], "not rigid"),
    (["fuse", "a.npz", "--sensors", "nosuch.toml"], "nosuch.toml"),
    (["fuse", "zz.npz", "--sensors", "calib.toml"], "no sensor 'zz'"),
    (["fuse", "a.npz", "--sensors", "calib.toml", "--out", "x.csv"], ".npz"),
    (["fuse", "text.npz", "--sensors", "calib.toml"], "text.npz"),
    (["fuse", "a.npz", "--sensors", "calib.toml", "--out", "a.npz"], "recordings read"),
    (["fuse", "a.npz", "./a.npz", "--sensors", "calib.toml"], "given twice"),
    (["run", "--human", "a.npz"], "--sensors"),
    (["run", "--human", "a.npz", "zz.npz"], "--sensors"),
    (["run", "--human", "a.npz", "zz.npz", "--sensors", "calib.toml"], "no sensor 'zz'"),
    (["run", "test1", "--sensors", "calib.toml"], "--sensors"),
    (["run", "--listen", "127.0.0.1:9"], "--listen"),
    (["run", "--listen", "nohost"], "HOST:PORT"),
    (["run", "test1", "--listen", "127.0.0.1:9", "--sensors", "calib.toml"], "--listen"),
    (["replay", "a.npz", "--to", "x"], "HOST:PORT"),
    (["replay", "a.npz", "--to", "127.0.0.1:9", "--rate", "0"], "--rate"),
    (["replay", "text.npz", "--to", "127.0.0.1:9"], "text.npz"),
    # safety campaigns (issue 11)
    (["sweep", "--n", "3", "--out", "c"], "--controller"),
    (["sweep", "--n", "0", "--controller", "qp", "--out", "c"], "--n"),
    (["sweep", "--n", "x", "--controller", "qp", "--out", "c"], "--n"),
    (["sweep", "--n", "3", "--controller", "qp", "--out", "afile"], "is a file"),
    (["sweep", "--n", "3", "--controller", "qp", "--out", "c", "--executor", "dask"], "--executor"),
    (["sweep", "--n", "3", "--controller", "qp", "--out", "c", "--workers", "0"], "--workers"),
    # what an adversarial tester found after the work, or never (issue 11)
    (["sweep", "--n", "1000001", "--controller", "qp", "--out", "c"], "--n"),
    (["sweep", "--n", "3", "--controller", "qp", "--out", ""], "empty path"),
    (["sweep", "--n", "3", "--controller", "qp", "--out", "dangling"], "symbolic link"),
    (["sweep", "--n", "3", "--controller", "qp", "--out", "dangling/c"], "symbolic link"),
    (["sweep", "--n", "3", "--controller", "qp", "--out", "c/" + "x" * 300], "longer than"),
    (["bench", "--json", ""], "--json"),
    (["bench", "--json", "."], "--json"),
    (["bench", "--json", "afile/x.json"], "--json"),
    (["bench", "--json", "missing/x.json"], "--json"),
    # a camera's latency measured (issue 41)
    (["latency", "--arm-log", "arm.npz"], "--camera-recording"),
    (["latency", "--camera-recording", "rest.npz"], "--arm-log"),
    (["latency", "--camera-recording", "rest.npz", "--arm-log", "text.npz"], "text.npz"),
    (["latency", "--camera-recording", "rest.npz", "--arm-log", "missing.csv"], "missing.csv"),
    (["latency", "--camera-recording", "text.npz", "--arm-log", "arm.npz"], "text.npz"),
    (["latency", "--camera-recording", "a.npz", "--arm-log", "arm.npz"], "--sensors"),
    (["latency", "--camera-recording", "rest.npz", "--arm-log", "arm.npz"], "only 0 frames"),
    (["latency", "--camera-recording", "rest.npz", "--arm-log", "a.npz"], "no array 'q'"),
    (
        ["latency", "--camera-recording", "rest.npz", "--arm-log", "arm.npz", "--robot", "ur5"],
        "another arm",
    ),
    (
        ["latency", "--camera-recording", "rest.npz", "--arm-log", "arm.npz", "--robot", "nosuch"],
        "unknown robot 'nosuch'",
    ),
    (
        ["latency", "--camera-recording", "rest.npz", "--arm-log", "arm.npz", "--landmark", "nose"],
        "--landmark",
    ),
    (
        ["latency", "--camera-recording", "rest.npz", "--arm-log", "arm.npz", "--max-lag", "5"],
        "max_lag_s",
    ),
    (
        ["latency", "--camera-recording", "rest.npz", "--arm-log", "arm.npz", "--max-lag", "x"],
        "--max-lag",
    ),
    (
        [
            "latency",
            "--camera-recording",
            "rest.npz",
            "--arm-log",
            "arm.npz",
            "--sensors",
            "calib.toml",
        ],
        "base-frame recording",
    ),
    (
        ["latency", "--camera-recording", "a.npz", "--arm-log", "arm.npz", "--sensors", "bad.toml"],
        "not rigid",
    ),
    (
        [
            "latency",
            "--camera-recording",
            "a.npz",
            "--arm-log",
            "arm.npz",
            "--sensors",
            "calib.toml",
            "--sensor",
            "zz",
        ],
        "no frame of sensor 'zz'",
    ),
]


@pytest.fixture(scope="module")
def workdir(tmp_path_factory, robot):
    d = tmp_path_factory.mktemp("cli")
    (d / "afile").write_text("")
    (d / "dangling").symlink_to(d / "nowhere")
    (d / "text.npz").write_text("hello, not an archive\n")
    (d / "calib.toml").write_text(
        "[sensors.a]\nbase_from_camera = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n"
    )
    (d / "bad.toml").write_text(
        "[sensors.a]\nbase_from_camera = [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n"
    )
    rest = Operator().rest()
    for name in ("a", "zz"):
        rec = SensorRecording([name], [0.0], [0], rest[None], np.full((1, 25), 2))
        save_sensor_npz(d / f"{name}.npz", rec)
    save_npz(d / "rest.npz", Recording([0.0], rest[None], np.full((1, 25), 2)))  # base frame
    t = np.arange(0.0, 2.0, 0.002)  # an arm log of the iiwa (at rest, 2 s later)
    save_arm_log(d / "arm.npz", ArmLog(t + 2.0, np.zeros((t.size, robot.nq))), robot)
    return d


@pytest.mark.parametrize("args, word", BAD_INPUTS, ids=[" ".join(a) for a, _ in BAD_INPUTS])
def test_bad_input_is_one_line_and_exit_2(workdir, args, word, monkeypatch, capsys):
    before = sorted(p.name for p in workdir.iterdir())
    monkeypatch.chdir(workdir)
    try:
        status = main(list(args))
    except SystemExit as exc:  # argparse's own refusals
        status = exc.code
    out = capsys.readouterr()
    assert_refused(status, out.out, out.err, word)
    assert sorted(p.name for p in workdir.iterdir()) == before  # no runs/, no --out


def assert_refused(status: object, stdout: str, stderr: str, word: str) -> None:
    """Exit status 2, one line ``qpavoid: error: ...`` with ``word``, nothing else."""
    assert status == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("qpavoid: error: "), stderr
    assert word in lines[0]
    assert "Traceback" not in stderr + stdout and stdout == ""


#: Two of them as a user types them: each subprocess costs a second of the suite, and every
#: one is refused in-process above.
THROUGH_THE_ENTRY_POINT = [
    bad if bad[0][0] == "run" else pytest.param(*bad, marks=pytest.mark.slow)
    for bad in BAD_INPUTS
    if bad[0]
    in (
        ["run", "test1", "--out", "afile"],
        ["sweep", "--n", "x", "--controller", "qp", "--out", "c"],
    )
]


@pytest.mark.parametrize("args, word", THROUGH_THE_ENTRY_POINT, ids=lambda a: " ".join(a))
def test_bad_input_through_the_installed_entry_point(workdir, args, word):
    """One refused by the library's checks (a file where the run's folder goes), one by
    argparse (``--n x``)."""
    before = sorted(p.name for p in workdir.iterdir())
    r = qpavoid_cli(*args, cwd=workdir)
    assert_refused(r.returncode, r.stdout, r.stderr, word)
    assert sorted(p.name for p in workdir.iterdir()) == before


def test_a_missing_solver_names_the_extra(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(qpsolvers, "available_solvers", ["osqp"])
    out = tmp_path / "x"
    assert main(["run", "test1", "--controller", "qp", "--solver", "daqp", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert 'pip install "qpavoid[solvers]"' in err and err.count("\n") == 1
    assert not out.exists()


def test_version(tmp_path):
    r = qpavoid_cli("--version", cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.startswith("qpavoid ")


def test_default_out_and_last_line(workdir, monkeypatch, capsys):
    """`qpavoid run free` works as typed: it writes runs/free and says so (through the
    command line's main in this process, standard error not a terminal, as a pipe's)."""
    monkeypatch.chdir(workdir)
    status = main(["run", "free", "--max-time", "0.5", "--rate", "100", "--no-plots"])
    out, err = capsys.readouterr()
    assert status == 0, err
    assert (workdir / "runs" / "free" / "metrics.json").is_file()
    last = "wrote metrics.json, log.npz and replay.html (open it in a browser) to runs/free/"
    assert out.strip().splitlines()[-1] == last
    assert err == ""  # no progress bar when not on a terminal
    shutil.rmtree(workdir / "runs")


def test_ctrl_c_while_the_library_loads_is_one_line(tmp_path):
    """An adversarial tester pressed Ctrl-C in the first second: Python's traceback."""
    import signal
    import time

    proc = subprocess.Popen(
        [*PYTHON, "-m", "qpavoid", "run", "free", "--out", str(tmp_path / "x")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(0.4)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip() == "qpavoid: interrupted; nothing written" and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def _processes_with(marker: str) -> list[int]:
    """The processes whose command line holds ``marker`` (forked workers share their
    parent's)."""
    found = []
    for d in Path("/proc").iterdir():
        try:
            if d.name.isdigit() and marker.encode() in (d / "cmdline").read_bytes():
                found.append(int(d.name))
        except OSError:  # ended meanwhile
            continue
    return found


@pytest.mark.parametrize(
    "signals, status, line",
    [
        pytest.param(["INT"], 130, "interrupted", marks=pytest.mark.slow),  # as twice's first
        pytest.param(  # hung forever in the adversary's hands (slow: the default suite's time)
            ["INT", "INT"], 130, "interrupted", marks=pytest.mark.slow
        ),
        (["TERM"], 143, "terminated"),  # left both workers running, orphaned
    ],
    ids=["ctrl-c", "ctrl-c twice", "sigterm"],
)
def test_a_sweep_stopped_by_a_signal_ends_at_once_and_leaves_nothing(
    tmp_path, signals, status, line
):
    """Ctrl-C goes to the terminal's whole process group (the workers too), ``kill`` to
    the main process alone: either way the command ends with its one line, its workers
    with it, and no folder, staging or final."""
    import signal
    import time

    out = tmp_path / "campaign"
    command = ["sweep", "--n", "6", "--controller", "qp", "--workers", "2", "--out", str(out)]
    proc = subprocess.Popen(
        [*PYTHON, "-m", "qpavoid", *command],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    deadline = time.monotonic() + 60
    while len(_processes_with(str(out))) < 3 and time.monotonic() < deadline:
        time.sleep(0.05)  # until both workers run
    assert len(_processes_with(str(out))) == 3, "the pool never started"
    time.sleep(0.5)
    for name in signals:
        if name == "INT":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.SIGTERM)
        time.sleep(0.3)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == status, err
    assert err.strip() == f"qpavoid: {line}; nothing written", err
    assert list(tmp_path.iterdir()) == []
    deadline = time.monotonic() + 5
    while _processes_with(str(out)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _processes_with(str(out)) == [], "workers left running"


def test_output_to_a_closed_pipe_or_a_narrow_terminal_is_no_traceback(tmp_path):
    """``qpavoid ... | head`` and a terminal without µs ended in tracebacks at the final
    print."""
    code = "import sys; from qpavoid.cli.args import run_command; "
    piped = subprocess.run(
        f"{shlex.join(PYTHON)} -c \"{code}sys.exit(run_command(lambda: 'x' * 1000000))\" | true",
        shell=True,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert piped.stderr == ""
    ascii_only = subprocess.run(
        [*PYTHON, "-c", f"{code}sys.exit(run_command(lambda: '291 µs'))"],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PYTHONIOENCODING": "ascii"},
    )
    assert ascii_only.returncode == 0 and ascii_only.stderr == ""
    assert ascii_only.stdout == "291 \\xb5s\n"
