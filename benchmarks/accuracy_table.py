"""The accuracy table of docs/accuracy.md, made from a bench's committed results so it cannot go stale.

    python benchmarks/accuracy_table.py [benchmarks/results/accuracy]          # print the Markdown table
    python benchmarks/accuracy_table.py benchmarks/results/accuracy --doc      # rewrite it in docs/accuracy.md
    python benchmarks/accuracy_table.py benchmarks/results/accuracy --check    # exit 1 if docs/accuracy.md's differs

It reads ``comparison.csv`` (errors, intervals, speed-ups), ``runs.csv`` (each candidate's time-step
fraction, stiffness scale and failed runs) and ``recommended_profile.json`` of the bench folder, and
writes one row per candidate, fastest last: a resolved error as ``+4.3 % (+1.0, +7.7)`` (the 95 %
interval), an unresolved one as ``not resolved (bound 3.0 %; -0.5 %)``. A candidate none of whose
runs completed gets a row naming why they stopped. In docs/accuracy.md (``--doc PATH`` for another
file) the table sits between the markers ``<!-- accuracy-table DIR -->`` and
``<!-- end accuracy-table -->``; tests/test_accuracy_table.py checks that it is this script's output for
the committed results.
"""
from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path

import pandas as pd

from siloflow.accuracy_bench import QUANTITIES, VALIDATION

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "accuracy.md"      # the page whose table this script writes
HEADER = ("| candidate (dt / t_c, stiffness) | runs | speed-up | flow rate | static band pressure | max dynamic band "
          "pressure | solid fraction | coordination |\n|---|---|---|---|---|---|---|---|")


def _pct(x: float) -> str:
    return f"{100 * x:+.1f}"


def error_cell(row) -> str:
    """A quantity's relative error: the interval when resolved, else the bound and the point estimate."""
    if row is None or not math.isfinite(row.rel_error):
        return "-"
    if row.resolved:
        return f"{_pct(row.rel_error)} % ({_pct(row.ci_lo)}, {_pct(row.ci_hi)})"
    bound = f"{100 * row.bound:.2f}" if row.bound < 0.1 else f"{100 * row.bound:.1f}"   # 3.04 % is not 3.0 %
    return f"not resolved (bound {bound} %; {_pct(row.rel_error)} %)"


def _figures3(v: float) -> str:
    """Three significant figures, trailing zeros kept (5.00, 14.0, 109)."""
    return "?" if not math.isfinite(v) else f"{v:.0f}" if abs(v) >= 99.95 else f"{v:#.3g}"


def speedup_cell(row) -> str:
    if row is None or not math.isfinite(row.speedup):
        return "-"
    return f"{_figures3(row.speedup)} ({_figures3(row.speedup_lo)}-{_figures3(row.speedup_hi)})"


def _reason(text) -> str:
    """The first clause of a failed run's reason: 'the run was stopped by siloflow's guard (overlap)'."""
    return re.split(r"[:\n]", str(text), maxsplit=1)[0].strip() or "failed"


def runs_cell(by_q: dict, failed: int, failed_fill: int) -> str:
    whole = by_q["flow_rate"].n_cand if "flow_rate" in by_q else 0
    settled = max((by_q[q].n_cand for q in ("static_pressure", "coordination") if q in by_q), default=whole)
    text = f"{whole}" + (f" (+{settled - whole} fill-only)" if settled > whole else "")
    method = next((by_q[q].method for q in QUANTITIES if q in by_q and isinstance(by_q[q].method, str)), "")
    text += f" {method}" if method else ""
    stopped = failed + failed_fill
    return text + (f" ({stopped} failed)" if stopped else "")


def table(folder: Path) -> str:
    """The Markdown table of the bench results in ``folder``."""
    comp = pd.read_csv(folder / "comparison.csv")
    runs = pd.read_csv(folder / "runs.csv")
    rec_path = folder / "recommended_profile.json"
    rec = json.loads(rec_path.read_text()) if rec_path.exists() else None
    recommended = (rec or {}).get("candidate")
    design = runs.groupby("candidate")[["timestep_fraction", "stiffness_scale"]].first()
    rows = []
    for name, group in comp[comp.candidate != "reference"].groupby("candidate", sort=False):
        by_q = {r.quantity: r for r in group.itertuples() if r.quantity in QUANTITIES}
        first = group.iloc[0]
        label = f"{name} ({design.at[name, 'timestep_fraction']:g}, {design.at[name, 'stiffness_scale']:g})"
        if name == recommended:
            label = f"**{label}: the recommended profile**"
        elif name.endswith(VALIDATION):
            label += ": new seeds, the check of " + name[: -len(VALIDATION)]
        # failed whole and fill-only runs (0 in a table written before the columns)
        failed = group.reindex(columns=["failed_runs", "failed_fill_only"]).iloc[0].fillna(0).astype(int)
        cells = [label, runs_cell(by_q, *failed),
                 speedup_cell(by_q.get("flow_rate", first))] + [error_cell(by_q.get(q)) for q in QUANTITIES]
        rows.append((float(first.speedup) if math.isfinite(first.speedup) else math.inf, name, cells))
    for name, group in runs[~runs.candidate.isin(comp.candidate)].groupby("candidate", sort=False):
        why = "; ".join(sorted({_reason(t) for t in group.reason}))
        label = f"{name} ({group.timestep_fraction.iloc[0]:g}, {group.stiffness_scale.iloc[0]:g})"
        rows.append((math.inf, name, [label, f"0 of {len(group)} complete: {why}", "-"] + ["-"] * len(QUANTITIES)))
    rows.sort(key=lambda r: (r[0], r[1]))
    return "\n".join([HEADER] + ["| " + " | ".join(cells) + " |" for _, _, cells in rows])


def markers(folder: str) -> tuple[str, str]:
    return f"<!-- accuracy-table {folder} -->", "<!-- end accuracy-table -->"


def _pattern(folder: str) -> re.Pattern:
    start, end = markers(folder)
    return re.compile(re.escape(start) + r"\n(.*?)" + re.escape(end), flags=re.S)


def doc_table(doc_text: str, folder: str) -> str | None:
    """The table between ``folder``'s markers in a page's text (None when the markers are missing)."""
    m = _pattern(folder).search(doc_text)
    return m.group(1).rstrip("\n") if m else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folder", nargs="?", default="benchmarks/results/accuracy")
    parser.add_argument("--doc", type=Path, nargs="?", const=DOC, metavar="PATH",
                        help=f"rewrite the table between the folder's markers in PATH (default {DOC.relative_to(ROOT)})")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 if the table in --doc PATH (default "
                             f"{DOC.relative_to(ROOT)}) is not the committed results'")
    args = parser.parse_args()
    text = table(ROOT / args.folder)
    if args.doc is None and not args.check:
        print(text)
        return
    path = args.doc or DOC
    doc = path.read_text()
    current = doc_table(doc, args.folder)
    if current is None:
        raise SystemExit(f"{path}: no markers {' ... '.join(markers(args.folder))}")
    if args.check:
        if current != text:
            raise SystemExit(f"{path}: the table of {args.folder} differs from its committed results; rewrite it: "
                             f"python benchmarks/accuracy_table.py {args.folder} --doc {path}")
        print(f"{path}: the table of {args.folder} is the committed results'")
        return
    start, end = markers(args.folder)
    new = _pattern(args.folder).sub(lambda _: f"{start}\n{text}\n{end}", doc)
    from siloflow.atomic_files import write_text
    write_text(path, new)
    print(f"{path}: table of {args.folder} rewritten")


if __name__ == "__main__":
    main()
