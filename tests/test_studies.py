"""siloflow bench and siloflow stability (issue 16): candidate and burst cases, the resumable run
table, the metrics read from a run, the envelope's safe edge; and one real envelope on the engine."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from siloflow import accuracy_bench as ab
from siloflow import stability as st
from siloflow.case_file import case_from_dict
from siloflow.derived import auto_dump_interval, derive
from siloflow.errors import EngineRunError, SetupError
from siloflow.run_table import PlannedRun, read_rows, run_missing

from conftest import ROOT, SMALL, render_deck

SHIPPED = sorted((ROOT / "decks").glob("*quick*.yaml")) + sorted((ROOT / "tests" / "data").glob("*.yaml"))


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_candidate_and_burst_cases_of_every_shipped_case_are_valid(path):
    base = yaml.safe_load(path.read_text())
    for cand in (ab.REFERENCE, ab.CANDIDATES[1]):
        data = ab.candidate_case(base, cand, 7)
        case = case_from_dict(data)
        assert case.engine.profile == "custom" and case.seed == 7
        assert case.engine.timestep_fraction == cand.timestep_fraction
        assert case.engine.stiffness_scale == cand.stiffness_scale
    burst = case_from_dict(st.burst_case(base, 1.0, 1e-2, 3, 0.05))
    assert burst.outputs.results == ["flow_rate"] and burst.discharge.duration == 0.05
    assert burst.engine.guard.enabled and burst.engine.timestep_fraction == 1.0
    assert burst.fill.settle.max_time <= 10 * burst.fill.settle.check_interval + 1e-12


def test_the_bench_reference_is_the_papers_settings():
    assert (ab.REFERENCE.timestep_fraction, ab.REFERENCE.stiffness_scale) == (0.02, 1.0)
    assert ab.CANDIDATES[0] is ab.REFERENCE and len({c.name for c in ab.CANDIDATES}) == len(ab.CANDIDATES)


def fake_summary(folder: Path, rate=0.01, bands=(500.0, 400.0, 10.0, 0.0), dyn=600.0, phi=0.6, z=5.0, wall=3.0):
    (folder / "results").mkdir(parents=True)
    summary = {"engine_wall_time_s": wall, "flow_rate": {"rate": rate},
               "bands": [{"band": k, "static_pressure": p, "dynamic_max_pressure": dyn} for k, p in enumerate(bands)],
               "frame_analyses": {"bulk_solid_fraction": phi, "coordination_settled": {"z_mean": z}}}
    (folder / "results" / "summary.json").write_text(json.dumps(summary))


def test_run_metrics_reads_the_quantities_and_skips_unloaded_bands(tmp_path):
    fake_summary(tmp_path)
    m = ab.run_metrics(tmp_path)
    assert m["flow_rate"] == 0.01 and m["wall_s"] == 3.0
    assert m["static_pressure"] == pytest.approx(450.0)          # 10 Pa is under 5 % of 500: not loaded
    assert m["dynamic_pressure_max"] == 600.0 and m["solid_fraction"] == 0.6 and m["coordination"] == 5.0


def test_a_measurement_that_could_not_be_made_is_nan(tmp_path):
    fake_summary(tmp_path)
    s = json.loads((tmp_path / "results" / "summary.json").read_text())
    s["frame_analyses"]["bulk_solid_fraction"] = {"error": "too shallow"}
    (tmp_path / "results" / "summary.json").write_text(json.dumps(s))
    assert math.isnan(ab.run_metrics(tmp_path)["solid_fraction"])


def test_the_run_table_resumes_and_keeps_interrupted_folders(tmp_path, monkeypatch):
    import siloflow.runs
    calls = []

    def fake_run(case, folder, **kw):
        calls.append(case.name)
        Path(folder).mkdir(parents=True)
        if case.seed == 2:
            raise EngineRunError("the run was stopped by siloflow's guard (speed): too fast")
    monkeypatch.setattr(siloflow.runs, "run", fake_run)
    base = yaml.safe_load(SMALL.read_text())
    planned = [PlannedRun(key={"seed": s}, case={**base, "name": f"r{s}", "seed": s}) for s in (1, 2, 3)]
    measure = lambda folder: {"x": 1.0}
    failed = lambda folder, reason: {"x": float("nan")}
    (tmp_path / "runs" / "r3").mkdir(parents=True)             # an interrupted run left its folder, no row
    rows = run_missing(tmp_path, planned, measure, failed)
    assert calls == ["r1", "r2", "r3"] and [r["state"] for r in rows] == ["complete", "failed", "complete"]
    assert "guard (speed)" in rows[1]["reason"] and rows[2]["folder"] == "runs/r3-retry1"
    assert (tmp_path / "runs" / "r3").is_dir()                  # kept as it was
    assert run_missing(tmp_path, planned, measure, failed) and calls == ["r1", "r2", "r3"]   # nothing again
    assert len(read_rows(tmp_path)) == 3


def test_a_run_table_is_of_one_case_and_says_where_each_run_ran(tmp_path, monkeypatch):
    import siloflow.runs
    from siloflow.run_table import case_digest, machine_id
    monkeypatch.setattr(siloflow.runs, "run", lambda case, folder, **kw: Path(folder).mkdir(parents=True))
    base = yaml.safe_load(SMALL.read_text())
    sha = case_digest(base)
    assert case_digest({**base, "seed": 5, "name": "other"}) == sha        # name and seed are not the case
    softer = case_digest({**base, "gravity": 5.0})
    assert softer != sha
    planned = [PlannedRun(key={"seed": s}, case={**base, "name": f"r{s}", "seed": s}) for s in (1, 2)]
    nothing = (lambda f: {}, lambda f, r: {})
    rows = run_missing(tmp_path, planned[:1], *nothing, case_sha=sha)
    assert rows[0]["case_sha"] == sha and rows[0]["machine"] == machine_id() != ""
    before = (tmp_path / "runs.csv").read_bytes()
    with pytest.raises(SetupError, match=f"another case \\(case_sha {sha}, this case {softer}\\).*-o"):
        run_missing(tmp_path, planned, *nothing, case_sha=softer)
    assert (tmp_path / "runs.csv").read_bytes() == before and not (tmp_path / "runs" / "r2").exists()
    assert len(run_missing(tmp_path, planned, *nothing, case_sha=sha)) == 2


def test_an_insert_counts_in_the_case_digest_by_its_bytes_not_its_path(tmp_path):
    from siloflow.run_table import case_digest
    from siloflow.study_case import read_study_case
    base = yaml.safe_load(SMALL.read_text())
    solid = "solid b\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0.05\nvertex 0.004 0 0.05\nvertex 0 0.004 0.05\n" \
            "endloop\nendfacet\nendsolid b\n"
    digests = {}
    for where in ("a", "b"):
        (tmp_path / where).mkdir()
        (tmp_path / where / "baffle.stl").write_text(solid)
        (tmp_path / where / "case.yaml").write_text(yaml.safe_dump(
            {**base, "inserts": [{"name": "baffle", "file": "baffle.stl"}]}))
        digests[where] = case_digest(read_study_case(tmp_path / where / "case.yaml")[0])
    assert digests["a"] == digests["b"] != case_digest(base)           # a moved folder: the same case
    (tmp_path / "b" / "baffle.stl").write_text(solid.replace("0.05", "0.06"))
    assert case_digest(read_study_case(tmp_path / "b" / "case.yaml")[0]) != digests["a"]    # an edited mesh: another


@pytest.mark.parametrize("sha", ["0123456789012345", "1234e56789012345", "12345678901234e5"])
def test_a_digest_that_looks_like_a_number_survives_the_table(tmp_path, monkeypatch, sha):
    import siloflow.runs
    monkeypatch.setattr(siloflow.runs, "run", lambda case, folder, **kw: Path(folder).mkdir(parents=True))
    base = yaml.safe_load(SMALL.read_text())
    planned = [PlannedRun(key={"seed": s}, case={**base, "name": f"r{s}", "seed": s}) for s in (1, 2)]
    run_missing(tmp_path, planned[:1], lambda f: {}, lambda f, r: {}, case_sha=sha)
    rows = run_missing(tmp_path, planned, lambda f: {}, lambda f, r: {}, case_sha=sha)     # resumes
    assert [r["case_sha"] for r in rows] == [sha, sha]


@pytest.mark.parametrize("reason,verdict,signal", [
    ("the run was stopped by siloflow's guard (overlap): two grains", "unstable", "overlap"),
    ("12 of 600 atoms (spheres) left the box during the fill", "unstable", "escape"),
    ("LIGGGHTS stopped with an error: ERROR: Lost atoms: original 600 current 590", "unstable", "escape"),
    ("LIGGGHTS was killed by SIGSEGV", "unstable", "crash"),
    ("the bed did not settle: kinetic/potential energy", "inconclusive", ""),
])
def test_failures_are_classified(reason, verdict, signal):
    assert st.classify(reason) == (verdict, signal)


def test_the_safe_edge_is_the_largest_stable_step_below_the_first_unstable():
    rows = [{"timestep_fraction": f, "stiffness_scale": 1.0, "dust_scale": None, "verdict": v, "signal": s}
            for f, v, s in ((0.1, "stable", ""), (0.2, "stable", ""), (0.5, "unstable", "speed"),
                            (0.7, "stable", ""), (1.0, "unstable", "overlap"))]
    rows += [{"timestep_fraction": 0.1, "stiffness_scale": 0.01, "dust_scale": None, "verdict": "stable", "signal": ""}]
    edges = {e["stiffness_scale"]: e for e in st.safe_edges(rows)}
    assert edges[1.0]["safe"] == 0.2 and edges[1.0]["unstable"] == 0.5 and edges[1.0]["margin"] == 2.5
    assert edges[1.0]["signal"] == "overlap,speed"
    assert edges[0.01]["safe"] == 0.1 and math.isnan(edges[0.01]["unstable"])


def test_conclude_writes_the_table_figure_and_a_recommendation(tmp_path):
    import numpy as np
    rng = np.random.default_rng(3)
    rows = []
    for cand, (bias, wall) in {"reference": (0.0, 100.0), "E1e-4_dt0.2": (0.002, 1.0), "E1_dt0.1": (0.0, 20.0)}.items():
        for seed in range(4):
            rows.append({"candidate": cand, "seed": seed, "state": "complete", "reason": "",
                         "timestep_fraction": 0.1, "stiffness_scale": 1.0, "ranks": 2,
                         "wall_s": wall * (1 + 0.02 * rng.standard_normal()),
                         "flow_rate": 0.01 * (1 + bias + 0.001 * rng.standard_normal()),
                         "static_pressure": 500 * (1 + 0.002 * rng.standard_normal()),
                         "dynamic_pressure_max": 600.0, "solid_fraction": 0.6, "coordination": 5.0})
    rows.append({**rows[-1], "seed": 9, "state": "failed", "reason": "guard", "flow_rate": float("nan")})
    rows.append({**rows[-1], "seed": 2009, "fill_only": True})
    pd.DataFrame(rows).to_csv(tmp_path / "runs.csv", index=False)
    table, rec = ab.conclude(tmp_path)
    assert rec["candidate"] == "E1e-4_dt0.2" and rec["speedup"] == pytest.approx(100, rel=0.1)
    assert set(rec["error_bounds"]) == {"flow_rate", "static_pressure"}
    assert json.loads((tmp_path / "recommended_profile.json").read_text())["candidate"] == "E1e-4_dt0.2"
    assert (tmp_path / "pareto.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    written = pd.read_csv(tmp_path / "comparison.csv")
    failed = written.drop_duplicates("candidate").set_index("candidate")[["failed_runs", "failed_fill_only"]]
    assert failed.loc["E1_dt0.1"].tolist() == [1, 1] and failed.loc["reference"].tolist() == [0, 0]
    needed = written.set_index(["candidate", "quantity"])["fills_needed"]
    assert needed[("E1e-4_dt0.2", "flow_rate")] <= 4 and math.isnan(needed[("E1e-4_dt0.2", "coordination")])
    # a hand-merged table repeating a seed is refused, naming the candidate and the seed, and nothing is rewritten
    before = (tmp_path / "comparison.csv").read_bytes()
    pd.DataFrame(rows + [rows[0]]).to_csv(tmp_path / "runs.csv", index=False)
    with pytest.raises(SetupError, match="reference with seed 0 more than once"):
        ab.conclude(tmp_path)
    assert (tmp_path / "comparison.csv").read_bytes() == before
    with pytest.raises(SetupError, match="reference with seed 0 more than once"):     # before running anything
        ab.run_bench(SMALL, tmp_path, seeds=5, candidates=[ab.REFERENCE])
    assert not (tmp_path / "runs").exists()


@pytest.mark.engine
def test_the_envelope_flags_dt_tc_unstable_and_its_edge_repeats_with_another_seed(tmp_path):
    """The small silo (400 grains, one rank) at 0.1 and 1.0 of the critical time: 1.0 is unstable
    (velocity Verlet diverges above 0.64 contact times), 0.1 stable, with two seeds."""
    base = yaml.safe_load(SMALL.read_text())
    base["fill"]["count"] = 400
    base["engine"] = {"ranks": 1}
    case_file = tmp_path / "tiny.yaml"
    case_file.write_text(yaml.safe_dump(base))
    edges = []
    for seed in (11, 12):
        rows = st.run_envelope(case_file, tmp_path / f"env{seed}", fractions=(0.1, 1.0), stiffness=(1.0,),
                               seed=seed, burst=0.05)
        verdicts = {r["timestep_fraction"]: r["verdict"] for r in rows}
        assert verdicts == {0.1: "stable", 1.0: "unstable"}, rows
        stable = next(r for r in rows if r["verdict"] == "stable")
        assert 0 < stable["overlap_ratio"] < 1 and 0 < stable["speed_ratio"] < 1     # ran inside the limits
        edges.append(st.conclude(tmp_path / f"env{seed}", rows)[0])
        assert (tmp_path / f"env{seed}" / "envelope.png").is_file()
    assert edges[0]["safe"] == edges[1]["safe"] == 0.1 and edges[0]["unstable"] == edges[1]["unstable"] == 1.0


def test_pairs_lost_counts_reference_values_whose_candidate_run_failed():
    # the candidate's whole seed 2 failed (a guard stop), its seed 3 failed and was retried to the
    # end, its fill-only seed 2002 failed: flow loses 1 pair, the static pressure 2; Welch rows lose none
    rows = [dict(candidate=c, seed=s, state="complete", fill_only=s >= 2000, flow_rate=np.nan if s >= 2000 else 1.0,
                 static_pressure=2.0) for c in ("reference", "cand") for s in (0, 1, 2, 3, 2000, 2001, 2002)]
    runs = pd.DataFrame(rows)
    failed = (runs.candidate == "cand") & runs.seed.isin([2, 3, 2002])
    runs.loc[failed, "state"] = "failed"
    runs = pd.concat([runs, pd.DataFrame([dict(rows[3], candidate="cand")])], ignore_index=True)   # seed 3's retry
    table = pd.DataFrame([dict(candidate=c, quantity=q, method=m) for c, m in (("reference", ""), ("cand", "paired"))
                          for q in ("flow_rate", "static_pressure")]
                         + [dict(candidate="cand", quantity="static_pressure", method="welch")])
    assert ab.pairs_lost(runs, table) == [0, 0, 1, 2, 0]


def test_validation_says_whether_new_seeds_stay_in_the_bounds():
    table = pd.DataFrame([{"candidate": "fast" + ab.VALIDATION, "quantity": "flow_rate", "rel_error": 0.01,
                           "ci_lo": -0.01, "ci_hi": 0.03, "n_cand": 3},
                          {"candidate": "fast" + ab.VALIDATION, "quantity": "static_pressure", "rel_error": -0.08,
                           "ci_lo": -0.12, "ci_hi": -0.04, "n_cand": 3}])
    rec = {"candidate": "fast", "error_bounds": {"flow_rate": 0.02, "static_pressure": 0.05}}
    checks = {c["quantity"]: c for c in ab.validation(table, rec)}
    assert checks["flow_rate"]["inside"] and not checks["static_pressure"]["inside"]
    # the static interval (-12 %, -4 %) reaches into the 5 % bound: outside, but not a contradiction
    assert checks["flow_rate"]["consistent"] and checks["static_pressure"]["consistent"]
    assert checks["flow_rate"]["failed"] == 0                         # a table without the failure columns
    table["failed_runs"], table["failed_fill_only"] = 1, 2
    assert {c["quantity"]: c for c in ab.validation(table, rec)}["flow_rate"]["failed"] == 3
    table.loc[1, ["ci_lo", "ci_hi"]] = [-0.12, -0.06]
    assert not {c["quantity"]: c for c in ab.validation(table, rec)}["static_pressure"]["consistent"]
    table.loc[1, ["ci_lo", "ci_hi", "n_cand"]] = [float("nan"), float("nan"), 1]     # one new fill: no interval
    assert {c["quantity"]: c for c in ab.validation(table, rec)}["static_pressure"]["consistent"] is None
    assert case_from_dict(ab.candidate_case(yaml.safe_load(SMALL.read_text()),
                                            ab.Candidate("x" + ab.VALIDATION, 0.1), 5)).name.endswith("-s5")


def test_without_a_proven_candidate_the_reference_stays_the_recommendation(tmp_path):
    """Not seeing a difference is not proving it small: noisy candidates are not recommended."""
    import numpy as np
    rng = np.random.default_rng(5)
    rows = []
    for cand, (bias, noise, wall) in {"reference": (0.0, 0.05, 100.0), "E1_dt0.1": (0.0, 0.05, 30.0),
                                      "E1e-4_dt0.2": (0.5, 0.01, 1.0), "E1e-3_dt0.1": (0.0, 0.05, 5.0)}.items():
        for seed in range(3):
            rows.append({"candidate": cand, "seed": seed, "state": "complete", "reason": "", "timestep_fraction": 0.1,
                         "stiffness_scale": 1.0, "ranks": 2, "wall_s": wall,
                         "flow_rate": 0.01 * (1 + bias + noise * rng.standard_normal()),
                         "static_pressure": 500 * (1 + noise * rng.standard_normal()),
                         "dynamic_pressure_max": 600.0, "solid_fraction": 0.6, "coordination": 5.0})
    pd.DataFrame(rows).to_csv(tmp_path / "runs.csv", index=False)
    table, rec = ab.conclude(tmp_path)
    assert rec["candidate"] == "reference" and rec["speedup"] == 1.0


def _identical_runs(walls: dict, seeds: int) -> list[dict]:
    """Complete runs of every candidate (name: engine wall time, s), equal in every quantity: all within any
    tolerance, so the recommendation is the fastest one allowed."""
    return [{"candidate": c, "seed": k, "state": "complete", "reason": "", "timestep_fraction": 0.2,
             "stiffness_scale": 1e-4, "ranks": 2, "wall_s": w, "flow_rate": 0.01, "static_pressure": 500.0,
             "dynamic_pressure_max": 600.0, "solid_fraction": 0.6, "coordination": 5.0}
            for c, w in walls.items() for k in range(seeds)]


def test_each_question_gets_the_fastest_candidate_proven_for_its_quantities(tmp_path):
    """A candidate whose static pressure is off but whose flow rate is not is the flow-only question's
    profile and nobody else's; the question "everything" also needs the coordination, which only the
    reference has right here; recommended_candidates lists what --validate checks, each once."""
    import numpy as np
    rng = np.random.default_rng(5)
    rows = []
    for cand, (static_bias, coord_bias, wall) in {"reference": (0, 0, 100.0), "E1e-4_dt0.2": (0.2, 0.2, 1.0),
                                                  "E1e-3_dt0.2": (0.0, 0.2, 4.0)}.items():
        for seed in range(4):
            rows.append({"candidate": cand, "seed": seed, "state": "complete", "reason": "", "timestep_fraction": 0.2,
                         "stiffness_scale": 1e-3, "ranks": 2, "wall_s": wall,
                         "flow_rate": 0.01 * (1 + 0.001 * rng.standard_normal()),
                         "static_pressure": 500 * (1 + static_bias + 0.001 * rng.standard_normal()),
                         "dynamic_pressure_max": 600.0, "solid_fraction": 0.6, "coordination": 5.0 * (1 + coord_bias)})
    pd.DataFrame(rows).to_csv(tmp_path / "runs.csv", index=False)
    table, rec = ab.conclude(tmp_path)
    picked = {q: r["candidate"] for q, r in rec["questions"].items()}
    assert picked == {"flow_rate": "E1e-4_dt0.2", "flow_rate_and_static_pressure": "E1e-3_dt0.2",
                      "everything": "reference"}
    assert rec["candidate"] == "E1e-3_dt0.2"
    flow = rec["questions"]["flow_rate"]
    assert set(flow["error_bounds"]) == {"flow_rate"} and flow["tolerances"] == {"flow_rate": 0.03}
    assert flow["measured"]["static_pressure"][0] == pytest.approx(0.2, abs=0.01)     # measured, not bounded
    assert set(rec["questions"]["everything"]["tolerances"]) == set(ab.QUANTITIES)
    assert ab.recommended_candidates(rec) == ["E1e-3_dt0.2", "E1e-4_dt0.2"]
    assert json.loads((tmp_path / "recommended_profile.json").read_text())["questions"]["flow_rate"] == flow


def test_candidates_that_are_not_profiles_are_never_recommended(tmp_path):
    rows = _identical_runs({"reference": 100.0, "E1e-4_dt0.2_1rank": 1.0, "E1e-4_dt0.2": 2.0}, 3)
    pd.DataFrame(rows).to_csv(tmp_path / "runs.csv", index=False)
    assert ab.conclude(tmp_path)[1]["candidate"] == "E1e-4_dt0.2"


def test_a_candidate_that_failed_on_any_seed_is_never_recommended(tmp_path):
    """Its completed runs are the survivors: a setting the guard stopped, or whose bed never settled, on one
    seed of the benchmark's case is no profile. The next fastest proven one is recommended instead."""
    rows = _identical_runs({"reference": 100.0, "E1e-4_dt0.2": 1.0, "E1e-3_dt0.2": 2.0}, 4)
    pd.DataFrame(rows).to_csv(tmp_path / "runs.csv", index=False)
    assert ab.conclude(tmp_path)[1]["candidate"] == "E1e-4_dt0.2"
    failed = {**rows[4], "seed": 2100, "state": "failed", "reason": "the bed did not settle", "fill_only": True}
    pd.DataFrame(rows + [failed]).to_csv(tmp_path / "runs.csv", index=False)
    assert ab.conclude(tmp_path)[1]["candidate"] == "E1e-3_dt0.2"
    # the recommendation's new seeds count too: one of them failing bars it as well
    check = [{**r, "candidate": "E1e-3_dt0.2" + ab.VALIDATION, "seed": 1100 + r["seed"]} for r in rows[8:]]
    check[0].update(state="failed", reason="the run was stopped by siloflow's guard (escape)")
    pd.DataFrame(rows + [failed] + check).to_csv(tmp_path / "runs.csv", index=False)
    assert ab.conclude(tmp_path)[1]["candidate"] == "reference"


def test_a_recommendation_whose_new_seeds_land_outside_its_bound_is_passed_over(tmp_path):
    """The new seeds' flow rate 10 % off puts the fastest proven candidate's error outside its bound:
    the next proven one is recommended, and the one passed over is recorded with its check."""
    import numpy as np
    rng = np.random.default_rng(7)
    rows = []
    for cand, wall in {"reference": 100.0, "E1e-4_dt0.2": 1.0, "E1e-3_dt0.2": 2.0}.items():
        for seed in range(4):
            rows.append({**_identical_runs({cand: wall}, 1)[0], "seed": seed,
                         "flow_rate": 0.01 * (1 + 0.001 * rng.standard_normal())})
    pd.DataFrame(rows).to_csv(tmp_path / "runs.csv", index=False)
    assert ab.conclude(tmp_path)[1]["candidate"] == "E1e-4_dt0.2"
    check = [{**r, "candidate": "E1e-4_dt0.2" + ab.VALIDATION, "seed": 1100 + r["seed"],
              "flow_rate": 0.011 * (1 + 0.001 * rng.standard_normal())} for r in rows[4:8]]
    pd.DataFrame(rows + check).to_csv(tmp_path / "runs.csv", index=False)
    rec = ab.conclude(tmp_path)[1]
    assert rec["candidate"] == "E1e-3_dt0.2" and rec["validation"] == []       # to be checked in turn
    (over,) = rec["passed_over"]
    assert over["candidate"] == "E1e-4_dt0.2"
    assert {c["quantity"]: c["inside"] for c in over["validation"]}["flow_rate"] is False
    assert rec["questions"]["flow_rate"]["candidate"] == "E1e-3_dt0.2"
    assert ab.recommended_candidates(rec) == ["E1e-3_dt0.2"]


def test_upscaling_keeps_the_bed_and_scales_the_grains():
    base = yaml.safe_load((ROOT / "benchmarks" / "cases" / "accuracy_small.yaml").read_text())
    cand = next(c for c in ab.CANDIDATES if c.upscale)
    data = ab.candidate_case(base, cand, 3)
    assert data["particles"]["radii"] == pytest.approx([r * cand.upscale for r in base["particles"]["radii"]])
    assert data["fill"]["count"] == round(base["fill"]["count"] / cand.upscale ** 3)
    fine, coarse = derive(case_from_dict(ab.candidate_case(base, ab.CANDIDATES[0], 3))), derive(case_from_dict(data))
    assert coarse.total_mass == pytest.approx(fine.total_mass, rel=0.01)       # the same bed, fewer grains
    assert not cand.profile
    from siloflow.study_case import read_study_case
    lin, _ = read_study_case(ROOT / "decks" / "paper_a_spheres_quick.yaml")
    up = ab.upscaled_case(lin, 2.0)
    assert up["materials"]["particle_particle"]["kn"] == 2.0 * float(lin["materials"]["particle_particle"]["kn"])


def test_a_fill_only_run_is_the_whole_run_up_to_the_end_of_its_static_stage(tmp_path):
    """A fill-only run (siloflow bench --fill-only-seeds) stands for the whole run's fill only if its
    deck is the same up to the opening: the same commands and meshes, hence (a seed making the same
    insertion stream) the same bed and the same static loads; after it, one sample interval."""
    base = yaml.safe_load((ROOT / "benchmarks" / "cases" / "accuracy_small.yaml").read_text())
    whole = ab.candidate_case(base, ab.REFERENCE, 2100)
    cut = ab.fill_only_case(whole)
    assert {k for k in whole if whole[k] != cut[k]} == {"discharge"} and whole["discharge"]["duration"] == 0.8
    plans = [derive(case_from_dict(d)).model_dump() for d in (whole, cut)]
    assert [k for k in plans[0] if plans[0][k] != plans[1][k]] == ["discharge"]   # the same guard, opening, dt
    a, b = render_deck(whole, tmp_path / "whole"), render_deck(cut, tmp_path / "cut")
    head = "SILOFLOW_STAGE open"
    assert a[:a.index(head)] == b[:b.index(head)] and a != b
    for mesh in (tmp_path / "whole" / "meshes").iterdir():
        assert (tmp_path / "cut" / "meshes" / mesh.name).read_bytes() == mesh.read_bytes()
    steps = {t: int(next(line.split()[3].strip('"') for line in d.splitlines()
                         if line.startswith('print           "SILOFLOW_STAGE discharge')))
             for t, d in (("whole", a), ("cut", b))}
    assert steps["cut"] * 0.8 / 0.01 == pytest.approx(steps["whole"], rel=1e-2)     # 0.01 s of 0.8 s (whole chunks)


def test_fill_only_runs_add_fills_to_the_settled_quantities_and_time_nothing(tmp_path):
    """Fill-only rows count in the static band pressure, solid fraction and coordination, paired
    by seed; not in the flow rate, the dynamic loads or the speed-up (their times are half-runs)."""
    import numpy as np
    rng = np.random.default_rng(8)
    rows = []
    for seed in [*range(4), *range(2100, 2106)]:
        fill_only = seed >= 2100
        p = 500 * (1 + 0.05 * rng.standard_normal())
        for cand, wall in (("reference", 100.0), ("E1e-2_dt0.1", 4.0)):
            rows.append({"candidate": cand, "seed": seed, "state": "complete", "reason": "", "fill_only": fill_only,
                         "timestep_fraction": 0.1, "stiffness_scale": 1.0, "ranks": 2,
                         "wall_s": wall / (50.0 if fill_only and cand == "reference" else 1.0),
                         "flow_rate": float("nan") if fill_only else 0.01 * (1 + 0.01 * rng.standard_normal()),
                         "static_pressure": p * (1.02 if cand != "reference" else 1.0),
                         "dynamic_pressure_max": float("nan") if fill_only else 600.0,
                         "solid_fraction": 0.6, "coordination": 5.0})
    pd.DataFrame(rows).to_csv(tmp_path / "runs.csv", index=False)
    table, rec = ab.conclude(tmp_path, tolerances={"flow_rate": 0.05, "static_pressure": 0.05})
    t = table[table.candidate == "E1e-2_dt0.1"].set_index("quantity")
    assert t.loc["static_pressure", "n_ref"] == 10 and t.loc["static_pressure", "method"] == "paired"
    assert t.loc["static_pressure", "rel_error"] == pytest.approx(0.02)
    assert t.loc["flow_rate", "n_ref"] == 4 and t.loc["dynamic_pressure_max", "n_cand"] == 4
    assert t.loc["flow_rate", "speedup"] == pytest.approx(25.0) and t.loc["flow_rate", "timed_runs"] == "4/4"
    assert rec["candidate"] == "E1e-2_dt0.1" and (rec["seeds"], rec["fill_only_seeds"]) == (4, 6)
    assert rec["reference_seeds"] == 4 and "6 fill-only" in rec["benchmark"]
    assert (pd.read_csv(tmp_path / "run_errors.csv").set_index("candidate").runs == 4).all()


def test_the_bench_plans_fill_only_seeds_after_the_whole_ones(tmp_path, monkeypatch):
    import siloflow.runs
    ran = []

    def fake_run(case, folder, **kw):
        ran.append((case.name, case.discharge.duration))
        fake_summary(Path(folder))
    monkeypatch.setattr(siloflow.runs, "run", fake_run)
    cands = [ab.REFERENCE, next(c for c in ab.CANDIDATES if c.name == "E1e-2_dt0.1")]
    base = yaml.safe_load(SMALL.read_text())
    rows = ab.run_bench(SMALL, tmp_path, seeds=2, candidates=cands, fill_only_seeds=2)
    s0 = base["seed"]
    assert [r["seed"] for r in rows] == [s0, s0, s0 + 1, s0 + 1, *[s0 + ab.FILL_ONLY_SEED_OFFSET + k
                                                                  for k in (0, 0, 1, 1)]]
    assert [r["fill_only"] for r in rows] == [False] * 4 + [True] * 4
    interval = case_from_dict(base).outputs.sample_interval
    assert [d for _, d in ran[4:]] == [interval] * 4 and all(d != interval for _, d in ran[:4])
    assert all(math.isnan(r["flow_rate"]) and math.isnan(r["dynamic_pressure_max"]) for r in rows[4:])
    assert all(r["static_pressure"] == pytest.approx(450.0) for r in rows)
    assert not ab.fill_only_rows(pd.DataFrame(read_rows(tmp_path))).iloc[:4].any()
    assert ab.fill_only_rows(pd.DataFrame(read_rows(tmp_path))).iloc[4:].all()
    # the new-seed check's fill-only seeds are new fills too: + 1000 from the bench's fill-only ones
    rows = ab.validate(SMALL, tmp_path, "E1e-2_dt0.1", 1, fill_only_seeds=2)
    check = [(r["seed"], r["fill_only"]) for r in rows if r["candidate"] == "E1e-2_dt0.1" + ab.VALIDATION]
    first = s0 + ab.VALIDATION_SEED_OFFSET
    assert check == [(first, False), *((first + ab.FILL_ONLY_SEED_OFFSET + k, True) for k in (0, 1))]
    with pytest.raises(SetupError, match="seeds: 1001 is more than 1000"):
        ab.run_bench(SMALL, tmp_path / "many", seeds=ab.SEED_RANGE + 1, candidates=cands)
    with pytest.raises(SetupError, match="seeds: 4 is more than 3"):      # offsets 997-1000: 1000 is the check's
        ab.run_bench(SMALL, tmp_path / "many", seeds=4, candidates=cands, seed_offset=ab.SEED_RANGE - 3)
    assert not (tmp_path / "many").exists()            # refused before anything is written
    from typer.testing import CliRunner
    from siloflow.cli import app
    for option in ("--seeds", "--validate", "--validate-fill-only", "--fill-only-seeds"):   # before the bench runs
        result = CliRunner().invoke(app, ["bench", str(SMALL), "-o", str(tmp_path / "cli"), option, "1001"])
        assert result.exit_code != 0 and f"{option}: 1001 is more than 1000" in result.output, result.output
    assert not (tmp_path / "cli").exists() and len(ran) == 11


def test_a_fill_only_run_keeps_the_whole_runs_automatic_dump_interval():
    """A case with results needing frames and no dump interval dumps as often as its discharge's
    length says: the cut pins the whole run's interval, or its settled frame would be another one."""
    base = yaml.safe_load(SMALL.read_text())
    base["outputs"] = {"sample_interval": 0.01, "results": ["flow_rate", "coordination"]}
    cut = ab.fill_only_case(base)
    auto = auto_dump_interval(case_from_dict(base))
    assert cut["outputs"]["dump_interval"] == auto and auto != auto_dump_interval(case_from_dict(
        {**base, "discharge": cut["discharge"]}))
    assert "dump_interval" not in base["outputs"]                      # the whole case is left as it was
    lean = {**base, "outputs": {"results": ["flow_rate", "force_balance"]}}
    assert "dump_interval" not in ab.fill_only_case(lean)["outputs"]   # no frames needed: nothing pinned



def _no_runs(monkeypatch) -> list:
    """siloflow.runs.run replaced by a recorder: a study that starts a run fails the test's check."""
    import siloflow.runs
    calls = []
    monkeypatch.setattr(siloflow.runs, "run", lambda case, folder, **kw: calls.append(case.name))
    return calls


@pytest.mark.parametrize("names, words", [("", "no candidate named"), (",", "no candidate named"),
                                          (" , ", "no candidate named"), ("dt0.1,,E1e-2", "an empty name"),
                                          ("reference,", "an empty name"), ("nosuch", "unknown nosuch"),
                                          ("reference,reference", "named more than once")])
def test_bench_refuses_an_empty_or_bad_candidate_list_before_any_run(tmp_path, monkeypatch, names, words):
    """Issue 34.9: --candidates '' (or ',') ran every candidate, hours of reference runs."""
    from typer.testing import CliRunner
    from siloflow.cli import app
    calls = _no_runs(monkeypatch)
    result = CliRunner().invoke(app, ["bench", str(SMALL), "-o", str(tmp_path / "b"), "--candidates", names],
                                env={"COLUMNS": "300"})
    assert result.exit_code == 1 and "--candidates" in result.output and words in result.output, result.output
    assert calls == [] and not (tmp_path / "b").exists()
    with pytest.raises(SetupError, match=words):
        ab.choose_candidates(names)


def test_choose_candidates_keeps_the_reference_first():
    assert ab.choose_candidates(None) == list(ab.CANDIDATES)
    other = ab.CANDIDATES[1].name
    assert [c.name for c in ab.choose_candidates(f" {other} ")] == ["reference", other]
    with pytest.raises(SetupError, match="Candidate objects"):
        ab.run_bench(SMALL, Path("unused"), candidates="reference")


@pytest.mark.parametrize("options, words", [
    (["--seed", "-5"], "--seed: must be a whole number from 0"),              # issue 34.10
    (["--seed", str(2 ** 31)], "--seed"),
    (["--fractions", ",".join(f"{0.01 * k:g}" for k in range(1, 22))], "--fractions: 21 values, at most 20"),
    (["--fractions", "0.1,0.2,0.1"], "--fractions: 0.1 given more than once"),
    (["--fractions", "0.1,0.10"], "given more than once"),
    (["--stiffness", "1,1"], "--stiffness: 1 given more than once"),
    (["--dust", ""], "--dust"),
])
def test_stability_checks_its_options_before_anything_runs(tmp_path, monkeypatch, options, words):
    """Issue 34.10: --seed -5 printed 'not run' for every point, then 'runs.csv is not a stability table'."""
    from typer.testing import CliRunner
    from siloflow.cli import app
    calls = _no_runs(monkeypatch)
    result = CliRunner().invoke(app, ["stability", str(SMALL), "-o", str(tmp_path / "s"), *options],
                                env={"COLUMNS": "300"})
    assert result.exit_code == 1 and words in result.output, result.output
    assert "not run" not in result.output and "not a stability table" not in result.output
    assert calls == [] and not (tmp_path / "s").exists()


def test_the_envelope_library_checks_its_grid_too(tmp_path, monkeypatch):
    calls = _no_runs(monkeypatch)
    for kwargs, words in (({"seed": -5}, "--seed"), ({"seed": 1.5}, "--seed"), ({"fractions": []}, "at least one"),
                          ({"fractions": [0.1] * 2}, "more than once"), ({"fractions": [0.0001]}, "--fractions"),
                          ({"stiffness": list(np.linspace(0.01, 1, 21))}, "at most 20"),
                          ({"dust_scales": []}, "--dust"), ({"dust_scales": [0.5]}, "--dust"),
                          ({"burst": float("nan")}, "--burst")):
        with pytest.raises(SetupError, match=words):
            st.run_envelope(SMALL, tmp_path / "s", **kwargs)
    assert calls == [] and not (tmp_path / "s").exists()
    st.check_options(st.FRACTIONS, st.STIFFNESS, [1.0, 25.0], 0, 0.1)         # the defaults pass


def test_an_envelope_whose_every_point_was_refused_says_so(tmp_path, monkeypatch):
    import siloflow.runs

    def refuse(case, folder, **kw):
        raise SetupError("over the step cap")
    monkeypatch.setattr(siloflow.runs, "run", refuse)
    with pytest.raises(SetupError, match="no point of the envelope ran"):
        st.run_envelope(SMALL, tmp_path / "s", fractions=[0.1], stiffness=[1.0])
