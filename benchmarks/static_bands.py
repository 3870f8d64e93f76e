"""Where and why a candidate's static wall load differs from the reference's.

1. By band: the accuracy benchmark's static band pressure (the mean over the loaded bands) split into its
   bands, each compared like the bench's quantities (``bench_stats.compare``: paired by seed, 95 %
   intervals), for the normal pressure and the wall shear (Pa): static_bands.csv, static_bands.png.
2. The settled bed's vertical force balance (why): the share of the weight the side walls carry by
   friction (``wall_friction_share``), the load on the floor (bottom and orifice plate, N), the bottom
   band's pressure and its ratio to the floor's mean pressure, compared the same way, and how many beds
   end with the wall friction reversed (share < 0: the walls pull the bed down), with Wilson 95 %
   intervals: wall_friction.csv, wall_friction.png.

    python benchmarks/static_bands.py [BENCH_FOLDER] [--out FOLDER] [--min-fills N]

BENCH_FOLDER defaults to runs/bench_accuracy (``make bench-accuracy``), --out to
benchmarks/results/accuracy, --min-fills (the candidates compared: those with this many fills or
more) to 20. It reads each complete run's ``results/bands.csv``, ``results/summary.json`` and
``plan.json`` in the bench folder's run table. Bands are numbered from the bottom; only those the
reference loads (mean static pressure above ``accuracy_bench.LOADED_BAND`` of the largest band's)
are compared.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import pandas as pd
from scipy import stats

from postprocess.report.figures import plt, save_figure
from siloflow import accuracy_bench as ab, bench_stats
from siloflow.atomic_files import write_text
from siloflow.run_table import read_rows

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "accuracy"
#: the candidates compared: those with at least this many fills (an ensemble)
MIN_FILLS = 20


#: the settled bed's force-balance quantities compared in wall_friction.csv
BALANCE = ("wall_friction_share", "floor_load", "band0_pressure", "band0_floor_ratio")


def balance_of(folder: Path) -> dict:
    """The settled bed's vertical force balance of a run folder, from results/summary.json and plan.json:
    ``wall_friction_share`` (wall shear / weight; < 0 when the walls pull the bed down), ``floor_load``
    (N, the vertical load on the walls of role bottom and plate: all walls' load less the side walls'
    shear) and ``floor_area`` (m2, those walls' area). NaN where the run has no force balance (or no
    summary or plan)."""
    def read(name):
        path = folder / name
        return json.loads(path.read_text()) if path.is_file() else {}
    fb = read("results/summary.json").get("force_balance") or {}
    walls = read("plan.json").get("walls") or []
    share, weight, load = (fb.get(k) for k in ("wall_friction_share", "weight_N", "wall_and_bottom_load_N"))
    if share is None or weight is None or load is None:
        share = weight = load = math.nan
    area = sum(w["area"] for w in walls if w.get("role") in ("bottom", "plate") and w.get("area"))
    return {"wall_friction_share": share, "floor_load": load - share * weight, "floor_area": area or math.nan}


def band_runs(bench: Path) -> pd.DataFrame:
    """One row per complete run of the bench folder whose folder is here: candidate, seed, wall_s, its
    stiffness_scale and timestep_fraction, ``band<i>_pressure`` / ``band<i>_shear`` (Pa, the static
    stage's means) from its bands.csv, the :func:`balance_of` quantities and ``band0_floor_ratio`` (the
    bottom band's pressure over the floor's mean pressure, floor_load / floor_area)."""
    runs = pd.DataFrame(read_rows(bench))
    runs = runs[runs.state == "complete"]
    rows = []
    for r in runs.itertuples():
        table = bench / r.folder / "results" / "bands.csv"
        if not table.is_file():
            continue
        bands = pd.read_csv(table).sort_values("z_mid")
        row = {"candidate": r.candidate, "seed": r.seed, "wall_s": r.wall_s,
               "stiffness_scale": float(r.stiffness_scale), "timestep_fraction": float(r.timestep_fraction)}
        for i, b in enumerate(bands.itertuples()):
            row[f"band{i}_pressure"], row[f"band{i}_shear"] = b.static_pressure, b.static_shear
        row.update(balance_of(bench / r.folder))
        row["band0_floor_ratio"] = row.get("band0_pressure", math.nan) * row["floor_area"] / row["floor_load"]
        rows.append(row)
    return pd.DataFrame(rows)


#: the columns written to the CSV tables
COLUMNS = ["candidate", "quantity", "n_ref", "n_cand", "ref_mean", "cand_mean", "rel_error", "ci_lo", "ci_hi",
           "resolved", "verdict", "method", "pair_corr"]


def reversed_beds(shares: pd.Series) -> dict:
    """How many settled beds end with the wall friction reversed (``wall_friction_share`` < 0: the side
    walls pull the bed down and the floor carries more than its weight), of how many, with the Wilson 95 %
    interval of that fraction (``reversed_lo``, ``reversed_hi``)."""
    s = shares.dropna()
    k, n = int((s < 0).sum()), len(s)
    if not n:
        return {"reversed": 0, "beds": 0, "reversed_fraction": math.nan, "reversed_lo": math.nan,
                "reversed_hi": math.nan}
    ci = stats.binomtest(k, n).proportion_ci(0.95, method="wilson")
    return {"reversed": k, "beds": n, "reversed_fraction": k / n, "reversed_lo": ci.low, "reversed_hi": ci.high}


def friction_table(runs: pd.DataFrame, min_fills: int = MIN_FILLS) -> pd.DataFrame:
    """The :data:`BALANCE` quantities compared with the reference's (``bench_stats.compare``, candidates
    with ``min_fills`` or more beds), each row with its candidate's :func:`reversed_beds` (the
    reference's row too)."""
    table = bench_stats.compare(runs, ab.REFERENCE.name, list(BALANCE), design=ab.DESIGN)
    table = table[table.n_cand >= min_fills][COLUMNS]
    rev = pd.DataFrame([{"candidate": name, **reversed_beds(g.wall_friction_share)}
                        for name, g in runs.groupby("candidate")])
    return table.merge(rev, on="candidate", how="left")


def _by_softness(runs: pd.DataFrame, names) -> list:
    """``names`` from the stiffest to the softest, then by time step (the run table's design columns)."""
    design = runs.groupby("candidate")[["stiffness_scale", "timestep_fraction"]].first()
    return sorted(names, key=lambda n: (-design.stiffness_scale.get(n, 0.0), design.timestep_fraction.get(n, 0.0)))


def friction_figure(runs: pd.DataFrame, table: pd.DataFrame, path: Path) -> None:
    """Left: every bed's wall friction share by candidate (reversed beds below 0, their count above).
    Right: the relative change of the floor load, the bottom band's pressure and their ratio, 95 % intervals."""
    names = _by_softness(runs, table.candidate.unique())
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for i, name in enumerate(names):
        s = runs.loc[runs.candidate == name, "wall_friction_share"].dropna()
        jitter = ((s.rank(method="first") / len(s)) - 0.5) * 0.5
        left.plot(i + jitter, 100 * s, ".", ms=4, alpha=0.6, color="C0" if name == ab.REFERENCE.name else "C1")
        left.plot([i - 0.3, i + 0.3], [100 * s.mean()] * 2, "k-", lw=1.5)
        rev = reversed_beds(s)
        left.annotate(f"{rev['reversed']}/{rev['beds']}", (i, 1.0), xycoords=("data", "axes fraction"),
                      ha="center", va="top", fontsize=7)
    left.axhline(0, color="k", lw=0.8)
    left.set_xticks(range(len(names)), names, rotation=60, ha="right", fontsize=7)
    left.set_ylabel("weight carried by wall friction (%)")
    left.set_title("settled beds (bar: mean; top: beds reversed)", fontsize=9)
    shown = [n for n in names if n != ab.REFERENCE.name]
    labels = {"floor_load": "floor load", "band0_pressure": "bottom band pressure",
              "band0_floor_ratio": "bottom band / floor pressure"}
    for k, (q, label) in enumerate(labels.items()):
        t = table[table.quantity == q].set_index("candidate").reindex(shown)
        x = [i + (k - 1) * 0.2 for i in range(len(shown))]
        right.errorbar(x, 100 * t.rel_error, yerr=[100 * (t.rel_error - t.ci_lo), 100 * (t.ci_hi - t.rel_error)],
                       fmt="o", capsize=3, label=label)
    right.axhline(0, color="k", lw=0.8)
    right.set_xticks(range(len(shown)), shown, rotation=60, ha="right", fontsize=7)
    right.set_ylabel("candidate / reference - 1 (%)")
    right.set_title("where the bottom band's over-load comes from (95 % intervals)", fontsize=9)
    right.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path)


def band_figure(table: pd.DataFrame, ref: pd.DataFrame, loaded: list, path: Path) -> None:
    """Each candidate's static wall pressure error by band, 95 % intervals."""
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
    save_figure(fig, path)


def main(bench: Path, out: Path = OUT, min_fills: int = MIN_FILLS) -> None:
    runs = band_runs(bench)
    if runs.empty or not (runs.candidate == ab.REFERENCE.name).any():
        raise SystemExit(f"{bench}: no complete reference run folder with results/bands.csv here")
    runs = ab.design_columns(runs)
    out.mkdir(parents=True, exist_ok=True)
    ref = runs[runs.candidate == ab.REFERENCE.name]
    pressures = [c for c in runs.columns if c.endswith("_pressure")]
    top = max(ref[c].mean() for c in pressures)
    loaded = [c[:-len("_pressure")] for c in pressures if ref[c].mean() > ab.LOADED_BAND * top]
    quantities = [f"{b}_{k}" for b in loaded for k in ("pressure", "shear")]
    table = bench_stats.compare(runs, ab.REFERENCE.name, quantities, design=ab.DESIGN)
    table = table[table.n_cand >= min_fills]          # the candidates with an ensemble
    write_text(out / "static_bands.csv", table[COLUMNS].to_csv(index=False))
    band_figure(table, ref, loaded, out / "static_bands.png")
    shown = table[table.quantity.str.endswith("_pressure") & (table.candidate != ab.REFERENCE.name)]
    print(shown[["candidate", "quantity", "n_cand", "verdict"]].to_string(index=False))

    friction = friction_table(runs, min_fills)
    write_text(out / "wall_friction.csv", friction.to_csv(index=False))
    friction_figure(runs, friction, out / "wall_friction.png")
    print(friction[["candidate", "quantity", "n_cand", "verdict", "reversed", "beds"]].to_string(index=False))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bench", nargs="?", type=Path, default=ROOT / "runs" / "bench_accuracy")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--min-fills", type=int, default=MIN_FILLS)
    args = parser.parse_args()
    main(args.bench, args.out, args.min_fills)
