"""Names earlier issues wrote down still work exactly: the console script's target,
``import qpavoid.control.qp``, ``qpavoid.cli.main``,
``AnalyticConfig(limit_mode, l2_joints)``, ``L2RepulsionTask``, ``load_robot(toml)``."""

from __future__ import annotations

import subprocess
from importlib import resources
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib
import tomllib
from conftest import PYTHON

import qpavoid
from qpavoid.control.analytic import AnalyticConfig
from qpavoid.control.qp.barriers.repulsion import RepelledRepulsionTask
from qpavoid.core.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


def test_the_console_script_is_qpavoid_launch_main():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"qpavoid": "qpavoid.launch:main"}
    import qpavoid.launch

    assert callable(qpavoid.launch.main)


def test_the_top_level_names_are_the_stages_objects():
    import qpavoid.cli
    from qpavoid.cli.commands import main
    from qpavoid.control.qp import QPController

    assert QPController is qpavoid.QPController
    assert qpavoid.cli.main is main
    with pytest.raises(AttributeError):
        qpavoid.cli.nothing  # noqa: B018


def test_import_qpavoid_control_qp_and_robots_in_a_fresh_interpreter():
    """What the quick start's check runs
    (``python -P -c "import qpavoid.control.qp, qpavoid.robots"``)."""
    done = subprocess.run(
        [*PYTHON, "-c", "import qpavoid.control.qp, qpavoid.robots; print('ok')"],
        capture_output=True,
        text=True,
        cwd="/",
    )
    assert done.returncode == 0 and done.stdout == "ok\n", done.stderr


def test_the_command_line_loads_no_optional_binding_it_does_not_use():
    """The command line (and a run on OSQP or daqp in the simulation) never imports
    qpsolvers (about 0.3 s with SciPy's optimizers) nor franky-control (0.1 s): each on
    first use, by the qpsolvers backend and ``--arm franka``. A second check builds the
    qpsolvers backend, which then has it."""
    code = (
        "import sys, qpavoid.cli.commands\n"
        "from qpavoid.control.qp import QPController, QPConfig\n"
        "from qpavoid.arm.model import load_robot\n"
        "QPController(load_robot('iiwa14'))\n"
        "print(sorted(m for m in ('qpsolvers', 'franky') if m in sys.modules))\n"
        "QPController(load_robot('iiwa14'), qp=QPConfig(backend='qpsolvers', solver='osqp'))\n"
        "print('qpsolvers' in sys.modules)"
    )
    done = subprocess.run([*PYTHON, "-c", code], capture_output=True, text=True, cwd="/")
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["[]", "True"]


def test_analytic_config_takes_l2_joints_as_it_did():
    joints = ("A1", "A2", "A4")
    assert AnalyticConfig("scale", joints).repelled_joints == joints  # positional
    assert AnalyticConfig(limit_mode="clip", l2_joints=joints).repelled_joints == joints
    assert AnalyticConfig(repelled_joints=joints, l2_joints=list(joints)).repelled_joints == joints
    with pytest.raises(InputError, match="name one setting"):
        AnalyticConfig(repelled_joints=("A1",), l2_joints=joints)


def test_l2_repulsion_task_is_the_repelled_sets():
    from qpavoid.control.qp.barriers.repulsion import L2RepulsionTask

    assert L2RepulsionTask is RepelledRepulsionTask


def test_load_robot_takes_a_control_point_file(robot):
    toml = resources.files("qpavoid.robots") / "iiwa14" / "control_points.toml"
    by_file = qpavoid.load_robot(str(toml))
    assert by_file.set_names == robot.set_names and by_file.nq == robot.nq
