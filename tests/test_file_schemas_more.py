"""The shape of the last user files, checked by their schemas (msgspec): for each kind (the
body-region file, ...) a wrong type, an out-of-range value, an unknown key and a missing key
are each one line naming the field's path, through the command line (where a flag reads
the file) exit 2 in one line; every shipped file of the kind has its schema's shape."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from schema_files import RefusedError, refused, written

from qpavoid.core.errors import DataFileError
from qpavoid.core.file_bounds import read_toml
from qpavoid.core.schema import convert
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
    paths = sorted((ROOT / "qpavoid").rglob("*regions*.toml"))
    assert paths == [BODY_REGIONS_FILE]
    file = convert(read_toml(BODY_REGIONS_FILE, 2**20), RegionsFile, RefusedError)
    assert len(file.regions) == len(load_regions()) == 12
