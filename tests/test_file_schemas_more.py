"""The shape of the last user files, checked by their schemas (msgspec): for each kind (the
body-region file, a Franka description's model file, a task file) a wrong type, an out-of-range
value, an unknown key and a missing key are each one line naming the field's path, through
the command line (where a flag reads the file) exit 2 in one line; every shipped file of
the kind has its schema's shape."""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest
import tomllib
from schema_files import RefusedError, exits_2, refused, written

import qpavoid
from qpavoid.control.task import load_task
from qpavoid.control.task_schema import TaskFile
from qpavoid.core.errors import DataFileError, RobotDescriptionError
from qpavoid.core.file_bounds import read_toml
from qpavoid.core.schema import convert
from qpavoid.drive import franka
from qpavoid.drive.franka_model import MODEL_FILE, FrankaModel, bundled_models
from qpavoid.drive.franka_model_schema import ModelFile
from qpavoid.laws.pfl import BODY_REGIONS_FILE, PFLConfig, load_regions
from qpavoid.laws.regions_schema import RegionsFile

ROOT = Path(__file__).resolve().parents[1]


# --- body-region files (qpavoid.laws.regions_schema) -----------------------------------------

REGIONS = BODY_REGIONS_FILE.read_text()
HAND = 'name = "hand_finger"\n'
REGION_REFUSALS = [
    (  # a wrong type
        "effective_mass_kg = 0.6\n",
        'effective_mass_kg = "0.6"\n',
        "regions[9].effective_mass_kg",
        "region 'hand_finger': regions[9].effective_mass_kg must be a number above 0 and at "
        "most 200, kg, got '0.6' (docs/formats.md: The body regions)",
    ),
    (  # out of range: a spring constant in N/m
        "spring_constant_n_per_mm = 75.0\neffective_mass_kg = 0.6",
        "spring_constant_n_per_mm = 75000.0\neffective_mass_kg = 0.6",
        "regions[9].spring_constant_n_per_mm",
        "region 'hand_finger': regions[9].spring_constant_n_per_mm must be a number above 0 "
        "and at most 1000, N/mm, got 75000.0 (a unit error?)",
    ),
    (  # out of range: beyond the TS's twice the quasi-static limit
        "transient_factor = 2.0\n",
        "transient_factor = 2.5\n",
        "regions[0].transient_factor",
        "region 'skull_forehead': regions[0].transient_factor must be a number at least 1 "
        "and at most 2, got 2.5 (docs/formats.md: The body regions)",
    ),
    (  # an unknown key
        HAND,
        HAND + "pressure = 3\n",
        "regions[9].pressure",
        "region 'hand_finger': regions[9] has unknown key(s) ['pressure']; its keys are "
        "['name', 'title', 'contact',",
    ),
    (  # a missing key
        "effective_mass_kg = 0.6\n",
        "",
        "regions[9].effective_mass_kg",
        "region 'hand_finger': regions[9] is missing key(s) effective_mass_kg "
        "(docs/formats.md: The body regions)",
    ),
    (  # an unknown contact kind
        'contact = "none"',
        'contact = "sometimes"',
        "regions[0].contact",
        "region 'skull_forehead': regions[0].contact must be one of 'transient', 'none', "
        "got 'sometimes'",
    ),
    (  # a name the body models cannot name
        'name = "face"',
        'name = "Face"',
        "regions[1].name",
        "regions[1].name must be a snake_case name ([a-z][a-z0-9_]*), got 'Face'",
    ),
    (  # the file's own keys
        "\n[[regions]]",
        "\nlimits = 3\n\n[[regions]]",
        "limits",
        "the top level has unknown key(s) ['limits']; its keys are ['regions']",
    ),
    (  # two regions of one name: code beside the schema
        'name = "face"',
        'name = "skull_forehead"',
        "regions[1].name",
        "regions[1].name: a second region called 'skull_forehead'",
    ),
]


@pytest.mark.parametrize("old, new, name, message", REGION_REFUSALS)
def test_a_region_file_of_the_wrong_shape_is_one_line_naming_the_path(
    tmp_path, old, new, name, message
):
    path = written(tmp_path / "regions.toml", REGIONS, old, new)
    err = refused(DataFileError, load_regions, path, f"{path}: ", message)
    assert isinstance(err, DataFileError) and (err.name, err.path) == (name, path)
    with pytest.raises(DataFileError, match=re.escape(message)):  # another table for PFL
        PFLConfig.from_file(path)


@pytest.mark.parametrize("text", ["", "regions = []\n", "regions = 3\n"])
def test_a_region_file_without_regions_says_what_it_must_hold(tmp_path, text):
    path = tmp_path / "regions.toml"
    path.write_text(text)
    refused(
        DataFileError, load_regions, path, f"{path}: ", "regions must be one or more [[regions]]"
    )


def test_every_shipped_region_file_has_its_schema_s_shape():
    """qpavoid/laws/body_regions.toml: Annex A's twelve regions (no other file ships)."""
    source = ROOT / "qpavoid"  # the tree's files; the package read may be an installed copy
    paths = sorted(p.relative_to(source) for p in source.rglob("*regions*.toml"))
    assert paths == [Path("laws") / BODY_REGIONS_FILE.name]
    assert BODY_REGIONS_FILE.parent.name == "laws"
    file = convert(read_toml(BODY_REGIONS_FILE, 2**20), RegionsFile, RefusedError)
    assert len(file.regions) == len(load_regions()) == 12


# --- Franka model files (qpavoid.drive.franka_model_schema) ----------------------------------

FR3 = Path(qpavoid.load_robot("fr3").path).parent
MODEL = (FR3 / MODEL_FILE).read_text()
VERSIONS = "server_versions = [6, 7, 8, 9, 10]"
MODEL_REFUSALS = [
    (  # a wrong type
        VERSIONS,
        "server_versions = [6, 7, 8, 9, 10.0]",
        "server_versions[4]",
        "server_versions[4] must be a whole number at least 1 and at most 65535, got 10.0 "
        "(docs/real-robot.md §1b)",
    ),
    (  # out of range
        VERSIONS,
        "server_versions = [0]",
        "server_versions[0]",
        "server_versions[0] must be a whole number at least 1 and at most 65535, got 0",
    ),
    (  # none at all
        VERSIONS,
        "server_versions = []",
        "server_versions",
        "server_versions must list the versions of libfranka's protocol the arm speaks, whole "
        "numbers from 1 to 65535 (server_versions = [10]), got []",
    ),
    (  # an unknown key
        VERSIONS,
        VERSIONS + "\nwhoami = 1",
        "whoami",
        "the top level has unknown key(s) ['whoami']; its keys are ['model', 'server_versions', "
        "'sources'] (docs/real-robot.md §1b)",
    ),
    (  # an unknown source
        "[sources]\n",
        '[sources]\nmodle = "x"\n',
        "sources.modle",
        "sources has unknown key(s) ['modle']; its keys are ['model', 'server_versions']",
    ),
    (  # a missing key
        'model = "FR3"\n',
        "",
        "model",
        'missing key(s) model: model must name the arm (model = "FR3") (docs/real-robot.md §1b)',
    ),
    ('model = "FR3"', 'model = " "', "model", "model must name the arm (model = \"FR3\"), got ' '"),
]


def _fr3(tmp_path: Path, old: str, new: str) -> Path:
    """A copy of the FR3's description whose franka.toml has ``old`` replaced by ``new``."""
    folder = tmp_path / "myfr3"
    shutil.copytree(FR3, folder, ignore=shutil.ignore_patterns("__pycache__"))
    written(folder / MODEL_FILE, MODEL, old, new)
    return folder


@pytest.mark.parametrize("old, new, name, message", MODEL_REFUSALS)
def test_a_franka_model_file_of_the_wrong_shape_is_one_line_naming_the_path(
    tmp_path, old, new, name, message
):
    path = _fr3(tmp_path, old, new) / MODEL_FILE
    err = refused(
        RobotDescriptionError, lambda p: FrankaModel.read(p, "myfr3"), path, f"{path}: ", message
    )
    assert isinstance(err, RobotDescriptionError) and (err.name, err.path) == (name, path)


@pytest.mark.parametrize("old, new, name, message", MODEL_REFUSALS)
def test_a_run_on_an_fr3_whose_model_file_is_of_the_wrong_shape_exits_2_in_one_line(
    tmp_path, capsys, monkeypatch, old, new, name, message
):
    """Refused before connecting: a franky that cannot make a robot stands in."""
    monkeypatch.setattr(franka, "franky", SimpleNamespace())
    folder = _fr3(tmp_path, old, new)
    args = ["run", "free", "--robot", str(folder), "--arm", "franka:127.0.0.1"]
    exits_2(capsys, [*args, "--max-time", "0.1"], tmp_path / "out", message)


def test_every_shipped_franka_model_file_has_its_schema_s_shape():
    """robots/fr3/franka.toml and robots/panda/franka.toml, each with its sources."""
    paths = sorted(Path(qpavoid.robots.__file__).parent.glob(f"*/{MODEL_FILE}"))
    assert [p.parent.name for p in paths] == ["fr3", "panda"]
    for path in paths:
        file = convert(read_toml(path, 2**16), ModelFile, RefusedError)
        assert file.sources.model and file.sources.server_versions
    assert [m.robot for m in bundled_models()] == ["fr3", "panda"]


# --- task files (qpavoid.control.task_schema) ------------------------------------------------

ROBOTS = Path(qpavoid.robots.__file__).parent
TASK = (ROBOTS / "iiwa14" / "task.toml").read_text()
TASK_REFUSALS = [
    (  # a wrong type
        "duration_s = 15.0",
        'duration_s = "15"',
        "waypoints[1].duration_s",
        "waypoints[1].duration_s must be a number above 0 and at most 3600, s, got '15' "
        "(docs/tasks.md §2)",
    ),
    (  # out of range: a position in mm
        "position_m = [0.3524, 0.6105, 0.5779]",
        "position_m = [352.4, 0.6105, 0.5779]",
        "waypoints[0].position_m[0]",
        "waypoints[0].position_m[0] must be a number at least -10 and at most 10, m, got 352.4 "
        "(a unit error?)",
    ),
    (  # out of range: the seat behind the base
        "distance_m = 1.05",
        "distance_m = -1.05",
        "operator.distance_m",
        "operator.distance_m must be a number above 0 and at most 10, m, got -1.05",
    ),
    (  # an unknown key
        "x_m = 0.15",
        "x_m = 0.15\nseat_m = 1.0",
        "operator.seat_m",
        "operator has unknown key(s) ['seat_m']; its keys are ['x_m', 'distance_m', "
        "'max_lean_m'] (docs/tasks.md §2)",
    ),
    (  # a missing key
        "reach_m = 0.946",
        "",
        "scaling.reach_m",
        "scaling is missing key(s) reach_m (docs/tasks.md §2)",
    ),
    (  # a strike that is neither a frame nor { frame, xyz }
        'shoulder = "A2"',
        "shoulder = 2",
        "strikes.shoulder",
        'strikes.shoulder must be "<frame>" or { frame = "<frame>", xyz = [x, y, z] }, got 2',
    ),
]


@pytest.mark.parametrize("old, new, name, message", TASK_REFUSALS)
def test_a_task_file_of_the_wrong_shape_is_one_line_naming_the_path(
    tmp_path, old, new, name, message
):
    robot = qpavoid.load_robot("iiwa14")
    path = written(tmp_path / "task.toml", TASK, old, new)
    err = refused(RobotDescriptionError, lambda p: load_task(p, robot), path, f"{path}: ", message)
    assert isinstance(err, RobotDescriptionError) and (err.name, err.path) == (name, path)


@pytest.mark.parametrize("old, new, name, message", TASK_REFUSALS)
def test_a_run_with_a_task_file_of_the_wrong_shape_exits_2_in_one_line(
    tmp_path, capsys, old, new, name, message
):
    path = written(tmp_path / "task.toml", TASK, old, new)
    err = exits_2(capsys, ["run", "test1", "--task", str(path)], tmp_path / "out", message)
    assert err.startswith(f"qpavoid: error: --task {path}: ")


def _toml_blocks(page: Path) -> list[str]:
    """The ``toml`` code blocks of a docs page."""
    parts = page.read_text().split("```toml\n")[1:]
    return [part.split("```")[0] for part in parts]


def test_every_shipped_task_file_loads(tmp_path):
    """robots/*/task.toml on their arms; docs/tasks.md's two files (the keys and the
    example) on the iiwa, whose joints and frames they name."""
    for folder in sorted(p.parent for p in ROBOTS.glob("*/task.toml")):
        robot = qpavoid.load_robot(folder.name)
        assert load_task(folder / "task.toml", robot).file == folder / "task.toml"
    examples = _toml_blocks(ROOT / "docs" / "tasks.md")
    assert len(examples) == 2
    iiwa = qpavoid.load_robot("iiwa14")
    for k, text in enumerate(examples):
        assert convert(tomllib.loads(text), TaskFile, RefusedError).waypoints
        path = tmp_path / f"example{k}.toml"
        path.write_text(text)
        assert len(load_task(path, iiwa).path.segments) >= 2
