"""Do LIGGGHTS and LAMMPS agree on the polydisperse case once both read the same placed fill? (issue 36)

``make bench-engines-poly`` (resumable: an (engine, seed) already in the table is not run again).
Before issue 36 each engine filled its own way (LIGGGHTS' insertion, short of small grains; LAMMPS'
random sequential addition), and on the accuracy case LAMMPS flowed 8.5-9.2 % faster, loaded the
wall 8.7-9.5 % more and packed 2.0-2.2 % denser (docs/accuracy.md, ``*_lammps`` rows against the
LIGGGHTS reference). Now both read the same batches (``siloflow.fill_placement``), so what is left
is the walls (LIGGGHTS' faceted mesh, LAMMPS' round region) and the contact law.

The case is the accuracy benchmark's (benchmarks/cases/accuracy_small.yaml: 1000 grains of paper B's
7 sizes, hooke) at the settings of the engine rows (``E1e-2_dt0.1``: dt = 0.1 t_c, 1/100 of the
stiffness), 2 ranks, ``SEEDS`` seeds per engine (the table resumes, so a larger ``SEEDS`` extends it); a seed places the same grains in both engines. One
engine job at a time.

Writes benchmarks/results/engines_poly/: runs.csv (every run: the accuracy bench's quantities),
summary.csv (LAMMPS against LIGGGHTS per quantity, the discharge's over the runs that did not clog: Welch's 95 % interval, ``siloflow.bench_stats.
difference``; a difference is within 3 % when its interval lies inside +/- 3 %; ``fills_needed``, the runs
per engine that would prove it within 3 % if the measured difference and spreads held, ``bench_stats.fills_needed``)
and engines_poly.png.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_runs import ROOT, clogged  # noqa: E402

sys.path.insert(0, str(ROOT))
from siloflow import bench_stats  # noqa: E402
from siloflow.accuracy_bench import DISCHARGE_QUANTITIES, QUANTITIES, Candidate, candidate_case, run_metrics  # noqa: E402
from siloflow.atomic_files import atomic_path, write_text  # noqa: E402
from siloflow.run_table import PlannedRun, case_digest, engine_wall_time, run_missing  # noqa: E402
from siloflow.study_case import read_study_case  # noqa: E402

CASE = ROOT / "benchmarks" / "cases" / "accuracy_small.yaml"
OUT = ROOT / "benchmarks" / "results" / "engines_poly"
WORK = ROOT / "runs" / "bench_engines_poly"
SEEDS = 40
ENGINES = ("liggghts", "lammps")
RANKS = 2
#: the settings measured (pinned: the table resumes on them)
TIMESTEP_FRACTION, STIFFNESS_SCALE = 0.1, 1e-2
#: what counts as agreement: the difference's 95 % interval inside +/- this
AGREE = 0.03


def candidate(engine: str) -> Candidate:
    """The settings measured on ``engine`` (the accuracy bench's ``E1e-2_dt0.1``, ``RANKS`` ranks)."""
    return Candidate(f"E1e-2_dt0.1_{engine}", TIMESTEP_FRACTION, STIFFNESS_SCALE, ranks=RANKS, engine=engine)


def measure(folder: Path) -> dict:
    """A finished run's quantities (``run_metrics``) and whether its discharge clogged."""
    return {**run_metrics(folder), "clogged": clogged(folder)}


def summary(runs: pd.DataFrame) -> pd.DataFrame:
    """Per quantity: LAMMPS against LIGGGHTS (relative difference of the means, Welch's 95 % interval)
    and whether it is within ``AGREE``; the discharge's quantities over the runs that did not clog."""
    ok = runs[runs.state == "complete"]
    flowing = ok[~ok.clogged.astype(bool)]
    rows = []
    for q in QUANTITIES:
        use = flowing if q in DISCHARGE_QUANTITIES else ok
        ref, cand = use[use.engine == "liggghts"], use[use.engine == "lammps"]
        d = bench_stats.difference(ref[q], cand[q])
        within = bool(-AGREE <= d["ci_lo"] and d["ci_hi"] <= AGREE)
        rows.append({"quantity": q, **d, "within_3_percent": within,
                     "fills_needed": bench_stats.fills_needed({**d, "method": "welch"}, AGREE)})
    return pd.DataFrame(rows)


def figure(table: pd.DataFrame, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 3.4))
    x = range(len(table))
    ax.errorbar(list(x), 100 * table.rel_error, fmt="o", capsize=4,
                yerr=[100 * (table.rel_error - table.ci_lo), 100 * (table.ci_hi - table.rel_error)])
    ax.axhspan(-100 * AGREE, 100 * AGREE, color="0.9", zorder=0)
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_xticks(list(x), [q.replace("_", "\n") for q in table.quantity], fontsize=8)
    ax.set_ylabel("LAMMPS / LIGGGHTS - 1, % (95 %)")
    ax.set_title("accuracy case, same placed fill, E1e-2_dt0.1, 2 ranks", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    plt.close(fig)


def main() -> None:
    base, _ = read_study_case(CASE)
    planned = [PlannedRun(key={"engine": e, "seed": base["seed"] + k},
                          case=candidate_case(base, candidate(e), base["seed"] + k))
               for k in range(SEEDS) for e in ENGINES]
    nan = {q: float("nan") for q in QUANTITIES}
    rows = run_missing(WORK, planned, measure, lambda f, reason: {"wall_s": engine_wall_time(f), "clogged": False, **nan},
                       print, case_digest(base))
    runs = pd.DataFrame(rows)
    table = summary(runs)
    OUT.mkdir(parents=True, exist_ok=True)
    write_text(OUT / "runs.csv", runs.to_csv(index=False))
    write_text(OUT / "summary.csv", table.to_csv(index=False))
    figure(table, OUT / "engines_poly.png")
    pd.set_option("display.width", 200)
    for e in ENGINES:
        print(f"{e}: {int(runs[runs.engine == e].clogged.astype(bool).sum())} of {int((runs.engine == e).sum())} runs clogged")
    print(table[["quantity", "n_ref", "n_cand", "ref_mean", "cand_mean", "rel_error", "ci_lo", "ci_hi",
                 "within_3_percent", "fills_needed"]].to_string(index=False))


if __name__ == "__main__":
    main()
