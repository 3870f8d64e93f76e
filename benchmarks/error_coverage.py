"""Do a run's stated errors stand for the spread of its seeds? (issue 35)

    python benchmarks/error_coverage.py [--case benchmarks/cases/coverage_small.yaml] [--seeds 12]
        [--work runs/coverage/<name>] [--out benchmarks/results/coverage/<name>] [--repost]
    (make bench-coverage: the small case, which clogs in some seeds, and coverage_flow, which does not)

Runs the case with ``--seeds`` seeds (the case's seed, +1, ...; each ``siloflow run`` into
``WORK/runs/s<seed>``; a finished run is kept, so a second call resumes), then compares, per
quantity, what each run states as its standard error with the standard deviation of the seeds'
values: the flow rate (its headline error, and the straight-line fit's) and each loaded band's
static pressure (its headline error, and the parts it is made of). ``--repost`` recomputes every
run's results with this checkout's post-processing first (``siloflow post``), so a change of an
estimator is measured on the same runs.

Writes ``OUT/runs.csv`` (a row a seed), ``OUT/coverage.csv`` (a row a quantity and estimator:
seeds, mean, seed sd with its 95 % chi-square interval, the root mean square of the stated errors,
their ratio, and whether it lies within a factor of 2) and ``OUT/coverage.png``.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_runs import run_case  # noqa: E402

from siloflow.answers import run_case  # noqa: E402
from siloflow.case_file import case_from_dict  # noqa: E402
from siloflow.run_folder import RunFolder, case_differences  # noqa: E402
from siloflow.runs import post_process  # noqa: E402

#: a band is loaded when its mean static pressure is above this share of the largest one's
LOADED_BAND = 0.2
#: the stated error agrees with the seed spread when their ratio lies within this factor
FACTOR = 2.0


def seed_case(base: dict, seed: int) -> dict:
    data = copy.deepcopy(base)
    data["seed"] = seed
    data["name"] = f"s{seed}"
    return data


def complete(folder: Path) -> bool:
    return (folder / "results" / "summary.json").is_file()


def check_same_case(folder: Path, data: dict) -> None:
    """Refuse to reuse a finished run of another case (the case file changed since it ran): the
    validated cases compared in every section the case file sets (``run_folder.case_differences``)."""
    changed = [path for path, _ in case_differences(case_from_dict(data), run_case(RunFolder(folder)), list(data))]
    if changed:
        raise SystemExit(f"{folder} ran another case ({', '.join(changed[:5])} differ): give another --work, "
                         f"or remove the old runs")


def rows_of(folder: Path, seed: int) -> dict:
    """A seed's values and stated errors (flow rate kg/s, band pressures Pa) from its summary."""
    s = json.loads((folder / "results" / "summary.json").read_text())
    fr = s["flow_rate"]
    row = {"seed": seed, "flow_rate": fr["rate"], "flow_rate_stderr": fr.get("stderr"),
           "flow_rate_fit_stderr": fr.get("fit_stderr", fr.get("stderr") if "batch_stderr" in fr else None)}
    for b in s.get("bands") or []:
        k = b["band"]
        row[f"static_{k}"] = b.get("static_pressure")
        for key, value in b.items():
            if key.startswith("static_pressure_") and key.endswith("stderr"):
                row[f"static_{k}_{key[len('static_pressure_'):]}"] = value
    return row


def chi2_interval(sd: float, n: int) -> tuple[float, float]:
    """95 % interval of a normal population's sd from a sample sd of ``n`` values."""
    from scipy.stats import chi2
    dof = n - 1
    return sd * math.sqrt(dof / chi2.ppf(0.975, dof)), sd * math.sqrt(dof / chi2.ppf(0.025, dof))


def coverage(runs: pd.DataFrame) -> pd.DataFrame:
    """A row per quantity and stated-error estimator (see the module docstring)."""
    quantities = {"flow_rate": [c for c in ("flow_rate_stderr", "flow_rate_fit_stderr") if c in runs]}
    bands = sorted({c.split("_")[1] for c in runs if c.startswith("static_") and c.split("_")[1].isdigit()}, key=int)
    means = {k: runs[f"static_{k}"].mean() for k in bands}
    top = max(means.values()) if means else 0.0
    for k in bands:
        if means[k] > LOADED_BAND * top:
            quantities[f"static_{k}"] = [c for c in runs if c.startswith(f"static_{k}_") and c.endswith("stderr")]
    rows = []
    for q, estimators in quantities.items():
        values = runs[q].dropna()
        n = len(values)
        sd = float(values.std(ddof=1)) if n > 1 else float("nan")
        lo, hi = chi2_interval(sd, n) if n > 2 else (float("nan"), float("nan"))
        for est in estimators:
            stated = runs.loc[values.index, est].astype(float)
            rms = float(np.sqrt(np.nanmean(stated ** 2))) if stated.notna().any() else float("nan")
            ratio = rms / sd if sd > 0 else float("nan")
            rows.append({"quantity": q, "estimator": est[len(q) + 1:] or "stderr", "seeds": n,
                         "stated_finite": int(stated.notna().sum()), "mean": float(values.mean()),
                         "seed_sd": sd, "seed_sd_lo95": lo, "seed_sd_hi95": hi, "stated_rms": rms,
                         "ratio": ratio, "within_factor_2": bool(1 / FACTOR <= ratio <= FACTOR)})
    return pd.DataFrame(rows)


def figure(table: pd.DataFrame, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from postprocess.report.figures import save_figure
    fig, ax = plt.subplots(figsize=(7.5, 0.45 * len(table) + 2.0))
    y = np.arange(len(table))
    ax.axvspan(1 / FACTOR, FACTOR, color="0.9", label=f"within a factor of {FACTOR:g}")
    ax.errorbar(table.stated_rms / table.seed_sd, y,
                xerr=[table.stated_rms / table.seed_sd - table.stated_rms / table.seed_sd_hi95,
                      table.stated_rms / table.seed_sd_lo95 - table.stated_rms / table.seed_sd],
                fmt="o", capsize=3, label="stated error / seed sd (95 % of the sd)")
    ax.set_yticks(y, [f"{q} ({e})" for q, e in zip(table.quantity, table.estimator)])
    ax.set_xscale("log")
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_xlabel("root mean square stated error / standard deviation of the seeds")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", type=Path, default=ROOT / "benchmarks/cases/coverage_small.yaml")
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--work", type=Path, default=None, help="default runs/coverage/<case name>")
    ap.add_argument("--out", type=Path, default=None, help="default benchmarks/results/coverage/<case name>")
    ap.add_argument("--repost", action="store_true", help="recompute each run's results first")
    args = ap.parse_args()
    if args.seeds < 3:
        raise SystemExit("--seeds: at least 3 (a spread needs them)")
    base = yaml.safe_load(args.case.read_text())
    args.work = args.work or ROOT / "runs" / "coverage" / base["name"]
    args.out = args.out or ROOT / "benchmarks" / "results" / "coverage" / base["name"]
    (args.work / "runs").mkdir(parents=True, exist_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for seed in range(base.get("seed", 12345), base.get("seed", 12345) + args.seeds):
        folder = args.work / "runs" / f"s{seed}"
        if complete(folder):
            check_same_case(folder, seed_case(base, seed))
            if args.repost:
                    post_process(folder)
        elif folder.exists():
            raise SystemExit(f"{folder} exists but is not finished: remove it or finish it "
                             f"(siloflow run --resume {folder})")
        else:
            _, wall = run_case(seed_case(base, seed), args.work)
            print(f"seed {seed}: {wall:.0f} s", flush=True)
        rows.append(rows_of(folder, seed))
    runs = pd.DataFrame(rows)
    table = coverage(runs)
    from siloflow.atomic_files import write_text
    write_text(args.out / "runs.csv", runs.to_csv(index=False))
    write_text(args.out / "coverage.csv", table.to_csv(index=False))
    figure(table, args.out / "coverage.png")
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(table[["quantity", "estimator", "seeds", "mean", "seed_sd", "stated_rms", "ratio", "within_factor_2"]])


if __name__ == "__main__":
    main()
