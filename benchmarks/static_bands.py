"""Where a candidate's static wall load differs from the reference's: the accuracy benchmark's static band
pressure (the mean over the loaded bands) split into its bands, each compared like the bench's quantities
(``bench_stats.compare``: paired by seed, 95 % intervals), for the normal pressure and the wall shear (Pa).

    python benchmarks/static_bands.py [BENCH_FOLDER]     # default runs/bench_accuracy (make bench-accuracy)

It reads each complete run's ``results/bands.csv`` in the bench folder's run table and writes
benchmarks/results/accuracy/static_bands.csv and static_bands.png. Bands are numbered from the bottom;
only those the reference loads (mean static pressure above ``accuracy_bench.LOADED_BAND`` of the
largest band's) are compared.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

from postprocess.figures import plt, save_figure
from siloflow import accuracy_bench as ab, bench_stats
from siloflow.atomic_files import write_text
from siloflow.run_table import read_rows

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "accuracy"


def band_runs(bench: Path) -> pd.DataFrame:
    """One row per complete run of the bench folder whose folder is here: candidate, seed, wall_s and
    ``band<i>_pressure`` / ``band<i>_shear`` (Pa, the static stage's means) from its bands.csv."""
    runs = pd.DataFrame(read_rows(bench))
    runs = runs[runs.state == "complete"]
    rows = []
    for r in runs.itertuples():
        table = bench / r.folder / "results" / "bands.csv"
        if not table.is_file():
            continue
        bands = pd.read_csv(table).sort_values("z_mid")
        row = {"candidate": r.candidate, "seed": r.seed, "wall_s": r.wall_s}
        for i, b in enumerate(bands.itertuples()):
            row[f"band{i}_pressure"], row[f"band{i}_shear"] = b.static_pressure, b.static_shear
        rows.append(row)
    return pd.DataFrame(rows)


def main(bench: Path) -> None:
    runs = band_runs(bench)
    if runs.empty or not (runs.candidate == ab.REFERENCE.name).any():
        raise SystemExit(f"{bench}: no complete reference run folder with results/bands.csv here")
    runs = ab.design_columns(runs)
    ref = runs[runs.candidate == ab.REFERENCE.name]
    pressures = [c for c in runs.columns if c.endswith("_pressure")]
    top = max(ref[c].mean() for c in pressures)
    loaded = [c[:-len("_pressure")] for c in pressures if ref[c].mean() > ab.LOADED_BAND * top]
    quantities = [f"{b}_{k}" for b in loaded for k in ("pressure", "shear")]
    table = bench_stats.compare(runs, ab.REFERENCE.name, quantities, design=ab.DESIGN)
    table = table[table.n_cand >= 20]          # the candidates with an ensemble
    cols = ["candidate", "quantity", "n_ref", "n_cand", "ref_mean", "cand_mean", "rel_error", "ci_lo", "ci_hi",
            "resolved", "verdict", "method", "pair_corr"]
    write_text(OUT / "static_bands.csv", table[cols].to_csv(index=False))
    cands = [c for c in table.candidate.unique() if c != ab.REFERENCE.name]
    fig, ax = plt.subplots(figsize=(7, 4))
    for k, name in enumerate(cands):
        t = table[(table.candidate == name) & table.quantity.str.endswith("_pressure")]
        x = [loaded.index(q[:-len("_pressure")]) + (k - (len(cands) - 1) / 2) * 0.12 for q in t.quantity]
        ax.errorbar(x, 100 * t.rel_error, yerr=[100 * (t.rel_error - t.ci_lo), 100 * (t.ci_hi - t.rel_error)],
                    fmt="o", capsize=3, label=name)
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xticks(range(len(loaded)), [f"band {b[4:]}\n(ref {ref[b + '_pressure'].mean():.0f} Pa)" for b in loaded])
    ax.set_ylabel("static wall pressure: candidate / reference - 1 (%)")
    ax.set_title("static wall pressure by band, from the bottom (95 % intervals)", fontsize=10)
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, OUT / "static_bands.png")
    shown = table[table.quantity.str.endswith("_pressure") & (table.candidate != ab.REFERENCE.name)]
    print(shown[["candidate", "quantity", "n_cand", "verdict"]].to_string(index=False))


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "runs" / "bench_accuracy")
