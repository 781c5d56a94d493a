"""Power and force limiting in the controllers and in the true-contact judge (issue 29).

Each pair's permitted contact speed against an independent computation (finite-difference
Jacobian, numpy's inverse of Pinocchio's mass matrix), the bounds of the head and trunk
untouched, the stop rules for them only, clamping, and the judge's speeds against finite
differences of the true distance.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import qpavoid
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.control.task import default_task
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.runs import simulate_one
from qpavoid.laws.pfl import PFLConfig, clampable, transient_speed_limit_mps
from qpavoid.loop.metrics import contact_metrics
from qpavoid.loop.truth import TrueClearance, TrueContact


def _controller(robot, safety, kind=qpavoid.QPController):
    return kind(robot, config=qpavoid.ControllerConfig(safety=safety, control_period_s=0.01))


def _start(robot):
    return inverse_kinematics(robot, default_task(robot).path.reference(0.0)[0])


def _hand_near(robot, q, set_name, gap_m, side="right"):
    """The seated operator, the ``side`` hand ``gap_m`` beyond the set's capsule surface,
    towards the operator (+y), at the capsule's middle."""
    op = default_task(robot).operator
    a, b = robot.capsules(q)[robot.set_index(set_name)]
    r = robot.capsule_radii[robot.set_index(set_name)]
    target = 0.5 * (a + b) + np.array([0.0, r + gap_m + 0.05, 0.0])  # hand radius 0.05
    return op.reach(op.rest(), side, target)


def _fd_jacobian(robot, q, s, u, eps=1e-7):
    """(3, nv) the Jacobian of the point at parameter u on set s's capsule axis, by central
    differences of the capsule ends (no Pinocchio Jacobian involved)."""
    out = np.zeros((3, robot.nv))
    for j in range(robot.nv):
        dq = np.zeros(robot.nv)
        dq[j] = eps
        pts = []
        for sign in (1.0, -1.0):
            a, b = robot.capsules(pin.integrate(robot.model, q, sign * dq))[s]
            pts.append(a + u * (b - a))
        out[:, j] = (pts[0] - pts[1]) / (2 * eps)
    return out


def test_a_hand_pair_may_approach_at_its_annex_a_speed_computed_independently(robot):
    q = _start(robot)
    joints = _hand_near(robot, q, "EE", 0.12)
    ctrl = _controller(robot, "pfl")
    stop_s = ctrl.stop_budget.budget()  # this tick's T_s (the first: one period)
    tick = ctrl.measure(q, joints, None, 0.0, frame_age_s=0.03)
    table = tick.table
    s, k = robot.set_index("EE"), table.part_names.index("right_hand")
    assert 0.05 < table.distance[s, k] < 0.2
    # independent: finite-difference Jacobian, numpy inverse of the mass matrix
    J = _fd_jacobian(robot, q, s, float(table.robot_s[s, k]))
    M = pin.crba(robot.model, robot.model.createData(), q)
    n = table.vector[s, k]
    m_r = 1.0 / (n @ J @ np.linalg.solve(M, J.T @ n))
    hand = PFLConfig().region("hand_finger")
    v_max = transient_speed_limit_mps(
        2.0 * 140.0, 75_000.0, 0.6, m_r
    )  # Table A.2 (× 2, transient) and A.3's hand row
    assert hand.transient_force_n == 280.0 and hand.spring_constant_n_per_m == 75_000.0
    # the stopping bound: (d - C - Z_d - Z_r + 280 N / 75 N/mm) / (T_r + T_s / 2)
    fixed = 0.02 + 0.03 + 0.005  # docs/safety.md §4's C, the Kinect v2's Z_d, Z_r
    assert ctrl.ssm.reaction_time_s == pytest.approx(0.02)  # 100 Hz: one period + 5 ms
    v_c = (table.distance[s, k] - fixed + 280.0 / 75_000.0) / (0.02 + stop_s / 2)
    expected = min(float(v_max), float(v_c))
    assert tick.contact_limit[s, k] == pytest.approx(expected, rel=1e-5)
    assert 0.5 < float(v_max) < 3.0
    assert tick.approach_limit[s, k] == pytest.approx(
        max(
            float(expected),
            float(
                _controller(robot, "ssm")
                .measure(q, joints, None, 0.0, frame_age_s=0.03)
                .approach_limit[s, k]
            ),
        ),
        rel=1e-5,
    )


def test_the_head_and_trunk_keep_their_speed_and_separation_bounds(robot, human):
    q = _start(robot)
    rng = np.random.default_rng(3)
    for _ in range(5):
        joints = _hand_near(robot, q, rng.choice(robot.set_names), rng.uniform(0.0, 0.3))
        ssm = _controller(robot, "ssm").measure(q, joints, None, 0.0, frame_age_s=0.03)
        pfl = _controller(robot, "pfl").measure(q, joints, None, 0.0, frame_age_s=0.03)
        protected = [human.part_names.index(p) for p in ("head", "trunk")]
        np.testing.assert_array_equal(
            pfl.approach_limit[:, protected], ssm.approach_limit[:, protected]
        )
        assert np.all(pfl.contact_limit[:, protected] == -np.inf)
        assert np.all(pfl.approach_limit >= ssm.approach_limit)
        np.testing.assert_array_equal(
            pfl.approach_limit, np.maximum(ssm.approach_limit, pfl.contact_limit)
        )


def test_the_paper_s_stop_rules_hold_for_the_head_and_trunk_only(robot):
    q = _start(robot)
    joints = _hand_near(robot, q, "EE", 0.01)  # inside the paper's 0.05 m stop distance
    assert _controller(robot, "ssm").measure(q, joints, None, 0.0, frame_age_s=0.03).reason
    assert not _controller(robot, "pfl").measure(q, joints, None, 0.0, frame_age_s=0.03).reason


@pytest.mark.parametrize("gap_m, sign", [(-0.02, -1), (0.04, -1), (0.15, 1)])
def test_a_part_seen_within_the_robot_s_stop_is_backed_off_from(robot, gap_m, sign):
    # the robot must stop within the hand's allowance (3.7 mm) of where it sees it, less
    # C + Z_d + Z_r (55 mm): touching, or a few cm away, it must back off; further, it may come
    q = _start(robot)
    joints = _hand_near(robot, q, "EE", gap_m)
    tick = _controller(robot, "pfl").measure(q, joints, None, 0.0, frame_age_s=0.03)
    s, k = robot.set_index("EE"), tick.table.part_names.index("right_hand")
    assert np.sign(tick.table.distance[s, k] - 0.055 + 0.0037) == sign
    assert np.sign(tick.contact_limit[s, k]) == sign


def test_clampable_by_hand():
    up, side = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    # a hand (r 0.05) lying on the table, touched from above: its far side is on the table
    assert clampable([0.0, 0.0, 0.10], up, 0.05, 0.0, 0.05)
    # lifted 0.04 m: still within the gap; 0.06 m: free to recoil
    assert clampable([0.0, 0.0, 0.14], up, 0.05, 0.0, 0.05)
    assert not clampable([0.0, 0.0, 0.16], up, 0.05, 0.0, 0.05)
    # touched from the side, or with no surface: never pinned
    assert not clampable([0.0, 0.0, 0.10], side, 0.05, 0.0, 0.05)
    assert not clampable([0.0, 0.0, 0.10], up, 0.05, None, 0.05)
    # at 60 degrees from the vertical (n_z = 0.5) the far side is h_z - 2 r n_z = h_z - 0.05
    # high, and the surface twice as far along the approach: pinned while h_z - 0.05 <= 0.025
    tilted = np.array([0.0, np.sin(np.pi / 3), 0.5])
    assert clampable([0.0, 0.0, 0.074], tilted, 0.05, 0.0, 0.05)
    assert not clampable([0.0, 0.0, 0.076], tilted, 0.05, 0.0, 0.05)


class _Still:
    """A person holding one pose."""

    def __init__(self, joints):
        self.joints = joints

    def frame_at(self, t):
        return self.joints, np.full(len(self.joints), 2, dtype=np.int8)


def test_the_judge_s_speed_is_the_true_distance_s_rate_of_change(robot, human):
    q = _start(robot)
    joints = _hand_near(robot, q, "L2", -0.005)
    truth = TrueClearance(robot, human, _Still(joints))
    s = robot.set_index("L2")
    rng = np.random.default_rng(0)
    checked = 0
    for _ in range(20):
        dq = rng.normal(0.0, 0.3, robot.nv)
        contacts = [c for c in truth.contacts(q, dq, 0.0) if c.set_name == "L2"]
        hand = [c for c in contacts if c.part == "right_hand"]
        if len(contacts) != 1 or not hand:
            continue
        (c,) = hand
        h = 1e-6
        rate = (
            truth(robot.kinematics(q + h * dq), 0.0)[s]
            - truth(robot.kinematics(q - h * dq), 0.0)[s]
        ) / (2 * h)
        assert c.speed_mps == pytest.approx(max(0.0, -rate), abs=1e-5)
        assert c.region == "hand_finger" and c.permitted and not c.clamped
        # F = v sqrt(mu k) and v_max = F_T / sqrt(mu k): F = v F_T / v_max (F_T 280 N)
        assert c.limit_mps > 1.0
        assert c.force_n == pytest.approx(c.speed_mps * 280.0 / c.limit_mps, rel=1e-9, abs=1e-12)
        checked += 1
    assert checked >= 10


def test_a_contact_names_its_person_by_id(robot, human):
    from qpavoid.loop.crowd import Crowd

    q = _start(robot)
    away, touching = _hand_near(robot, q, "L2", 0.4), _hand_near(robot, q, "L2", -0.005)
    crowd = Crowd({2: _Still(away), 5: _Still(touching)})  # the one touching comes second
    contacts = TrueClearance(robot, human, crowd).contacts(q, np.zeros(robot.nv), 0.0)
    assert contacts and {c.person for c in contacts} == {5}


def _contact(
    region="hand_finger", permitted=True, clamped=False, speed=0.1, limit=1.0, part="right_hand"
):
    allowance = 280.0 / 75_000.0 if permitted and not clamped else 0.0
    return TrueContact(
        0, "EE", part, region, permitted, clamped, -0.001, speed, limit, allowance, 75_000.0, 10.0
    )


def test_contact_metrics_by_hand():
    moving = np.array([True, False, False, True, True])
    contacts = {
        0: [_contact()],  # within
        1: [_contact(speed=1.2)],  # above
        2: [_contact("face", permitted=False, speed=0.0, limit=0.0, part="head")],  # at rest
        3: [
            _contact("chest", permitted=False, speed=0.0, limit=0.0, part="trunk"),
            _contact(speed=0.5),
        ],
        4: [_contact(clamped=True, speed=0.01, limit=0.0)],  # pushing a pinned hand
    }
    t = np.arange(5) * 0.5  # ticks far apart: each contact its own
    m = contact_metrics({k: contacts[k] for k in (0, 2, 4)}, moving, t)
    assert m["ticks_above_limit"] == 1 and m["ticks_within_limit"] == 1
    assert m["max_advance_m"] == pytest.approx(0.005)  # the crossing tick: 0.01 m/s × 0.5 s
    m = contact_metrics(contacts, moving, t)
    assert m["ticks_moving_protected"] == 1
    assert m["ticks_above_limit"] == 2 and m["ticks_within_limit"] == 2
    assert m["ticks_clamped"] == 1
    assert m["max_speed_mps"] == 1.2 and m["max_speed_ratio"] == 1.2
    assert m["by_region"] == {"chest": 1, "face": 1, "hand_finger": 4}
    assert contact_metrics({}, moving, t)["max_force_n"] is None
    # a robot that stops on the touch moved into it: the tick before counts too
    face = {1: [_contact("face", permitted=False, speed=0.0, limit=0.0, part="head")]}
    assert contact_metrics(face, np.array([True, False]), t[:2])["ticks_moving_protected"] == 1
    assert contact_metrics(face, np.array([False, False]), t[:2])["ticks_moving_protected"] == 0


def test_a_robot_that_keeps_advancing_into_a_hand_pushes_it_and_into_a_pinned_one_is_above():
    # 0.1 m/s into a hand, 10 ms ticks from the tick that crossed its surface: its
    # allowance 280 N / 75 N/mm = 3.73 mm (and the 0.5 mm tolerance) is used up after
    # 42 ms; the ticks after that (advance 5 mm and more) push a free hand along, and are
    # above the limit of a pinned one
    t = np.arange(11) * 0.01
    moving = np.ones(11, dtype=bool)
    m = contact_metrics({k: [_contact(speed=0.1)] for k in range(1, 11)}, moving, t)
    assert m["max_advance_m"] == pytest.approx(0.010)  # 1 mm a tick, the crossing one too
    assert m["ticks_pushed"] == 6 and m["ticks_within_limit"] == 10  # 5..10 mm
    assert m["ticks_above_limit"] == 0
    # backing off undoes it; a gap in the contact starts a new one
    back = {k: [_contact(speed=0.1 if k < 4 else -0.1)] for k in range(1, 11)}
    assert contact_metrics(back, moving, t)["ticks_pushed"] == 0
    gaps = {k: [_contact(speed=0.1)] for k in (1, 2, 3, 5, 6, 7, 9, 10)}
    assert contact_metrics(gaps, moving, t)["ticks_pushed"] == 0
    # a pinned hand: any approach beyond 1 mm/s is above, and so is any advance
    creep = {k: [_contact(clamped=True, speed=0.0005, limit=0.0)] for k in range(1, 11)}
    m = contact_metrics(creep, moving, t)  # 0.5 mm/s: 50 µm after 10 ticks, within
    assert m["ticks_above_limit"] == 0 and m["ticks_clamped"] == 10
    press = {
        k: [_contact(clamped=True, speed=0.1 if k == 1 else 0.0, limit=0.0)] for k in range(1, 11)
    }
    m = contact_metrics(press, moving, t)  # 1 mm in, then held: above from the first tick
    assert m["ticks_above_limit"] == 10
    assert m["ticks_pushed"] == 0  # a pinned part is not pushed along: it is above


@pytest.mark.slow  # two 10 s runs; the default suite has the bounds tick by tick
def test_pfl_moves_where_ssm_holds_and_touches_nothing_above_its_limit():
    out = {}
    for safety in ("ssm", "pfl"):
        spec = RunSpec(
            scenario="test1", controller="qp", safety=safety, rate_hz=100.0, max_time_s=10.0
        )
        out[safety] = simulate_one(spec).sim.metrics
    # the hand beside the path (from 3 s on) holds SSM's robot, not PFL's
    assert out["ssm"]["stopped_s"] > 1.0
    assert out["pfl"]["stopped_s"] < out["ssm"]["stopped_s"]
    contacts = out["pfl"]["true_contacts"]
    assert contacts["ticks_moving_protected"] == 0 and contacts["ticks_above_limit"] == 0


def _iiwa_without_inertias(folder):
    """The iiwa's description in ``folder`` with every link's mass zero."""
    import re
    import shutil
    from pathlib import Path

    src = Path(__file__).resolve().parents[1] / "robots" / "iiwa14"  # the source tree's
    for name in ("control_points.toml", "task.toml"):
        shutil.copy(src / name, folder / name)
    urdf = (src / "iiwa14.urdf").read_text()
    (folder / "iiwa14.urdf").write_text(re.sub(r'<mass value="[^"]*"', '<mass value="0"', urdf))
    return folder


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--payload", "14.5"], "payload"),  # the iiwa 14's rating: 14 kg
        (["--payload", "-1"], "--payload"),
        (["--payload", "nan"], "--payload"),
        (["--robot", "NOINERTIA"], "inerti"),
    ],
)
def test_pfl_refuses_bad_arms_and_payloads_in_one_line(tmp_path, monkeypatch, capsys, argv, words):
    from qpavoid.cli import main

    monkeypatch.chdir(tmp_path)
    if "NOINERTIA" in argv:
        (tmp_path / "arm").mkdir()
        argv = [
            str(_iiwa_without_inertias(tmp_path / "arm")) if a == "NOINERTIA" else a for a in argv
        ]
    try:
        code = main(["run", "test1", "--safety", "pfl", "--max-time", "1", "--out", "r", *argv])
    except SystemExit as exc:  # argparse's refusal of a flag's value
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("qpavoid: error:") and words in err
    assert not (tmp_path / "r").exists()


def test_a_body_region_missing_from_the_table_is_refused(robot):
    regions = tuple(r for r in PFLConfig().regions if r.name != "hand_finger")
    config = qpavoid.ControllerConfig(safety="pfl", pfl=PFLConfig(regions=regions))
    with pytest.raises(qpavoid.InputError, match="hand_finger") as info:
        qpavoid.QPController(robot, config=config)
    assert "\n" not in str(info.value)


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["qp", "analytic"])
def test_pfl_strikes_touch_no_head_nor_trunk_and_nothing_above_its_limit(controller):
    from qpavoid.experiments.sweep import strike_sweep
    from qpavoid.experiments.sweep_summary import summarize

    checks = strike_sweep(range(40), controller, "pfl", workers=2)
    summary = summarize(checks)
    contacts = summary["contacts"]
    assert contacts["runs_touching_protected_regions"] == 0
    assert contacts["runs_touching_above_limit"] == 0
    assert contacts["runs_clamping"] == 0
    assert summary["runs_with_limit_violations"] == 0
    assert summary["runs_with_command_limit_violations"] == 0
    assert contacts["runs_touching_within_limit"] > 0  # strikes do touch: the judge saw them


@pytest.mark.slow
def test_a_push_without_a_fault_is_the_camera_s_latency():
    """The one push of the 1000-strike campaigns without a sensor fault (Panda, QP, seed
    291: the right hand into link6 at 1.52 m/s) comes from the camera's latency: seen 60 ms
    late, the hand is 91 mm further on, inside link5, while the controller sees it 7 cm
    clear and deflects from it at up to 1.8 rad/s, the link's mesh moving into the hand
    where it really is. Seen 1 ms late, the same strike is stopped within the hand's
    allowance δ = F_T / k = 280 N / 75 N/mm = 3.73 mm (docs/safety.md §9)."""
    from qpavoid.experiments.sweep import SweepSpec, run_case

    runs = {
        latency: run_case(
            SweepSpec("strike", "qp", safety="pfl", robot="panda", latency_s=latency), 291
        )
        for latency in (None, 0.001)  # None: the Kinect v2's own, 60 ms
    }
    late, timely = runs[None], runs[0.001]
    assert late.fault == "none" and late.speed_mps == pytest.approx(1.5248, abs=1e-4)
    assert late.ticks_pushed > 0 and late.max_contact_advance_m > 280.0 / 75e3
    assert timely.ticks_pushed == 0 and timely.max_contact_advance_m < 280.0 / 75e3
    for run in runs.values():  # either way the touch is within the hand's limit
        assert run.ticks_contact_above_limit == 0 and run.ticks_moving_protected_contact == 0


@pytest.mark.slow
def test_pfl_works_within_reach_where_ssm_waits():
    from qpavoid.experiments.sweep import SweepSpec, sweep
    from qpavoid.experiments.sweep_summary import summarize

    out = {}
    for safety in ("ssm", "pfl"):
        out[safety] = summarize(
            sweep(SweepSpec("closework", "qp", safety=safety), range(12), workers=2)
        )
    assert out["pfl"]["fraction_reaching_goal"] >= 0.9
    assert out["pfl"]["mean_time_stopped_s"] < out["ssm"]["mean_time_stopped_s"]
    for variant, row in out["pfl"]["per_variant"].items():
        assert (
            row["mean_time_stopped_s"] <= out["ssm"]["per_variant"][variant]["mean_time_stopped_s"]
        )
    contacts = out["pfl"]["contacts"]
    assert contacts["runs_touching_protected_regions"] == 0
    assert contacts["runs_touching_above_limit"] == 0


@pytest.mark.parametrize("distance", ["capsules", "spheres"])
def test_a_hand_on_the_table_under_the_arm_may_not_be_approached(robot, distance):
    # the end effector lowered to 0.3 m over the table, the right hand flat on the table
    # under it: a press would pin the hand, so the pair's contact speed is at most 0, in
    # both distance methods (a sphere's witness point lies higher than the capsule's);
    # with no table (surface_z_m=None) the same pair may be approached
    pose = default_task(robot).path.reference(0.0)[0].copy()
    pose[2, 3] = 0.30
    q = inverse_kinematics(robot, pose)
    op = default_task(robot).operator
    ee = robot.end_effector(q)[:3, 3]
    joints = op.reach(op.rest(), "right", np.array([ee[0], ee[1], 0.05]))
    hand = np.array(joints)
    limits = {}
    for surface in (0.0, None):
        pfl = PFLConfig(surface_z_m=surface)
        config = qpavoid.ControllerConfig(
            safety="pfl", control_period_s=0.01, distance=distance, pfl=pfl
        )
        tick = qpavoid.QPController(robot, config=config).measure(
            q, hand, None, 0.0, frame_age_s=0.03
        )
        s, k = robot.set_index("EE"), tick.table.part_names.index("right_hand")
        assert tick.table.vector[s, k, 2] > 0.7  # the arm above the hand
        limits[surface] = tick.contact_limit[s, k]
    assert limits[0.0] <= 0.0 < limits[None]
