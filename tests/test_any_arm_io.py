"""Any arm on every command: URDFs from installed packages, ``--robot`` everywhere, a
missing extra named in one line, the truth against the arm's collision meshes."""

from __future__ import annotations

import importlib.metadata
import re
import shutil
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest

from qpavoid.arm.description import description_reference
from qpavoid.arm.meshes import collision_geometry, object_vertices
from qpavoid.arm.model import load_robot
from qpavoid.arm.urdf import package_entry
from qpavoid.cli.commands import build_parser, main
from qpavoid.core.errors import RobotDescriptionError
from qpavoid.human.body import HumanGeometry, KinectHuman
from qpavoid.loop.truth import MeshClearance

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
PANDA_URDF = "cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf"


def _has(package: str) -> bool:
    try:
        importlib.metadata.distribution(package)
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


needs_erd = pytest.mark.skipif(
    not _has("example-robot-data"), reason="the extra 'robots' (example-robot-data) is missing"
)


def _iiwa_with_urdf(tmp_path: Path, urdf_line: str) -> Path:
    """The iiwa's description in ``tmp_path`` with its ``urdf`` line replaced."""
    text = (ROBOTS / "iiwa14" / "control_points.toml").read_text()
    lines = [urdf_line if ln.startswith("urdf = ") else ln for ln in text.splitlines()]
    (tmp_path / "control_points.toml").write_text("\n".join(lines) + "\n")
    return tmp_path


def test_a_urdf_from_an_installed_package_is_found_through_its_metadata(tmp_path):
    # the iiwa's own URDF, named as a file of a (fake) distribution found by importlib
    folder = _iiwa_with_urdf(tmp_path, 'urdf = { package = "qpavoid", path = "x/iiwa14.urdf" }')

    class Dist:
        def locate_file(self, inner: str) -> Path:
            assert inner == "x/iiwa14.urdf"
            return ROBOTS / "iiwa14" / "iiwa14.urdf"

    original = importlib.metadata.distribution
    try:
        importlib.metadata.distribution = lambda name: Dist()  # type: ignore[assignment]
        robot = load_robot(folder)
    finally:
        importlib.metadata.distribution = original
    iiwa = load_robot("iiwa14")
    assert robot.urdf == ROBOTS / "iiwa14" / "iiwa14.urdf"
    q = np.linspace(-0.5, 0.5, iiwa.nq)
    np.testing.assert_array_equal(robot.control_points(q), iiwa.control_points(q))


@pytest.mark.parametrize(
    "package, hint",
    [
        ("example-robot-data", 'pip install "qpavoid[robots]"'),
        ("no-such-package-qpavoid", "pip install no-such-package-qpavoid"),
    ],
)
def test_a_missing_package_is_one_line_naming_the_extra(tmp_path, monkeypatch, package, hint):
    folder = _iiwa_with_urdf(tmp_path, f'urdf = {{ package = "{package}", path = "a.urdf" }}')

    def missing(name: str) -> object:
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "distribution", missing)
    with pytest.raises(RobotDescriptionError) as err:
        load_robot(folder)
    message = str(err.value)
    assert hint in message and package in message and "\n" not in message
    assert err.value.name == "urdf.package"


@pytest.mark.parametrize(
    "bad", ['{ package = "x" }', '{ package = "x", path = "a", extra = 1 }', "3"]
)
def test_a_malformed_urdf_key_is_refused(tmp_path, bad):
    folder = _iiwa_with_urdf(tmp_path, f"urdf = {bad}")
    with pytest.raises(RobotDescriptionError) as err:
        load_robot(folder)
    assert "urdf" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "free", "--robot", "panda"],
        ["compare", "--robot", "panda"],
        ["sweep", "--n", "1", "--controller", "qp", "--out", "x", "--robot", "panda"],
        ["bench", "--robot", "panda"],
    ],
)
def test_every_command_that_runs_an_arm_takes_robot(argv):
    assert build_parser().parse_args(argv).robot == "panda"


def test_an_unknown_robot_is_one_line(tmp_path, capsys):
    out = tmp_path / "x"
    assert main(["run", "free", "--robot", "no_such_arm", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "no_such_arm" in err and "iiwa14" in err and err.count("\n") == 1
    assert not out.exists()


def test_the_iiwa_collision_objects_follow_its_reduced_model():
    # A3 locked: link 3's cylinder rides on A2's body; its world placement equals the
    # one of the full model at the same angles (A3 = 0)
    robot = load_robot("iiwa14")
    geometry = collision_geometry(robot)
    full = pin.buildModelFromUrdf(str(robot.urdf))
    full_geometry = pin.buildGeomFromUrdf(full, str(robot.urdf), pin.GeometryType.COLLISION)
    rng = np.random.default_rng(3)
    q = rng.uniform(robot.q_min, robot.q_max)
    q_full = np.array([robot.full_configuration(q)[str(full.names[j])] for j in range(1, 8)])
    data, full_data = robot.model.createData(), full.createData()
    gdata = geometry.createData()
    pin.updateGeometryPlacements(robot.model, data, geometry, gdata, q)
    fdata = full_geometry.createData()
    pin.updateGeometryPlacements(full, full_data, full_geometry, fdata, q_full)
    assert len(geometry.geometryObjects) == len(full_geometry.geometryObjects) == 8
    for k in range(8):
        np.testing.assert_allclose(gdata.oMg[k].homogeneous, fdata.oMg[k].homogeneous, atol=1e-12)
    # a cylinder's sample points lie on its rims: radius and half length of the URDF
    link2 = geometry.geometryObjects[2]
    pts = object_vertices(link2) - link2.placement.translation
    axial = pts @ link2.placement.rotation[:, 2]
    radial = np.linalg.norm(pts - np.outer(axial, link2.placement.rotation[:, 2]), axis=1)
    np.testing.assert_allclose(radial, link2.geometry.radius, atol=1e-12)
    np.testing.assert_allclose(np.abs(axial), link2.geometry.halfLength, atol=1e-12)


def test_the_iiwa_truth_stays_its_capsules():
    # its URDF has cylinders, not meshes: the truth is the capsules', bit for bit
    robot = load_robot("iiwa14")
    clearance = MeshClearance(robot, KinectHuman())
    assert not clearance.has_mesh
    capsule = np.array([0.01, -0.02, 0.3])
    assert clearance(robot.neutral(), capsule, None) is capsule  # type: ignore[arg-type]


@needs_erd
def test_a_capsule_that_misses_part_of_the_arm_shows_up_as_contact():
    """On the Panda, capsule distances that say 5 cm (a capsule missing part of a link
    would): a person touching the link's mesh is in contact for the truth all the same."""
    robot = load_robot("panda")
    human = KinectHuman()
    clearance = MeshClearance(robot, human)
    assert clearance.has_mesh and np.all(clearance.excess <= 1e-6)  # covered
    q = 0.5 * (robot.q_min + robot.q_max)
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    k = next(
        i for i, o in enumerate(clearance.objects) if isinstance(o.geometry, coal.BVHModelBase)
    )
    obj = clearance.objects[k]
    M = data.oMi[obj.parentJoint]
    world = object_vertices(obj) @ M.rotation.T + M.translation
    centre = world.mean(axis=0)
    outer = world[np.argmax(np.linalg.norm(world - centre, axis=1))]
    # one part of the person: a capsule whose surface touches that outermost vertex
    radius = float(human.capsule_radii[0])
    out = (outer - centre) / np.linalg.norm(outer - centre)
    n_parts = len(human.capsule_radii)
    segments = np.full((n_parts, 2, 3), np.nan)
    segments[0] = [outer + (radius - 1e-3) * out, outer + (radius + 0.1) * out]
    valid = np.zeros(n_parts, dtype=bool)
    valid[0] = True
    geo = HumanGeometry(
        np.zeros((0, 3)),
        np.zeros(0, dtype=bool),
        segments,
        valid,
        np.zeros(n_parts),
        np.zeros(n_parts),
    )
    s = int(np.flatnonzero(clearance.on_set[:, k])[0])
    far = np.full(len(robot.sets), 0.05)  # what shrunk capsules would report: a gap
    truth = clearance(q, far, geo)
    assert truth[s] <= 0.0 < far[s]
    # capsules (which contain the meshes) beyond the margin: their distances, a lower
    # bound of the meshes', are the answer and no mesh is measured
    beyond = np.full(len(robot.sets), clearance.margin_m + 0.01)
    assert clearance(q, beyond, geo) is beyond


# ----------------------------------------------------------------- the adversary's findings


def _copy(src: str, dst: Path, edit) -> Path:
    """A copy of the bundled description ``src`` in ``dst``, its file passed through ``edit``
    (a URDF beside it is copied too)."""
    shutil.copytree(ROBOTS / src, dst)
    file = dst / "control_points.toml"
    file.write_text(edit(file.read_text()))
    return dst


@needs_erd
def test_a_moving_link_cannot_be_excluded_from_the_capsules(tmp_path):
    """The Panda's forearm excluded 'because x' and its capsule shrunk to 1 cm: refused, as
    the controller would be blind to it; the base's exclusion stays allowed."""

    def edit(text: str) -> str:
        text = text.replace(
            "exclude = { panda_link0_0 = ", 'exclude = { panda_link5_0 = "x", panda_link0_0 = '
        )
        start = text.index('name = "link5"')
        end = text.index("[[sets]]", start)
        return (
            text[:start]
            + re.sub(r"capsule_radius_m = [0-9.]+", "capsule_radius_m = 0.01", text[start:end])
            + text[end:]
        )

    folder = _copy("panda", tmp_path / "p", edit)
    with pytest.raises(RobotDescriptionError) as err:
        load_robot(folder)
    message = str(err.value)
    assert "panda_link5_0" in message and "only an object on the base" in message
    assert err.value.name == "coverage.exclude" and "\n" not in message


@pytest.mark.parametrize(
    "old, new, key",
    [
        ("max_point_speed_mps = 3.0", "max_point_speed_mps = 0.05", "arm.max_point_speed_mps"),
        ("A1 = 8.57", "A1 = 491.0", "arm.max_acceleration_radps2.A1"),  # 8.57 rad/s² in °/s²
        ("reaction_time_s = 0.005", "reaction_time_s = 1", "arm.reaction_time_s"),  # 1 ms
    ],
)
def test_unit_errors_in_arm_are_refused(tmp_path, old, new, key):
    folder = _copy("iiwa14", tmp_path / "a", lambda t: t.replace(old, new))
    with pytest.raises(RobotDescriptionError) as err:
        load_robot(folder)
    assert err.value.name == key and "\n" not in str(err.value)


def test_a_bundled_name_wins_over_a_local_folder_of_that_name(tmp_path, monkeypatch):
    _copy(
        "iiwa14",
        tmp_path / "iiwa14",
        lambda t: t.replace("sphere_radius_m = 0.09", "sphere_radius_m = 0.1", 1),
    )
    monkeypatch.chdir(tmp_path)
    assert load_robot("iiwa14").sets[0].sphere_radius_m == 0.09  # the bundled one
    assert load_robot("./iiwa14").sets[0].sphere_radius_m == 0.1  # the folder, by path
    assert description_reference("iiwa14") == "iiwa14"
    assert description_reference("./iiwa14") == str(tmp_path / "iiwa14")


@needs_erd
def test_redundant_on_an_arm_that_locks_nothing_is_refused(tmp_path, capsys):
    out = tmp_path / "x"
    argv = ["run", "free", "--robot", "ur5", "--controller", "qp", "--redundant", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "locks none" in err and err.count("\n") == 1 and not out.exists()


@pytest.mark.slow
def test_a_fitted_file_left_unfinished_names_its_first_to_do(tmp_path):
    folder = tmp_path / "fitted"
    assert main(["robot", "fit", str(ROBOTS / "iiwa14" / "iiwa14.urdf"), "--out", str(folder)]) == 0
    with pytest.raises(RobotDescriptionError) as err:
        load_robot(folder)
    assert err.value.name == "end_effector" and "as `qpavoid robot fit` wrote it" in str(err.value)


@pytest.mark.parametrize(
    "args, words",
    [
        (["README.md"], "cannot build a model from this URDF"),
        (
            [str(ROBOTS / "iiwa14" / "iiwa14.urdf"), "--lock", "A4=90"],
            "not within the joint's limits",
        ),
        (
            [str(ROBOTS / "iiwa14" / "iiwa14.urdf"), "--lock", *(f"A{k}=0" for k in range(1, 8))],
            "nothing would move",
        ),
    ],
)
def test_robot_fit_refuses_what_the_loader_would_in_one_line(tmp_path, capsys, args, words):
    readme = ROBOTS.parent / "README.md"
    args = [str(readme) if a == "README.md" else a for a in args]
    assert main(["robot", "fit", *args, "--out", str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err
    assert words in err and err.strip().count("\n") == 0 and "internal error" not in err


@needs_erd
def test_a_package_urdf_is_named_by_its_package_and_a_wrong_path_by_its_key(tmp_path):
    panda = load_robot("panda")
    assert package_entry(panda.urdf) == {"package": "example-robot-data", "path": PANDA_URDF}
    assert package_entry(ROBOTS / "iiwa14" / "iiwa14.urdf") is None  # not an installed file
    folder = _iiwa_with_urdf(tmp_path, 'urdf = { package = "example-robot-data", path = "x.urdf" }')
    with pytest.raises(RobotDescriptionError) as err:
        load_robot(folder)
    assert err.value.name == "urdf.path" and "\n" not in str(err.value)
