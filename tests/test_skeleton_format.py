"""The skeleton format as data: the Kinect v2 file read right, and a wrong file refused with
an error naming the file, the key and the value."""

from __future__ import annotations

import fnmatch
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from qpavoid.core.errors import InputError
from qpavoid.human import kinect_v2
from qpavoid.human.camera_spec import BASES, EVIDENCED, Evidence
from qpavoid.human.kinect_v2 import KINECT_V2, KINECT_V2_FILE, JointType, TrackingState
from qpavoid.human.landmarks import FORMAT_NAMES
from qpavoid.human.skeleton import SkeletonFormat, SkeletonFormatError
from qpavoid.human.skeleton_file import FORMATS_DIR, MAX_FORMAT_FILE_BYTES
from qpavoid.sensing.calibration import known_formats

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

TEXT = KINECT_V2_FILE.read_text()
J = JointType


def test_the_kinect_v2_file_is_the_sdks_skeleton():
    assert KINECT_V2.name == "kinect_v2" and KINECT_V2.n_joints == 25
    assert KINECT_V2.joints == tuple(j.name for j in JointType)
    # parents by hand: the spine up, each arm out from SpineShoulder, the legs left out
    hand_parents = {
        J.SpineMid: J.SpineBase,
        J.SpineShoulder: J.SpineMid,
        J.Neck: J.SpineShoulder,
        J.Head: J.Neck,
        J.ShoulderLeft: J.SpineShoulder,
        J.ElbowLeft: J.ShoulderLeft,
        J.WristLeft: J.ElbowLeft,
        J.HandLeft: J.WristLeft,
        J.HandTipLeft: J.HandLeft,
        J.ThumbLeft: J.HandLeft,
        J.ShoulderRight: J.SpineShoulder,
        J.ElbowRight: J.ShoulderRight,
        J.WristRight: J.ElbowRight,
        J.HandRight: J.WristRight,
        J.HandTipRight: J.HandRight,
        J.ThumbRight: J.HandRight,
    }
    want = np.full(25, -1)
    for child, parent in hand_parents.items():
        want[child] = parent
    np.testing.assert_array_equal(KINECT_V2.parent, want)
    # the longest plausible bones: 25 % above adult segments (upper arm 0.40 ...)
    assert KINECT_V2.max_bone_m[J.ElbowRight] == 0.40 and KINECT_V2.max_bone_m[J.WristLeft] == 0.33
    assert KINECT_V2.max_bone_m[J.HandTipLeft] == 0.15 and KINECT_V2.max_bone_m[J.Neck] == 0.15
    assert (KINECT_V2.max_bone_m[KINECT_V2.parent < 0] == 0).all()
    assert (KINECT_V2.max_bone_m[KINECT_V2.parent >= 0] > 0).all()
    np.testing.assert_array_equal(
        KINECT_V2.torso_ids,
        [
            J.SpineBase,
            J.SpineMid,
            J.SpineShoulder,
            J.Neck,
            J.ShoulderLeft,
            J.ShoulderRight,
            J.HipLeft,
            J.HipRight,
        ],
    )
    sensor = KINECT_V2.sensor
    assert (sensor.latency_s, sensor.noise_m, sensor.tracked_uncertainty_m) == (0.06, 0.002, 0.03)
    assert sensor.range_m == (0.5, 4.5) and sensor.field_of_view_deg == (70.6, 60.0)
    assert (sensor.max_bodies, sensor.frame_rate_hz) == (6, 30.0)
    assert dict(KINECT_V2.tracking_states) == {
        s: int(v)
        for s, v in zip(("not_tracked", "inferred", "tracked"), TrackingState, strict=True)
    }


def test_the_mirror_is_the_left_right_swap_of_the_names():
    """Second method: swap Left and Right in the SDK's names."""
    names = list(KINECT_V2.joints)
    by_name = [
        names.index(re.sub("Left$|Right$", lambda m: {"Left": "Right"}.get(m[0], "Left"), n))
        for n in names
    ]
    np.testing.assert_array_equal(KINECT_V2.mirror, by_name)
    np.testing.assert_array_equal(KINECT_V2.mirror[KINECT_V2.mirror], np.arange(25))
    sided = [j for j, n in enumerate(names) if n.endswith(("Left", "Right"))]
    np.testing.assert_array_equal(KINECT_V2.sided, sided)
    # a swap maps the tree onto itself
    parent, mirror = KINECT_V2.parent, KINECT_V2.mirror
    for j in range(25):
        assert parent[mirror[j]] == (-1 if parent[j] < 0 else mirror[parent[j]])


def test_joints_by_role_and_by_name():
    arm = KINECT_V2.group("arm_right")
    assert list(arm) == ["shoulder", "elbow", "wrist", "hand", "hand_tip", "thumb"]
    assert arm["hand"] == J.HandRight and arm["thumb"] == J.ThumbRight
    assert KINECT_V2.group("spine")["chest"] == J.SpineShoulder
    assert KINECT_V2.group("leg_left") == {
        "hip": J.HipLeft,
        "knee": J.KneeLeft,
        "ankle": J.AnkleLeft,
        "foot": J.FootLeft,
    }
    KINECT_V2.group("arm_right")["hand"] = -1  # a copy: the format is not changed
    assert KINECT_V2.group("arm_right")["hand"] == J.HandRight
    assert KINECT_V2.index("WristLeft") == J.WristLeft
    np.testing.assert_array_equal(KINECT_V2.indices(["Head", "Neck"]), [J.Head, J.Neck])
    with pytest.raises(InputError, match="no joint group 'tail'") as err:
        KINECT_V2.group("tail")
    assert err.value.value == "tail"
    with pytest.raises(InputError, match="'Tail' is not a joint of the kinect_v2") as err:
        KINECT_V2.index("Tail")
    assert err.value.value == "Tail"


def test_the_derived_arrays_are_read_only_and_the_format_a_value():
    for name in ("parent", "mirror", "sided", "torso_ids", "max_bone_m"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(KINECT_V2, name)[0] = 1
    again = SkeletonFormat.load(KINECT_V2_FILE)
    assert again == KINECT_V2 and hash(again) == hash(KINECT_V2)


def test_the_sdk_enums_are_checked_against_the_file(tmp_path):
    kinect_v2.check_enums(KINECT_V2)
    swapped = TEXT.replace('name = "Neck"', 'name = "Nek"').replace('"Neck"', '"Nek"')
    other = load(tmp_path, swapped)
    with pytest.raises(SkeletonFormatError, match="at id 2 the file has 'Nek', the SDK 'Neck'"):
        kinect_v2.check_enums(other)


def load(tmp_path: Path, text: str) -> SkeletonFormat:
    path = tmp_path / "format.toml"
    path.write_text(text)
    return SkeletonFormat.load(path)


def refused(tmp_path: Path, text: str, match: str) -> SkeletonFormatError:
    """The error of loading ``text``: a SkeletonFormatError (an InputError) naming the file."""
    with pytest.raises(SkeletonFormatError, match=match) as err:
        load(tmp_path, text)
    assert isinstance(err.value, InputError)
    assert err.value.path == tmp_path / "format.toml"
    assert str(err.value).startswith(str(tmp_path / "format.toml"))
    return err.value


def test_a_missing_or_unknown_key_is_named(tmp_path):
    err = refused(
        tmp_path,
        re.sub(r"(?ms)^torso = \[.*?\]\n", "", TEXT),
        r"missing key\(s\) torso: torso must be an array of joint names",
    )
    assert err.name == "torso"
    err = refused(
        tmp_path,
        TEXT.replace("torso = [", "torsso = ["),
        r"the top level has unknown key\(s\) \['torsso'\]",
    )
    assert err.name == "torsso"
    err = refused(
        tmp_path, TEXT.replace("max_bodies = 6", ""), r"sensor is missing key\(s\) max_bodies"
    )
    err = refused(tmp_path, TEXT.replace("max_bone_m = 0.35 }", "max_bone = 0.35 }", 1), "max_bone")
    assert err.name == "joints[1].max_bone"


def test_joints_out_of_order_twice_named_or_with_unknown_parents_are_refused(tmp_path):
    err = refused(tmp_path, TEXT.replace("{ id = 3,", "{ id = 4,"), r"joints\[3\].id must be 3")
    assert (err.name, err.value) == ("joints[3].id", 4)
    err = refused(tmp_path, TEXT.replace('name = "KneeLeft"', 'name = "HipLeft"'), "used twice")
    assert err.value == "HipLeft"
    err = refused(
        tmp_path, TEXT.replace('parent = "ElbowLeft"', 'parent = "Elbow"'), "unknown joint 'Elbow'"
    )
    assert err.name == "joints[6].parent"


def test_a_cycle_of_parents_is_refused(tmp_path):
    text = TEXT.replace(
        '{ id = 0, name = "SpineBase" }', '{ id = 0, name = "SpineBase", parent = "SpineMid" }'
    )
    err = refused(tmp_path, text, "the parents of 'SpineBase' form a cycle")
    assert err.value == "SpineMid"


def test_bad_bone_bounds_are_refused(tmp_path):
    err = refused(
        tmp_path,
        TEXT.replace("max_bone_m = 0.40", "max_bone_m = -0.40", 1),
        "at least 0 and at most 2",
    )
    assert err.value == -0.40
    text = TEXT.replace(
        '{ id = 12, name = "HipLeft" }', '{ id = 12, name = "HipLeft", max_bone_m = 0.3 }'
    )
    refused(tmp_path, text, "'HipLeft' has a max_bone_m .* but no parent")
    # a left bone longer than its right one: the mirror would not map the tree onto itself
    text = TEXT.replace(
        'parent = "ShoulderLeft", max_bone_m = 0.40', 'parent = "ShoulderLeft", max_bone_m = 0.5'
    )
    err = refused(tmp_path, text, "do not mirror each other")
    assert set(err.value) == {"ElbowLeft", "ElbowRight"}


def test_bad_mirror_pairs_are_refused(tmp_path):
    text = TEXT.replace('["HipLeft", "HipRight"]', '["HipLeft", "KneeRight"]')
    refused(tmp_path, text, "'KneeRight' is in two pairs")
    refused(
        tmp_path, TEXT.replace('["FootLeft", "FootRight"]', '["FootLeft"]'), "must be two joints"
    )
    refused(tmp_path, TEXT.replace('["FootLeft", "FootRight"]', '["Foot", "FootRight"]'), "'Foot'")


def test_tracking_states_other_than_the_librarys_are_refused(tmp_path):
    err = refused(
        tmp_path, TEXT.replace("tracked = 2", "tracked = 3"), "translated by its streamer"
    )
    assert err.value == {"not_tracked": 0, "inferred": 1, "tracked": 3}


@pytest.mark.parametrize(
    ("line", "bad", "match"),
    [
        (
            "latency_s = 0.06",
            "latency_s = -0.06",
            "sensor.latency_s must be a number at least 0 and at most 1, s, got -0.06",
        ),
        ("range_m = [0.5, 4.5]", "range_m = [4.5, 0.5]", "near < far"),
        ("field_of_view_deg = [70.6, 60.0]", "field_of_view_deg = [70.6]", "two angles"),
        ("max_bodies = 6", "max_bodies = 0", "whole number from 1 to 100"),
        (
            "frame_rate_hz = 30.0",
            'frame_rate_hz = "30"',
            "sensor.frame_rate_hz must be a number at least 1 and at most 1000, Hz, got '30'",
        ),
    ],
)
def test_bad_sensor_numbers_are_refused(tmp_path, line, bad, match):
    assert line in TEXT
    refused(tmp_path, TEXT.replace(line, bad), match)


def test_an_unreadable_file_is_refused_with_its_path(tmp_path):
    refused(tmp_path, "joints = [", "not TOML")
    missing = tmp_path / "nowhere.toml"
    with pytest.raises(SkeletonFormatError, match="cannot read the file") as err:
        SkeletonFormat.load(missing)
    assert err.value.path == missing
    refused(tmp_path, "#" * (MAX_FORMAT_FILE_BYTES + 1), "cannot read the file: .* bytes")


def test_every_format_file_ships_in_the_wheel():
    """pyproject's package-data covers each file of qpavoid/human/formats (the wheel test
    checks the modules; these are data)."""
    pyproject = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    globs = pyproject["tool"]["setuptools"]["package-data"]["qpavoid.human"]
    files = sorted(FORMATS_DIR.iterdir())
    assert [f.name for f in files if f.suffix == ".toml"] == [
        "k4abt.toml",
        "k4abt_body.toml",
        "kinect_v2.toml",
        "kinect_v2_body.toml",
        "mediapipe_pose.toml",
        "mediapipe_pose_body.toml",
        "zed_body_34.toml",
        "zed_body_34_body.toml",
        "zed_body_38.toml",
        "zed_body_38_body.toml",
    ]
    for f in files:
        assert any(fnmatch.fnmatch(f"formats/{f.name}", g) for g in globs), f.name
    assert "qpavoid.human" in pyproject["tool"]["setuptools"]["packages"]


# --- [sensor.evidence]: how each number was obtained (issue 41) ---

LATENCY_EVIDENCE = re.compile(r"^latency_s = \{ basis = .*$", re.M)


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ('latency_s = { basis = "measured" }', "a measured number needs its source"),
        ('latency_s = { basis = "vendor", source = "  " }', "a vendor number needs its source"),
        ('latency_s = { basis = "estimate" }', "an estimate needs its note"),
        ('latency_s = { basis = "guess", note = "x" }', r"basis must be one of \['measured'"),
        (
            'latency_s = { basis = "measured", source = 3 }',
            r"sensor.evidence.latency_s.source must be text, got 3",
        ),
        ('latency_s = { basis = "measured", source = "a", doi = "b" }', "unknown key"),
        ("latency_s = 0.06", "sensor.evidence.latency_s must be a table { basis, source, note }"),
        ('latency = { basis = "estimate", note = "x" }', "latency names no number"),
        ("", "sensor.evidence.latency_s is missing"),
    ],
)
def test_a_number_without_its_evidence_is_refused(tmp_path, line, match):
    assert LATENCY_EVIDENCE.search(TEXT)
    refused(tmp_path, LATENCY_EVIDENCE.sub(line, TEXT), match)


def test_a_measured_number_with_its_source_is_taken(tmp_path):
    line = 'latency_s = { basis = "measured", source = "Doe 2030, Sensors 1(1) 1" }'
    fmt = load(tmp_path, LATENCY_EVIDENCE.sub(line, TEXT))
    assert fmt.sensor.basis("latency_s") == Evidence("measured", "Doe 2030, Sensors 1(1) 1")


@pytest.mark.parametrize("name", FORMAT_NAMES)
def test_every_shipped_camera_says_how_its_safety_numbers_were_obtained(name):
    sensor = known_formats()[name].sensor
    for key in EVIDENCED:
        evidence = sensor.basis(key)
        assert evidence.basis in BASES
        assert evidence.source if evidence.basis != "estimate" else evidence.note
