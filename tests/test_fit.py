"""Capsules fitted to point clouds and to a URDF's collision meshes (qpavoid.arm.fit).

The smallest capsule holds every point (brute force over random clouds), gives a sampled
capsule back, is never larger than the principal-axis capsule (computed here a second
way), shrinks to a sphere around a round cloud; its spheres cover it (sampled); a fitted
description of a URDF loads once its roles are named, and holds every collision vertex.
"""

from __future__ import annotations

import re
from importlib import metadata, resources
from pathlib import Path

import numpy as np
import pytest
from conftest import seeds

import qpavoid
from qpavoid.arm.coverage import coverage
from qpavoid.arm.fit import (
    capsule_volume,
    fit_capsule,
    fit_description,
    segment_distances,
    sphere_centres,
)
from qpavoid.arm.urdf import mesh_dirs
from qpavoid.cli.commands import main

IIWA_URDF = Path(str(resources.files("qpavoid.robots") / "iiwa14" / "iiwa14.urdf"))


def _rotation(rng: np.random.Generator) -> np.ndarray:
    """A random rotation (QR of a Gaussian matrix, signs fixed)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


def _capsule_surface(a, b, radius, n, rng) -> np.ndarray:
    """``n`` points on the surface of the capsule [a, b], r: on its cylinder and caps."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    u = (b - a) / np.linalg.norm(b - a)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    s = rng.uniform(-0.3, 1.3, n).clip(0.0, 1.0)  # some on the caps' centres' spheres
    centre = a + s[:, None] * (b - a)
    along = d @ u
    # on the cylinder part keep the direction across the axis only
    inner = (s > 0.0) & (s < 1.0)
    d[inner] -= along[inner, None] * u
    d[inner] /= np.linalg.norm(d[inner], axis=1)[:, None]
    # on a cap keep the outward half
    d[(s == 0.0) & (along > 0.0)] -= 2 * along[(s == 0.0) & (along > 0.0), None] * u
    d[(s == 1.0) & (along < 0.0)] -= 2 * along[(s == 1.0) & (along < 0.0), None] * u
    return centre + radius * d


def _principal_axis_capsule(points: np.ndarray) -> float:
    """Volume of the capsule on the cloud's first principal axis through its centroid,
    with the least radius r = max d_i and the shortest segment, checked to hold every
    point."""
    c = points.mean(axis=0)
    u = np.linalg.svd(points - c)[2][0]
    t = (points - c) @ u
    d = np.linalg.norm(points - c - t[:, None] * u, axis=1)
    r = d.max()
    h = np.sqrt(np.maximum(r * r - d * d, 0.0))
    ta, tb = (t + h).min(), (t - h).max()
    if ta > tb:
        ta = tb = 0.5 * (ta + tb)
    assert np.all(segment_distances(points, c + ta * u, c + tb * u) <= r + 1e-9)
    return capsule_volume(tb - ta, r)


CLOUDS = 12


@pytest.mark.parametrize("seed", seeds(CLOUDS, fast=3))  # every shape (seed % 3)
def test_every_point_lies_inside_and_the_fit_beats_the_principal_axis(seed):
    rng = np.random.default_rng(seed)
    shape = seed % 3
    n = int(rng.integers(8, 60))
    if shape == 0:  # an elongated Gaussian
        points = rng.normal(size=(n, 3)) * rng.uniform(0.02, 0.3, 3)
    elif shape == 1:  # a box
        points = rng.uniform(-1, 1, (n, 3)) * rng.uniform(0.02, 0.2, 3)
    else:  # two lumps (a link's two joint housings)
        points = np.concatenate(
            [rng.normal(size=(n, 3)) * 0.04, rng.normal(size=(n, 3)) * 0.03 + [0.2, 0.05, 0]]
        )
    points = points @ _rotation(rng).T + rng.uniform(-1, 1, 3)
    a, b, r = fit_capsule(points)
    assert np.all(segment_distances(points, a, b) <= r + 1e-9)
    fitted = capsule_volume(float(np.linalg.norm(b - a)), r)
    assert fitted <= _principal_axis_capsule(points) * (1 + 1e-6)


def test_segment_distances_against_a_dense_sampling_of_the_segment():
    rng = np.random.default_rng(5)
    a, b = rng.normal(size=3), rng.normal(size=3)
    points = rng.normal(size=(50, 3)) * 2
    along = a + np.linspace(0, 1, 200001)[:, None] * (b - a)
    brute = np.array([np.linalg.norm(along - p, axis=1).min() for p in points])
    np.testing.assert_allclose(segment_distances(points, a, b), brute, atol=1e-10)
    np.testing.assert_allclose(segment_distances(points, a, a), np.linalg.norm(points - a, axis=1))


@pytest.mark.parametrize("seed", seeds(4, fast=1))
def test_a_sampled_capsule_gives_back_its_own_capsule(seed):
    rng = np.random.default_rng(100 + seed)
    radius = rng.uniform(0.03, 0.09)
    length = rng.uniform(0.05, 0.4)
    a = rng.uniform(-0.5, 0.5, 3)
    u = _rotation(rng)[:, 0]
    b = a + length * u
    points = _capsule_surface(a, b, radius, 3000, rng)
    fa, fb, fr = fit_capsule(points)
    if (fb - fa) @ u < 0:  # the same segment either way round
        fa, fb = fb, fa
    # the samples lie on the surface: the fit can only be smaller, and barely
    assert fr == pytest.approx(radius, abs=2e-3)
    np.testing.assert_allclose(fa, a, atol=4e-3)
    np.testing.assert_allclose(fb, b, atol=4e-3)
    assert capsule_volume(np.linalg.norm(fb - fa), fr) <= capsule_volume(length, radius) * 1.001


def test_a_round_cloud_gives_a_short_capsule():
    # points on a sphere of 0.1 m (a Fibonacci lattice): the best capsule is the sphere
    n = 400
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5**0.5) * k
    points = 0.1 * np.stack(
        [np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], 1
    )
    points += [0.3, -0.2, 0.5]
    a, b, r = fit_capsule(points)
    assert np.linalg.norm(b - a) < 0.005
    assert r == pytest.approx(0.1, abs=2e-3)
    np.testing.assert_allclose(0.5 * (a + b), [0.3, -0.2, 0.5], atol=2e-3)


def test_degenerate_clouds():
    a, b, r = fit_capsule(np.array([[1.0, 2.0, 3.0]]))
    assert r == 0.0 and np.allclose(a, [1, 2, 3]) and np.allclose(b, [1, 2, 3])
    line = np.outer(np.linspace(0, 1, 20), [0.0, 0.0, 1.0])  # collinear: no 3-D hull
    a, b, r = fit_capsule(line)
    assert r < 1e-6 and np.all(segment_distances(line, a, b) <= r + 1e-9)
    assert abs(np.linalg.norm(b - a) - 1.0) < 1e-5
    with pytest.raises(ValueError, match="finite"):
        fit_capsule(np.array([[np.nan, 0.0, 0.0]]))


@pytest.mark.parametrize(
    "length, radius, per_radius", [(0.3, 0.07, 1.5), (0.01, 0.05, 1.5), (0.4, 0.06, 0.7)]
)
def test_the_spheres_cover_their_capsule(length, radius, per_radius):
    rng = np.random.default_rng(7)
    a = np.array([0.1, 0.2, 0.3])
    b = a + length * _rotation(rng)[:, 0]
    centres, big = sphere_centres(a, b, radius, per_radius)
    n = len(centres)
    spacing = length / (n - 1)
    assert spacing <= per_radius * radius + 1e-12
    assert big == pytest.approx(np.hypot(radius, spacing / 2))
    np.testing.assert_allclose(centres[[0, -1]], [a, b])
    # points of the capsule (its surface, the hardest) lie within R of some centre
    surface = _capsule_surface(a, b, radius, 20000, rng)
    gap = np.linalg.norm(surface[:, None] - centres[None], axis=2).min(axis=1)
    assert gap.max() <= big + 1e-12
    # and R is the least that does: the surface point across the axis midway between two
    # centres lies exactly R from both
    u = (b - a) / length
    across = np.cross(u, [1.0, 0.0, 0.0])
    across /= np.linalg.norm(across)
    mid = 0.5 * (centres[0] + centres[1]) + radius * across
    assert np.linalg.norm(mid - centres, axis=1).min() == pytest.approx(big)


def test_a_sphere_has_one_centre_of_its_own_radius():
    centres, big = sphere_centres(np.zeros(3), np.zeros(3), 0.05)
    assert centres.shape == (1, 3) and big == 0.05


def named(text: str, ee: str, roles: str) -> str:
    """A fitted file with its TO DO lines filled in, as its user would."""
    text = re.sub(r'end_effector = "TO DO[^"]*"', f'end_effector = "{ee}"', text)
    text = text[: text.index("[roles]")] + roles
    return text


def test_a_fitted_description_of_the_iiwa_urdf_loads_and_covers_every_vertex(tmp_path):
    text = fit_description(IIWA_URDF, str(IIWA_URDF))
    assert "TO DO" in text and text.count("[[sets]]") == 7  # link_1 .. link_7, not the base
    assert '"link_0_0" = "fixed to the base' in text
    roles = """[roles]
scaled = { set = "link_3", joints = ["A1", "A2"] }
repelled = { set = "link_5", joints = ["A1", "A2", "A4"] }
end_effector = { set = "link_7" }

[arm]
reaction_time_s = 0.005
max_acceleration_radps2 = { A1 = 8.0, A2 = 8.0, A3 = 8.0, A4 = 8.0, A5 = 8.0, A6 = 8.0, A7 = 8.0 }
max_point_speed_mps = 3.0

[coverage]
exclude = { "link_0_0" = "fixed to the base: it never moves" }
"""
    folder = tmp_path / "fitted"
    folder.mkdir()
    (folder / "control_points.toml").write_text(named(text, "flange", roles))
    robot = qpavoid.load_robot(folder)  # the coverage check at load time passes
    rows = [r for r in coverage(robot) if not r.excluded]
    assert rows and all(r.covered == r.vertices for r in rows)
    # Each link is one cylinder (radius rho, length H). By symmetry its best capsule runs
    # on its axis, its ends delta inside the rims: r² = rho² + delta², L = H − 2 delta,
    # V(delta) = pi r² L + 4/3 pi r³ minimised over delta in [0, H/2] (a second method).
    cylinders = {"link_2": (0.07, 0.2045), "link_3": (0.07, 0.2155), "link_4": (0.065, 0.1845)}
    cylinders |= {"link_5": (0.06, 0.2155), "link_6": (0.06, 0.081), "link_7": (0.045, 0.045)}
    radii = {s.name: s.capsule_radius_m for s in robot.sets}
    for name, (rho, height) in cylinders.items():
        delta = np.linspace(0.0, height / 2, 200001)
        r = np.sqrt(rho**2 + delta**2)
        best = r[np.argmin(np.pi * r**2 * (height - 2 * delta) + 4 / 3 * np.pi * r**3)]
        # the rims are 64-gons (within 0.12 % of rho inside), the file rounds up to 0.1 mm
        assert best - 0.0012 * rho - 1e-6 <= radii[name] <= best + 1.01e-4, name
    # link_7, as long as wide: the sphere through its rims (length 0)
    assert radii["link_7"] == pytest.approx(np.hypot(0.045, 0.0225), abs=1.1e-4)


ARMS = {
    "panda": (
        "example-robot-data",
        "cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf",
        ["panda_finger_joint1", "panda_finger_joint2"],
    ),
    "ur5": (
        "example-robot-data",
        "cmeel.prefix/share/example-robot-data/robots/ur_description/urdf/ur5_robot.urdf",
        ["ee_fixed_joint"],
    ),
    "fr3": ("franky-sim", "franky_sim/assets/fr3.urdf", ["fr3_finger_joint1", "fr3_finger_joint2"]),
}


def _installed(package: str) -> bool:
    try:
        metadata.distribution(package)
    except metadata.PackageNotFoundError:
        return False
    return True


@pytest.mark.slow
@pytest.mark.parametrize("arm", sorted(ARMS))
def test_a_fitted_description_of_each_shipped_urdf_covers_every_vertex(arm, tmp_path):
    """The bundled description's geometry is what `qpavoid robot fit` writes: both hold
    every vertex but the base's (a few seconds of fitting each)."""
    package, inner, merge = ARMS[arm]
    if not _installed(package):
        pytest.skip(f"{package} is not installed (the extra 'robots')")
    urdf = Path(str(metadata.distribution(package).locate_file(inner)))
    shipped = qpavoid.load_robot(arm)
    fingers = {j: 0.04 for j in merge if "finger" in j}  # open, as the shipped files
    text = fit_description(
        urdf, {"package": package, "path": inner}, mesh_dirs(urdf), merge, fingers
    )
    sets = text[text.index("[[sets]]") : text.index("# TO DO: which set")]
    folder = Path(str(shipped.path)).parent
    original = (folder / "control_points.toml").read_text()
    rest = original[original.index("\n# Which set") :]
    rest = re.sub(r"\nelbow = .*\n", "\n", rest)  # a point of the shipped sets
    folder = tmp_path / arm
    folder.mkdir()
    (folder / "control_points.toml").write_text(
        original[: original.index("[[sets]]")] + sets + rest
    )
    robot = qpavoid.load_robot(folder, coverage=False)
    rows = coverage(robot)
    for method in ("capsules", "spheres"):
        mine = [r for r in rows if r.method == method and not r.excluded]
        assert sum(r.covered for r in mine) == sum(r.vertices for r in mine)
    assert {r.object_name for r in rows if r.excluded} == set(shipped.coverage_exclude)


def test_robot_fit_writes_a_file_and_refuses_to_overwrite_it(tmp_path, capsys):
    out = tmp_path / "myarm"
    assert main(["robot", "fit", str(IIWA_URDF), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert f"wrote {out / 'control_points.toml'}: 7 set(s)" in said
    text = (out / "control_points.toml").read_text()
    assert f'urdf = "{IIWA_URDF.resolve()}"' in text
    assert main(["robot", "fit", str(IIWA_URDF), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "already holds control_points.toml" in err and "--force" in err
    assert main(["robot", "fit", str(tmp_path / "none.urdf"), "--out", str(out)]) == 2
    assert "no such file" in capsys.readouterr().err


@pytest.mark.slow
def test_a_joint_the_urdf_lacks_is_an_input_error(capsys, tmp_path):
    assert main(["robot", "fit", str(IIWA_URDF), "--out", str(tmp_path), "--lock", "A9=0.1"]) == 2
    err = capsys.readouterr().err
    assert "locked: ['A9'] are not joints of iiwa14.urdf" in err and err.count("\n") == 1
    assert main(["robot", "fit", str(IIWA_URDF), "--out", str(tmp_path), "--merge", "X"]) == 2
    assert "merge: ['X'] are not joints" in capsys.readouterr().err
