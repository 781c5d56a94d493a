"""Shared fixtures: the iiwa (A3 locked and free), the human model, random inputs."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import qpavoid
from qpavoid.control.qp import kernels as qp_kernels
from qpavoid.control.qp import solver_kernels
from qpavoid.distance import _kernels as distance_kernels
from qpavoid.drive.limits import CommandCheck
from qpavoid.fusion import person as fusion_person
from qpavoid.human import _kernels as body_kernels
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.laws import _kernels as law_kernels
from qpavoid.loop import plants
from qpavoid.loop.camera import CameraConfig
from qpavoid.perception import _kernels as perception_kernels
from qpavoid.perception.tracker import PerceptionConfig

#: This interpreter, for a subprocess that must import the installed package: ``-P``
#: (Python 3.11+) keeps the working directory off its ``sys.path``. pytest runs in the
#: checkout, whose own ``qpavoid/`` a plain ``python -m``/``-c`` imports instead of the
#: package under test: a non-editable install's subprocesses ran the source tree, and
#: compiled its kernels afresh (their numba cache is the source tree's, cold in a new
#: clone: about 14 s of a cold suite's time).
PYTHON = (sys.executable, "-P") if sys.version_info >= (3, 11) else (sys.executable,)

#: The fusion's kernels compiled (or loaded) in a process of their own.
WARM_UP_FUSION = (
    "from qpavoid.fusion import person; from qpavoid.human.kinect_v2 import KINECT_V2; "
    "person.warm_up(KINECT_V2)"
)


def pytest_configure(config):
    """Compile the numba kernels once, in the first process, before the workers and the
    command-line subprocesses need them (a fresh install compiles for about 20 s of one
    core, 10 s here with the fusion's beside the rest; every process after that loads them
    from the disk cache)."""
    if not hasattr(config, "workerinput"):  # pytest-xdist's controller, or no xdist
        # the largest kernel (about half of a fresh install's 20 s) compiled beside the rest
        fusion = subprocess.Popen([*PYTHON, "-c", WARM_UP_FUSION])
        perception_kernels.warm_up(KINECT_V2)
        body_kernels.warm_up(KINECT_V2)
        distance_kernels.warm_up()
        qp_kernels.warm_up()
        solver_kernels.warm_up()
        law_kernels.warm_up()
        if fusion.wait() != 0:  # compile it here, where an error shows
            fusion_person.warm_up(KINECT_V2)


@pytest.fixture(autouse=True)
def every_command_within_the_arms_limits(request, monkeypatch):
    """Every command of every run a test makes (through ``simulate``'s arms,
    :mod:`qpavoid.loop.plants`) is within the arm's velocity, acceleration and jerk limits
    (issue 27): the run's own check is recorded and the test fails on any broken limit.
    A test that runs the paper's steps on purpose (``ControllerConfig(smooth=False)``)
    says so with ``@pytest.mark.paper_steps``."""
    checks: list[CommandCheck] = []

    class Recorded(CommandCheck):
        def __post_init__(self) -> None:
            super().__post_init__()
            checks.append(self)

    monkeypatch.setattr(plants, "CommandCheck", Recorded)
    yield
    if request.node.get_closest_marker("paper_steps") is None:
        broken = [c.counts for c in checks if c.total()]
        assert not broken, f"commands beyond the arm's limits in {len(broken)} run(s): {broken}"


@pytest.fixture(scope="session")
def robot():
    return qpavoid.load_robot("iiwa14")


@pytest.fixture(scope="session")
def robot7():
    return qpavoid.load_robot("iiwa14", locked=())


@pytest.fixture(scope="session")
def human():
    return qpavoid.KinectHuman()


def seeds(n: int, fast: int) -> list:
    """Seeds ``0 .. n-1`` as parameters, all but the first ``fast`` in the slow suite: the
    default suite keeps a few random cases of a sweep, ``-m slow`` runs them all."""
    return [i if i < fast else pytest.param(i, marks=pytest.mark.slow) for i in range(n)]


def random_q(rng: np.random.Generator, robot, margin: float = 0.05) -> np.ndarray:
    """Uniform joint angles inside the position limits (rad)."""
    return rng.uniform(robot.q_min + margin, robot.q_max - margin)


def ideal_sim(**kw) -> qpavoid.SimConfig:
    """The paper's bench: a perfect sensor (no latency, no noise) and an arm that follows
    its command at once."""
    return qpavoid.SimConfig(camera=CameraConfig.ideal(), braking=None, **kw)


def paper_config(**kw) -> qpavoid.ControllerConfig:
    """The paper's controller settings: spheres, its rules, and no frozen-frame check (a
    perfect sensor films a still person bit for bit)."""
    kw.setdefault("distance", "spheres")
    return qpavoid.ControllerConfig(perception=PerceptionConfig(max_identical_frames=None), **kw)


def write_calibration(folder, calibration) -> str:
    """Write ``calibration`` as ``folder/calib.toml``, with each sensor's key file beside it
    (mode 0600) when it has keys; the calibration file's path."""
    from pathlib import Path

    folder = Path(folder)
    key_files = {name: f"{name}.key" for name in calibration.keys} or None
    for name, keys in calibration.keys.items():
        path = folder / f"{name}.key"
        path.write_text(keys.to_toml())
        path.chmod(0o600)
    path = folder / "calib.toml"
    path.write_text(calibration.to_toml(key_files))
    return str(path)
