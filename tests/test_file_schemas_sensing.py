"""The shape of the sensing side's user files, checked by their schemas (msgspec): for each
kind (calibrations, key files, the ROS 2 cell file) a wrong type, an out-of-range value, an
unknown key and a missing key are each one line naming the field's path, and through the
command line exit 2 in one line; every shipped file of the kind has its schema's shape."""

from __future__ import annotations

import typing
from pathlib import Path

import pytest
from schema_files import RefusedError, exits_2, refused, written

from qpavoid.core.errors import CalibrationError, InputError
from qpavoid.core.file_bounds import read_toml
from qpavoid.core.schema import convert
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.calibration_schema import CalibrationFile
from qpavoid.sensing.ros2_cell import load_cell
from qpavoid.sensing.ros2_cell_schema import CellFile
from qpavoid.sensing.ros2_types import DISTRIBUTIONS

ROOT = Path(__file__).resolve().parents[1]
EYE = "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]"
CALIBRATION = f'cell = "c"\n\n[sensors.cam]\nbase_from_camera = {EYE}\nweight = 1.0\n'


# --- calibration files (qpavoid.sensing.calibration_schema) ----------------------------------

CALIBRATION_REFUSALS = [
    (  # a wrong type
        "weight = 1.0",
        'weight = "1"',
        "sensors.cam.weight",
        "sensors.cam.weight must be a number at least 0.001 and at most 1000, relative, got '1'",
    ),
    (  # out of range: a latency in ms
        "weight = 1.0",
        "latency_s = 104",
        "sensors.cam.latency_s",
        "sensors.cam.latency_s must be a number at least 0 and at most 1, s, got 104",
    ),
    (  # an unknown key
        "weight = 1.0",
        "wieght = 1.0",
        "sensors.cam.wieght",
        "sensors.cam has unknown key(s) ['wieght']; its keys are ['base_from_camera',",
    ),
    (  # a missing key
        f"base_from_camera = {EYE}\n",
        "",
        "sensors.cam.base_from_camera",
        "sensors.cam is missing key(s) base_from_camera: base_from_camera must be 4 rows of 4 "
        "numbers (shape (4, 4): a rigid transform, m) (docs/sensors.md §1)",
    ),
]


def _calibration(tmp_path: Path, old: str, new: str) -> Path:
    return written(tmp_path / "calib.toml", CALIBRATION, old, new)


@pytest.mark.parametrize("old, new, name, message", CALIBRATION_REFUSALS)
def test_a_calibration_of_the_wrong_shape_is_one_line_naming_the_path(
    tmp_path, old, new, name, message
):
    path = _calibration(tmp_path, old, new)
    err = refused(CalibrationError, load_calibration, path, f"calibration {path}: ", message)
    assert isinstance(err, CalibrationError) and (err.name, err.sensor) == (name, "cam")


@pytest.mark.parametrize("old, new, name, message", CALIBRATION_REFUSALS)
def test_a_run_with_a_calibration_of_the_wrong_shape_exits_2_in_one_line(
    tmp_path, capsys, old, new, name, message
):
    path = _calibration(tmp_path, old, new)
    exits_2(
        capsys, ["run", "--listen", "127.0.0.1:9", "--sensors", str(path)], tmp_path / "o", message
    )


def test_every_shipped_calibration_has_its_schema_s_shape():
    """docs/calibrations/*.toml: the shape alone (their key files are the user's to write)."""
    paths = sorted((ROOT / "docs" / "calibrations").glob("*.toml"))
    assert len(paths) == 5
    for path in paths:
        file = convert(read_toml(path, 2**20), CalibrationFile, RefusedError)
        assert file.sensors and all(s.key_file for s in file.sensors.values())


# --- key files (qpavoid.sensing.key_schema) --------------------------------------------------

SECRET = "ab" * 32
KEY_FILE = f'sensor = "cam"\n\n[[key]]\nid = 2\nsecret = "{SECRET}"\n'
KEY_REFUSALS = [
    (
        "id = 2",
        'id = "2"',
        "key[0].id",
        "key[0].id must be a whole number at least 0",
    ),  # a wrong type
    (  # out of range: ids are 32-bit
        "id = 2",
        "id = 4294967296",
        "key[0].id",
        "key[0].id must be a whole number at least 0 and at most 4294967295, got 4294967296",
    ),
    (  # an unknown key
        "id = 2",
        "id = 2\nkid = 3",
        "key[0].kid",
        "key[0] has unknown key(s) ['kid']; its keys are ['id', 'secret']",
    ),
    ("id = 2\n", "", "key[0].id", "key[0] is missing key(s) id (docs/security.md)"),  # missing
    (  # a secret is never shown, even a wrong one
        f'secret = "{SECRET}"',
        f'secret = "{SECRET}0"',
        "key[0].secret",
        "key[0].secret must be 64 hex digits (256 bits), got <hidden> (docs/security.md)",
    ),
]


def _keyed_cell(tmp_path: Path, old: str, new: str) -> Path:
    assert old in KEY_FILE
    key = tmp_path / "cam.key"
    key.write_text(KEY_FILE.replace(old, new, 1))
    key.chmod(0o600)
    path = tmp_path / "calib.toml"
    path.write_text(CALIBRATION + 'key_file = "cam.key"\n')
    return path


@pytest.mark.parametrize("old, new, name, message", KEY_REFUSALS)
def test_a_key_file_of_the_wrong_shape_is_one_line_naming_the_path(
    tmp_path, old, new, name, message
):
    start = f"key file {tmp_path / 'cam.key'} of sensor 'cam': "
    err = refused(
        CalibrationError, load_calibration, _keyed_cell(tmp_path, old, new), start, message
    )
    assert SECRET not in str(err) and isinstance(err, CalibrationError)
    assert err.name == name and err.value is None


@pytest.mark.parametrize("old, new, name, message", KEY_REFUSALS)
def test_a_run_with_a_key_file_of_the_wrong_shape_exits_2_in_one_line(
    tmp_path, capsys, old, new, name, message
):
    path = _keyed_cell(tmp_path, old, new)
    args = ["run", "--listen", "127.0.0.1:9", "--sensors", str(path)]
    assert SECRET not in exits_2(capsys, args, tmp_path / "out", message)


def test_a_key_file_of_the_right_shape_loads(tmp_path):
    path = _keyed_cell(tmp_path, "id = 2", "id = 2")
    assert load_calibration(path).keys["cam"].ids == (2,)


# --- ROS 2 cell files (qpavoid.sensing.ros2_cell_schema) -------------------------------------

CELL = (
    'distribution = "humble"\ndomain_id = 7\n[arm]\njoints = ["a", "b"]\n[output]\nrate_hz = 20.0\n'
)
CELL_REFUSALS = [
    ("domain_id = 7", 'domain_id = "7"', "domain_id", "domain_id must be a whole number"),
    (  # out of range
        "rate_hz = 20.0",
        "rate_hz = 500.0",
        "output.rate_hz",
        "output.rate_hz must be a number at least 1 and at most 30, Hz, got 500.0",
    ),
    (  # an unknown key
        "rate_hz = 20.0",
        "rate = 20.0",
        "output.rate",
        "output has unknown key(s) ['rate']; its keys are ['rate_hz', 'diagnostics', 'markers']",
    ),
    (  # a missing key
        'distribution = "humble"\n',
        "",
        "distribution",
        "missing key(s) distribution: distribution must be one of humble, jazzy (docs/ros2.md)",
    ),
]


def _cell(tmp_path: Path, old: str, new: str) -> Path:
    return written(tmp_path / "cell.toml", CELL, old, new)


@pytest.mark.parametrize("old, new, name, message", CELL_REFUSALS)
def test_a_cell_file_of_the_wrong_shape_is_one_line_naming_the_path(
    tmp_path, old, new, name, message
):
    path = _cell(tmp_path, old, new)
    err = refused(InputError, load_cell, path, f"ROS 2 cell file {path}: ", message)
    assert isinstance(err, InputError) and err.name == name


@pytest.mark.parametrize("old, new, name, message", CELL_REFUSALS)
def test_a_run_with_a_cell_file_of_the_wrong_shape_exits_2_in_one_line(
    tmp_path, capsys, old, new, name, message
):
    cell = _cell(tmp_path, old, new)
    calib = _calibration(tmp_path, "weight = 1.0", 'topic = "/body_tracking_data"')
    exits_2(
        capsys,
        ["run", "--listen", f"ros2:{cell}", "--sensors", str(calib)],
        tmp_path / "o",
        message,
    )


def test_a_cell_file_of_the_right_shape_loads_and_its_distributions_are_the_library_s(tmp_path):
    cell = load_cell(_cell(tmp_path, "domain_id = 7", "domain_id = 7"))
    assert (cell.distribution, cell.domain_id, cell.arm.joints) == ("humble", 7, ("a", "b"))
    distribution = typing.get_type_hints(CellFile, include_extras=True)["distribution"]
    assert typing.get_args(typing.get_args(distribution)[0]) == DISTRIBUTIONS
