"""Time to answer (issue 41 item 3): how long three questions a user asks take, from case file to report,
at the papers' numerical settings and on siloflow's fastest proven path, with the error bounds each
path carries.

    python benchmarks/time_to_answer.py        # make bench-time-to-answer (about 8 min; nothing else may run)
    python benchmarks/time_to_answer.py --doc  # only rewrite docs/time_to_answer.md's table from the committed results

The questions:

1. **Beverloo's C and k over three orifices**: benchmarks/cases/accuracy_small.yaml (paper B's
   grains and contact law, 1000 grains; where the fast profiles were proven) at orifice radii
   ``BEVERLOO_RADII``, one run each, fitted by ``siloflow beverloo``'s fit.
2. **Static wall pressure per band**: the same case, one run that stops one sample after the
   opening (the static stage is all it needs).
3. **Paper B's coarse-grained fields at one aperture**: decks/paper_b.yaml (393,216 grains), one
   fill and one aperture (paper B's 12 r_b).

For 1 and 2 the fastest proven path is RUN here, timed end to end through ``siloflow.run`` (render,
engine, checks, first results and report): ``profile: fast`` (which picks the profile proven for the
results asked, siloflow.packaged_profile), ``outputs.results`` cut to what the question needs (the
lean deck), LIGGGHTS on 2 ranks, and for 1 the fill cache (the three orifices share one settled bed,
as ``siloflow sweep`` shares it). The papers' settings (``profile: reference``) are EXTRAPOLATED, not
run: the same runs are made again at the profile's settings as the bench ran them (the full deck,
each run its own fill: ``plain_wall_s``), and their engine time x the profile's speed-up measured by
the accuracy benchmark on this very case (benchmarks/results/accuracy/comparison.csv, with its 95 %
interval), plus their post-processing time, is the papers' settings' time. For 3 both are
extrapolated from planned steps x grains at LIGGGHTS' rate (its contact dumps carry the contact
stress) measured by ``make bench-scale`` at 3e5 grains (benchmarks/results/scale/scale.csv): the
steps are an upper bound (settling to its cap) and the rate a collapsing column's (faster than a
settled bed's), so the time is an estimate, not a bound. No profile bounds coarse-grained fields,
so the papers' settings are the fastest proven path, and the fast profile's time is given as what
it would cost unbounded.

Writes benchmarks/results/time_to_answer/time_to_answer.csv and time_to_answer.md, and puts the
table in docs/time_to_answer.md between ``<!-- time-to-answer -->`` and ``<!-- end time-to-answer -->``
(tests/test_profiles.py checks that the two agree).
"""
from __future__ import annotations

import copy
import json
import math
import shutil
import sys
import time
from pathlib import Path

import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_runs import run_case  # noqa: E402

OUT = ROOT / "benchmarks" / "results" / "time_to_answer"
WORK = ROOT / "benchmarks" / "work" / "time_to_answer"
CASE = ROOT / "benchmarks" / "cases" / "accuracy_small.yaml"
ACCURACY = ROOT / "benchmarks" / "results" / "accuracy"
SCALE = ROOT / "benchmarks" / "results" / "scale" / "scale.csv"
#: orifice radii (m) of question 1: the bench case's 5 r_b, and 4.5 and 6 r_b (r_b = 15.6 mm)
BEVERLOO_RADII = (0.0703125, 0.078125, 0.09375)
#: paper B's aperture of question 3, in r_b (its largest grain radius)
PAPER_B_APERTURE_RB = 12.0


def fast_case(results: list[str], name: str, orifice_radius: float | None = None, static_only: bool = False) -> dict:
    data = copy.deepcopy(yaml.safe_load(CASE.read_text()))
    data["name"] = name
    data["engine"] = {"ranks": 2, "profile": "fast"}
    data["outputs"] = {"sample_interval": data["outputs"]["sample_interval"], "results": results}
    if orifice_radius is not None:
        data["geometry"] = {**data["geometry"], "orifice_radius": orifice_radius}
    if static_only:     # the discharge as short as the case allows: one sample (accuracy_bench.fill_only_case)
        data["discharge"] = {"duration": data["outputs"]["sample_interval"]}
    return data


def timed_run(data: dict, cache: Path | None = None) -> dict:
    """One run through siloflow's whole pipeline (``cache``: a fill cache folder): wall time (s) and
    the engine's share."""
    from siloflow.run_folder import RunFolder
    folder, wall = run_case(data, WORK, force=True, cache=cache)
    run = RunFolder(folder)
    engine = float(run.record.wall_time)
    return {"folder": folder, "wall_s": wall, "engine_s": engine, "profile": run.plan.profile}


def bench_speedup(candidate: str) -> tuple[float, float, float]:
    """The accuracy benchmark's speed-up of ``candidate`` over the reference on its case (and 95 % interval)."""
    t = pd.read_csv(ACCURACY / "comparison.csv")
    row = t[t.candidate == candidate].iloc[0]
    return float(row.speedup), float(row.speedup_lo), float(row.speedup_hi)


def candidate_of(profile) -> str:
    """The bench candidate a fast run's profile is (its question's published record)."""
    from siloflow.packaged_profile import fast_profile
    return fast_profile()["profiles"][profile.question]["candidate"]


def plain_case(data: dict, profile) -> dict:
    """``data`` (a fast case) as a user gets it without siloflow's shortcuts: the settings its fast
    run's plan recorded (``profile``) on the full deck (every result, every sensor), each run its own
    fill: what the bench's speed-up was measured on, so that times the speed-up is the papers' settings."""
    plain = copy.deepcopy(data)
    plain["name"] = data["name"] + "_plain"
    plain["engine"] = {"ranks": 2, "profile": "custom", "timestep_fraction": profile.timestep_fraction,
                       "stiffness_scale": profile.stiffness_scale}
    plain["outputs"] = {"sample_interval": data["outputs"]["sample_interval"]}
    return plain


def measured_row(question: str, runs: list[dict], plain: list[dict], answer: str) -> dict:
    """A question's row from its fast runs (measured) and the same runs on the full deck, each its
    own fill (``plain``, measured): their engine time x the bench's speed-up is the papers' settings."""
    p = runs[0]["profile"]
    s, lo, hi = bench_speedup(candidate_of(p))
    fast_engine = sum(r["engine_s"] for r in runs)
    fast_post = sum(r["wall_s"] - r["engine_s"] for r in runs)
    engine = sum(r["engine_s"] for r in plain)
    post = sum(r["wall_s"] - r["engine_s"] for r in plain)
    bounds = ", ".join(f"{q} {b:.1%}" for q, b in p.error_bounds.items())
    unbounded = ", ".join(f"{q} (measured {p.measured[q][0]:+.1%})" for q in p.unbounded if q in p.measured)
    return {"question": question, "runs": len(runs), "grains": 1000,
            "fast_path": f"profile fast ({candidate_of(p)}, proven for {p.question}), results "
                         f"{'/'.join(runs[0]['results'])}, LIGGGHTS 2 ranks"
                         + (", one fill shared through the fill cache" if len(runs) > 1 else ""),
            "fast_wall_s": fast_engine + fast_post, "fast_how": "measured",
            "fast_bounds": bounds + (f"; unbounded: {unbounded}" if unbounded else ""),
            "plain_wall_s": engine + post,
            "reference_wall_s": engine * s + post, "reference_wall_lo_s": engine * lo + post,
            "reference_wall_hi_s": engine * hi + post,
            "reference_how": f"extrapolated: the same runs at the profile's settings on the full deck, each its own "
                             f"fill ({engine + post:.0f} s measured), engine time x the bench's speed-up {s:.3g}x "
                             f"[{lo:.3g}, {hi:.3g}] + the post-processing measured",
            "speedup": (engine * s + post) / (fast_engine + fast_post), "answer": answer}


def beverloo_question() -> dict:
    from siloflow.answers import beverloo
    runs, plain = [], []
    for radius in BEVERLOO_RADII:
        data = fast_case(["flow_rate"], f"tta_beverloo_{radius * 1000:.2f}mm", radius)
        r = timed_run(data, cache=WORK / "fill_cache")
        runs.append({**r, "results": ["flow_rate"]})
        plain.append(timed_run(plain_case(data, r["profile"])))
    t0 = time.perf_counter()
    _, fit = beverloo([r["folder"] for r in runs])
    fit_s = time.perf_counter() - t0
    runs[-1]["wall_s"] += fit_s
    return measured_row("Beverloo C and k, three orifices", runs, plain,
                        f"C = {fit.C:.3g} +/- {fit.C_stderr:.2g}, k = {fit.k:.3g} +/- {fit.k_stderr:.2g} (the fit's "
                        f"standard errors from 3 runs, one seed each: 1 degree of freedom)")


def static_question() -> dict:
    from siloflow.run_row import run_row
    data = fast_case(["wall_pressure", "force_balance"], "tta_static", static_only=True)
    r = timed_run(data)
    plain = timed_run(plain_case(data, r["profile"]))
    row = run_row(r["folder"])
    return measured_row("static wall pressure per band", [{**r, "results": ["wall_pressure", "force_balance"]}],
                        [plain],
                        f"static band pressure {row['static_pressure']:.4g} Pa (mean over the loaded bands), "
                        f"force balance {row['force_balance_ratio']:.4g}")


def scale_rate(engine: str = "liggghts") -> tuple[float, str]:
    """``engine``'s particle-steps/s at the largest size of make bench-scale (paper B's contact stress
    needs the contact dumps only LIGGGHTS writes)."""
    t = pd.read_csv(SCALE)
    t = t[t.engine == engine]
    big = t[t.grains == t.grains.max()].iloc[0]
    return float(big.particle_steps_per_s), (f"{big.engine} at {int(big.grains):,} grains on {int(big.ranks)} ranks "
                                             f"(make bench-scale): {big.particle_steps_per_s:.3g} particle-steps/s")


def paper_b_question() -> dict:
    from siloflow.case_file import case_from_dict
    from siloflow.derived import derive
    from siloflow.reproduce_paper_b import SCALES, rb_of, study_case
    rate, source = scale_rate()
    data = study_case(SCALES["paper"])
    data["geometry"] = {**data["geometry"], "orifice_radius": PAPER_B_APERTURE_RB * rb_of(data)}
    cost = {}
    for profile in ("reference", "fast"):
        d = copy.deepcopy(data)
        d["engine"] = {k: v for k, v in d["engine"].items() if k not in ("timestep_fraction", "stiffness_scale")}
        d["engine"]["profile"] = profile
        plan = derive(case_from_dict(d))
        steps = sum(plan.planned_steps().values())
        cost[profile] = (plan.fill.count * steps, plan.profile)
    ref_s = cost["reference"][0] / rate
    fast_s = cost["fast"][0] / rate
    p = cost["fast"][1]
    return {"question": "paper B's CG fields, one aperture (12 r_b)", "runs": 1, "grains": 393_216,
            "fast_path": "none faster proven: no profile bounds coarse-grained fields (the papers' settings are "
                         f"the fastest proven path; profile fast, {p.question}, would take "
                         f"{fast_s / 3600:.3g} h with the fields unbounded)",
            "fast_wall_s": ref_s, "fast_how": f"extrapolated: planned steps (settling at its cap) x grains / {source}",
            "fast_bounds": "none (no profile bounds the fields)",
            "reference_wall_s": ref_s, "reference_wall_lo_s": math.nan, "reference_wall_hi_s": math.nan,
            "reference_how": f"extrapolated: {cost['reference'][0]:.3g} particle-steps (settling at its cap) / {source}",
            "speedup": 1.0, "answer": "not a bound: the steps are an upper bound (settling runs to its cap, 5 s), the rate a "
                      "collapsing column's, faster than a settled bed's (on the quick case, 2.3e6 against the "
                      "burst's 3.2e6 at 3e3 grains, docs/engines.md)"}


def duration(s: float) -> str:
    if not math.isfinite(s):
        return "-"
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.1f} min" if s < 7200 else f"{s / 3600:.1f} h" if s < 3 * 86400 \
        else f"{s / 86400:.0f} days"


def markdown(table: pd.DataFrame) -> str:
    lines = ["| question | papers' settings | fastest proven path | speed-up | bounds of the fast path |",
             "|---|---|---|---|---|"]
    for r in table.itertuples():
        ref = duration(r.reference_wall_s)
        if math.isfinite(r.reference_wall_lo_s):
            ref += f" ({duration(r.reference_wall_lo_s)} to {duration(r.reference_wall_hi_s)})"
        lines.append(f"| {r.question} | {ref}, {r.reference_how} | {duration(r.fast_wall_s)} ({r.fast_how}): "
                     f"{r.fast_path} | {r.speedup:.3g}x | {r.fast_bounds} |")
    return "\n".join(lines) + "\n"


DOC = ROOT / "docs" / "time_to_answer.md"
MARKERS = ("<!-- time-to-answer -->\n", "<!-- end time-to-answer -->")


def doc_table(doc: str) -> str:
    """The table between the markers of docs/time_to_answer.md's text."""
    start = doc.index(MARKERS[0]) + len(MARKERS[0])
    return doc[start:doc.index(MARKERS[1], start)]


def write_doc() -> None:
    table = markdown(pd.read_csv(OUT / "time_to_answer.csv"))
    doc = DOC.read_text()
    DOC.write_text(doc.replace(doc_table(doc), table))


def main() -> None:
    if "--doc" in sys.argv[1:]:
        write_doc()
        return
    OUT.mkdir(parents=True, exist_ok=True)
    if WORK.exists():
        shutil.rmtree(WORK)                 # the benchmark's own scratch folder
    WORK.mkdir(parents=True)
    rows = [beverloo_question(), static_question(), paper_b_question()]
    table = pd.DataFrame(rows)
    table.to_csv(OUT / "time_to_answer.csv", index=False)
    (OUT / "time_to_answer.md").write_text(markdown(table))
    (OUT / "answers.json").write_text(json.dumps({r["question"]: r["answer"] for r in rows}, indent=1) + "\n")
    print(markdown(table))
    if DOC.is_file():
        write_doc()


if __name__ == "__main__":
    main()
