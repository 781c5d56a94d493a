"""The sweep engine (qpavoid.experiments.sweep): one engine for approaches and strikes,
behind ``qpavoid sweep`` and ``safety_sweep``; settings checked before any run."""

from __future__ import annotations

import shlex
from dataclasses import replace

import pytest

from qpavoid.cli.commands import build_parser
from qpavoid.core.errors import InputError, RobotDescriptionError
from qpavoid.experiments import campaign, sweep
from qpavoid.experiments.sweep import SweepSpec
from qpavoid.experiments.sweep_checks import ApproachCheck, StrikeCheck
from qpavoid.experiments.sweep_summary import summarize


def untimed(check: StrikeCheck) -> StrikeCheck:
    """``check`` without its measured tick times."""
    return replace(check, tick_us_median=0.0, tick_us_p99=0.0)


@pytest.mark.parametrize(
    "settings, word",
    [
        (dict(kind="walk"), "sweep kind"),
        (dict(kind="strike", controller="pid"), "controller"),
        (dict(kind="approach", rate_hz=5.0), "--rate"),
        (dict(kind="strike", latency_s=-0.1), "--latency"),
        (dict(kind="approach", max_time_s=0.0), "--max-time"),
    ],
)
def test_bad_settings_are_refused_before_any_run(settings, word):
    with pytest.raises(InputError, match=word):
        SweepSpec(**settings)


def test_nothing_to_sum_up_is_an_input_error():
    with pytest.raises(InputError, match="at least one run"):
        summarize([])


def test_the_kind_chooses_the_motion_and_the_check():
    approach = SweepSpec("approach", "analytic", "spheres", "paper", 50.0, 1.0)
    strike = SweepSpec("strike", "analytic", "spheres", "ssm", 100.0, 1.0)
    assert approach.run_spec(7).scenario == "random:7" and not approach.run_spec(7).measure_truth
    assert strike.run_spec(7).scenario == "free" and strike.run_spec(7).measure_truth
    # a strike lasts its own duration unless capped
    assert SweepSpec("strike").run_spec(7, 4.25).max_time_s == 4.25
    checks = sweep.sweep(approach, [3], workers=1) + sweep.sweep(strike, [3], workers=1)
    assert [type(c) for c in checks] == [ApproachCheck, StrikeCheck]
    assert [c.seed for c in checks] == [3, 3]
    assert summarize(checks[:1])["approaches"] == 1
    assert summarize(checks[1:])["runs"] == 1
    # the documented callers are the engine's runs
    assert sweep.safety_sweep([3], "analytic", "spheres", 50.0, 1.0, workers=1) == checks[:1]
    (again,) = sweep.strike_sweep(
        [3], "analytic", "ssm", workers=1, distance="spheres", max_time_s=1.0
    )
    assert untimed(again) == untimed(checks[1])


def test_a_campaign_uses_its_spec_s_robot(tmp_path):
    """campaign.py loaded "iiwa14" whatever the spec said."""
    elsewhere = str(tmp_path / "no such robot")
    spec = campaign.campaign_spec("qp", robot=elsewhere)
    run = StrikeCheck(4, "qp", "ssm", "L2", 1.0, "right", False, "none", 0, 0.1, 1.0, 1.0, 0.0)
    with pytest.raises(RobotDescriptionError):
        campaign.true_recording(run, spec)
    args = build_parser().parse_args(shlex.split(campaign.rerun_command(run, spec))[1:])
    assert args.robot == elsewhere
    default = campaign.rerun_command(run, campaign.campaign_spec("qp"))
    assert "--robot" not in default  # the default robot's line as it always was
