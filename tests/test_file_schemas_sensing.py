"""The shape of the sensing side's user files, checked by their schemas (msgspec): for each
kind (calibrations, key files, the ROS 2 cell file) a wrong type, an out-of-range value, an
unknown key and a missing key are each one line naming the field's path, and through the
command line exit 2 in one line; every shipped file of the kind has its schema's shape."""

from __future__ import annotations

from pathlib import Path

import pytest

from qpavoid.cli.commands import main
from qpavoid.core.errors import CalibrationError
from qpavoid.core.file_bounds import read_toml
from qpavoid.core.schema import convert
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.calibration_schema import CalibrationFile

ROOT = Path(__file__).resolve().parents[1]
EYE = "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]"
CALIBRATION = f'cell = "c"\n\n[sensors.cam]\nbase_from_camera = {EYE}\nweight = 1.0\n'


class _RefusedError(Exception):
    def __init__(self, name: str, message: str, value: object) -> None:
        super().__init__(message)
        self.name, self.value = name, value


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
    assert old in CALIBRATION
    path = tmp_path / "calib.toml"
    path.write_text(CALIBRATION.replace(old, new, 1))
    return path


@pytest.mark.parametrize("old, new, name, message", CALIBRATION_REFUSALS)
def test_a_calibration_of_the_wrong_shape_is_one_line_naming_the_path(
    tmp_path, old, new, name, message
):
    path = _calibration(tmp_path, old, new)
    with pytest.raises(CalibrationError) as info:
        load_calibration(path)
    text = str(info.value)
    assert text.startswith(f"calibration {path}: ") and "\n" not in text and message in text
    assert info.value.name == name and info.value.sensor == "cam"


@pytest.mark.parametrize("old, new, name, message", CALIBRATION_REFUSALS)
def test_a_run_with_a_calibration_of_the_wrong_shape_exits_2_in_one_line(
    tmp_path, capsys, old, new, name, message
):
    path, out = _calibration(tmp_path, old, new), tmp_path / "out"
    args = ["run", "--listen", "127.0.0.1:9", "--sensors", str(path), "--out", str(out)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and not out.exists()


def test_every_shipped_calibration_has_its_schema_s_shape():
    """docs/calibrations/*.toml: the shape alone (their key files are the user's to write)."""
    paths = sorted((ROOT / "docs" / "calibrations").glob("*.toml"))
    assert len(paths) == 5
    for path in paths:
        file = convert(read_toml(path, 2**20), CalibrationFile, _RefusedError)
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
    with pytest.raises(CalibrationError) as info:
        load_calibration(_keyed_cell(tmp_path, old, new))
    text = str(info.value)
    assert text.startswith(f"key file {tmp_path / 'cam.key'} of sensor 'cam': ")
    assert "\n" not in text and message in text and SECRET not in text
    assert info.value.name == name and info.value.value is None


@pytest.mark.parametrize("old, new, name, message", KEY_REFUSALS)
def test_a_run_with_a_key_file_of_the_wrong_shape_exits_2_in_one_line(
    tmp_path, capsys, old, new, name, message
):
    path, out = _keyed_cell(tmp_path, old, new), tmp_path / "out"
    assert main(["run", "--listen", "127.0.0.1:9", "--sensors", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and SECRET not in err and not out.exists()


def test_a_key_file_of_the_right_shape_loads(tmp_path):
    path = _keyed_cell(tmp_path, "id = 2", "id = 2")
    assert load_calibration(path).keys["cam"].ids == (2,)
