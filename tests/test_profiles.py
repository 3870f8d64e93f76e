"""Numerical profiles (issue 16): engine.profile custom / reference / fast, engine.stiffness_scale,
siloflow run --profile; the plan records which profile ran and the bounds that come with it."""
from __future__ import annotations

import copy
import json
import math

import pytest
import yaml

from siloflow import contact_physics as cp
from siloflow.case_file import case_from_dict
from siloflow.derived import derive
from siloflow.errors import CaseError
from siloflow.profiles import FAST_PROFILE_FILE, REFERENCE, effective_case, fast_profile, with_profile

from conftest import ROOT


def plan_of(data):
    return derive(case_from_dict(data))


def with_engine(data, **engine):
    data = copy.deepcopy(data)
    data["engine"] = {**{k: v for k, v in data.get("engine", {}).items() if k not in ("timestep_fraction",)}, **engine}
    return data


def test_custom_is_the_default_and_keeps_the_case_settings(quick_dict):
    plan = plan_of(quick_dict)
    assert plan.profile.name == "custom"
    assert plan.timestep.fraction == quick_dict["engine"].get("timestep_fraction", 0.15)
    assert plan.profile.stiffness_scale == 1.0
    bare = with_engine(quick_dict)
    assert plan_of(bare).timestep.fraction == 0.15                 # the documented default


def test_reference_runs_the_papers_time_step(quick_dict):
    ref = plan_of(with_engine(quick_dict, profile="reference"))
    custom = plan_of(quick_dict)
    assert ref.profile.name == "reference" and ref.timestep.fraction == REFERENCE["timestep_fraction"] == 0.02
    assert ref.timestep.critical_time == pytest.approx(custom.timestep.critical_time, rel=1e-12)
    assert ref.dt == pytest.approx(0.02 * custom.timestep.critical_time, rel=1e-12)


def test_fast_profile_applies_the_benchmark_settings_and_records_its_bounds(quick_dict):
    fast = fast_profile()
    plan = plan_of(with_engine(quick_dict, profile="fast"))
    assert plan.profile.name == "fast"
    assert plan.timestep.fraction == fast["timestep_fraction"]
    assert plan.profile.stiffness_scale == fast["stiffness_scale"]
    assert plan.profile.error_bounds == fast.get("error_bounds", {})
    e = plan_of(quick_dict).materials["particle"].youngs_modulus
    assert plan.materials["particle"].youngs_modulus == pytest.approx(e * fast["stiffness_scale"], rel=1e-12)
    assert json.loads(FAST_PROFILE_FILE.read_text()) == fast


def test_the_packaged_fast_profile_is_the_committed_benchmarks_recommendation():
    """siloflow/fast_profile.json is copied from the accuracy benchmark's result: the two agree."""
    committed = ROOT / "benchmarks" / "results" / "accuracy" / "recommended_profile.json"
    if not committed.is_file():
        pytest.fail(f"{committed} is missing: the fast profile must come from a committed benchmark")
    rec = json.loads(committed.read_text())
    fast = fast_profile()
    assert (fast["timestep_fraction"], fast["stiffness_scale"]) == (rec["timestep_fraction"], rec["stiffness_scale"])
    assert fast["error_bounds"] == rec["error_bounds"]


@pytest.mark.parametrize("field,value", [("timestep_fraction", 0.1), ("stiffness_scale", 0.5)])
@pytest.mark.parametrize("profile", ["reference", "fast"])
def test_a_profile_refuses_the_settings_it_owns(quick_dict, field, value, profile):
    with pytest.raises(CaseError) as info:
        case_from_dict(with_engine(quick_dict, profile=profile, **{field: value}))
    assert f"engine.{field}" in str(info.value) and profile in str(info.value)


def test_stiffness_scale_scales_every_modulus_and_the_time_step_follows_hertz(quick_dict):
    base = plan_of(quick_dict)
    soft = plan_of(with_engine(quick_dict, timestep_fraction=base.timestep.fraction, stiffness_scale=0.01))
    for m in ("particle", "wall"):
        assert soft.materials[m].youngs_modulus == pytest.approx(0.01 * base.materials[m].youngs_modulus)
    # Hertz: contact time ~ E^(-2/5); Rayleigh time ~ E^(-1/2)
    c_base = min(p.contact_time for p in base.contacts)
    c_soft = min(p.contact_time for p in soft.contacts)
    assert c_soft / c_base == pytest.approx(0.01 ** -0.4, rel=1e-9)
    assert soft.timestep.critical_time / base.timestep.critical_time == pytest.approx(
        min(0.01 ** -0.5 * base.timestep.rayleigh_time, 0.01 ** -0.4 * c_base) / base.timestep.critical_time, rel=1e-9)


def test_stiffness_scale_scales_the_springs_of_the_linear_model():
    data = yaml.safe_load((ROOT / "decks" / "paper_a_spheres_quick.yaml").read_text())
    base = plan_of(data)
    data["engine"] = {**data.get("engine", {}), "stiffness_scale": 0.1}
    soft = plan_of(data)
    for a, b in zip(base.contacts, soft.contacts):
        assert b.kn == pytest.approx(0.1 * a.kn) and b.kt == pytest.approx(0.1 * a.kt)
        assert b.contact_time == pytest.approx(a.contact_time / math.sqrt(0.1), rel=1e-9)   # t_c ~ kn^(-1/2)


def test_a_scaled_modulus_below_the_floor_is_refused_naming_the_scale(quick_dict):
    with pytest.raises(CaseError) as info:
        plan_of(with_engine(quick_dict, stiffness_scale=1e-6))      # 5e6 Pa x 1e-6 is below 1e3 Pa
    assert "engine.stiffness_scale" in [f for f, _ in info.value.problems]


def test_reference_refuses_scaled_dust():
    data = yaml.safe_load((ROOT / "tests" / "data" / "slab_dust.yaml").read_text())
    data["particles"]["dust"]["density_scale"] = 25.0
    data["engine"] = {k: v for k, v in data.get("engine", {}).items() if k != "timestep_fraction"}
    data["engine"]["profile"] = "reference"
    with pytest.raises(CaseError) as info:
        plan_of(data)
    assert info.value.problems[0][0] == "particles.dust.density_scale"


def test_with_profile_replaces_the_case_settings_and_says_which(quick_dict):
    case = case_from_dict(with_engine(quick_dict, timestep_fraction=0.1, stiffness_scale=0.5))
    fast, dropped = with_profile(case, "fast")
    assert dropped == ["engine.timestep_fraction", "engine.stiffness_scale"]
    assert fast.engine.profile == "fast" and fast.engine.timestep_fraction is None
    same, none = with_profile(case, "custom")
    assert none == [] and same.engine.timestep_fraction == 0.1
    with pytest.raises(CaseError) as info:
        with_profile(case, "turbo")
    assert info.value.problems[0][0] == "--profile"


def test_the_effective_case_keeps_the_profile_name_and_validates(quick_dict):
    case = case_from_dict(with_engine(quick_dict, profile="reference"))
    eff = effective_case(case)
    assert eff.engine.profile == "reference" and eff.engine.timestep_fraction == 0.02


def test_the_profile_does_not_change_the_fill_key_of_the_same_bed(quick_dict):
    """custom at 0.02 and reference make the same bed: one fill in the cache."""
    from siloflow.fill_cache import fill_key

    class FakeEngine:
        def fill_key_parts(self, plan):
            return {"name": "fake"}
    ref = plan_of(with_engine(quick_dict, profile="reference"))
    custom = plan_of(with_engine(quick_dict, timestep_fraction=0.02))
    assert ref.profile != custom.profile
    assert fill_key(ref, FakeEngine()) == fill_key(custom, FakeEngine())
