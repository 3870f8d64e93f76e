"""Does the deck at the engine's speed measure what the sensor-mesh deck does? (issue 56)

The quick case (``decks/quick.yaml``) on LIGGGHTS, seed by seed, with its side walls as sensor
meshes (``engine.side_walls: meshes``, the default) and as primitive walls whose band forces are
binned in the engine (``engine.side_walls: primitive``). The same seed places the same fill in both
(the placed fill is siloflow's, not the engine's), so the runs are paired by seed. Per run: whether it
clogged, the steady flow rate, the settled bed's force balance, and each band's static and discharge
(steady-window mean) pressure.

Resumable: each finished run's row is appended to ``benchmarks/results/deck_equivalence/runs.csv``,
and a run already there is not run again. ``--table`` writes ``comparison.csv``: per quantity the
two decks' means, the mean paired difference and its standard error over seeds (sd / sqrt(n)),
whether the difference lies within 2 standard errors, the paired t test's two-sided p value (n - 1
degrees of freedom) and, over the family of quantities, whether it differs at 5 % after Holm's
correction (with a dozen quantities, one beyond 2 standard errors is what chance gives). Clogged
seeds leave the flow and discharge rows; bands above the bed (zero on both decks) leave the table.

    .venv/bin/python benchmarks/deck_equivalence.py --seeds 1-10
    .venv/bin/python benchmarks/deck_equivalence.py --table
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "deck_equivalence"
WORK = ROOT / "runs" / "deck_equivalence"
CASE = ROOT / "decks" / "quick.yaml"

#: the decks compared: name -> the case's engine.side_walls
DECKS = {"primitive": "primitive", "sensor_meshes": "meshes"}


def case_file(seed: int, deck: str) -> Path:
    data = yaml.safe_load(CASE.read_text())
    data["seed"] = seed
    data["name"] = f"quick_{deck}_s{seed}"
    data.setdefault("engine", {})["side_walls"] = DECKS[deck]
    WORK.mkdir(parents=True, exist_ok=True)
    path = WORK / f"{data['name']}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def run_row(folder: Path, seed: int, deck: str) -> dict:
    """A finished run's numbers: flow rate, force balance, each band's static and discharge pressure."""
    summary = yaml.safe_load((folder / "results" / "summary.json").read_text())
    bands = pd.read_csv(folder / "results" / "bands.csv")
    row = {"seed": seed, "deck": deck, "clogged": summary.get("clogged") is not None,
           "flow_rate": summary["flow_rate"]["rate"],
           "flow_rate_stderr": summary["flow_rate"]["stderr"],
           "force_balance": (summary.get("force_balance") or {}).get("ratio", math.nan)}
    for _, b in bands.iterrows():
        row[f"static_band{int(b.band):02d}"] = b.static_pressure
        row[f"dynamic_band{int(b.band):02d}"] = b.dynamic_mean_pressure
    return row


def run_one(seed: int, deck: str) -> dict:
    from siloflow.errors import SiloflowError
    from siloflow.runs import run
    folder = WORK / f"{deck}_s{seed}"
    try:
        run(case_file(seed, deck), folder, force=True)
    except SiloflowError as exc:
        raise SystemExit(f"{deck} seed {seed} failed: {exc}") from None
    return run_row(folder, seed, deck)


def comparison(runs: pd.DataFrame) -> pd.DataFrame:
    """Per quantity: each deck's mean over the seeds both have, the paired difference (primitive -
    sensor meshes) with its standard error, relative to the sensor meshes' mean, and the verdict."""
    runs = with_clogged(runs)
    a = runs[runs.deck == "sensor_meshes"].set_index("seed")
    b = runs[runs.deck == "primitive"].set_index("seed")
    seeds = a.index.intersection(b.index)
    # a clogged discharge has no steady flow: its seed leaves the flow and discharge comparisons
    flowing = [s for s in seeds if not (a.loc[s, "clogged"] or b.loc[s, "clogged"])]
    rows = []
    for q in [c for c in runs.columns if c not in ("seed", "deck", "flow_rate_stderr", "clogged")]:
        seeds_q = seeds if q.startswith("static") or q == "force_balance" else pd.Index(flowing)
        x, y = a.loc[seeds_q, q].astype(float), b.loc[seeds_q, q].astype(float)
        ok = np.isfinite(x) & np.isfinite(y)
        d = (y - x)[ok]
        n = int(ok.sum())
        se = float(d.std(ddof=1) / math.sqrt(n)) if n >= 2 else math.nan
        mean_d = float(d.mean()) if n else math.nan
        ref = float(x[ok].mean()) if n else math.nan
        if n and not (x[ok].any() or y[ok].any()):
            continue                                # a band above the bed: zero on both decks
        p = float(2 * stats.t.sf(abs(mean_d) / se, n - 1)) if n >= 2 and se > 0 else math.nan
        rows.append({"quantity": q, "seeds": n, "sensor_meshes_mean": ref, "primitive_mean": float(y[ok].mean()) if n else math.nan,
                     "difference": mean_d, "difference_stderr": se,
                     "relative_difference": mean_d / ref if ref else math.nan,
                     "relative_stderr": se / abs(ref) if ref else math.nan,
                     "within_2_stderr": bool(abs(mean_d) <= 2 * se) if np.isfinite(se) else None,
                     "p_value": p})
    table = pd.DataFrame(rows)
    # the family of quantities: each p against 0.05 / (quantities left) in increasing order (Holm), so that
    # a difference is claimed only where it stands out of the chance exceedances of many comparisons
    order = table.p_value.sort_values().index
    m, holm = len(order), {}
    for rank, i in enumerate(order):
        holm[i] = bool(table.p_value[i] < 0.05 / (m - rank)) and (rank == 0 or holm[order[rank - 1]])
    table["differs_holm_5pct"] = pd.Series(holm)
    return table


def with_clogged(runs: pd.DataFrame) -> pd.DataFrame:
    """``runs`` with its ``clogged`` column, read from the run folders' summaries for rows that lack it."""
    runs = runs.copy()
    if "clogged" not in runs:
        runs["clogged"] = np.nan
    for i, r in runs[runs.clogged.isna()].iterrows():
        summary = WORK / f"{r.deck}_s{int(r.seed)}" / "results" / "summary.json"
        if not summary.exists():
            raise SystemExit(f"{summary} is missing: the row of {r.deck} seed {int(r.seed)} has no clogged column")
        runs.loc[i, "clogged"] = yaml.safe_load(summary.read_text()).get("clogged") is not None
    runs["clogged"] = runs.clogged.astype(bool)
    return runs


def figure(comp: pd.DataFrame, path: Path) -> None:
    """Each quantity's relative paired difference (primitive - sensor meshes) with +/- 2 standard errors."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 0.35 * len(comp) + 1.5))
    y = np.arange(len(comp))[::-1]
    ax.errorbar(comp.relative_difference * 100, y, xerr=2 * comp.relative_stderr * 100, fmt="o", capsize=3)
    ax.axvline(0, color="k", lw=0.8)
    ax.set_yticks(y, [f"{q} ({n} seeds)" for q, n in zip(comp.quantity, comp.seeds)], fontsize=8)
    ax.set(xlabel="primitive - sensor meshes (% of the meshes' mean; +/- 2 SE over seeds)",
           title="The quick case on both LIGGGHTS decks, paired by seed")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="1-10", help="seeds a-b (inclusive)")
    ap.add_argument("--table", action="store_true", help="only write comparison.csv from the committed runs")
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    table = OUT / "runs.csv"
    runs = pd.read_csv(table) if table.exists() else pd.DataFrame(columns=["seed", "deck"])
    if not args.table:
        lo, hi = (int(s) for s in args.seeds.split("-"))
        for seed in range(lo, hi + 1):
            for deck in ("primitive", "sensor_meshes"):
                if ((runs.seed == seed) & (runs.deck == deck)).any():
                    continue
                row = run_one(seed, deck)
                runs = pd.concat([runs, pd.DataFrame([row])], ignore_index=True)
                runs.to_csv(table, index=False)
                print(f"seed {seed} {deck}: flow {row['flow_rate'] * 1000:.2f} g/s, balance {row['force_balance']:.4f}",
                      flush=True)
    comp = comparison(runs)
    comp.to_csv(OUT / "comparison.csv", index=False)
    figure(comp, OUT / "comparison.png")
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(comp.to_string(index=False))


if __name__ == "__main__":
    main()
