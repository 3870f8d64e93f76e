"""Statistics of the accuracy-vs-speed benchmark (siloflow.bench_stats) on synthetic ensembles."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from siloflow.bench_stats import best_bounds, compare, difference, pareto_figure, recommend, speedup

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
    assert [p.name for p in tmp_path.iterdir()] == ["pareto.png"]
    import matplotlib.pyplot as plt
    assert plt.get_fignums() == []
