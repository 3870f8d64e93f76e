"""Bad case files are refused with the field named, a non-zero exit and no deck on disk."""
from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from siloflow.case_file import case_from_dict, load_case
from siloflow.cli import app
from siloflow.derived import MAX_RUN_STEPS, check_run_length, derive
from siloflow.errors import CaseError, SetupError

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
    ("engine.timestep_fraction", 0.0, "engine.timestep_fraction", "greater than or equal to 0.001"),
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


# ----------------------------------------------------------------- issue 13, item 10: absurd values
ABSURD = [
    # (path, value, field named, words): each passed validation before
    ("particles.radius", 1e-12, "particles.radius", "greater than or equal to 0.000001"),
    ("engine.timestep_fraction", 1e-9, "engine.timestep_fraction", "greater than or equal to 0.001"),
    ("materials.particle.density", 1e-9, "materials.particle.density", "greater than or equal to 1.2"),
    ("materials.particle.density", True, "materials.particle.density", "not true/false"),
    ("fill.count", True, "fill.count", "whole number, not true/false"),
    ("seed", False, "seed", "whole number, not true/false"),
    ("fill.count", 5000.5, "fill.count", "whole number"),
    ("outputs.sample_interval", 2.0, "(top level)", "longer than the discharge (discharge.duration 1.0 s)"),
    ("fill.settle.static_window", 0.006, "(top level)", "at least two outputs.sample_interval"),
]


@pytest.mark.parametrize("path,value,field,words", ABSURD, ids=[f"{a[0]}={a[1]!r}" for a in ABSURD])
def test_absurd_values_are_refused(quick_dict, path, value, field, words):
    set_path(quick_dict, path, value)
    with pytest.raises(CaseError) as info:
        case_from_dict(quick_dict)
    assert any(f.startswith(field) and words in m for f, m in info.value.problems), info.value.problems


def test_sample_interval_is_checked_against_an_until_empty_discharge(quick_dict):
    quick_dict["discharge"] = {"until_empty": True, "max_time": 0.5}
    quick_dict["outputs"]["sample_interval"] = 0.6
    quick_dict["fill"]["settle"]["static_window"] = 1.2
    with pytest.raises(CaseError, match=r"discharge.max_time 0.5 s"):
        case_from_dict(quick_dict)


def test_a_run_over_the_step_cap_needs_allow_long(quick_dict):
    quick_dict["discharge"]["duration"] = 1e5        # valid on its own (le 1e5 s), 3.6e9 steps
    d = derive(case_from_dict(quick_dict))
    assert d.total_planned_steps > MAX_RUN_STEPS
    with pytest.raises(SetupError) as info:
        check_run_length(d, allow_long=False)
    message = str(info.value)
    for words in ("discharge.duration", "particles.radius", "materials.particle.youngs_modulus",
                  "engine.timestep_fraction", "--allow-long", f"{d.total_planned_steps:.3g} steps"):
        assert words in message, message
    assert check_run_length(d, allow_long=True) == d.total_planned_steps


@pytest.mark.parametrize("case_file", sorted((QUICK.parent).glob("*.yaml")), ids=lambda p: p.name)
def test_shipped_decks_are_within_the_step_cap_and_warn_about_nothing(case_file):
    d = derive(load_case(case_file))
    assert check_run_length(d) == d.total_planned_steps <= MAX_RUN_STEPS
    assert d.warnings == []


def test_soft_benchmark_modulus_is_accepted_with_a_warning_naming_the_consequence(quick_dict):
    """Published hopper benchmarks use E = 1e6 Pa on purpose: it validates, and the expected overlap
    under the bed's weight (Hertz, Janssen pressure) comes with a warning saying what it does."""
    quick_dict["materials"]["particle"]["youngs_modulus"] = 1e6
    quick_dict["materials"]["wall"]["youngs_modulus"] = 1e6
    d = derive(case_from_dict(quick_dict))
    [warning] = d.warnings
    for words in ("overlap", "% of their radius", "compressed", "materials.particle.youngs_modulus"):
        assert words in warning, warning
    assert json.loads(d.to_json())["warnings"] == [warning]          # plan.json keeps it


def test_overlap_warning_follows_hertz_scaling(quick_dict):
    """The overlap goes as E^(-2/3): ten times softer grains overlap 10^(2/3) = 4.64 times more."""
    import re

    def overlap(e):
        data = {**quick_dict, "materials": {**quick_dict["materials"],
                                            "particle": {**quick_dict["materials"]["particle"], "youngs_modulus": e},
                                            "wall": {"youngs_modulus": e, "poisson_ratio": 0.3}}}
        [warning] = derive(case_from_dict(data)).warnings
        return float(re.search(r"overlap by about ([0-9.]+)%", warning).group(1))

    assert overlap(1e4) / overlap(1e5) == pytest.approx(10 ** (2 / 3), rel=0.02)


def test_coarse_timestep_and_air_drag_are_warned_about(quick_dict):
    quick_dict["engine"]["timestep_fraction"] = 0.5
    [warning] = derive(case_from_dict(quick_dict)).warnings
    assert "engine.timestep_fraction" in warning and "unstable" in warning
    quick_dict["engine"]["timestep_fraction"] = 0.15
    quick_dict["particles"]["radius"] = 2e-5          # 40 um powder: air matters, siloflow models none
    quick_dict["geometry"].update(radius=0.002, height=0.01, orifice_radius=0.0005)   # within the engine's bins
    quick_dict["fill"]["count"] = 300
    quick_dict["sensors"] = {"bands": 2}
    warnings = derive(case_from_dict(quick_dict)).warnings
    assert any("air drag" in w and "no gas" in w for w in warnings), warnings


def test_a_needle_hopper_is_refused_before_its_meshes_fill_memory(tmp_path):
    """Found by the scaled fuzz test: a half angle of 6e-8 degrees made a wedge hopper 1.4e7 m tall
    whose meshes needed gigabytes (MemoryError); the hopper's height is now bounded like the wall's."""
    import yaml
    from conftest import ROOT
    data = yaml.safe_load((ROOT / "tests" / "data" / "slab_dust.yaml").read_text())
    data["geometry"]["half_angle_deg"] = 2e-7        # 6e-8 is now below the field's own bound (MIN_HALF_ANGLE_DEG)
    with pytest.raises(CaseError) as info:
        case_from_dict(data)
    assert any(f == "geometry" and "makes the hopper" in m for f, m in info.value.problems), info.value.problems
    data["geometry"]["half_angle_deg"] = 6e-8
    with pytest.raises(CaseError) as info:
        case_from_dict(data)
    assert [f for f, _ in info.value.problems] == ["geometry.half_angle_deg"], info.value.problems


#: every time and interval of the case schema (s): its dotted path and the case fields it needs to be read
TIME_FIELDS = {
    "fill.settle.check_interval": {}, "fill.settle.max_time": {}, "fill.settle.static_window": {},
    "fill.mobilise.time": {"fill.mobilise": {}}, "fill.pour_time": {"fill.protocol": "pour"},
    "discharge.duration": {}, "discharge.max_time": {"discharge": {"until_empty": True}},
    "discharge.batch_time": {"discharge": {"until_steady": True}},
    "discharge.startup_time": {"discharge": {"until_steady": True}},
    "outputs.sample_interval": {}, "outputs.dump_interval": {},
}


def test_the_time_fields_list_covers_the_schema():
    """A new time or interval field of the schema joins TIME_FIELDS (and so the bound test below)."""
    import re
    from siloflow.case import Case
    defs = Case.model_json_schema()["$defs"]
    found = {(model, name) for model, d in defs.items() for name in d.get("properties", {})
             if re.search(r"time|interval|duration|window", name) and "fraction" not in name}
    assert found == {("Settle", "check_interval"), ("Settle", "max_time"), ("Settle", "static_window"),
                     ("Mobilise", "time"), ("Fill", "pour_time"), ("Discharge", "duration"),
                     ("Discharge", "max_time"), ("Discharge", "batch_time"), ("Discharge", "startup_time"),
                     ("Outputs", "sample_interval"), ("Outputs", "dump_interval")}, found
    assert len(TIME_FIELDS) == len(found)


@pytest.mark.parametrize("value", [1e308, math.inf, -math.inf, math.nan, 1e9])
@pytest.mark.parametrize("path", sorted(TIME_FIELDS))
def test_every_time_and_interval_is_bounded_naming_the_field(quick_dict, path, value):
    """Issue 34.11: outputs.dump_interval 1e308 ended in an OverflowError traceback in validate."""
    import copy
    for where, given in copy.deepcopy(TIME_FIELDS[path]).items():
        if where == "discharge":
            quick_dict["discharge"] = given
        else:
            set_path(quick_dict, where, given)
    case_from_dict(quick_dict)                      # the setting itself is valid
    set_path(quick_dict, path, value)
    with pytest.raises(CaseError) as info:
        derive(case_from_dict(quick_dict))
    section = path.rsplit(".", 1)[0]
    assert any(p == path or (p == section and path in m) for p, m in info.value.problems), info.value.problems


@pytest.mark.parametrize("text", ["1e308", ".inf", ".nan", "1000"])
def test_validate_refuses_a_huge_dump_interval_without_a_traceback(tmp_path, quick_dict, text):
    import yaml
    quick_dict["outputs"]["dump_interval"] = "PLACEHOLDER"
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(quick_dict).replace("PLACEHOLDER", text))
    result = runner.invoke(app, ["validate", str(path)], env={"COLUMNS": "300"})
    assert result.exit_code == 1 and "outputs.dump_interval" in result.output, result.output
    assert isinstance(result.exception, SystemExit)
    if text == "1000":
        assert "longer than the whole run" in result.output


def test_a_settling_check_longer_than_the_settling_is_refused(quick_dict):
    set_path(quick_dict, "fill.settle.check_interval", 2.0)
    with pytest.raises(CaseError, match="check_interval .* longer than the settling"):
        case_from_dict(quick_dict)


@pytest.mark.parametrize("changes, field", [
    ({"fill.settle.check_interval": 1.0e-308, "fill.settle.max_time": 2.0}, "fill.settle.check_interval"),
    ({"materials.model": "hooke", "materials.characteristic_velocity": 1.0e-308}, "materials.characteristic_velocity"),
    ({"design": {"phi_r_deg": 89.99, "material": "wheat"}}, "design.phi_r_deg"),
    ({"design": {"phi_r_deg": 1.0e-300, "material": "wheat"}}, "design.phi_r_deg"),
    ({"gravity": 5e-324}, "gravity"),
    ({"sensors": {"heights": [5e-324, 0.1], "sectors": 4}}, "sensors"),
], ids=["check-interval", "characteristic-velocity", "steep-repose", "flat-repose", "gravity", "band-boundary"])
def test_validate_refuses_extreme_but_once_valid_numbers_by_field(quick_dict, write_case, changes, field):
    """Issue 55.8: these passed the schema and ended in an OverflowError (check_interval, a repose
    angle of 89.99 deg on a squat silo), a ZeroDivisionError (characteristic_velocity, gravity), an
    OverflowError in the walls (a band 5e-324 m high) or NaN design loads (repose 1e-300 deg): each
    is now bounded by physics in the schema, and validate names the field."""
    for path, value in changes.items():
        set_path(quick_dict, path, value)
    result = runner.invoke(app, ["validate", str(write_case(quick_dict))], env={"COLUMNS": "300"})
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit), result.output
    assert f"  {field}:" in result.output and "Traceback" not in result.output, result.output
