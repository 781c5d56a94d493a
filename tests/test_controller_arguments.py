"""A controller takes the robot by position and its settings by keyword (issue 46, item
6.3: ``QPController(robot, cfg)`` was accepted, ``cfg`` taken for the path, and failed at
the first tick).

Misplaced settings are refused when the controller is made, with a :class:`TypeError`
that writes the call as it should be; the signature says so to a type checker too.
"""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from qpavoid.control.analytic import AnalyticConfig, AnalyticController
from qpavoid.control.controller import Controller
from qpavoid.control.path import ArcPath
from qpavoid.control.qp import QPConfig, QPController
from qpavoid.control.tick import ControllerConfig
from qpavoid.human.body import KinectHuman
from qpavoid.human.posture import Operator

KINDS = [Controller, AnalyticController, QPController]


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.__name__)
def test_everything_after_the_robot_is_keyword_only(kind):
    params = list(inspect.signature(kind).parameters.values())
    assert params[0].name == "robot"
    assert params[0].kind is inspect.Parameter.POSITIONAL_OR_KEYWORD
    assert all(p.kind is inspect.Parameter.KEYWORD_ONLY for p in params[1:])
    assert [p.name for p in params[1:4]] == ["path", "config", "human"]


@pytest.mark.parametrize("kind", [AnalyticController, QPController], ids=lambda k: k.__name__)
def test_a_config_by_position_is_refused_at_construction_with_the_fix(robot, kind):
    """The user's call: the config second. The message names the keyword to use."""
    cfg = ControllerConfig(control_period_s=0.01)
    with pytest.raises(TypeError) as info:
        kind(robot, cfg)
    message = str(info.value)
    assert message.startswith(f"{kind.__name__} takes the robot alone by position")
    assert f"write {kind.__name__}(robot, config=<your ControllerConfig>)" in message
    assert "\n" not in message


@pytest.mark.parametrize("kind", [AnalyticController, QPController], ids=lambda k: k.__name__)
def test_each_setting_by_position_is_named_by_its_type(robot, kind):
    own = AnalyticConfig() if kind is AnalyticController else QPConfig()
    own_key = "analytic" if kind is AnalyticController else "qp"
    path, cfg, human = ArcPath(), ControllerConfig(), KinectHuman()
    with pytest.raises(TypeError) as info:
        kind(robot, path, cfg, human, own)
    assert (
        f"write {kind.__name__}(robot, path=<your ArcPath>, config=<your ControllerConfig>, "
        f"human=<your KinectHuman>, {own_key}=<your {type(own).__name__}>)"
    ) in str(info.value)
    with pytest.raises(TypeError, match=r"\(robot, <keyword>=<your int>\)"):
        kind(robot, 3)  # nothing it could be: the keywords are listed
    with pytest.raises(TypeError, match=r"by keyword \(path, config, human, "):
        kind(robot, 3)


def test_by_keyword_it_runs(robot):
    """The same settings by keyword: made, and a tick commands joint velocities on the
    path given (its start reached by the inverse kinematics)."""
    cfg = ControllerConfig(control_period_s=0.01)
    for ctrl in (
        AnalyticController(robot, path=ArcPath(), config=cfg),
        QPController(robot, config=cfg, path=ArcPath()),
    ):
        assert ctrl.config is cfg and isinstance(ctrl.path, ArcPath)
        q = np.radians([60, 35.3, -82.7, 0, -58.0, 0])  # the paper's start
        cmd = ctrl.step(q, Operator().rest(), None, t=0.0)
        assert cmd.dq.shape == (robot.nv,) and np.all(np.isfinite(cmd.dq))


def test_a_subclass_keeps_its_own_signature(robot):
    """The check is on the library's constructors, not on a subclass's own."""

    class Slow(QPController):
        def __init__(self, robot, period_s: float):
            super().__init__(robot, config=ControllerConfig(control_period_s=period_s))

    assert Slow(robot, 0.02).config.control_period_s == 0.02
