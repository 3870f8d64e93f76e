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
from siloflow.packaged_profile import QUESTIONS
from siloflow.profiles import (FAST_PROFILE_FILE, REFERENCE, effective_case, fast_profile, impact_overlap_ratio,
                               packaged_fast_profile,
                               profile_settings, with_profile)

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


def test_fast_profile_softens_a_stiff_case_to_the_benchmarked_impact_overlap():
    """The accuracy benchmark's own case at paper B's stiffness (hooke, Y 1.2e11 Pa) is stiffer than the
    profile's softness: its moduli are lowered until the impact overlap is the profile's overlap_ratio;
    the time step is the profile's."""
    data = yaml.safe_load((ROOT / "benchmarks" / "cases" / "accuracy_small.yaml").read_text())
    fast = packaged_fast_profile(data.get("outputs", {}).get("results"))
    data["engine"] = {k: v for k, v in data["engine"].items() if k not in ("profile", "timestep_fraction")}
    case = case_from_dict(data)
    assert impact_overlap_ratio(case) < fast["overlap_ratio"]
    plan = derive(case_from_dict({**data, "engine": {**data["engine"], "profile": "fast"}}))
    assert plan.profile.name == "fast" and plan.timestep.fraction == fast["timestep_fraction"]
    s = plan.profile.stiffness_scale
    assert s < 1 and impact_overlap_ratio(case, s) == pytest.approx(fast["overlap_ratio"], rel=1e-9)
    assert plan.materials["particle"].youngs_modulus == pytest.approx(1.2e11 * s, rel=1e-12)
    assert plan.profile.error_bounds == fast.get("error_bounds", {})
    assert plan.profile.overlap_ratio == fast["overlap_ratio"]


def test_fast_profile_never_stiffens_or_softens_an_already_soft_case(quick_dict):
    case = case_from_dict(with_engine(quick_dict, profile="fast"))
    soft = case.model_copy(update={"engine": case.engine.model_copy(update={"fast_profile": case.engine.fast_profile.model_copy(
        update={"overlap_ratio": 1e-4})})})
    assert impact_overlap_ratio(soft) > 1e-4
    assert profile_settings(soft)["stiffness_scale"] == 1.0


def test_the_impact_overlap_follows_hertz_and_the_linear_spring(quick_dict):
    case = case_from_dict(quick_dict)
    assert impact_overlap_ratio(case, 0.01) / impact_overlap_ratio(case) == pytest.approx(0.01 ** -0.4, rel=1e-12)
    lin = case_from_dict(yaml.safe_load((ROOT / "decks" / "paper_a_spheres_quick.yaml").read_text()))
    assert impact_overlap_ratio(lin, 0.25) / impact_overlap_ratio(lin) == pytest.approx(2.0, rel=1e-12)


def test_a_fast_case_carries_its_profile_and_keeps_it(quick_dict):
    """The validated case holds a copy of the fast profile (its run folder resumes with it); a copy
    given in the case wins over what this siloflow packages."""
    case = case_from_dict(with_engine(quick_dict, profile="fast"))
    fast = packaged_fast_profile(quick_dict.get("outputs", {}).get("results"))
    assert case.engine.fast_profile.overlap_ratio == fast["overlap_ratio"]
    pinned = case.model_dump(mode="json")
    pinned["engine"]["fast_profile"]["timestep_fraction"] = 0.123
    again = case_from_dict(pinned)
    assert derive(again).timestep.fraction == 0.123
    with pytest.raises(CaseError) as info:
        case_from_dict(with_engine(quick_dict, fast_profile=pinned["engine"]["fast_profile"]))
    assert "engine.fast_profile belongs to profile 'fast'" in str(info.value)


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


@pytest.mark.parametrize("profile", ["reference", "fast"])
def test_the_effective_case_is_a_valid_custom_case_and_applying_it_twice_changes_nothing(quick_dict, profile):
    case = case_from_dict(with_engine(quick_dict, profile=profile))
    eff = effective_case(case)
    assert eff.engine.profile == "custom" and eff.engine.timestep_fraction == profile_settings(case)["timestep_fraction"]
    assert case_from_dict(eff.model_dump(mode="json")) == eff
    assert effective_case(eff) == eff


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


def test_the_report_names_the_profile_and_its_bounds():
    from postprocess.report import profile_line
    fast = {"name": "fast", "timestep_fraction": 0.2, "stiffness_scale": 1e-4,
            "error_bounds": {"flow_rate": 0.041, "static_pressure": 0.12}, "benchmark": "accuracy_small"}
    line = profile_line(fast)
    assert "profile fast" in line and "flow_rate 4.1%" in line and "static_pressure 12.0%" in line
    assert "measured on the benchmark's case" in line and "another case's own error is not measured" in line
    assert "not measured yet" in profile_line({**fast, "error_bounds": {}})
    assert "custom" in profile_line({"name": "custom", "timestep_fraction": 0.15, "stiffness_scale": 1.0})
    assert "older siloflow" in profile_line(None)


def test_the_run_line_says_the_bounds_are_the_benchmark_cases():
    from siloflow.cli import profile_note
    from siloflow.plan import Profile
    fast = Profile(name="fast", timestep_fraction=0.1, stiffness_scale=0.1, overlap_ratio=0.026,
                   error_bounds={"flow_rate": 0.03}, speedup=11.2, benchmark="accuracy_small.yaml",
                   question="flow_rate", unbounded=["coordination"], measured={"coordination": [0.053, 0.033, 0.074]})
    line = profile_note(fast)
    assert "flow_rate within 3.0%" in line and "measured on the benchmark's case" in line
    assert "proven for flow rate" in line
    assert "not bounded by this profile: coordination (measured +5.3% [+3.3%, +7.4%] there)" in line
    assert "another case's own error is not measured" in line
    assert "11.2x faster there: accuracy_small.yaml" in line
    assert "not measured yet" in profile_note(fast.model_copy(update={"error_bounds": {}}))


def test_the_packaged_fast_profile_is_the_committed_benchmarks_proven_recommendation():
    """siloflow/fast_profile.json is written from the accuracy benchmark's result
    (benchmarks/publish_fast_profile.py): the two agree, and the recommendation met its tolerances."""
    committed = ROOT / "benchmarks" / "results" / "accuracy" / "recommended_profile.json"
    if not committed.is_file():
        pytest.fail(f"{committed} is missing: the fast profile must come from a committed benchmark")
    rec = json.loads(committed.read_text())
    published = fast_profile()["profiles"]
    assert "flow_rate_and_static_pressure" in published
    for question, fast in published.items():
        r = rec["questions"][question]
        assert (fast["candidate"], fast["timestep_fraction"], fast["overlap_ratio"]) == (
            r["candidate"], r["timestep_fraction"], r["overlap_ratio"])
        assert fast["error_bounds"] == r["error_bounds"] and r["meets_tolerances"] is True
        assert set(r["error_bounds"]) == set(QUESTIONS[question])
        assert all(r["error_bounds"][q] <= r["tolerances"][q] for q in r["tolerances"])
        assert {c["quantity"] for c in r["validation"] if c["inside"]} == set(r["error_bounds"])
    for question, r in rec["questions"].items():       # a question left out has nothing faster proven
        assert question in published or r["candidate"] == "reference" or not all(
            c["inside"] for c in r["validation"])


@pytest.mark.engine
def test_siloflow_run_profile_fast_runs_and_says_what_it_ran(tmp_path):
    """`siloflow run --profile fast` on the small silo: the case's own time step is replaced (and said so),
    its glass-soft grains (impact overlap 0.18 of a radius) are not softened further, the run completes,
    and the run folder's case, plan, report and summary name the profile and its bounds; a second render of
    the folder's case.yaml gives the same plan (the pinned profile), as a resume needs."""
    from typer.testing import CliRunner
    from siloflow.cli import app
    from siloflow.run_folder import RunFolder
    data = yaml.safe_load((ROOT / "tests" / "data" / "small_silo.yaml").read_text())
    data.update(name="fast_small")
    data["fill"]["count"] = 600
    data["discharge"] = {"duration": 0.3}
    data["outputs"] = {"sample_interval": 0.005, "results": ["flow_rate", "force_balance"]}
    data["engine"] = {"ranks": 1, "timestep_fraction": 0.2}
    case_file = tmp_path / "case.yaml"
    case_file.write_text(yaml.safe_dump(data))
    result = CliRunner().invoke(app, ["run", str(case_file), "-o", str(tmp_path / "run"), "--profile", "fast"])
    assert result.exit_code == 0, result.output
    assert "--profile fast replaces the case's engine.timestep_fraction" in result.output
    run = RunFolder(tmp_path / "run")
    plan = run.plan
    assert plan.profile.name == "fast" and plan.profile.stiffness_scale == 1.0
    fast = packaged_fast_profile(["flow_rate", "force_balance"])
    assert plan.timestep.fraction == fast["timestep_fraction"]
    report = (run.results / "report.md").read_text()
    assert "numerical profile fast" in report and "95 % error bounds" in report
    assert run.read_summary()["numerical_profile"]["error_bounds"] == fast["error_bounds"]
    from siloflow.case_file import load_case
    again = derive(load_case(run.case_file))
    assert again.to_json() == plan.to_json()


def test_a_bed_settled_without_the_guard_is_not_taken_from_the_cache_by_a_guarded_run(quick_dict):
    from siloflow.fill_cache import fill_key

    class FakeEngine:
        def fill_key_parts(self, plan):
            return {"name": "fake"}
    watched = plan_of(quick_dict)
    loose = plan_of(with_engine(quick_dict, timestep_fraction=watched.timestep.fraction, guard={"max_overlap": 1.0}))
    unwatched = plan_of(with_engine(quick_dict, timestep_fraction=watched.timestep.fraction, guard={"enabled": False}))
    assert fill_key(watched, FakeEngine()) == fill_key(loose, FakeEngine())          # other limits: the same bed
    assert fill_key(watched, FakeEngine()) != fill_key(unwatched, FakeEngine())


def test_publishing_needs_every_bounded_quantity_checked_inside_its_bound(tmp_path, monkeypatch):
    """benchmarks/publish_fast_profile.py writes a question's profile only when the new seeds' check put
    each bounded quantity's error inside its bound; a missing or outside check refuses the flow rate and
    static pressure's profile (writing nothing) and leaves out another question's."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("publish", ROOT / "benchmarks" / "publish_fast_profile.py")
    publish = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(publish)
    source, target = tmp_path / "recommended_profile.json", tmp_path / "fast_profile.json"
    monkeypatch.setattr(publish, "SOURCE", source)
    monkeypatch.setattr(publish, "TARGET", target)
    check = dict(rel_error=0.004, ci_lo=-0.03, ci_hi=0.04, bound=0.03, inside=True, consistent=True, n=10)
    both = {"candidate": "E1e-1_dt0.1", "meets_tolerances": True, "timestep_fraction": 0.1, "overlap_ratio": 0.026,
            "speedup": 11.0, "error_bounds": {"flow_rate": 0.03, "static_pressure": 0.038},
            "validation": [dict(check, quantity="flow_rate")]}
    flow = {**both, "candidate": "E1e-2_dt0.1", "speedup": 27.0, "error_bounds": {"flow_rate": 0.03},
            "validation": [dict(check, quantity="flow_rate", inside=False, rel_error=0.031)]}
    rec = {**both, "questions": {"flow_rate": flow, "flow_rate_and_static_pressure": both,
                                 "everything": {"candidate": "reference"}}}

    def write():
        source.write_text(json.dumps(rec))
    write()
    with pytest.raises(SystemExit, match="not confirmed"):         # static pressure not checked
        publish.main()
    both["validation"].append(dict(check, quantity="static_pressure", inside=False, rel_error=0.05, bound=0.038))
    write()
    with pytest.raises(SystemExit, match="not confirmed"):         # outside its bound, though consistent
        publish.main()
    assert not target.exists()
    both["validation"][1].update(inside=True, rel_error=0.0, failed=1)
    write()
    with pytest.raises(SystemExit, match="new seeds failed"):     # inside, but a new seed's run failed
        publish.main()
    assert not target.exists()
    both["validation"][1].update(failed=0)
    write()
    publish.main()                                                 # the flow-only one outside its bound: left out
    assert list(json.loads(target.read_text())["profiles"]) == ["flow_rate_and_static_pressure"]
    flow["validation"][0].update(inside=True, rel_error=0.01)
    write()
    publish.main()
    profiles = json.loads(target.read_text())["profiles"]
    assert {q: p["candidate"] for q, p in profiles.items()} == {"flow_rate": "E1e-2_dt0.1",
                                                                 "flow_rate_and_static_pressure": "E1e-1_dt0.1"}
    del rec["questions"]
    write()
    with pytest.raises(SystemExit, match="no recommendation for flow_rate_and_static_pressure"):
        publish.main()


def test_a_fast_case_runs_the_profile_proven_for_what_it_asks(quick_dict):
    """profile: fast applies the fastest published profile that bounds every benchmarked quantity the
    case's outputs.results ask (the flow rate alone: the flow-only profile); a case asking more than any
    profile bounds runs the one bounding the most, and its plan names the rest as unbounded with the
    errors measured at the profile; the report says so."""
    from postprocess.report.text import profile_line
    from siloflow.packaged_profile import asked_quantities, choose_profile
    published = fast_profile()["profiles"]
    assert asked_quantities(["porosity"]) == ("flow_rate", "solid_fraction")
    assert asked_quantities(None) == QUESTIONS["everything"]
    assert asked_quantities(["wall_pressure", "vtk"]) == ("flow_rate", "static_pressure", "dynamic_pressure_max")
    flow_only = plan_of(with_engine({**quick_dict, "outputs": {**quick_dict.get("outputs", {}),
                                                                 "results": ["flow_rate"]}}, profile="fast"))
    assert flow_only.profile.question == choose_profile(["flow_rate"])[0]
    assert flow_only.profile.unbounded == []
    assert flow_only.profile.speedup == max(p["speedup"] for p in published.values())
    static = plan_of(with_engine({**quick_dict, "outputs": {**quick_dict.get("outputs", {}),
                                                              "results": ["flow_rate", "force_balance"]}},
                                 profile="fast"))
    assert static.profile.question == "flow_rate_and_static_pressure" and static.profile.unbounded == []
    everything = plan_of(with_engine({k: v for k, v in quick_dict.items() if k != "outputs"}, profile="fast"))
    if "everything" not in published:
        assert everything.profile.question == "flow_rate_and_static_pressure"
        assert everything.profile.unbounded == ["dynamic_pressure_max", "solid_fraction", "coordination"]
        assert set(everything.profile.measured) >= set(everything.profile.unbounded)
        line = profile_line(everything.profile.model_dump(mode="json"))
        assert "not bounded by this profile: dynamic_pressure_max (measured" in line and "profile reference" in line
    # a choice among made-up profiles: the fastest covering wins; none covering: the most covered
    made = {"a": {"error_bounds": {"flow_rate": 0.03}, "speedup": 50.0},
            "b": {"error_bounds": {"flow_rate": 0.03, "static_pressure": 0.05}, "speedup": 10.0},
            "c": {"error_bounds": {"flow_rate": 0.03, "coordination": 0.05}, "speedup": 5.0}}
    assert choose_profile(["flow_rate"], made)[0] == "a"
    assert choose_profile(["force_balance"], made)[0] == "b"
    assert choose_profile(["coordination"], made)[0] == "c"
    assert choose_profile(["porosity"], made)[0] == "a"            # none bounds it: the fastest of the most
    assert choose_profile(None, made)[0] == "b"                    # two bounded each: the faster


def test_the_time_to_answer_page_shows_the_committed_table():
    """docs/time_to_answer.md's table is benchmarks/results/time_to_answer/time_to_answer.csv as
    ``make bench-time-to-answer`` writes it (its --doc option puts it there again)."""
    import importlib.util
    import pandas as pd
    spec = importlib.util.spec_from_file_location("time_to_answer", ROOT / "benchmarks" / "time_to_answer.py")
    tta = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tta)
    table = pd.read_csv(tta.OUT / "time_to_answer.csv")
    assert len(table) == 3
    assert tta.doc_table(tta.DOC.read_text()) == tta.markdown(table)
    assert (tta.OUT / "time_to_answer.md").read_text() == tta.markdown(table)
