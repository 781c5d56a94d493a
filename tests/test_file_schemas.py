"""The shape of every file a user writes, checked by its schema (msgspec): for each file
kind a wrong type, an out-of-range value, an unknown key and a missing key are each one
line naming the field's path (and, through the command line, exit 2); every shipped file
loads."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, ClassVar

import pytest
from msgspec import Meta, Struct
from schema_files import RefusedError, refused, written

import qpavoid
from qpavoid.arm.description_schema import ControlPointFile
from qpavoid.cli.commands import main
from qpavoid.core.errors import RobotDescriptionError, SkeletonFormatError
from qpavoid.core.file_bounds import read_toml
from qpavoid.core.schema import convert
from qpavoid.human.body import BodyModel
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.human.skeleton_file import FORMATS_DIR

ROBOTS = Path(__file__).resolve().parents[1] / "robots"


# --- the refusals' words (qpavoid.core.schema) -----------------------------------------------


class _Inner(Struct, frozen=True, forbid_unknown_fields=True):
    radius_m: Annotated[float, Meta(gt=0.0, le=1.0)]
    label: str = ""


class _Outer(Struct, frozen=True, forbid_unknown_fields=True):
    name: Annotated[str, Meta(pattern="^[a-z]+$", description="lower-case letters")]
    parts: list[_Inner]
    limits: dict[str, Annotated[float, Meta(ge=0.0, le=10.0)]] = {}


def _refusal(data: object) -> RefusedError:
    with pytest.raises(RefusedError) as info:
        convert(data, _Outer, RefusedError, prefix="cell")
    assert "\n" not in str(info.value)
    return info.value


@pytest.mark.parametrize(
    "data, name, message",
    [
        (  # a number out of its range: both bounds said, the value given
            {"name": "a", "parts": [{"radius_m": 1.5}]},
            "cell.parts[0].radius_m",
            "cell.parts[0].radius_m must be a number above 0 and at most 1, got 1.5",
        ),
        (  # a table's key, which msgspec leaves unnamed ([...]), named
            {"name": "a", "parts": [], "limits": {"x": 1.0, "y": -1.0}},
            "cell.limits.y",
            "cell.limits.y must be a number at least 0 and at most 10, got -1.0",
        ),
        (  # every unknown key, and the keys the table has
            {"name": "a", "parts": [{"radius_m": 0.5, "radius": 1, "colour": 2}]},
            "cell.parts[0].colour",
            "cell.parts[0] has unknown key(s) ['colour', 'radius']; its keys are "
            "['radius_m', 'label']",
        ),
        (  # every missing key
            {"parts": []},
            "cell.name",
            "cell is missing key(s) name: name must be lower-case letters",
        ),
        (  # a described field: its description, the value
            {"name": "A", "parts": []},
            "cell.name",
            "cell.name must be lower-case letters, got 'A'",
        ),
        (  # a wrong type: no int for a text, no bool for a number
            {"name": "a", "parts": [{"radius_m": True}]},
            "cell.parts[0].radius_m",
            "must be a number above 0 and at most 1, got True",
        ),
        (
            {"name": "a", "parts": [{"radius_m": 0.5, "label": 3}]},
            "cell.parts[0].label",
            "cell.parts[0].label: Expected `str`, got 3",
        ),
    ],
)
def test_a_refusal_is_one_line_naming_the_field_s_path(data, name, message):
    refused = _refusal(data)
    assert refused.name == name and message in str(refused)


class _Piece(Struct, frozen=True, forbid_unknown_fields=True):
    docs: ClassVar[str] = "docs/pieces.md: Piece"

    name: str
    size_m: Annotated[float, Meta(gt=0.0, le=2.0, extra={"unit": "m"})]
    colour: Annotated[str, Meta(description="must name a colour (text)")] = ""


class _Box(Struct, frozen=True, forbid_unknown_fields=True):
    pieces: list[_Piece]
    lid: _Piece = _Piece("lid", 1.0)


@pytest.mark.parametrize(
    "data, name, message",
    [
        (  # a named entry by its name, a number's unit, the table's page in the docs
            {"pieces": [{"name": "a", "size_m": 1.0}, {"name": "b", "size_m": 3.0}]},
            "box.pieces[1].size_m",
            "piece 'b': box.pieces[1].size_m must be a number above 0 and at most 2, m, got 3.0 "
            "(docs/pieces.md: Piece)",
        ),
        (  # a description that says its own verb
            {"pieces": [{"name": "a", "size_m": 1.0, "colour": 3}]},
            "box.pieces[0].colour",
            "piece 'a': box.pieces[0].colour must name a colour (text), got 3 "
            "(docs/pieces.md: Piece)",
        ),
        (  # a missing key, its table's page
            {"pieces": [], "lid": {"name": "x"}},
            "box.lid.size_m",
            "box.lid is missing key(s) size_m (docs/pieces.md: Piece)",
        ),
        (  # an entry's own name is not said twice
            {"pieces": [{"name": 3, "size_m": 1.0}]},
            "box.pieces[0].name",
            "box.pieces[0].name: Expected `str`, got 3 (docs/pieces.md: Piece)",
        ),
    ],
)
def test_a_refusal_names_the_entry_the_unit_and_the_docs(data, name, message):
    with pytest.raises(RefusedError) as info:
        convert(data, _Box, RefusedError, prefix="box")
    assert info.value.name == name and str(info.value) == message


def test_a_missing_table_is_refused_in_its_own_words():
    class Holder(Struct, frozen=True, forbid_unknown_fields=True):
        lid: Annotated[_Piece, Meta(extra={"missing": "needs lid = { name = ..., size_m = ... }"})]

    with pytest.raises(RefusedError) as info:
        convert({}, Holder, RefusedError, prefix="box")
    assert str(info.value) == "box needs lid = { name = ..., size_m = ... } (docs/pieces.md: Piece)"


# --- robot descriptions (qpavoid.arm.description_schema) -------------------------------------


def _iiwa(tmp_path: Path, old: str, new: str) -> Path:
    folder = tmp_path / "arm"
    shutil.copytree(ROBOTS / "iiwa14", folder)
    file = folder / "control_points.toml"
    written(file, file.read_text(), old, new)
    return folder


ROBOT_REFUSALS = [
    (  # a wrong type
        "sphere_radius_m = 0.09",
        'sphere_radius_m = "0.09"',
        "sets[0].sphere_radius_m",
        "sets[0].sphere_radius_m must be a number above 0 and at most 1, got '0.09'",
    ),
    (  # out of range: a radius in mm
        "capsule_radius_m = 0.07",
        "capsule_radius_m = 70",
        "sets[0].capsule.capsule_radius_m",
        "sets[0].capsule.capsule_radius_m must be a number above 0 and at most 1, got 70",
    ),
    (  # an offset in cm
        'points = [["A2", "A3"]',
        'points = [{ frame = "A3", xyz = [0, 0, 12] }',
        "sets[0].points[0].xyz[2]",
        "sets[0].points[0].xyz[2] must be a number at least -10 and at most 10, got 12",
    ),
    (  # an unknown key
        "wrist_to_tool_m = 0.126",
        "wrist_to_tool_m = 0.126\nwrist_to_tool = 0.1",
        "ik_seed.wrist_to_tool",
        "ik_seed has unknown key(s) ['wrist_to_tool']",
    ),
    (  # a missing key
        ", capsule_radius_m = 0.065 }",
        " }",
        "sets[1].capsule.capsule_radius_m",
        "sets[1].capsule is missing key(s) capsule_radius_m",
    ),
    (
        "A4 = 11.36",
        "A4 = 1136",
        "arm.max_acceleration_radps2.A4",
        "arm.max_acceleration_radps2.A4 must be a number at least 0.1 and at most 100, got 1136",
    ),
    (
        'link_0_0 = "the base',
        'link_0_0 = 3, link_9 = "the base',
        "coverage.exclude.link_0_0",
        "coverage.exclude must map each collision object it leaves out to the reason",
    ),
]


@pytest.mark.parametrize("old, new, name, message", ROBOT_REFUSALS)
def test_a_robot_description_of_the_wrong_shape_is_one_line_naming_the_path(
    tmp_path, old, new, name, message
):
    folder = _iiwa(tmp_path, old, new)
    with pytest.raises(RobotDescriptionError) as info:
        qpavoid.load_robot(folder)
    text = str(info.value)
    assert text.startswith(f"{folder / 'control_points.toml'}: ") and "\n" not in text
    assert message in text
    if name.startswith("coverage"):
        name = "coverage.exclude"  # the table that says its shape
    assert info.value.name == name


@pytest.mark.parametrize("old, new, name, message", ROBOT_REFUSALS[:2] + ROBOT_REFUSALS[3:5])
def test_a_run_on_a_robot_description_of_the_wrong_shape_exits_2_in_one_line(
    tmp_path, capsys, old, new, name, message
):
    folder = _iiwa(tmp_path, old, new)
    out = tmp_path / "out"
    assert (
        main(["run", "free", "--robot", str(folder), "--out", str(out), "--max-time", "0.1"]) == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and not out.exists()


def test_every_shipped_robot_description_has_its_schema_s_shape():
    """Each of robots/*: the file's shape alone (the URDFs of three come from extras)."""
    names = sorted(p.parent.name for p in ROBOTS.glob("*/control_points.toml"))
    assert names == ["fr3", "iiwa14", "panda", "ur5"]
    for name in names:
        data = read_toml(ROBOTS / name / "control_points.toml", 2**20)
        file = convert(data, ControlPointFile, RefusedError)
        assert file.sets and file.arm.max_acceleration_radps2
    assert qpavoid.load_robot("iiwa14").sets[0].name == "L1"


def _edited_format_file(tmp_path: Path, name: str, old: str, new: str) -> Path:
    """A copy of the shipped ``formats/<name>`` with ``old`` replaced by ``new`` once."""
    return written(tmp_path / name, (FORMATS_DIR / name).read_text(), old, new)


def _one_line_naming(load: Callable[[], object], path: Path, name: str, message: str) -> None:
    """``load()`` refused with one line that starts with the file and names ``name``."""
    error = refused(SkeletonFormatError, lambda _: load(), path, f"{path}: ", message)
    assert isinstance(error, SkeletonFormatError)
    assert error.name == name and error.path == path


# --- camera bodies (qpavoid.human.body_schema) -----------------------------------------------

BODY_REFUSALS = [
    (  # a wrong type
        "moves_with_body = true",
        "moves_with_body = 1",
        "parts[0].moves_with_body",
        "parts[0].moves_with_body must be true or false, got 1",
    ),
    (  # out of range: a radius in mm
        "sphere_radius_m = 0.11",
        "sphere_radius_m = 110",
        "parts[0].sphere_radius_m",
        "part 'head': parts[0].sphere_radius_m must be a number at least 0.01 and at most 1, m, "
        "got 110",
    ),
    (  # an unknown key
        'format = "kinect_v2"',
        'format = "kinect_v2"\nformats = "x"',
        "formats",
        "the top level has unknown key(s) ['formats']; its keys are ['format', 'parts',",
    ),
    (  # a missing key
        'format = "kinect_v2"',
        "",
        "format",
        "missing key(s) format: format must be a format's name (letters, digits, _ and -)",
    ),
]


@pytest.mark.parametrize("old, new, name, message", BODY_REFUSALS)
def test_a_body_file_of_the_wrong_shape_is_one_line_naming_the_path(
    tmp_path, old, new, name, message
):
    path = _edited_format_file(tmp_path, "kinect_v2_body.toml", old, new)
    _one_line_naming(lambda: BodyModel.load(path, KINECT_V2), path, name, message)


def test_every_shipped_body_loads():
    bodies = sorted(FORMATS_DIR.glob("*_body.toml"))
    assert len(bodies) == 5
    for path in bodies:
        body = BodyModel.load(path)
        assert body.part_names


# --- camera formats (qpavoid.human.format_schema) --------------------------------------------

FORMAT_REFUSALS = [
    (  # a wrong type
        "max_bodies = 10",
        "max_bodies = 10.0",
        "sensor.max_bodies",
        "sensor.max_bodies must be a whole number from 1 to 100, got 10.0",
    ),
    (  # out of range: a latency in ms
        "latency_s = 0.10",
        "latency_s = 100",
        "sensor.latency_s",
        "sensor.latency_s must be a number at least 0 and at most 1, s, got 100",
    ),
    (  # an unknown key
        "max_bodies = 10",
        "max_bodies = 10\nmax_body = 6",
        "sensor.max_body",
        "sensor has unknown key(s) ['max_body']; its keys are ['frame_rate_hz',",
    ),
    (  # a missing key
        'title = "Azure Kinect body tracking"\n',
        "",
        "title",
        "missing key(s) title",
    ),
]


@pytest.mark.parametrize("old, new, name, message", FORMAT_REFUSALS)
def test_a_format_file_of_the_wrong_shape_is_one_line_naming_the_path(
    tmp_path, old, new, name, message
):
    path = _edited_format_file(tmp_path, "k4abt.toml", old, new)
    _one_line_naming(lambda: SkeletonFormat.load(path), path, name, message)


@pytest.mark.parametrize("old, new, name, message", FORMAT_REFUSALS)
def test_a_run_with_a_format_file_of_the_wrong_shape_exits_2_in_one_line(
    tmp_path, capsys, old, new, name, message
):
    for file in ("k4abt.toml", "k4abt_body.toml"):
        text = (FORMATS_DIR / file).read_text().replace('name = "k4abt"', 'name = "mycam"')
        text = text.replace('format = "k4abt"', 'format = "mycam"')
        (tmp_path / file.replace("k4abt", "mycam")).write_text(text.replace(old, new, 1))
    out = tmp_path / "out"
    argv = ["run", "free", "--camera", str(tmp_path / "mycam.toml"), "--out", str(out)]
    assert main([*argv, "--max-time", "0.1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and not out.exists()


def test_every_shipped_format_loads():
    files = sorted(p for p in FORMATS_DIR.glob("*.toml") if not p.stem.endswith("_body"))
    assert [p.stem for p in files] == [
        "k4abt",
        "kinect_v2",
        "mediapipe_pose",
        "zed_body_34",
        "zed_body_38",
    ]
    for path in files:
        assert SkeletonFormat.load(path).n_joints >= 25
