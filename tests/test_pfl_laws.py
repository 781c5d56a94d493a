"""Power and force limiting's laws (qpavoid.laws.pfl): ISO/TS 15066 Annex A's transient speed
limit and contact force by hand, the body-region table and its refusals, and the body model's
regions."""

from __future__ import annotations

import math
import pickle
from pathlib import Path

import numpy as np
import pytest

from qpavoid.core.errors import DataFileError, InputError, SkeletonFormatError
from qpavoid.human.body import KINECT_V2_BODY_FILE, BodyModel, KinectHuman
from qpavoid.human.kinect_v2 import KINECT_V2_FILE
from qpavoid.laws.pfl import (
    BODY_REGIONS,
    BODY_REGIONS_FILE,
    BodyRegion,
    PFLConfig,
    contact_force_n,
    load_regions,
    reduced_mass_kg,
    transient_speed_limit_mps,
)

REGIONS_TEXT = BODY_REGIONS_FILE.read_text()

# ISO/TS 15066 Annex A: (Table A.2 force N, Table A.3 k N/mm, m_H kg, contact), as
# qpavoid/laws/body_regions.toml cites them.
ANNEX_A = {
    "skull_forehead": (130.0, 150.0, 4.4, "none"),
    "face": (65.0, 75.0, 4.4, "none"),
    "neck": (150.0, 50.0, 1.2, "none"),
    "back_shoulders": (210.0, 35.0, 40.0, "none"),
    "chest": (140.0, 25.0, 40.0, "none"),
    "abdomen": (110.0, 10.0, 40.0, "none"),
    "pelvis": (180.0, 25.0, 40.0, "none"),
    "upper_arm_elbow": (150.0, 30.0, 3.0, "transient"),
    "lower_arm_wrist": (160.0, 40.0, 2.0, "transient"),
    "hand_finger": (140.0, 75.0, 0.6, "transient"),
    "thigh_knee": (220.0, 50.0, 75.0, "transient"),
    "lower_leg": (130.0, 60.0, 75.0, "transient"),
}


# -- the laws, by hand ---------------------------------------------------------------------


def test_the_hand_s_transient_speed_by_hand():
    # the hand: F_T = 2 x 140 N, k = 75 N/mm, m_H = 0.6 kg, against m_R = 5 kg
    mu = reduced_mass_kg(0.6, 5.0)
    assert mu == pytest.approx(0.6 * 5.0 / 5.6, rel=1e-12)  # 0.535714 kg
    assert mu == pytest.approx(0.535714, abs=1e-6)
    v = transient_speed_limit_mps(280.0, 75_000.0, 0.6, 5.0)
    # 280 / sqrt(0.535714 x 75000) = 280 / 200.446 = 1.39688 m/s
    assert v == pytest.approx(1.39688, abs=1e-5)
    assert contact_force_n(v, 75_000.0, 0.6, 5.0) == pytest.approx(280.0, rel=1e-12)


def test_an_arm_that_cannot_be_pushed_back_leaves_the_region_s_own_mass():
    # m_R = inf: mu = m_H, the smallest speed any arm may touch the region at
    assert reduced_mass_kg(0.6, np.inf) == 0.6
    v_inf = transient_speed_limit_mps(280.0, 75_000.0, 0.6, np.inf)
    assert v_inf == pytest.approx(280.0 / math.sqrt(0.6 * 75_000.0), rel=1e-12)  # 1.31993
    assert v_inf == pytest.approx(1.31993, abs=1e-5)
    masses = np.array([0.5, 1.0, 5.0, 50.0, 5e3, np.inf])
    v = transient_speed_limit_mps(280.0, 75_000.0, 0.6, masses)
    assert np.all(np.diff(v) < 0.0) and v[-1] == v_inf  # heavier arm, slower contact


def test_speed_and_force_are_inverse_element_wise_on_every_pair():
    rng = np.random.default_rng(3)
    force = rng.uniform(50.0, 500.0, (4, 8))
    k = rng.uniform(1e4, 1.5e5, 8)  # broadcast over the parts
    m_h = rng.uniform(0.5, 80.0, 8)
    m_r = np.where(rng.random((4, 8)) < 0.2, np.inf, rng.uniform(0.5, 30.0, (4, 8)))
    v = transient_speed_limit_mps(force, k, m_h, m_r)
    assert v.shape == (4, 8)
    np.testing.assert_allclose(contact_force_n(v, k, m_h, m_r), force, rtol=1e-12)
    # the energy balance itself: 1/2 mu v^2 = F^2 / (2k) (Annex A, A.1-A.2)
    mu = reduced_mass_kg(m_h, m_r)
    np.testing.assert_allclose(0.5 * mu * v**2, force**2 / (2.0 * k), rtol=1e-12)


def test_moving_apart_transfers_no_force_and_nan_stays_nan():
    f = contact_force_n([-1.0, 0.0, 0.5, np.nan], 75_000.0, 0.6, 5.0)
    assert f[0] == 0.0 and f[1] == 0.0 and f[2] > 0.0 and np.isnan(f[3])
    assert np.isnan(transient_speed_limit_mps(280.0, np.nan, np.nan, 5.0))
    assert np.isnan(transient_speed_limit_mps(280.0, 75_000.0, 0.6, np.nan))


def test_a_pinned_part_takes_the_robot_s_whole_energy():
    # a hand that cannot recoil, 0.5 m/s from 5 kg: μ = m_R, F = 0.5 √(5 × 75 000) = 306.19 N
    # (free: μ = 0.6 × 5 / 5.6 = 0.5357 kg, 100.2 N); an immovable point gives 0 N at rest
    f = contact_force_n(
        [0.5, 0.5, 0.0, 0.1],
        75_000.0,
        0.6,
        [5.0, 5.0, np.inf, np.inf],
        pinned=[True, False, True, True],
    )
    assert f[0] == pytest.approx(306.186218, rel=1e-8)
    assert f[1] == pytest.approx(100.222966, rel=1e-8)
    assert f[2] == 0.0 and f[3] == np.inf


@pytest.mark.parametrize(
    ("call", "name", "value"),
    [
        (lambda: reduced_mass_kg(0.0, 5.0), "m_h_kg", 0.0),
        (lambda: reduced_mass_kg(np.inf, 5.0), "m_h_kg", np.inf),
        (lambda: reduced_mass_kg(0.6, [5.0, -1.0]), "m_r_kg", -1.0),
        (lambda: transient_speed_limit_mps(-1.0, 75e3, 0.6, 5.0), "force_n", -1.0),
        (lambda: transient_speed_limit_mps(280.0, 0.0, 0.6, 5.0), "spring_n_per_m", 0.0),
        (lambda: contact_force_n(np.inf, 75e3, 0.6, 5.0), "speed_mps", np.inf),
        (lambda: contact_force_n(1.0, -75e3, 0.6, 5.0), "spring_n_per_m", -75e3),
    ],
)
def test_a_mass_or_spring_out_of_range_is_refused_with_the_argument(call, name, value):
    with pytest.raises(InputError) as err:
        call()
    assert err.value.name == name and "\n" not in str(err.value)
    assert str(value) in str(err.value)


# -- the body-region table ------------------------------------------------------------------


def test_the_table_holds_annex_a_as_cited():
    regions = load_regions()
    assert tuple(regions) == tuple(ANNEX_A) == tuple(r.name for r in BODY_REGIONS)
    for name, (force, k, m_h, contact) in ANNEX_A.items():
        r = regions[name]
        assert (r.max_force_n, r.spring_constant_n_per_mm, r.effective_mass_kg) == (force, k, m_h)
        assert r.contact == contact and r.transient_factor == 2.0
        assert r.spring_constant_n_per_m == 1000.0 * k and r.transient_force_n == 2.0 * force
        assert "ISO/TS 15066:2016 Table A.2" in r.source and "Table A.3" in r.source
    # the TS's own transferable energies (Table A.4) are E = (2 F)^2 / (2 k): its factor is 2
    energy = {
        n: r.transient_force_n**2 / (2.0 * r.spring_constant_n_per_m) for n, r in regions.items()
    }
    assert round(energy["upper_arm_elbow"], 1) == 1.5
    assert round(energy["lower_arm_wrist"], 1) == 1.3
    assert round(energy["chest"], 1) == 1.6
    assert round(energy["back_shoulders"], 1) == 2.5
    assert round(energy["face"], 2) == 0.11


def _refused(tmp_path: Path, text: str, match: str) -> DataFileError:
    path = tmp_path / "regions.toml"
    path.write_text(text)
    with pytest.raises(DataFileError, match=match) as err:
        load_regions(path)
    assert isinstance(err.value, InputError) and err.value.path == path
    assert str(err.value).startswith(f"{path}: ") and "\n" not in str(err.value)
    return err.value


def test_a_malformed_region_file_is_one_line_naming_the_file_and_the_key(tmp_path):
    hand = 'name = "hand_finger"'
    err = _refused(tmp_path, REGIONS_TEXT.replace(hand, hand + "\npressure = 3"), "unknown key")
    assert err.name == "regions[9].pressure"
    err = _refused(
        tmp_path,
        REGIONS_TEXT.replace("effective_mass_kg = 0.6\n", ""),
        r"region 'hand_finger': regions\[9\] is missing key\(s\) effective_mass_kg",
    )
    assert err.name == "regions[9].effective_mass_kg"
    err = _refused(
        tmp_path,
        REGIONS_TEXT.replace(
            "max_force_n = 140.0\ntransient_factor = 2.0\nspring_constant_n_per_mm = 75.0",
            "max_force_n = -140.0\ntransient_factor = 2.0\nspring_constant_n_per_mm = 75.0",
        ),
        "max_force_n must be a number above 0",
    )
    assert (err.name, err.value) == ("regions[9].max_force_n", -140.0)
    err = _refused(
        tmp_path,
        REGIONS_TEXT.replace(
            "spring_constant_n_per_mm = 75.0\neffective_mass_kg = 0.6",
            "spring_constant_n_per_mm = 75000.0\neffective_mass_kg = 0.6",
        ),
        r"regions\[9\].spring_constant_n_per_mm must be a number above 0 and at most 1000, N/mm, "
        r"got 75000.0 \(a unit error\?\)",
    )
    assert err.value == 75000.0
    err = _refused(
        tmp_path,
        REGIONS_TEXT.replace(
            'name = "face"\ntitle = "Face"\ncontact = "none"',
            'name = "face"\ntitle = "Face"\ncontact = "sometimes"',
        ),
        "contact must be one of 'transient', 'none'",
    )
    assert (err.name, err.value) == ("regions[1].contact", "sometimes")
    err = _refused(
        tmp_path, REGIONS_TEXT.replace('"face"', '"skull_forehead"', 1), "a second region"
    )
    err = _refused(
        tmp_path,
        REGIONS_TEXT.replace("effective_mass_kg = 0.6", 'effective_mass_kg = "0.6"'),
        "effective_mass_kg must be a number",
    )
    err = _refused(tmp_path, "limits = 3\n" + REGIONS_TEXT, r"unknown key\(s\) \['limits'\]")
    err = _refused(tmp_path, "regions = 3\n", "regions must be one or more")
    err = _refused(tmp_path, "[[regions]\n", "not TOML")
    with pytest.raises(DataFileError, match="cannot read the file"):
        load_regions(tmp_path / "absent.toml")


def test_a_region_checks_its_own_values():
    hand = load_regions()["hand_finger"]
    fields = {f: getattr(hand, f) for f in ("name", "title", "contact", "source")}
    numbers = {
        "max_force_n": 140.0,
        "transient_factor": 2.0,
        "spring_constant_n_per_mm": 75.0,
        "effective_mass_kg": 0.6,
    }
    assert BodyRegion(**fields, **numbers) == hand
    for key, bad in (
        ("transient_factor", 0.5),
        ("transient_factor", 2.5),  # beyond the TS's twice the quasi-static limit
        ("effective_mass_kg", math.nan),
        ("max_force_n", True),
    ):
        with pytest.raises(InputError) as err:
            BodyRegion(**fields, **{**numbers, key: bad})
        assert err.value.name == key
    with pytest.raises(InputError, match="snake_case"):
        BodyRegion(**{**fields, "name": "Hand"}, **numbers)


# -- the config and the body model's regions --------------------------------------------


def test_the_paper_s_parts_name_their_regions():
    human = KinectHuman()
    assert human.regions == (
        "face",
        "chest",
        "upper_arm_elbow",
        "lower_arm_wrist",
        "hand_finger",
        "upper_arm_elbow",
        "lower_arm_wrist",
        "hand_finger",
    )
    assert BodyModel.load(KINECT_V2_BODY_FILE).regions == human.regions
    assert human.n_points == 21 and len(human.parts) == 8  # the paper's model, unchanged


def test_part_limits_of_the_paper_s_parts():
    contact, force, spring, mass = PFLConfig().part_limits(KinectHuman().regions)
    np.testing.assert_array_equal(contact, [False, False, True, True, True, True, True, True])
    # head (face) and trunk (chest): no contact permitted, no force permissible
    np.testing.assert_array_equal(force, [0.0, 0.0, 300.0, 320.0, 280.0, 300.0, 320.0, 280.0])
    np.testing.assert_array_equal(spring, [75e3, 25e3, 30e3, 40e3, 75e3, 30e3, 40e3, 75e3])
    np.testing.assert_array_equal(mass, [4.4, 40.0, 3.0, 2.0, 0.6, 3.0, 2.0, 0.6])
    assert not force.flags.writeable
    # a part without a region: no contact, its spring and mass unknown
    contact, force, spring, mass = PFLConfig().part_limits(["hand_finger", None])
    assert contact.tolist() == [True, False] and force.tolist() == [280.0, 0.0]
    assert np.isnan(spring[1]) and np.isnan(mass[1])


def test_a_part_naming_a_region_the_table_lacks_is_refused():
    cfg = PFLConfig(regions=tuple(r for r in BODY_REGIONS if r.name != "hand_finger"))
    with pytest.raises(InputError, match="a body-region table entry missing") as err:
        cfg.part_limits(KinectHuman().regions)
    assert (err.value.name, err.value.value) == ("part_regions", "hand_finger")
    assert "part 4" in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(InputError, match="a body-region table entry missing"):
        cfg.region("hand_finger")
    with pytest.raises(InputError, match="a region's name or None"):
        PFLConfig().part_limits([3])


@pytest.mark.parametrize("payload", [-1.0, math.nan, math.inf, 2000.0, True, "2"])
def test_a_bad_payload_is_refused(payload):
    with pytest.raises(InputError) as err:
        PFLConfig(payload_kg=payload)
    assert err.value.name == "payload_kg" and err.value.value is payload


def test_a_config_is_complete_and_picklable(tmp_path):
    cfg = PFLConfig(payload_kg=2)
    assert cfg.payload_kg == 2.0 and cfg.regions == BODY_REGIONS
    assert pickle.loads(pickle.dumps(cfg)) == cfg
    path = tmp_path / "regions.toml"
    path.write_text(REGIONS_TEXT.replace("max_force_n = 140.0", "max_force_n = 135.0"))
    other = PFLConfig.from_file(path, payload_kg=1.0)
    assert other.region("hand_finger").transient_force_n == 270.0 and other != cfg
    with pytest.raises(InputError, match="two regions called 'face'"):
        PFLConfig(regions=(*BODY_REGIONS, BODY_REGIONS[1]))


def test_a_body_file_s_region_must_be_a_name(tmp_path):
    (tmp_path / "kinect_v2.toml").write_text(KINECT_V2_FILE.read_text())
    path = tmp_path / "kinect_v2_body.toml"
    body = KINECT_V2_BODY_FILE.read_text()
    path.write_text(body.replace('region = "face"', "region = 3"))
    with pytest.raises(
        SkeletonFormatError, match=r"part 'head': parts\[0\].region must name a body region"
    ):
        BodyModel.load(path)
    path.write_text(body.replace('region = "chest"\n', ""))  # optional: absent is None
    assert BodyModel.load(path).regions[:2] == ("face", None)
