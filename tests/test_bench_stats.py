"""Statistics of the accuracy-vs-speed benchmark (siloflow.bench_stats) on synthetic ensembles."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from siloflow.bench_stats import best_bounds, compare, difference, paired_difference, pareto_figure, recommend, speedup

PNG = b"\x89PNG\r\n\x1a\n"


def _runs(spec, seed=0):
    """A runs table from ``{candidate: (wall_s, flow mean, flow sd, pressure mean, pressure sd)}``,
    five seeds each."""
    rng = np.random.default_rng(seed)
    rows = []
    for name, (wall, fm, fs, pm, ps) in spec.items():
        for s in range(5):
            rows.append(dict(candidate=name, seed=s, wall_s=wall * (1 + 0.02 * rng.standard_normal()),
                             flow_rate=rng.normal(fm, fs), static_pressure=rng.normal(pm, ps)))
    return pd.DataFrame(rows)


SPEC = {"ref": (100.0, 2.0, 0.01, 500.0, 2.0),
        "fine": (50.0, 2.02, 0.01, 505.0, 2.0),          # 1 % off, tight: qualifies at 5 %
        "noisy": (20.0, 2.0, 0.15, 500.0, 40.0),         # unbiased but too noisy: bound > 5 %
        "slow": (120.0, 2.0, 0.01, 500.0, 2.0)}


def test_interval_coverage_includes_reference_uncertainty():
    # The reference is noisier than the candidate and the true ratio is 1.5: an interval that
    # ignored the reference mean's uncertainty, or used a normal quantile, covers only ~90 %.
    rng = np.random.default_rng(0)
    truth, hits = 15.0 / 10.0 - 1, 0
    for _ in range(2000):
        d = difference(rng.normal(10.0, 0.8, 4), rng.normal(15.0, 0.6, 4))
        hits += d["ci_lo"] <= truth <= d["ci_hi"]
    assert 0.93 <= hits / 2000 <= 0.97


def test_zero_difference_is_mostly_not_resolved():
    rng = np.random.default_rng(1)
    verdicts = [difference(rng.normal(3.0, 0.2, 5), rng.normal(3.0, 0.2, 5))["verdict"] for _ in range(1000)]
    assert sum(v == "not resolved" for v in verdicts) / 1000 >= 0.92


def test_large_difference_is_resolved_with_sign_and_truth_inside():
    rng = np.random.default_rng(2)
    d = difference(rng.normal(100.0, 1.0, 5), rng.normal(80.0, 1.0, 5))
    assert d["resolved"] and d["rel_error"] < 0 and d["ci_hi"] < 0
    assert d["ci_lo"] <= -0.2 <= d["ci_hi"]
    assert d["bound"] == pytest.approx(max(abs(d["ci_lo"]), abs(d["ci_hi"])))
    assert d["verdict"] == f"{d['rel_error']:+.1%} [{d['ci_lo']:+.1%}, {d['ci_hi']:+.1%}]"
    assert d["verdict"].startswith("-19.5% [-21.")


def test_single_run_and_zero_reference():
    for ref, cand in [([1.0], [1.0, 1.1, 0.9]), ([1.0, 1.1], [2.0]), ([], [1.0, 2.0])]:
        d = difference(ref, cand)
        assert d["verdict"] == "not resolved (n < 2)" and d["bound"] == math.inf
        assert math.isnan(d["ci_lo"]) and math.isnan(d["ci_hi"]) and not d["resolved"]
    z = difference([1.0, -1.0], [1.0, 2.0])
    assert z["verdict"] == "reference mean is zero" and math.isnan(z["rel_error"]) and not z["resolved"]


def test_nan_values_are_dropped():
    d = difference([1.0, np.nan, 1.2, 0.8], [np.nan, 1.5, 1.5, 1.6])
    assert (d["n_ref"], d["n_cand"]) == (3, 3)
    assert d["ref_mean"] == pytest.approx(1.0) and d["rel_error"] == pytest.approx(1.5333333 - 1)
    runs = _runs(SPEC)
    runs.loc[(runs.candidate == "fine") & (runs.seed < 2), "flow_rate"] = np.nan
    row = compare(runs, "ref", ["flow_rate"]).set_index("candidate").loc["fine"]
    assert row["n_cand"] == 3 and np.isfinite(row["bound"])


def test_speedup_of_identical_timings_and_of_a_faster_candidate():
    wall = [100.0, 104.0, 98.0, 101.0]
    s = speedup(wall, wall)
    assert s["speedup"] == pytest.approx(1.0) and s["lo"] < 1.0 < s["hi"]
    f = speedup(wall, [50.0, 51.0, 49.5])
    assert 1.9 < f["lo"] < f["speedup"] < f["hi"] < 2.2
    one = speedup(wall, [50.0])                      # borrows the reference's relative spread
    assert one["lo"] < one["speedup"] < one["hi"] and np.isfinite(one["hi"])
    assert math.isnan(speedup([100.0], [50.0])["lo"])


def test_compare_rows_and_reference():
    table = compare(_runs(SPEC), "ref", ["flow_rate", "static_pressure"])
    assert len(table) == 8 and list(table.candidate[:2]) == ["ref", "ref"]
    ref = table[table.candidate == "ref"]
    assert (ref.rel_error == 0).all() and (ref.bound == 0).all() and (ref.verdict == "the reference").all()
    assert (ref.speedup == 1).all()
    fine = table[(table.candidate == "fine") & (table.quantity == "flow_rate")].iloc[0]
    assert fine.speedup == pytest.approx(2.0, rel=0.05) and fine.resolved
    with pytest.raises(ValueError, match="'reference_x'"):
        compare(_runs(SPEC), "reference_x", ["flow_rate"])


def test_recommend_skips_a_faster_candidate_with_a_wide_bound():
    table = compare(_runs(SPEC), "ref", ["flow_rate", "static_pressure"])
    noisy = table[table.candidate == "noisy"].set_index("quantity")
    assert noisy.speedup.iloc[0] > 4 and noisy.at["flow_rate", "bound"] > 0.05    # faster but too wide
    rec = recommend(table, {"flow_rate": 0.05, "static_pressure": 0.05})
    assert rec["candidate"] == "fine" and rec["speedup"] == pytest.approx(2.0, rel=0.05)
    assert set(rec["bounds"]) == {"flow_rate", "static_pressure"} and max(rec["bounds"].values()) <= 0.05
    assert rec["tolerances"] == {"flow_rate": 0.05, "static_pressure": 0.05}
    assert recommend(table, {})["candidate"] == "noisy"              # no tolerance: the fastest
    bb = best_bounds(table, "flow_rate")
    assert list(bb.candidate) == ["noisy", "fine", "ref", "slow"]


def test_recommend_falls_back_to_the_reference_or_none():
    table = compare(_runs(SPEC), "ref", ["flow_rate", "static_pressure"])
    assert recommend(table, {"flow_rate": 0.001})["candidate"] == "ref"
    assert recommend(table, {"solid_fraction": 0.05}) is None        # quantity not in the table
    runs = _runs(SPEC)
    runs["coordination"] = np.nan
    runs.loc[runs.candidate == "fine", "coordination"] = 4.0
    assert recommend(compare(runs, "ref", ["coordination"]), {"coordination": 0.5}) is None


def test_pareto_figure_writes_a_png_atomically(tmp_path):
    table = compare(_runs(SPEC), "ref", ["flow_rate", "static_pressure"])
    path = tmp_path / "pareto.png"
    pareto_figure(table, path, {"flow_rate": 0.05})
    assert path.read_bytes()[:8] == PNG
    pareto_figure(table, path, {"flow_rate": 0.05}, highlight="fine")     # the recommendation starred, rewritten
    assert path.read_bytes()[:8] == PNG
    assert [p.name for p in tmp_path.iterdir()] == ["pareto.png"]
    import matplotlib.pyplot as plt
    assert plt.get_fignums() == []


def _paired_runs(rng, n, corr, shift=0.0):
    """Reference and candidate values of ``n`` seeds whose pairs correlate by ``corr`` (both sd 1
    around 10; the candidate shifted by ``shift``)."""
    common = rng.standard_normal(n)
    own = rng.standard_normal((2, n))
    a = np.sqrt(abs(corr))
    ref = 10.0 + a * common + np.sqrt(1 - abs(corr)) * own[0]
    cand = 10.0 + shift + np.sign(corr) * a * common + np.sqrt(1 - abs(corr)) * own[1]
    return ref, cand


@pytest.mark.parametrize("corr", [-0.5, 0.0, 0.8])
def test_paired_interval_covers_the_truth_at_any_correlation(corr):
    rng = np.random.default_rng(3)
    truth, hits, trials = 0.5 / 10.0, 0, 2000
    for _ in range(trials):
        hits += (lambda d: d["ci_lo"] <= truth <= d["ci_hi"])(paired_difference(*_paired_runs(rng, 6, corr, 0.5)))
    assert 0.93 <= hits / trials <= 0.97


def test_pairing_by_seed_narrows_the_bound_when_seeds_share_their_fill():
    rng = np.random.default_rng(4)
    ref, cand = _paired_runs(rng, 8, 0.8)
    paired, welch = paired_difference(ref, cand), difference(ref, cand)
    assert paired["pair_corr"] > 0.5 and paired["bound"] < 0.8 * welch["bound"]
    assert paired["rel_error"] == pytest.approx(welch["rel_error"])
    with pytest.raises(ValueError, match="length"):
        paired_difference([1.0, 2.0], [1.0])
    d = paired_difference([1.0, np.nan, 1.2, 0.8], [1.1, 1.5, np.nan, 0.9])   # pairs with a NaN dropped
    assert d["n_ref"] == d["n_cand"] == 2 and d["rel_error"] == pytest.approx(2.0 / 1.8 - 1)


def test_compare_pairs_only_candidates_whose_seeds_the_reference_ran():
    rng = np.random.default_rng(5)
    ref, cand = _paired_runs(rng, 6, 0.8)
    runs = pd.DataFrame([dict(candidate="ref", seed=s, wall_s=100.0, q=v) for s, v in enumerate(ref)]
                        + [dict(candidate="same", seed=s, wall_s=10.0, q=v) for s, v in enumerate(cand)]
                        + [dict(candidate="new", seed=100 + s, wall_s=10.0, q=v) for s, v in enumerate(cand)]
                        + [dict(candidate="two", seed=s, wall_s=10.0, q=v) for s, v in enumerate(cand[:2])])
    runs = pd.concat([runs, pd.DataFrame(
        [dict(candidate="some", seed=s, wall_s=10.0, q=v) for s, v in zip((0, 1, 2, 99), cand)]      # seed 99: no reference
        + [dict(candidate="other_engine", seed=s, wall_s=10.0, q=v, engine="lammps") for s, v in enumerate(cand)]
        + [dict(candidate="gaps", seed=s, wall_s=10.0, q=v if s < 2 else np.nan) for s, v in enumerate(cand)])])
    runs["engine"] = runs.get("engine").fillna("")
    t = compare(runs, "ref", ["q"], design=("engine",)).set_index("candidate")
    assert t.at["ref", "method"] == ""
    assert t.at["same", "method"] == "paired" and t.at["same", "n_cand"] == 6
    for name in ("new", "two", "some", "other_engine", "gaps"):    # unmatched seeds, too few, another design
        assert t.at[name, "method"] == "welch", name
    assert t.at["same", "bound"] < t.at["new", "bound"]
    assert t.at["same", "rel_error"] == pytest.approx(t.at["new", "rel_error"])
    assert compare(runs, "ref", ["q"]).set_index("candidate").at["other_engine", "method"] == "paired"   # no design given


def test_a_failed_reference_run_costs_its_own_pair_not_the_pairing():
    # 6 whole seeds (flow and static) and 6 fill-only ones (static only); the reference's fill-only
    # seed 12 failed, so its row is missing: every other pair still pairs, for both quantities
    rng = np.random.default_rng(8)
    ref, cand = _paired_runs(rng, 12, 0.9)
    whole = lambda s: s < 6                                     # noqa: E731
    rows = [dict(candidate=name, seed=s if whole(s) else s + 4, wall_s=wall, timed=whole(s),
                 flow=v if whole(s) else np.nan, static=v)
            for name, vals, wall in (("ref", ref, 100.0), ("cand", cand, 10.0)) for s, v in enumerate(vals)]
    runs = pd.DataFrame([r for r in rows if not (r["candidate"] == "ref" and r["seed"] == 12)])
    t = compare(runs, "ref", ["flow", "static"]).set_index("quantity")
    t = t[t.candidate == "cand"]
    assert list(t["method"]) == ["paired", "paired"]
    assert t.at["flow", "n_cand"] == 6 and t.at["static", "n_cand"] == 11
    keep = [s for s in range(12) if s != 8]                     # seed 12 is the 9th run (index 8)
    assert t.at["static", "rel_error"] == pytest.approx(np.mean(cand[keep]) / np.mean(ref[keep]) - 1)
    assert t.at["flow", "timed_runs"] == "6/6"
    # each quantity pairs on its own values: with the reference's whole seeds 1-5 lost too, the flow
    # rate has 1 pair of 6 values and the static pressure 6 of 12, both below 80 %: Welch
    lost = runs[~((runs.candidate == "ref") & runs.seed.between(1, 5))]
    t = compare(lost, "ref", ["flow", "static"]).query("candidate == 'cand'").set_index("quantity")
    assert t.at["flow", "method"] == "welch" and t.at["static", "method"] == "welch"
    many = pd.concat([runs, pd.DataFrame([dict(candidate=c, seed=100 + s, wall_s=1.0, timed=False, flow=np.nan,
                                               static=10.0 + rng.standard_normal()) for c in ("ref", "cand")
                                          for s in range(40)])])
    many = many[~((many.candidate == "ref") & many.seed.between(1, 5))]
    t = compare(many, "ref", ["flow", "static"]).query("candidate == 'cand'").set_index("quantity")
    # 40 fill-only seeds more: the static pressure's 46 pairs of 52 (88 %) pair; the flow rate's do not
    assert t.at["flow", "method"] == "welch" and t.at["static", "method"] == "paired"
    assert t.at["static", "n_cand"] == 46 and t.at["flow", "n_cand"] == 6


@pytest.mark.parametrize("candidate_seeds, method", [((0, 1, 2, 3, 99), "paired"), ((0, 1, 2, 99), "welch")])
def test_a_quantity_pairs_when_80_percent_of_its_values_have_a_reference_seed(candidate_seeds, method):
    rows = ([dict(candidate="ref", seed=s, wall_s=10.0, q=1.0 + 0.1 * s) for s in range(5)]
            + [dict(candidate="cand", seed=s, wall_s=1.0, q=1.1 + 0.1 * s) for s in candidate_seeds])
    row = compare(pd.DataFrame(rows), "ref", ["q"]).set_index("candidate").loc["cand"]
    assert row["method"] == method
    assert row["n_cand"] == (len(candidate_seeds) - 1 if method == "paired" else len(candidate_seeds))


def test_speedups_are_timed_on_one_machine():
    rows = ([dict(candidate="ref", seed=s, wall_s=400.0 + s, q=1.0, machine="old") for s in range(4)]
            + [dict(candidate="ref", seed=10 + s, wall_s=300.0, q=1.0, machine=np.nan) for s in range(3)]
            + [dict(candidate="legacy", seed=10 + s, wall_s=3.0, q=1.0, machine=np.nan) for s in range(3)]
            + [dict(candidate="legacy", seed=s, wall_s=8.0, q=1.0, machine="old") for s in range(1)]
            + [dict(candidate="only_unrecorded", seed=10 + s, wall_s=6.0, q=1.0, machine=np.nan) for s in range(3)]
            + [dict(candidate="ref", seed=4, wall_s=900.0, q=1.0, machine="slow")]
            + [dict(candidate="fast", seed=s, wall_s=10.0 + s, q=1.0, machine="old") for s in range(2)]
            + [dict(candidate="fast", seed=s, wall_s=22.0 + s, q=1.0, machine="slow") for s in range(2, 5)]
            + [dict(candidate="elsewhere", seed=s, wall_s=5.0, q=1.0, machine="third") for s in range(3)])
    t = compare(pd.DataFrame(rows), "ref", ["q"]).set_index("candidate")
    # the slow machine ran 3 of fast's 5 runs and a reference: 900 / 25, not a mix of the two machines
    assert t.at["fast", "timing_machine"] == "slow" and t.at["fast", "timed_runs"] == "1/3"
    assert t.at["fast", "speedup"] == pytest.approx(900.0 / 25.0)
    assert math.isnan(t.at["elsewhere", "speedup"]) and pd.isna(t.at["elsewhere", "timing_machine"])
    # runs that recorded no machine are one machine only when no recorded machine ran both
    assert t.at["legacy", "timing_machine"] == "old" and t.at["legacy", "speedup"] == pytest.approx(401.5 / 8.0)
    assert t.at["only_unrecorded", "timing_machine"] == "unrecorded"
    assert t.at["only_unrecorded", "speedup"] == pytest.approx(50.0)
    no_column = compare(pd.DataFrame(rows).drop(columns="machine"), "ref", ["q"]).set_index("candidate")
    assert no_column.at["fast", "timed_runs"] == "8/5"


def _bench_rows(n: int, seed: int, paired: bool, err: float = 0.01, sd: float = 0.04) -> pd.DataFrame:
    """n fills of a reference (mean 1, relative sd ``sd``) and of a candidate ``err`` off; paired: the
    candidate shares half of each fill's noise (the same seeds)."""
    rng = np.random.default_rng(seed)
    common = rng.standard_normal(n)
    ref = 1.0 + sd * common
    cand = (1.0 + err) * (1.0 + sd * (np.sqrt(0.5) * common + np.sqrt(0.5) * rng.standard_normal(n))
                          if paired else 1.0 + sd * rng.standard_normal(n))
    seeds = np.arange(n) if paired else np.arange(n) + 1000       # other seeds: no pairs
    return pd.DataFrame({"candidate": ["ref"] * n + ["cand"] * n, "seed": np.r_[np.arange(n), seeds],
                         "wall_s": np.r_[np.full(n, 10.0), np.full(n, 1.0)], "q": np.r_[ref, cand]})


@pytest.mark.parametrize("paired", [True, False])
def test_fills_needed_is_the_ensemble_whose_bound_meets_the_tolerance(paired):
    from siloflow.bench_stats import _t_half, fills_needed
    from scipy import stats
    row = compare(_bench_rows(8, 3, paired), "ref", ["q"]).set_index("candidate").loc["cand"]
    assert row["method"] == ("paired" if paired else "welch")
    rel, tol = abs(row["rel_error"]), row["bound"] * 0.8       # 8 fills do not prove this tolerance
    n = fills_needed(row, tol)
    assert 8 < n < math.inf

    def bound(k):      # the projected bound at k fills a side, from the row's own spread
        if paired:
            sd = (row["ci_hi"] - row["ci_lo"]) / 2 * math.sqrt(8) / stats.t.ppf(0.975, 7)
            return rel + stats.t.ppf(0.975, k - 1) * sd / math.sqrt(k)
        a = row["cand_sd"] ** 2 / row["ref_mean"] ** 2
        b = row["cand_mean"] ** 2 * row["ref_sd"] ** 2 / row["ref_mean"] ** 4
        return rel + _t_half([(a / k, k - 1), (b / k, k - 1)], 0.95)
    assert bound(int(n)) <= tol < bound(int(n) - 1)
    # at the row's own tolerance, its own fills are enough (the projection reproduces the bound)
    assert fills_needed(row, row["bound"] * 1.0001) <= 8


def test_fills_needed_is_infinite_at_an_error_beyond_the_tolerance_and_nan_for_the_reference():
    from siloflow.bench_stats import fills_needed
    table = compare(_bench_rows(8, 4, True, err=0.06), "ref", ["q"]).set_index("candidate")
    assert fills_needed(table.loc["cand"], 0.05) == math.inf          # 6 % off: no ensemble proves 5 %
    assert fills_needed(table.loc["cand"], 0.5) <= 8
    assert math.isnan(fills_needed(table.loc["ref"], 0.05))


def test_fills_needed_keeps_the_fills_a_side_already_has():
    from siloflow.bench_stats import fills_needed
    rows = _bench_rows(15, 6, False)
    rows = rows[(rows.candidate == "ref") | (rows.index < 15 + 4)]            # 15 reference fills, 4 candidate
    row = compare(rows, "ref", ["q"]).set_index("candidate").loc["cand"]
    assert (row["n_ref"], row["n_cand"], row["method"]) == (15, 4, "welch")
    assert fills_needed(row, row["bound"] * 1.0001) <= 4                      # already proven: no more fills
    assert fills_needed(row, abs(row["rel_error"]) + 0.5 * (row["bound"] - abs(row["rel_error"]))) > 4
