"""Errors a program can act on: types, attributes, one-line messages, pickling.

No ``numpy.linalg.LinAlgError`` (nor any non-qpavoid error) leaves the public API on bad
input; inside a controller tick a numerical failure is a stop with a reason.
"""

from __future__ import annotations

import dataclasses
import pickle
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

import qpavoid
from qpavoid.arm.ik import IKConfig, inverse_kinematics
from qpavoid.control.path import A_IN, ArcPath
from qpavoid.control.qp.backends import make_backend
from qpavoid.control.qp.config import QPConfig
from qpavoid.core.errors import (
    IKNotConvergedError,
    InputError,
    QpavoidError,
    RecordingError,
    RobotDescriptionError,
    SolverError,
)
from qpavoid.core.geometry import orthonormalize
from qpavoid.human.posture import Operator
from qpavoid.laws import avoidance as laws
from qpavoid.output.run_files import load_log
from qpavoid.scenarios.generated import make_scenario
from qpavoid.sensing.recording import Recording, csv_header, load_recording, save_csv


def one_line(exc: BaseException) -> str:
    """The message, checked to be a single non-empty line."""
    text = str(exc)
    assert text and "\n" not in text, repr(text)
    return text


@pytest.fixture(scope="module")
def q_start(robot):
    return inverse_kinematics(robot, ArcPath().reference(0.0)[0])


# --------------------------------------------------------------------------- hierarchy


def test_hierarchy():
    assert issubclass(InputError, QpavoidError) and issubclass(InputError, ValueError)
    assert issubclass(RecordingError, InputError)
    assert issubclass(IKNotConvergedError, InputError)  # old `except InputError` works
    for cls in (RobotDescriptionError, SolverError):
        assert issubclass(cls, QpavoidError) and not issubclass(cls, InputError)
    for name in ("IKNotConvergedError", "RecordingError"):
        assert getattr(qpavoid, name) is globals()[name] and name in qpavoid.__all__


def test_message_only_construction_keeps_working():
    for cls in (
        QpavoidError,
        InputError,
        RecordingError,
        IKNotConvergedError,
        RobotDescriptionError,
        SolverError,
    ):
        err = cls("plain message")
        assert str(err) == "plain message"
    err = InputError("rate must be positive", name="--rate", value=0.0)
    assert (err.name, err.value) == ("--rate", 0.0)
    assert SolverError("x").solver is None and RecordingError("x").path is None


EXAMPLES = [
    QpavoidError("base"),
    InputError("bad rate", name="--rate", value=0.0),
    InputError("bad q", name="q", value=np.array([1.0, np.nan])),
    RecordingError("rec.npz: not an NPZ archive", path="rec.npz", name="t", value=3),
    IKNotConvergedError(
        "unreachable", target=np.eye(4), residual=0.25, iterations=500, q=np.zeros(6)
    ),
    RobotDescriptionError("unknown robot 'ur10'", path="ur10", name="robot", value="ur10"),
    SolverError("SVD failed", solver="lapack.dgesdd", status=-4),
]


@pytest.mark.parametrize("err", EXAMPLES, ids=lambda e: type(e).__name__)
def test_errors_pickle_with_their_attributes(err):
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is type(err) and str(back) == str(err) and back.args == err.args
    assert back.__dict__.keys() == err.__dict__.keys()
    for key, value in err.__dict__.items():
        np.testing.assert_equal(getattr(back, key), value)


def test_unpicklable_attribute_becomes_its_repr():
    err = InputError("bad callback", name="progress", value=lambda t: t)
    back = pickle.loads(pickle.dumps(err))
    assert back.name == "progress" and back.value.startswith("<function")


def test_errors_cross_a_process_pool():
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1) as pool:
        future = pool.submit(load_recording, "/nonexistent/rec.npz")
        with pytest.raises(RecordingError, match="not found") as info:
            future.result()
    assert str(info.value.path) == "/nonexistent/rec.npz"


# --------------------------------------------------------------------------- public API


def test_sphere_distances_bad_shape(robot, human):
    with pytest.raises(InputError) as info:
        qpavoid.sphere_distances(robot, np.zeros(4), human, Operator().rest())
    err = info.value
    assert err.name == "q" and err.value.shape == (4,)
    assert one_line(err) == "q (joint angles, rad) must have shape (6,), got (4,)"
    with pytest.raises(InputError) as info:
        qpavoid.sphere_distances(robot, np.zeros(6), human, np.zeros((24, 3)))
    assert info.value.name == "joints" and info.value.value.shape == (24, 3)
    assert "must have shape (25, 3), got (24, 3)" in one_line(info.value)


def test_sphere_distances_nan_and_non_numeric(robot, human):
    q = np.zeros(6)
    q[2] = np.nan
    with pytest.raises(InputError) as info:
        qpavoid.sphere_distances(robot, q, human, Operator().rest())
    assert info.value.name == "q" and np.isnan(info.value.value[2])
    assert one_line(info.value) == "q (joint angles, rad) has a non-finite entry at index (2,): nan"
    with pytest.raises(InputError) as info:
        qpavoid.sphere_distances(robot, "abc", human, Operator().rest())
    assert (info.value.name, info.value.value) == ("q", "abc")
    state = np.full(25, 2)
    state[11] = 7
    with pytest.raises(InputError) as info:
        qpavoid.sphere_distances(robot, np.zeros(6), human, Operator().rest(), state)
    assert info.value.name == "state" and info.value.value[11] == 7
    assert "state[11] (HandRight) is 7" in one_line(info.value)


@pytest.mark.parametrize("ctrl_cls", [qpavoid.AnalyticController, qpavoid.QPController])
def test_controller_step_bad_inputs(robot, q_start, ctrl_cls):
    ctrl = ctrl_cls(robot)
    rest = Operator().rest()
    bad_q = q_start.copy()
    bad_q[0] = np.nan  # would make the SVD of the Jacobians fail
    with pytest.raises(InputError) as info:
        ctrl.step(bad_q, rest, None, 1.0)
    assert not isinstance(info.value, np.linalg.LinAlgError)
    assert info.value.name == "q" and "non-finite entry at index (0,)" in one_line(info.value)
    with pytest.raises(InputError) as info:
        ctrl.step(q_start[:5], rest, None, 1.0)
    assert info.value.name == "q" and info.value.value.shape == (5,)
    with pytest.raises(InputError) as info:
        ctrl.step(q_start, rest[:20], None, 1.0)
    assert info.value.name == "joints"
    with pytest.raises(InputError) as info:
        ctrl.step(q_start, rest, None, float("nan"))
    assert info.value.name == "t" and np.isnan(info.value.value)
    assert one_line(info.value) == "t (path time, s) must be a finite number, got nan"


def test_a_failed_svd_stops_the_analytic_controller(robot, q_start, monkeypatch):
    class FailingLapack:
        @staticmethod
        def dgesdd(J, full_matrices=0):
            return None, None, None, 3  # "did not converge"

    monkeypatch.setattr(laws, "lapack", FailingLapack)
    with pytest.raises(SolverError) as info:
        laws.damped_pinv(np.eye(6), 0.02, 0.05)
    assert (info.value.solver, info.value.status) == ("lapack.dgesdd", 3)
    assert "did not converge" in one_line(info.value)
    cmd = qpavoid.AnalyticController(robot).step(q_start, Operator().rest(), None, 1.0)
    assert cmd.stopped and cmd.time_scale == 0.0
    np.testing.assert_array_equal(cmd.dq, 0.0)
    assert re.fullmatch(
        r"numerical failure: SVD of the \dx\d Jacobian failed: did not converge "
        r"\(LAPACK dgesdd info 3\)",
        cmd.reason,
    )
    assert cmd.info == {"solver": "lapack.dgesdd", "status": 3}


def test_a_nan_jacobian_stops_the_robot(robot, q_start, monkeypatch):
    """A NaN Jacobian (whatever LAPACK makes of it) is a stop, never an exception."""
    real = type(robot).kinematics

    def nan_jacobian(q, jacobians=True):
        kin = real(robot, q, jacobians)
        return dataclasses.replace(kin, ee_jacobian=np.full_like(kin.ee_jacobian, np.nan))

    monkeypatch.setattr(robot, "kinematics", nan_jacobian)
    cmd = qpavoid.AnalyticController(robot).step(q_start, Operator().rest(), None, 1.0)
    assert cmd.stopped and cmd.reason
    np.testing.assert_array_equal(cmd.dq, 0.0)
    with pytest.raises(SolverError, match="non-finite entry"):
        laws.damped_pinv(np.full((3, 3), np.nan), 0.02, 0.05)


def test_qp_numerical_failures_stop_the_robot(robot, q_start, monkeypatch):
    ctrl = qpavoid.QPController(robot)

    def fail(prob):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(ctrl.backend, "solve", fail)
    cmd = ctrl.step(q_start, Operator().rest(), None, 1.0)
    assert cmd.stopped and cmd.reason == "numerical failure: Singular matrix"
    assert cmd.info == {"error": "LinAlgError"}


def test_orthonormalize_rejects_nan():
    R = np.eye(3)
    R[0, 1] = np.nan
    with pytest.raises(InputError) as info:
        orthonormalize(R)
    assert info.value.name == "R" and "non-finite entry at index (0, 1)" in one_line(info.value)
    start = A_IN.copy()
    start[1, 0] = np.nan  # the rotation: its SVD used to fail
    with pytest.raises(InputError) as info:
        ArcPath(start=start)
    assert info.value.name == "start"
    with pytest.raises(InputError) as info:
        ArcPath(duration_s=float("nan"))
    assert info.value.name == "duration_s" and np.isnan(info.value.value)


def test_unconverged_ik(robot):
    far = A_IN.copy()
    far[:3, 3] = [1.5, 0.0, 0.5]
    with pytest.raises(IKNotConvergedError) as info:
        qpavoid.inverse_kinematics(robot, far, config=IKConfig(max_iter=50, restarts=0))
    err = info.value
    np.testing.assert_array_equal(err.target, far)
    assert 0 < err.iterations <= 50 and err.residual > 0.3  # ~0.6 m short of the target
    assert err.q.shape == (robot.nq,)
    assert np.all(err.q >= robot.q_min) and np.all(err.q <= robot.q_max)
    assert (err.name, err.value) == ("target", err.target)
    assert re.fullmatch(
        r"inverse kinematics did not reach the target position \(1\.5, 0, 0\.5\) "
        r"m from the seed \(smallest residual \S+ > tol 1e-10\): unreachable within "
        r"the joint limits \(the robot description's \[ik_seed\] chooses the branch: "
        r"docs/robot\.md\)",
        one_line(err),
    )
    assert f"{err.residual:.2e}" in str(err)
    assert isinstance(err, InputError)  # existing except clauses still work


def test_unknown_names(robot):
    with pytest.raises(RobotDescriptionError) as info:
        qpavoid.load_robot("ur10")
    err = info.value
    assert (err.name, err.value, str(err.path)) == ("robot", "ur10", "ur10")
    assert one_line(err).startswith("unknown robot 'ur10': not a folder with control_points.toml")
    with pytest.raises(InputError) as info:
        make_scenario("test3", robot)
    assert (info.value.name, info.value.value) == ("scenario", "test3")
    assert "unknown scenario 'test3'" in one_line(info.value)
    with pytest.raises(InputError) as info:
        qpavoid.distance_method("boxes", robot, qpavoid.KinectHuman())
    assert (info.value.name, info.value.value) == ("distance", "boxes")
    assert one_line(info.value) == (
        "unknown distance method 'boxes'; choose from ['capsules', 'capsules-coal', 'spheres']"
    )
    with pytest.raises(InputError) as info:
        qpavoid.AnalyticConfig(limit_mode="wrap")
    assert (info.value.name, info.value.value) == ("limit_mode", "wrap")
    with pytest.raises(InputError) as info:
        robot.set_index("L3")
    assert (info.value.name, info.value.value) == ("set", "L3")
    with pytest.raises(InputError) as info:
        qpavoid.load_robot(locked=["A9"])
    assert (info.value.name, info.value.value) == ("locked", "A9")
    assert one_line(info.value).startswith("cannot lock 'A9': joints are ['A1', 'A2'")
    with pytest.raises(InputError) as info:
        qpavoid.load_robot(locked={"A3": "zero"})
    assert (info.value.name, info.value.value) == ("locked", {"A3": "zero"})


def test_unknown_solver_and_backend():
    with pytest.raises(SolverError) as info:
        make_backend(QPConfig(backend="qpsolvers", solver="no-such-solver"), 8, 4)
    assert (info.value.solver, info.value.status) == ("no-such-solver", "not installed")
    assert one_line(info.value).startswith(
        "QP solver 'no-such-solver' is not installed; available:"
    )
    with pytest.raises(SolverError) as info:
        make_backend(QPConfig(backend="magic"), 8, 4)
    assert (info.value.solver, info.value.status) == ("magic", "unknown backend")


def test_robot_description_errors(tmp_path):
    (tmp_path / "control_points.toml").write_text(
        'urdf = "arm.urdf"\nend_effector = "tool"\nsets = [{ name = "L1" }]\n'
    )
    with pytest.raises(RobotDescriptionError) as info:
        qpavoid.load_robot(tmp_path)
    err = info.value
    assert err.path == tmp_path / "control_points.toml" and err.name == "sets[0].sphere_radius_m"
    assert err.value == ["sphere_radius_m", "points", "capsule"]
    assert "sets[0] is missing key(s) sphere_radius_m, points, capsule" in one_line(err)
    iiwa = Path(__file__).parents[1] / "robots" / "iiwa14" / "control_points.toml"
    (tmp_path / "control_points.toml").write_text(
        iiwa.read_text().replace('urdf = "iiwa14.urdf"', 'urdf = "arm.urdf"')
    )  # a file of the right shape whose URDF is broken
    (tmp_path / "arm.urdf").write_text("<robot name='broken'><link>")
    with pytest.raises(RobotDescriptionError) as info:
        qpavoid.load_robot(tmp_path)
    assert info.value.path == tmp_path / "arm.urdf"
    assert "cannot build a model from this URDF" in one_line(info.value)


# --------------------------------------------------------------------------- recordings

NPZ_HINT = (
    "expected a NumPy .npz archive with arrays t (N,), joints (N, 25, 3) and state "
    "(N, 25); see docs/formats.md"
)
#: What a CSV header that names no format's joints is told (the formats the library has).
NO_FORMAT = (
    "the joints of no skeleton format (kinect_v2, k4abt, zed_body_34, zed_body_38, mediapipe_pose)"
)
CSV_HINT = (
    "expected a UTF-8 CSV file: the header row t,SpineBase_x,SpineBase_y,SpineBase_z,"
    "SpineBase_state,...,ThumbRight_state (101 columns), then one row of numbers per "
    "frame; see docs/formats.md"
)


def _zip(path, members: dict[str, bytes]):
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)


def _write(path, save, *args, **kwargs):
    """``save(file, ...)`` exactly at ``path`` (numpy would add a suffix to a name)."""
    with path.open("wb") as handle:
        save(handle, *args, **kwargs)


def _arrays(n: int = 3):
    return np.arange(n, dtype=float), np.zeros((n, 25, 3)), np.full((n, 25), 2)


BAD_FILES = {
    # name: (make(path), message after "<path>: ", .name)
    "text.npz": (
        lambda p: p.write_text("t,joints,state\n1,2,3\n"),
        f"not a readable NPZ archive (it is a text file); {NPZ_HINT}",
        None,
    ),
    "empty.npz": (
        lambda p: p.write_bytes(b""),
        f"not a readable NPZ archive (the file is empty); {NPZ_HINT}",
        None,
    ),
    "single.npz": (
        lambda p: _write(p, np.save, np.zeros(3)),
        f"not a readable NPZ archive (it is a single .npy array); {NPZ_HINT}",
        None,
    ),
    "garbage.npz": (
        lambda p: p.write_bytes(bytes(range(256)) * 8),
        f"not a readable NPZ archive (it is binary data); {NPZ_HINT}",
        None,
    ),
    "plainzip.npz": (
        lambda p: _zip(p, {"readme.txt": b"hello"}),
        (
            "not a readable NPZ archive (a ZIP archive without .npy arrays; members: "
            f"readme.txt); {NPZ_HINT}"
        ),
        None,
    ),
    "not_npy.npz": (
        lambda p: _zip(p, {"t.npy": b"junk", "joints.npy": b"", "state.npy": b""}),
        f"member 't.npy' is not a .npy array; {NPZ_HINT}",
        "t",
    ),
    "damaged.npz": (
        lambda p: _zip(
            p, {name: b"\x93NUMPY\x01\x00junk" for name in ("t.npy", "joints.npy", "state.npy")}
        ),
        None,
        None,
    ),
    "truncated.npz": (
        lambda p: (np.savez(p, t=np.zeros(2)), p.write_bytes(p.read_bytes()[:40])),
        f"not a readable NPZ archive (damaged: File is not a zip file); {NPZ_HINT}",
        None,
    ),
    "keys.npz": (
        lambda p: np.savez(p, t=np.arange(3.0)),
        f"NPZ file has no array 'joints', 'state' (found: 't'); {NPZ_HINT}",
        "joints",
    ),
    "objects.npz": (
        lambda p: np.savez(
            p,
            t=np.array([0.0, "a"], dtype=object),
            joints=np.zeros((2, 25, 3)),
            state=np.zeros((2, 25)),
        ),
        f"array 't' holds Python objects (pickled data, never loaded); {NPZ_HINT}",
        "t",
    ),
    "shape.npz": (
        lambda p: np.savez(
            p, t=np.arange(3.0), joints=np.zeros((3, 24, 3)), state=np.zeros((3, 25))
        ),
        ("joints (Kinect v2, m) must have shape (3, 25, 3), got (3, 24, 3); see docs/formats.md"),
        "joints",
    ),
    "nan_t.npz": (
        lambda p: np.savez(
            p, t=np.array([0.0, np.nan]), joints=np.zeros((2, 25, 3)), state=np.zeros((2, 25))
        ),
        "t (frame times, s) has a non-finite value at index 1: nan; see docs/formats.md",
        "t",
    ),
    "garbage.csv": (
        lambda p: p.write_bytes(bytes(range(256)) * 8),
        f"not a CSV text file (it is binary data); {CSV_HINT}",
        None,
    ),
    "archive.csv": (
        lambda p: _write(p, np.savez, t=np.zeros(2)),
        f"not a CSV text file (it is a ZIP archive); {CSV_HINT}",
        None,
    ),
    "empty.csv": (
        lambda p: p.write_text(""),
        f"not a CSV text file (the file is empty); {CSV_HINT}",
        None,
    ),
    "header.csv": (
        lambda p: p.write_text("time,x,y,z\n0,1,2,3\n"),
        f"CSV header not found: the first row is 'time,x,y,...' (4 columns), {NO_FORMAT}; "
        f"{CSV_HINT}",
        "header",
    ),
    "prose.csv": (
        lambda p: p.write_text("just some notes\n"),
        (
            f"CSV header not found: the first row is 'just some notes' (1 column), "
            f"{NO_FORMAT}; {CSV_HINT}"
        ),
        "header",
    ),
    "short_row.csv": (
        lambda p: p.write_text(",".join(csv_header()) + "\n0.0,1.0\n"),
        "CSV line 2 has 2 values, expected 101; see docs/formats.md",
        "line",
    ),
    "no_frames.csv": (
        lambda p: p.write_text(",".join(csv_header()) + "\n"),
        ("the recording has no frame: t (frame times, s) is empty; see docs/formats.md"),
        "t",
    ),
}


@pytest.mark.parametrize("filename", sorted(BAD_FILES))
def test_bad_recording_files(tmp_path, filename):
    make, message, name = BAD_FILES[filename]
    path = tmp_path / filename
    make(path)
    with pytest.raises(RecordingError) as info:
        load_recording(path)
    err = info.value
    assert err.path == path and err.name == name
    if message is None:  # text from zipfile/numpy
        assert one_line(err).startswith(f"{path}: not a readable NPZ archive (damaged: ")
        assert one_line(err).endswith(NPZ_HINT)
    else:
        assert one_line(err) == f"{path}: {message}"


def test_csv_the_csv_module_refuses(tmp_path):
    path = tmp_path / "long.csv"
    save_csv(path, Recording(*_arrays(2)))
    path.write_text(path.read_text() + '"' + "1" * 200_000 + '"\n')
    with pytest.raises(RecordingError) as info:
        load_recording(path)
    assert one_line(info.value).startswith(
        f"{path}: not a readable CSV file (field larger than field limit"
    )
    assert one_line(info.value).endswith(CSV_HINT)


def test_csv_invalid_utf8_past_the_first_block(tmp_path):
    path = tmp_path / "late.csv"
    save_csv(path, Recording(*_arrays(200)))
    path.write_bytes(path.read_bytes() + b"\xff\xfe\n")
    with pytest.raises(RecordingError) as info:
        load_recording(path)
    assert one_line(info.value).startswith(f"{path}: not a CSV text file (invalid UTF-8: ")


def test_missing_file_and_folder(tmp_path):
    for name in ("absent.npz", "absent.csv"):
        with pytest.raises(RecordingError) as info:
            load_recording(tmp_path / name)
        assert info.value.path == tmp_path / name
        assert one_line(info.value) == f"recording file not found: {str(tmp_path / name)!r}"
    folder = tmp_path / "run.npz"
    folder.mkdir()
    with pytest.raises(RecordingError) as info:
        load_recording(folder)
    assert info.value.path == folder
    assert one_line(info.value) == f"{str(folder)!r} is a folder, not a recording file"
    with pytest.raises(RecordingError, match=r"unknown recording format '\.json'") as info:
        load_recording(tmp_path / "motion.json")
    assert info.value.path == tmp_path / "motion.json"


def test_bad_run_log(tmp_path):
    (tmp_path / "log.npz").write_text("not a log")
    with pytest.raises(RecordingError) as info:
        load_log(tmp_path)
    assert info.value.path == tmp_path / "log.npz"
    assert one_line(info.value).startswith(
        f"{tmp_path / 'log.npz'}: not a readable NPZ archive "
        "(it is a text file); expected the log.npz of a run"
    )
    with pytest.raises(RecordingError, match="run log file not found"):
        load_log(tmp_path / "other")
