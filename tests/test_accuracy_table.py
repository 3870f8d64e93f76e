"""benchmarks/accuracy_table.py: the accuracy table of docs/accuracy.md is made from the committed results."""
import importlib.util
import json
import math
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]


def _module():
    spec = importlib.util.spec_from_file_location("accuracy_table", ROOT / "benchmarks" / "accuracy_table.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_docs_table_is_the_committed_results():
    mod = _module()
    folder = "benchmarks/results/accuracy"
    assert mod.DOC == ROOT / "docs" / "accuracy.md"
    in_doc = mod.doc_table(mod.DOC.read_text(), folder)
    assert in_doc is not None, "docs/accuracy.md lost the accuracy table's markers"
    assert in_doc == mod.table(ROOT / folder), (
        "docs/accuracy.md's accuracy table differs from the committed results: "
        "python benchmarks/accuracy_table.py benchmarks/results/accuracy --doc docs/accuracy.md")


def _row(candidate, quantity, err, lo, hi, resolved, speedup=10.0, n=6, method="paired", failed=0):
    return dict(candidate=candidate, quantity=quantity, n_cand=n, rel_error=err, ci_lo=lo, ci_hi=hi,
                bound=max(abs(lo), abs(hi)), resolved=resolved, method=method, speedup=speedup,
                speedup_lo=speedup * 0.9, speedup_hi=speedup * 1.1, failed_runs=failed, failed_fill_only=0)


def test_cells_rows_and_order(tmp_path):
    mod = _module()
    comp = [_row("reference", q, 0.0, 0.0, 0.0, False, 1.0) for q in ("flow_rate", "static_pressure")]
    comp += [_row("fast", "flow_rate", -0.005, -0.0304, 0.02, False, 20.0),
             _row("fast", "static_pressure", 0.043, 0.010, 0.077, True, 20.0, n=10),
             _row("slow", "flow_rate", 0.01, -0.2, 0.22, False, 3.0, failed=1),
             _row("slow", "static_pressure", math.nan, math.nan, math.nan, False, 3.0, n=0)]
    pd.DataFrame(comp).to_csv(tmp_path / "comparison.csv", index=False)
    runs = pd.DataFrame([dict(candidate=c, timestep_fraction=dt, stiffness_scale=k, state=st, reason=why)
                         for c, dt, k, st, why in [("reference", 0.02, 1.0, "complete", ""),
                                                   ("fast", 0.1, 0.01, "complete", ""),
                                                   ("slow", 0.05, 1.0, "complete", ""),
                                                   ("soft", 0.2, 1e-4, "failed",
                                                    "the run was stopped by siloflow's guard (overlap): two grains "
                                                    "overlap by 0.007 m\nlikely cause: ...")]])
    runs.to_csv(tmp_path / "runs.csv", index=False)
    (tmp_path / "recommended_profile.json").write_text(json.dumps({"candidate": "fast"}))
    lines = mod.table(tmp_path).splitlines()
    assert len(lines) == 2 + 3                                 # header, rule, three candidates; no reference
    slow, fast, soft = lines[2:]                               # by speed-up; a candidate that never ran last
    assert slow.startswith("| slow (0.05, 1) | 6 paired (1 failed) | 3.00 (2.70-3.30) |")
    assert "not resolved (bound 22.0 %; +1.0 %)" in slow and "| - |" in slow     # no static value: a dash
    assert fast.startswith("| **fast (0.1, 0.01): the recommended profile** | 6 (+4 fill-only) paired | 20.0 (18.0-22.0) |")
    assert "not resolved (bound 3.04 %; -0.5 %)" in fast       # a bound just past 3 % is not printed as 3.0 %
    assert "+4.3 % (+1.0, +7.7)" in fast                       # resolved: the interval
    assert soft == ("| soft (0.2, 0.0001) | 0 of 1 complete: the run was stopped by siloflow's guard (overlap) "
                    "| - | - | - | - | - | - |")
