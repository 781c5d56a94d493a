"""The ``[arm]`` table (qpavoid.arm.dynamics): its refusals, the maker's stopping data, the
jerk-limited braking model, and how they reach speed and separation monitoring."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from qpavoid.arm.braking import ArmResponse, BrakingConfig, jerk_lag_s, stop_time
from qpavoid.arm.dynamics import (
    ArmDynamics,
    StoppingData,
    read_arm,
    tighter_limits,
)
from qpavoid.core.errors import RobotDescriptionError
from qpavoid.laws.ssm import SSMConfig, StopTimeBudget, joint_speed_limits

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

PATH = Path("/robots/arm/control_points.toml")
UR5 = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
#: A UR5's [arm] with its maker's Category 0 stops (the values of the UR5/CB3 manual).
UR5_ARM = """
[arm]
reaction_time_s = 0.008
max_acceleration_radps2 = { shoulder_pan_joint = 20.0, shoulder_lift_joint = 20.0, elbow_joint = 20.0, wrist_1_joint = 20.0, wrist_2_joint = 20.0, wrist_3_joint = 20.0 }
max_point_speed_mps = 8.0
max_jerk_radps3 = { shoulder_pan_joint = 2000.0 }
max_velocity_radps = { elbow_joint = 3.0 }
position_limits_rad = { elbow_joint = [-3.0, 3.0] }

[[arm.stopping]]
joints = ["shoulder_pan_joint"]
category = 0
speed_radps = 3.194
distance_rad = 0.31
time_s = 0.244
extension = 1.0
payload_kg = 5.0

[[arm.stopping]]
joints = ["shoulder_lift_joint", "elbow_joint"]
category = 1
speed_radps = 3.194
distance_rad = 0.70
time_s = 0.530
extension = 0.66
payload_kg = 3.3

[arm.sources]
max_jerk_radps3 = "a test's"
max_velocity_radps = "a test's"
position_limits_rad = "a test's"
stopping = "UR5/CB3 User Manual 3.4.5, Annex A.1"
"""  # noqa: E501


def arm_of(text: str, joints: tuple[str, ...] = UR5) -> ArmDynamics:
    return read_arm(tomllib.loads(text), PATH, joints)


def test_a_ur5_arm_table_is_read_with_every_value_in_urdf_order():
    arm = arm_of(UR5_ARM)
    assert arm.reaction_time_s == 0.008 and arm.max_point_speed_mps == 8.0
    assert [n for n, _ in arm.max_acceleration_radps2] == list(UR5)
    assert arm.max_jerk_radps3 == (("shoulder_pan_joint", 2000.0),)
    assert arm.max_velocity_radps == (("elbow_joint", 3.0),)
    assert arm.position_limits_rad == (("elbow_joint", (-3.0, 3.0)),)
    assert arm.stopping[1] == StoppingData(
        ("shoulder_lift_joint", "elbow_joint"), 1, 3.194, 0.70, 0.530, 0.66, 3.3
    )
    assert dict(arm.sources)["stopping"].startswith("UR5/CB3")


def test_the_maker_s_stop_gives_the_slower_of_its_time_and_its_distance():
    # base: 3.194 / 0.244 = 13.090 rad/s² (time) against 3.194² / 0.62 = 16.454 (distance)
    # shoulder and elbow: 3.194 / 0.53 = 6.0264 against 3.194² / 1.4 = 7.2870
    arm = arm_of(UR5_ARM)
    maker = dict(arm.stopping_deceleration_radps2())
    assert maker == pytest.approx(
        {"shoulder_pan_joint": 13.0902, "shoulder_lift_joint": 6.0264, "elbow_joint": 6.0264},
        abs=1e-4,
    )
    # a ramp at that deceleration from v0 lasts at least T0 and travels at least D0
    for entry in arm.stopping:
        a, v = entry.deceleration_radps2, entry.speed_radps
        assert v / a >= entry.time_s - 1e-12 and v * v / (2 * a) >= entry.distance_rad - 1e-12
    # braking: the slower of that and the acceleration limit (20 rad/s² for every joint)
    brake = dict(arm.braking_deceleration_radps2())
    assert brake["shoulder_pan_joint"] == maker["shoulder_pan_joint"]
    assert brake["wrist_1_joint"] == 20.0
    # a distance-bound stop: D0 = 0.5 rad from 2 rad/s in 0.1 s brakes at 2²/1 = 4, not 20
    far = StoppingData(("elbow_joint",), 0, 2.0, 0.5, 0.1, 1.0, 0.0)
    assert far.deceleration_radps2 == pytest.approx(4.0)


def test_without_stopping_data_braking_is_the_acceleration_limit_itself():
    sources = 'max_jerk_radps3 = "x"\nmax_velocity_radps = "x"\nposition_limits_rad = "x"\n'
    arm = arm_of(UR5_ARM.split("\n[[arm.stopping]]")[0] + "\n[arm.sources]\n" + sources)
    assert arm.stopping == () and arm.stopping_deceleration_radps2() == ()
    assert arm.braking_deceleration_radps2() is arm.max_acceleration_radps2


def edit(old: str, new: str):
    return lambda t: t.replace(old, new, 1)


@pytest.mark.parametrize(
    "change, name, message",
    [
        (
            lambda t: "",
            "arm",
            "no [arm] table; add one, e.g. reaction_time_s = 0.005",
        ),
        (
            edit("[arm]\n", "[arm]\nmax_acceleration = 3\n"),
            "arm.max_acceleration",
            "arm has unknown key(s) ['max_acceleration']",
        ),
        (
            edit("max_point_speed_mps = 8.0\n", ""),
            "arm.max_point_speed_mps",
            "arm is missing key(s) max_point_speed_mps (docs/robot.md: Arm)",
        ),
        (  # a joint's acceleration missing
            edit(", wrist_3_joint = 20.0", ""),
            "arm.max_acceleration_radps2",
            "must give one limit (rad/s²) for each joint of the URDF",
        ),
        (
            edit(
                "max_jerk_radps3 = { shoulder_pan_joint = 2000.0 }", "max_jerk_radps3 = { x = 1e3 }"
            ),
            "arm.max_jerk_radps3",
            "arm.max_jerk_radps3: ['x'] are not joints of the URDF",
        ),
        (  # a jerk in rad/s³ typed as 0.5: below any arm's
            edit("shoulder_pan_joint = 2000.0", "shoulder_pan_joint = 0.5"),
            "arm.max_jerk_radps3.shoulder_pan_joint",
            "must be a number at least 1 and at most 1e+06, got 0.5",
        ),
        (  # 172 deg/s typed in rad/s
            edit("elbow_joint = 3.0 }", "elbow_joint = 172.0 }"),
            "arm.max_velocity_radps.elbow_joint",
            "must be a number above 0 and at most 20, got 172.0",
        ),
        (
            edit("[-3.0, 3.0]", "[3.0, -3.0]"),
            "arm.position_limits_rad.elbow_joint",
            "must be [lower, upper] with lower below upper",
        ),
        (  # degrees
            edit("[-3.0, 3.0]", "[-170, 170]"),
            "arm.position_limits_rad.elbow_joint[0]",
            "must be a number at least -12.5664 and at most 12.5664, got -170",
        ),
        (
            edit("[-3.0, 3.0]", "-3.0"),
            "arm.position_limits_rad.elbow_joint",
            "must be [lower, upper] in rad, got -3.0",
        ),
        (  # a stopping time in ms
            edit("time_s = 0.244", "time_s = 244"),
            "arm.stopping[0].time_s",
            "arm.stopping[0].time_s must be a number above 0 and at most 5, got 244",
        ),
        (  # a stopping distance in degrees
            edit("distance_rad = 0.31", "distance_rad = 17.8"),
            "arm.stopping[0].distance_rad",
            "must be a number above 0 and at most 6.28319, got 17.8",
        ),
        (
            edit("category = 0", "category = 2"),
            "arm.stopping[0].category",
            "arm.stopping[0].category must be the stop category 0 or 1 of IEC 60204-1, got 2",
        ),
        (
            edit("category = 0", "category = true"),
            "arm.stopping[0].category",
            "must be the stop category 0 or 1",
        ),
        (
            edit("extension = 1.0\n", ""),
            "arm.stopping[0].extension",
            "arm.stopping[0] is missing key(s) extension (docs/robot.md: Arm)",
        ),
        (
            edit("extension = 1.0\n", "extension = 1.0\nspeed = 3\n"),
            "arm.stopping[0].speed",
            "arm.stopping[0] has unknown key(s) ['speed']",
        ),
        (
            edit('joints = ["shoulder_pan_joint"]', 'joints = ["base"]'),
            "arm.stopping[0].joints",
            "arm.stopping[0].joints: ['base'] are not joints of the URDF",
        ),
        (
            edit('joints = ["shoulder_pan_joint"]', "joints = []"),
            "arm.stopping[0].joints",
            "must be a list of distinct joint names, got []",
        ),
        (
            edit("extension = 0.66", "extension = 66"),
            "arm.stopping[1].extension",
            "must be a number above 0 and at most 1, got 66",
        ),
        (  # a maker's number without its document
            edit('stopping = "UR5/CB3 User Manual 3.4.5, Annex A.1"\n', ""),
            "arm.sources.stopping",
            '[arm] stopping needs its source: add stopping = "<the maker',
        ),
        (
            edit('max_jerk_radps3 = "a test\'s"', 'max_jerk_radps3 = "  "'),
            "arm.sources.max_jerk_radps3",
            "[arm] max_jerk_radps3 needs its source",
        ),
        (  # a misspelt source would leave its fact unsourced
            edit("[arm.sources]\n", '[arm.sources]\nmax_jerk = "x"\n'),
            "arm.sources.max_jerk",
            "arm.sources has unknown key(s) ['max_jerk']",
        ),
        (
            edit("reaction_time_s = 0.008", "reaction_time_s = 8"),
            "arm.reaction_time_s",
            "arm.reaction_time_s must be a number at least 0 and at most 0.1, got 8",
        ),
        (
            edit("reaction_time_s = 0.008", "reaction_time_s = 1" + "0" * 400),
            "arm.reaction_time_s",
            "arm.reaction_time_s must be a number at least 0 and at most 0.1",
        ),
    ],
)
def test_a_bad_arm_table_is_one_line_naming_the_file_the_key_and_the_fix(change, name, message):
    with pytest.raises(RobotDescriptionError) as info:
        arm_of(change(UR5_ARM))
    text = str(info.value)
    assert message in text and text.startswith(f"{PATH}: ") and "\n" not in text
    assert info.value.name == name and info.value.path == PATH


def test_a_ur5_with_its_joints_renamed_cannot_run_with_another_arm_s_accelerations():
    """The issue's case: UR5 joints renamed A1... with the iiwa's table is refused, and so
    is the UR5's table on an arm whose joints are named otherwise."""
    iiwa = Path(__file__).parents[1] / "robots" / "iiwa14" / "control_points.toml"
    cfg = tomllib.loads(iiwa.read_text())
    renamed = ("A1", "A2", "A4", "A5", "A6", "A7")  # six joints under the iiwa's names
    with pytest.raises(RobotDescriptionError, match="for each joint of the URDF"):
        read_arm(cfg, iiwa, renamed)
    with pytest.raises(RobotDescriptionError, match="for each joint of the URDF"):
        arm_of(UR5_ARM, tuple(f"joint{k}" for k in range(6)))
    with pytest.raises(RobotDescriptionError, match=r"no \[arm\] table"):
        read_arm({k: v for k, v in cfg.items() if k != "arm"}, iiwa, renamed)


def test_the_iiwa_s_table_reads_as_today():
    iiwa = Path(__file__).parents[1] / "robots" / "iiwa14" / "control_points.toml"
    arm = read_arm(tomllib.loads(iiwa.read_text()), iiwa, tuple(f"A{k}" for k in range(1, 8)))
    assert arm.reaction_time_s == 0.005 and arm.max_point_speed_mps == 3.0
    assert arm.max_acceleration_radps2[0] == ("A1", 8.57) and arm.stopping == ()
    assert arm.max_jerk_radps3 == () and arm.braking_deceleration_radps2() is (
        arm.max_acceleration_radps2
    )


def test_the_maker_s_limits_only_ever_narrow_the_urdf_s():
    arm = arm_of(UR5_ARM)
    lo, hi = np.full(6, -2 * np.pi), np.full(6, 2 * np.pi)
    vel = np.full(6, 3.15)
    new_lo, new_hi, new_vel = tighter_limits(arm, PATH, UR5, lo, hi, vel)
    assert new_lo[2] == -3.0 and new_hi[2] == 3.0 and new_vel[2] == 3.0
    assert np.array_equal(np.delete(new_lo, 2), np.delete(lo, 2))
    assert np.array_equal(np.delete(new_vel, 2), np.delete(vel, 2))
    # a maker's range wider than the URDF's leaves the URDF's; a higher speed too
    narrow_lo, narrow_hi = np.full(6, -1.0), np.full(6, 1.0)
    out = tighter_limits(arm, PATH, UR5, narrow_lo, narrow_hi, np.full(6, 2.0))
    assert out[0][2] == -1.0 and out[1][2] == 1.0 and out[2][2] == 2.0
    # no overlap: two different arms in one description
    with pytest.raises(RobotDescriptionError, match="does not overlap the URDF's"):
        tighter_limits(arm, PATH, UR5, np.full(6, 3.5), np.full(6, 4.0), vel)


# --- the jerk-limited braking model ----------------------------------------------------------


def test_a_jerk_limited_stop_by_hand():
    """v = 1 rad/s, a = 10 rad/s², j = 1000 rad/s³ (v ≥ a²/j = 0.1: a is reached).

    Phases: jerk to −a in a/j = 0.01 s (v falls by a²/2j = 0.05, travels
    1 · 0.01 − 1000 · 0.01³/6 = 0.0098333); −a for 0.09 s (0.95 → 0.05, travels 0.045);
    back to 0 in 0.01 s (travels 0.05 · 0.01 − 10 · 0.01²/2 + 1000 · 0.01³/6 = 0.0001667).
    T = 0.11 s, D = 0.055 rad = v T / 2.
    """
    assert stop_time([1.0], [10.0], [1000.0]) == pytest.approx(0.11)
    phases_m = 0.0098333 + 0.045 + 0.0001667
    assert phases_m == pytest.approx(1.0 * 0.11 / 2, abs=1e-7)
    # v = 0.04 < 0.1: a is never reached, T = 2 √(v/j) = 0.012649 s
    assert stop_time([0.04], [10.0], [1000.0]) == pytest.approx(2 * math.sqrt(0.04 / 1000))
    # without jerk: v/a, as before
    assert stop_time([1.0, 0.5], [10.0, 2.0]) == 0.25
    assert stop_time([1.0, 0.5], [10.0, 2.0], [np.inf, np.inf]) == 0.25
    assert stop_time([0.0, 0.0], [10.0, 2.0], [1.0, 1.0]) == 0.0


def test_the_simulated_arm_brakes_along_the_hand_computed_profile():
    """The arm's stop from 1 rad/s (a = 10, j = 1000), stepped at 0.1 ms: it stands after
    0.11 s and has travelled 0.055 rad, with |q̈| ≤ a and |q⃛| ≤ j at every step."""
    dt = 1e-4
    cfg = BrakingConfig(0.0, (("J", 10.0),), (("J", 1000.0),))
    arm = ArmResponse(cfg, ["J"], dt)
    arm.dq = np.array([1.0])
    v = [1.0]
    while v[-1] > 0.0 and len(v) < 5000:
        v.append(float(arm(np.zeros(1))[0]))
    v = np.array(v)
    assert (len(v) - 1) * dt == pytest.approx(0.11, abs=1.5 * dt)
    assert np.trapezoid(v, dx=dt) == pytest.approx(0.055, abs=1e-6)
    acc = np.diff(v) / dt
    assert np.all(np.abs(acc) <= 10.0 + 1e-9)
    assert np.all(np.abs(np.diff(acc)) / dt <= 1000.0 * (1 + 1e-6))


def test_a_jerk_limited_stop_keeps_the_path_and_ends_at_once_on_every_joint():
    rng = np.random.default_rng(3)
    a, j = np.array([8.0, 4.0, 12.0]), np.array([900.0, 400.0, np.inf])
    cfg = BrakingConfig(0.0, tuple(zip("xyz", a)), tuple(zip("xyz", j)))
    for _ in range(20):
        arm = ArmResponse(cfg, list("xyz"), 1e-3)
        dq0 = rng.uniform(-2.0, 2.0, 3)
        arm.dq = dq0.copy()
        steps = []
        while np.any(arm.dq != 0.0) and len(steps) < 3000:
            steps.append(arm(np.zeros(3)).copy())
        path = np.array(steps)
        ratio = path / dq0  # every joint at the same fraction of its start
        np.testing.assert_allclose(ratio, ratio[:, :1] * np.ones(3), atol=1e-12)
        # the stop lasts the synchronised ramp of stop_time (to within a step)
        assert len(steps) * 1e-3 == pytest.approx(stop_time(dq0, a, j), abs=1.01e-3)


def test_a_command_changed_mid_ramp_still_reaches_its_target():
    cfg = BrakingConfig(0.0, (("J", 10.0),), (("J", 1000.0),))
    arm = ArmResponse(cfg, ["J"], 1e-3)
    for _ in range(30):
        arm(np.array([2.0]))  # accelerating towards 2 rad/s
    assert 0.0 < arm.dq[0] < 2.0 and arm.ddq[0] > 0.0
    out = [float(arm(np.array([0.5]))[0]) for _ in range(400)]  # now slow down to 0.5
    assert out[-1] == 0.5 and arm.ddq[0] == 0.0


def test_the_jerk_lag_bounds_every_jerk_limited_stop():
    """A stop found accelerating at +a towards V (the worst case: speed v with
    v + a²/(2j) ≤ V, or it would overshoot V) first brings its acceleration to 0 in a/j,
    travelling v a/j + a³/(3j²) and reaching v' = v + a²/(2j), then stops from v' in
    stop_time(v'), travelling v' T/2. That never lasts longer than τ + V/a nor travels
    farther than V τ + V²/(2a), τ = 2 a/j (jerk_lag_s). The simulated arm (which drops an
    acceleration away from its new target at once) stays within the bound too."""
    rng = np.random.default_rng(7)
    for _ in range(2000):
        a, j, big_v = rng.uniform(2.0, 20.0), rng.uniform(200.0, 5000.0), rng.uniform(0.01, 3.0)
        tau = 2 * a / j
        v = rng.uniform(0.0, max(big_v - a * a / (2 * j), 0.0))
        v_peak = v + a * a / (2 * j)
        if v_peak > big_v:
            continue
        rise_s, rise_m = a / j, v * a / j + a**3 / (3 * j * j)
        fall_s = stop_time([v_peak], [a], [j])
        assert rise_s + fall_s <= tau + big_v / a + 1e-12
        assert rise_m + v_peak * fall_s / 2 <= big_v * tau + big_v**2 / (2 * a) + 1e-12
    dt = 2e-4
    for _ in range(30):
        a, j, big_v = rng.uniform(2.0, 20.0), rng.uniform(200.0, 5000.0), rng.uniform(0.05, 3.0)
        tau = jerk_lag_s((("J", a),), (("J", j),))
        assert tau == pytest.approx(2 * a / j)
        arm = ArmResponse(BrakingConfig(0.0, (("J", a),), (("J", j),)), ["J"], dt)
        for _ in range(int(rng.uniform(0.0, 1.0) * (big_v / a + a / j) / dt)):
            arm(np.array([big_v]))  # stopped somewhere along the way to V
        moved, steps = 0.0, 0
        while arm.dq[0] > 0.0 and steps < 100000:
            moved += float(arm(np.zeros(1))[0]) * dt
            steps += 1
        assert steps * dt <= tau + big_v / a + dt
        assert moved <= big_v * tau + big_v**2 / (2 * a) + big_v * dt
    assert jerk_lag_s((("J", 10.0),), ()) == 0.0


def test_the_iiwa_s_arm_without_jerk_ramps_as_before():
    """No jerk limits: the velocity changes by a·dt a step, straight to the target."""
    arm = ArmResponse(BrakingConfig(0.0, (("J", 10.0),), ()), ["J"], 0.01)
    assert arm.j_max is None
    assert [float(arm(np.array([0.25]))[0]) for _ in range(4)] == [0.1, 0.2, 0.25, 0.25]


# --- speed and separation monitoring -----------------------------------------------------


def test_ssm_brakes_at_the_maker_s_stop_where_it_is_slower():
    """The UR5 table above: accelerations of 20 rad/s², the maker's stops slower on three
    joints. SSM takes the maker's there (its stop time from v is v/13.09, not v/20), and
    the acceleration limit elsewhere; the jerk of the base joint adds its lag to T_r."""
    arm = arm_of(UR5_ARM)
    cfg = SSMConfig(stop_time_s=0.06).resolve(arm)
    a = dict(cfg.max_acceleration_radps2)
    assert a["shoulder_pan_joint"] == pytest.approx(3.194 / 0.244)
    assert a["wrist_2_joint"] == 20.0
    assert cfg.reaction_time_s == pytest.approx(0.008 + 2 * 20.0 / 2000.0)
    limits = joint_speed_limits(cfg, UR5)
    assert limits[0] == pytest.approx(3.194 / 0.244 * 0.06) and limits[4] == 20.0 * 0.06
    budget = StopTimeBudget(cfg, UR5, 0.002)
    budget.record(np.array([0.5, 0, 0, 0, 0, 0.5]))  # the base's stop: 0.5 / 13.09 s
    assert budget.budget() == pytest.approx(0.5 * 0.244 / 3.194 + 0.002)
    # settings given explicitly are used as given
    mine = SSMConfig(reaction_time_s=0.01, max_acceleration_radps2=(("x", 1.0),)).resolve(arm)
    assert mine.reaction_time_s == 0.01 and mine.max_acceleration_radps2 == (("x", 1.0),)
