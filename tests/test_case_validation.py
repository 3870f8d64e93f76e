"""Bad case files are refused with the field named, a non-zero exit and no deck on disk."""
from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from siloflow.case import load_case
from siloflow.cli import app
from siloflow.errors import CaseError

from conftest import QUICK, set_path

runner = CliRunner()


def test_quick_case_is_valid():
    case = load_case(QUICK)
    assert case.name == "quick" and case.fill.count == 5000


BAD = [
    ("geometry.orifice_radius", 0.02, "geometry", "smaller than radius"),
    ("geometry.radius", 0.0, "geometry.radius", "greater than 0"),
    ("geometry.radius", -0.1, "geometry.radius", "greater than 0"),
    ("geometry.height", math.nan, "geometry.height", "finite"),
    ("geometry.height", math.inf, "geometry.height", "finite"),
    ("materials.particle_particle.friction", -0.1, "materials.particle_particle.friction", "greater than or equal"),
    ("materials.particle_wall.friction", -1.0, "materials.particle_wall.friction", "greater than or equal"),
    ("engine.timestep_fraction", 1.5, "engine.timestep_fraction", "less than or equal to 1"),
    ("engine.timestep_fraction", 0.0, "engine.timestep_fraction", "greater than 0"),
    ("particles.radius", 0.009, "(top level)", "smaller than the outlet"),
    ("name", "quick\nshell rm -rf /", "name", "only letters"),
    ("name", "a;shell ls", "name", "only letters"),
    ("name", "../escape", "name", "only letters"),
    ("materials.particle.density", "heavy", "materials.particle.density", "valid number"),
    ("sensors.sectors", 1, "sensors.sectors", "greater than or equal to 3"),
    ("engine.ranks", 0, "engine.ranks", "greater than or equal to 1"),
    ("fill.settle.ke_pe_ratio", 2.0, "fill.settle.ke_pe_ratio", "less than 1"),
]


@pytest.mark.parametrize("path,value,field,words", BAD, ids=[f"{b[0]}={b[1]!r}" for b in BAD])
def test_bad_value_is_refused_with_its_field(quick_dict, write_case, tmp_path, path, value, field, words):
    set_path(quick_dict, path, value)
    case_file = write_case(quick_dict)
    with pytest.raises(CaseError) as info:
        load_case(case_file)
    fields = [f for f, _ in info.value.problems]
    assert any(f.startswith(field) for f in fields), info.value.problems
    assert words in str(info.value)
    # the CLI refuses it too: exit code 1, the field named, no deck written
    out = tmp_path / "deck"
    result = runner.invoke(app, ["render", str(case_file), "-o", str(out)])
    assert result.exit_code == 1
    assert field.split(".")[0] in result.output
    assert not out.exists()


@pytest.mark.parametrize("where", [None, "geometry", "materials.particle", "fill.settle"])
def test_unknown_keys_are_errors(quick_dict, write_case, where):
    target = quick_dict
    for k in (where.split(".") if where else []):
        target = target[k]
    target["colour"] = "blue"
    with pytest.raises(CaseError) as info:
        load_case(write_case(quick_dict))
    assert any(f.endswith("colour") and "unknown key" in m for f, m in info.value.problems)


def test_every_problem_is_reported_at_once(quick_dict, write_case):
    quick_dict["geometry"]["radius"] = -1
    quick_dict["materials"]["particle_particle"]["friction"] = -1
    quick_dict["bogus"] = 1
    with pytest.raises(CaseError) as info:
        load_case(write_case(quick_dict))
    assert len(info.value.problems) >= 3


def test_count_and_height_are_exclusive(quick_dict, write_case):
    quick_dict["fill"]["height"] = 0.1
    with pytest.raises(CaseError, match="exactly one of 'count' or 'height'"):
        load_case(write_case(quick_dict))


def test_linear_model_needs_springs(quick_dict, write_case):
    quick_dict["materials"]["model"] = "linear"
    with pytest.raises(CaseError, match="kn and kt are required"):
        load_case(write_case(quick_dict))


def test_hertz_model_refuses_springs(quick_dict, write_case):
    quick_dict["materials"]["particle_wall"]["kn"] = 1e5
    with pytest.raises(CaseError, match="belong to model 'linear'"):
        load_case(write_case(quick_dict))


@pytest.mark.parametrize("text,words", [
    ("name: a\nname: b\n", "duplicate key"),
    ("base: &b {radius: 1}\ngeometry: *b\n", "aliases"),
    ("geometry: [unclosed\n", "line"),
    ("- just\n- a list\n", "mapping"),
    ("", "mapping"),
])
def test_malformed_yaml_is_refused(write_case, text, words):
    with pytest.raises(CaseError, match=words):
        load_case(write_case(text))


def test_validate_cli_exit_codes(quick_dict, write_case):
    good = runner.invoke(app, ["validate", str(QUICK)])
    assert good.exit_code == 0 and "valid case" in good.output
    quick_dict["geometry"]["radius"] = "nan"
    bad = runner.invoke(app, ["validate", str(write_case(quick_dict))])
    assert bad.exit_code == 1
    assert "geometry.radius" in bad.output and "Traceback" not in bad.output


def test_schema_cli_prints_json_schema():
    result = runner.invoke(app, ["schema"])
    assert result.exit_code == 0
    schema = json.loads(result.output)
    assert {"geometry", "materials", "fill", "discharge", "engine"} <= set(schema["properties"])
    assert schema.get("additionalProperties") is False
