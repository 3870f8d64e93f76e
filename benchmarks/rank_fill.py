"""Do MPI ranks change a LIGGGHTS fill, and does the bed hold the particles the case asks for?

``make bench-rank-fill`` (resumable: a (batch fraction, ranks, seed) already in the table is not run
again). Until issue 36, LIGGGHTS' ``fix insert/rate/region`` placed each batch largest first and
dropped what did not fit (more on 2 ranks: no grain within a radius of a subdomain border): the
bed came out heavier than asked by amounts that depended on the rank count. Those results are kept
in benchmarks/results/rank_fill_fix_insert/. Since then siloflow places every batch itself
(``siloflow.fill_placement``) and LIGGGHTS reads them (``read_dump``): this benchmark checks that
the bed's weight is the planned one on both rank counts, and what is left of a rank effect.

The case is the accuracy benchmark's (benchmarks/cases/accuracy_small.yaml: 1000 grains of paper B's
7 sizes, ``fill.batch_volume_fraction`` 0.35) at dt = 0.2 t_c and 1/1000 of the stiffness (candidate
``E1e-3_dt0.2``, where the bench measured 1 rank 17 % below 2 ranks in static band pressure), run
at the case's batch fraction and at one that fits on both rank counts, on 1 and 2 ranks, over
``SEEDS`` seeds each. One engine job at a time.

Writes benchmarks/results/rank_fill/: runs.csv (every run: the accuracy bench's quantities, the
batches, the settled bed's weight against the plan's), summary.csv (per batch fraction: 1 rank against 2, Welch's
95 % interval, ``siloflow.bench_stats.difference``) and rank_fill.png.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_runs import ROOT  # noqa: E402

sys.path.insert(0, str(ROOT))
from siloflow import bench_stats  # noqa: E402
from siloflow.accuracy_bench import QUANTITIES, Candidate, candidate_case, run_metrics  # noqa: E402
from siloflow.atomic_files import write_text  # noqa: E402
from siloflow.engine.liggghts.log import PLACED, parse_log_text  # noqa: E402
from siloflow.fill_placement import class_counts  # noqa: E402
from siloflow.run_table import PlannedRun, case_digest, engine_wall_time, run_missing  # noqa: E402
from siloflow.study_case import read_study_case  # noqa: E402

CASE = ROOT / "benchmarks" / "cases" / "accuracy_small.yaml"
OUT = ROOT / "benchmarks" / "results" / "rank_fill"
WORK = ROOT / "runs" / "bench_rank_fill_placed"
SEEDS = 8
RANKS = (1, 2)
#: the case's batch fraction (over-full: short batches on any rank count) and one that fits on both
BATCH_FRACTIONS = (0.35, 0.15)
#: the settings measured (pinned: the table resumes on them)
TIMESTEP_FRACTION, STIFFNESS_SCALE = 0.2, 1e-3


def case_of(base: dict, fraction: float, ranks: int, seed: int) -> dict:
    """The case fields of one run: the accuracy bench's candidate at the pinned settings on ``ranks``
    ranks, with the batch fraction ``fraction``."""
    cand = Candidate(f"b{fraction:g}_r{ranks}", TIMESTEP_FRACTION, STIFFNESS_SCALE, ranks=ranks)
    data = candidate_case(base, cand, seed)
    return {**data, "fill": {**data["fill"], "batch_volume_fraction": fraction}}


def bed_weight(folder: Path) -> float:
    """The settled bed's weight (the static window's mass in the silo x g), N."""
    from siloflow.run_folder import RunFolder
    return float((RunFolder(folder).read_summary().get("force_balance") or {}).get("weight_N", float("nan")))


def planned_weight(folder: Path) -> float:
    """The weight of the bed the plan asks for (every grain of :func:`class_counts`), N."""
    from siloflow.run_folder import RunFolder
    plan = RunFolder(folder).plan
    return plan.gravity * sum(plan.species[k].mass * n for k, n in class_counts(plan).items())


def batches(folder: Path) -> dict:
    """The fill of a run's log: batches read, the first batch's size, the settled bed's weight
    against the planned one, N."""
    state = parse_log_text((folder / "log.liggghts").read_text(errors="replace"))
    placed = state.batches.get(PLACED, [])
    weight, planned = bed_weight(folder), planned_weight(folder)
    return {"weight_N": weight, "planned_weight_N": planned, "weight_error": weight / planned - 1,
            "batches": len(placed), "first_batch": placed[0] if placed else float("nan"),
            "inserted": sum(placed)}


def summary(runs: pd.DataFrame) -> pd.DataFrame:
    """Per batch fraction and quantity: 2 ranks against 1 (relative difference of the means with
    Welch's 95 % interval); the mean batch count and first batch per rank count."""
    rows = []
    ok = runs[runs.state == "complete"]
    for fraction, g in ok.groupby("batch_volume_fraction"):
        one, two = g[g.ranks == 1], g[g.ranks == 2]
        for q in (*QUANTITIES, "weight_N", "weight_error", "batches", "first_batch"):
            d = bench_stats.difference(one[q], two[q])
            rows.append({"batch_volume_fraction": fraction, "quantity": q, "n_1rank": len(one), "n_2ranks": len(two),
                         "mean_1rank": one[q].mean(), "mean_2ranks": two[q].mean(), **d})
    return pd.DataFrame(rows)


def figure(table: pd.DataFrame, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    shown = ["static_pressure", "weight_N", "flow_rate", "solid_fraction"]
    fig, axes = plt.subplots(1, len(shown), figsize=(3.2 * len(shown), 3.2))
    for ax, q in zip(axes, shown):
        t = table[table.quantity == q]
        x = range(len(t))
        ax.errorbar(list(x), 100 * t.rel_error, yerr=[100 * (t.rel_error - t.ci_lo), 100 * (t.ci_hi - t.rel_error)],
                    fmt="o", capsize=4)
        ax.axhline(0, color="0.6", lw=0.8)
        ax.set_xticks(list(x), [f"{b:g}" for b in t.batch_volume_fraction])
        ax.set_xlim(-0.5, len(t) - 0.5)
        ax.set_xlabel("fill.batch_volume_fraction")
        ax.set_title(q.replace("_", " "), fontsize=9)
    axes[0].set_ylabel("2 ranks / 1 rank - 1, % (95 %)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    base, _ = read_study_case(CASE)
    planned = [PlannedRun(key={"batch_volume_fraction": b, "ranks": r, "seed": base["seed"] + k},
                          case=case_of(base, b, r, base["seed"] + k))
               for k in range(SEEDS) for b in BATCH_FRACTIONS for r in RANKS]
    nan = {q: float("nan") for q in QUANTITIES}
    rows = run_missing(WORK, planned, lambda f: {**run_metrics(f), **batches(f)},
                       lambda f, reason: {"wall_s": engine_wall_time(f), **nan}, print, case_digest(base))
    runs = pd.DataFrame(rows)
    if "weight_N" not in runs:                 # rows written before the column: read their folders
        runs["weight_N"] = float("nan")
    for i in runs.index[runs.weight_N.isna() & (runs.state == "complete")]:
        folder = WORK / str(runs.at[i, "folder"])
        if folder.is_dir():
            runs.at[i, "weight_N"] = bed_weight(folder)
    table = summary(runs)
    OUT.mkdir(parents=True, exist_ok=True)
    write_text(OUT / "runs.csv", runs.to_csv(index=False))
    write_text(OUT / "summary.csv", table.to_csv(index=False))
    figure(table, OUT / "rank_fill.png")
    pd.set_option("display.width", 200)
    print(table[["batch_volume_fraction", "quantity", "n_1rank", "n_2ranks", "mean_1rank", "mean_2ranks",
                 "rel_error", "ci_lo", "ci_hi"]].to_string(index=False))


if __name__ == "__main__":
    main()
