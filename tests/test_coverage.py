"""Coverage: every collision-mesh vertex inside the capsules and the spheres (qpavoid.arm.coverage).

The distances are checked against a dense sampling of the capsules' axes; the shipped arms
hold every vertex but their bases'; the iiwa's exceptions are measured to the hand-worked
millimetre; a description whose capsule or sphere no longer holds its link is refused at
load time in one line naming the file, the object and the fix.
"""

from __future__ import annotations

import re
import shutil
from importlib import metadata, resources
from pathlib import Path

import numpy as np
import pytest

import qpavoid
from qpavoid.arm.coverage import (
    _segment_excess,
    _sphere_excess,
    configurations,
    coverage,
    coverage_table,
)
from qpavoid.cli.commands import main
from qpavoid.core.errors import RobotDescriptionError

#: The shipped arms beside the iiwa, the package their URDF comes from, their base object.
ARMS = {
    "panda": ("example-robot-data", "panda_link0_0"),
    "ur5": ("example-robot-data", "base_link_0"),
    "fr3": ("franky-sim", "fr3_link0_0"),
}


def _installed(package: str) -> bool:
    try:
        metadata.distribution(package)
    except metadata.PackageNotFoundError:
        return False
    return True


def _copy(name: str, folder: Path, edit) -> Path:
    """A bundled description copied into ``folder`` (its URDF beside it if it has one),
    its control-point file passed through ``edit``."""
    src = resources.files("qpavoid.robots") / name
    folder.mkdir(parents=True)
    for item in src.iterdir():
        if item.is_file():
            shutil.copy(str(item), folder / item.name)
    path = folder / "control_points.toml"
    path.write_text(edit(path.read_text()))
    return folder


def test_the_excess_is_the_distance_to_the_nearest_surface():
    """Against a dense sampling of the axes (a second method), over random cases."""
    rng = np.random.default_rng(3)
    vertices = rng.uniform(-0.5, 0.5, (60, 3))
    segments = rng.uniform(-0.5, 0.5, (4, 2, 3))
    segments[3, 1] = segments[3, 0]  # a sphere-like capsule of length 0
    radii = rng.uniform(0.02, 0.1, 4)
    s = np.linspace(0.0, 1.0, 20001)
    brute = np.full(len(vertices), np.inf)
    for (a, b), r in zip(segments, radii, strict=True):
        along = a + s[:, None] * (b - a)
        gap = np.linalg.norm(vertices[:, None] - along[None], axis=2).min(axis=1) - r
        brute = np.minimum(brute, gap)
    # the samples are 5e-5 of an axis apart: the nearest lies within 2.5e-5 of the
    # closest point, off by at most (2.5e-5 · 0.7 m)² / (2 · 1 mm) ≈ 1.5e-7 m
    np.testing.assert_allclose(_segment_excess(vertices, segments, radii), brute, atol=2e-7)
    centres, big = segments[:, 0], radii + 0.01
    expected = (np.linalg.norm(vertices[:, None] - centres[None], axis=2) - big).min(axis=1)
    np.testing.assert_allclose(_sphere_excess(vertices, centres, big), expected, atol=1e-15)


def test_the_configurations_are_fixed_and_within_the_limits(robot):
    qs = configurations(robot)
    assert len(qs) == 4 and np.all(qs[0] == 0.0)
    for q in qs[1:]:
        assert np.all((robot.q_min <= q) & (q <= robot.q_max))
    np.testing.assert_array_equal(np.array(qs), np.array(configurations(robot)))


def test_the_iiwa_leaves_out_its_base_link_1_and_the_shoulder_rim_as_measured(robot):
    rows = {(r.object_name, r.method): r for r in coverage(robot)}
    excluded = {r.object_name for r in rows.values() if r.excluded}
    assert excluded == {"link_0_0", "link_1_0", "link_2_0"}
    for r in rows.values():
        if not r.excluded:
            assert r.covered == r.vertices and r.worst_excess_m <= 1e-6, r
    # link_1 (A1 to A2, r 0.07): its bottom rim, 0.2025 m below A2 and 0.07 m off the
    # axis, is sqrt(0.07² + 0.2025²) − 0.07 outside the L1 capsule (which starts at A2)
    worst = rows["link_1_0", "capsules"].worst_excess_m
    assert worst == pytest.approx(np.hypot(0.07, 0.2025) - 0.07, abs=1e-12)
    assert rows["link_1_0", "capsules"].covered == rows["link_1_0", "capsules"].vertices // 2
    # link_2 (A2 to A3): inside the capsules; its rim at A2 is sqrt(0.07² + 0.10225²) from
    # the first sphere centre mid(A2, A3), of radius 0.09
    assert rows["link_2_0", "capsules"].covered == rows["link_2_0", "capsules"].vertices
    worst = rows["link_2_0", "spheres"].worst_excess_m
    assert worst == pytest.approx(np.hypot(0.07, 0.2045 / 2) - 0.09, abs=1e-12)


@pytest.mark.parametrize("arm", sorted(ARMS))
def test_the_shipped_arms_hold_every_vertex_but_their_base(arm):
    package, base = ARMS[arm]
    if not _installed(package):
        pytest.skip(f"{package} is not installed (the extra 'robots')")
    for locked in (None, ()):  # the paper's mode and the redundant one
        robot = qpavoid.load_robot(arm, locked=locked)
        rows = coverage(robot)
        assert {r.object_name for r in rows if r.excluded} == {base}
        for method in ("capsules", "spheres"):
            mine = [r for r in rows if r.method == method and not r.excluded]
            assert len(mine) == len({r.object_name for r in rows}) - 1
            assert all(r.covered == r.vertices for r in mine), method
        assert "fixed to the table" in robot.coverage_exclude[base]


@pytest.mark.parametrize("arm", ["panda", "fr3"])
def test_the_hand_capsule_fitted_open_holds_the_fingers_closed(arm, tmp_path):
    """The fingers are held open (0.04 m); closed, they lie between the open ones, inside
    the same convex capsule: the copy holding them closed loads (the check passes)."""
    if not _installed(ARMS[arm][0]):
        pytest.skip("the extra 'robots' is not installed")
    folder = _copy(
        arm, tmp_path / arm, lambda t: t.replace("finger_joint1 = 0.04", "finger_joint1 = 0.0")
    )
    robot = qpavoid.load_robot(folder)
    assert robot.locked[f"{arm}_finger_joint1"] == 0.0
    hand = [r for r in coverage(robot) if "finger" in r.object_name]
    assert hand and all(r.covered == r.vertices for r in hand)


def _one_line_refusal(folder: Path) -> RobotDescriptionError:
    with pytest.raises(RobotDescriptionError) as info:
        qpavoid.load_robot(folder)
    message = str(info.value)
    assert "\n" not in message
    assert str(folder / "control_points.toml") in message
    assert info.value.path == folder / "control_points.toml"
    return info.value


def test_a_shrunk_capsule_is_refused_at_load_time_naming_the_object_and_the_fix(tmp_path):
    # L2's capsule from 0.065 to 0.05 m: link_4 (A4 to A5, r 0.065) sticks out 15 mm
    folder = _copy(
        "iiwa14",
        tmp_path / "arm",
        lambda t: t.replace("capsule_radius_m = 0.065", "capsule_radius_m = 0.05"),
    )
    error = _one_line_refusal(folder)
    message = str(error)
    assert "collision object 'link_4_0' of iiwa14.urdf is not inside the capsules" in message
    assert "the worst by 15.00 mm" in message
    assert "qpavoid robot fit" in message and "larger capsule_radius_m" in message
    assert '[coverage] exclude = { link_4_0 = "<why>" }' in message
    assert error.name == "coverage.link_4_0"
    assert error.value == pytest.approx(0.015, abs=1e-12)


def test_a_shrunk_sphere_is_refused_naming_the_sphere_radius(tmp_path):
    def edit(text: str) -> str:
        return text.replace("sphere_radius_m = 0.09", "sphere_radius_m = 0.07")

    error = _one_line_refusal(_copy("iiwa14", tmp_path / "arm", edit))
    assert "is not inside the spheres" in str(error) and "sphere_radius_m" in str(error)


@pytest.mark.parametrize(
    "exclude, name, fix",
    [
        (
            '{ link_9_0 = "none" }',
            "coverage.exclude",
            "['link_9_0'], which are not collision objects",
        ),
        (
            '{ link_0_0 = "" }',
            "coverage.exclude",
            "must map each collision object it leaves out to the reason",
        ),
        ('["link_0_0"]', "coverage.exclude", "must map each collision object"),
    ],
)
def test_an_exclusion_needs_an_object_of_the_urdf_and_a_reason(tmp_path, exclude, name, fix):
    def edit(text: str) -> str:
        return re.sub(r"\nexclude = .*\n", f"\nexclude = {exclude}\n", text)

    error = _one_line_refusal(_copy("iiwa14", tmp_path / "arm", edit))
    assert error.name == name and fix in str(error)


def test_a_description_without_the_exclusions_is_refused_for_the_worst_object(tmp_path):
    def edit(text: str) -> str:
        return re.sub(r"\n\[coverage\]\nexclude = .*\n", "\n", text)

    error = _one_line_refusal(_copy("iiwa14", tmp_path / "arm", edit))
    # the worst: the base's bottom rim (0.11 m off the axis) from the first sphere centre
    # mid(A2, A3), 0.36 + 0.10225 m above it, of radius 0.09
    assert error.name == "coverage.link_0_0" and "not inside the spheres" in str(error)
    assert error.value == pytest.approx(np.hypot(0.11, 0.36 + 0.2045 / 2) - 0.09, abs=1e-12)


def test_the_table_and_robot_check(robot, capsys, tmp_path):
    table = coverage_table(coverage(robot))
    assert table.splitlines()[0].split()[:5] == ["object", "method", "checked", "covered", "worst"]
    assert "capsules: 3328 of 4096 vertex checks inside (81.25 %), 3 object(s) excluded" in table
    assert main(["robot", "check", "iiwa14"]) == 0
    out = capsys.readouterr().out
    assert "link_1_0  capsules" in out and out.strip().endswith("inside the spheres")
    folder = _copy(
        "iiwa14",
        tmp_path / "arm",
        lambda t: t.replace("capsule_radius_m = 0.065", "capsule_radius_m = 0.05"),
    )
    assert main(["robot", "check", str(folder)]) == 2
    captured = capsys.readouterr()
    assert "link_4_0  capsules" in captured.out  # the table first
    assert captured.err.count("\n") == 1 and "'link_4_0'" in captured.err
