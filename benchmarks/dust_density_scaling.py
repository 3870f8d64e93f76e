"""The dust time-step remedy, measured: the same clumps + dust silo run with the dust at its own
density and with the dust density scaled (``particles.dust.density_scale``), over several seeds.

``make bench-dust`` (resumable: a (variant, seed) already in the table is not run again; one engine
job at a time). Each variant is compared with the true density as ``siloflow bench`` compares a
candidate with its reference (``siloflow.bench_stats.compare``: paired by seed, 95 % intervals,
"not resolved" when the interval holds 0, the speed-up from the engine's wall time):

- ``x25``, ``x200``: the dust density scaled, at the time step it allows (the point of the remedy);
- ``x25_dt1``, ``x200_dt1``: the dust density scaled at the true density's time step, so the dust's
  mass is all that changes.

    python benchmarks/dust_density_scaling.py [case.yaml] [--scales 25 200] [--seeds 5]

Default case: tests/data/clump_silo.yaml (600 wheat clumps, 60 dust balls, Hertz, multisphere on
one rank; 1000x did not settle in the allowed time). Work folder runs/bench_dust; results in
benchmarks/results/dust/: runs.csv (every run, with its time step and the dust's mass share),
comparison.csv (the bench's columns, and ``failed_runs``: a variant is compared on the runs that
completed) and dust.png (error against speed-up, one panel per quantity).
"""
from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from siloflow import bench_stats  # noqa: E402
from siloflow.accuracy_bench import QUANTITIES, run_metrics  # noqa: E402
from siloflow.atomic_files import write_text  # noqa: E402
from siloflow.case_file import case_from_dict  # noqa: E402
from siloflow.derived import derive  # noqa: E402
from siloflow.run_table import PlannedRun, case_digest, engine_wall_time, run_missing, run_name  # noqa: E402
from siloflow.study_case import read_study_case  # noqa: E402

OUT = ROOT / "benchmarks" / "results" / "dust"
WORK = ROOT / "runs" / "bench_dust"
TRUE = "true_density"


def variant_data(base: dict, scale: float, seed: int, keep_dt: bool) -> dict:
    """The case of one run: dust density x ``scale``; with ``keep_dt`` the time step of the true
    density (timestep_fraction lowered), so that the dust's mass is all that changes."""
    data = copy.deepcopy(base)
    data["particles"]["dust"]["density_scale"] = scale
    data["seed"] = seed
    if keep_dt:
        true = variant_data(base, 1.0, seed, keep_dt=False)
        engine = data.setdefault("engine", {})
        fraction = derive(case_from_dict(data)).timestep.fraction        # the case's, or the profile's
        engine["timestep_fraction"] = fraction * derive(case_from_dict(true)).dt / derive(case_from_dict(data)).dt
    return data


def variant_name(scale: float, keep_dt: bool) -> str:
    return TRUE if scale == 1.0 else f"x{scale:g}" + ("_dt1" if keep_dt else "")


def dust_columns(folder: Path) -> dict:
    """The run's time step (s) and the dust's share of the mass, from its plan."""
    from siloflow.run_folder import RunFolder
    plan = RunFolder(folder).plan
    share = plan.fill.dust_count * plan.dust.mass / plan.total_mass if plan.dust is not None else 0.0
    return {"dt": plan.dt, "dust_mass_share": share}


def planned_runs(base: dict, scales: list[float], seeds: int, keep_dt: bool) -> list[PlannedRun]:
    variants = [(1.0, False)] + [(s, False) for s in scales] + ([(s, True) for s in scales] if keep_dt else [])
    return [PlannedRun(key={"candidate": variant_name(s, k), "seed": base["seed"] + n},
                       case={**variant_data(base, s, base["seed"] + n, k),
                             "name": run_name(base["name"], "dust", variant_name(s, k), f"s{base['seed'] + n}")},
                       columns={"density_scale": s, "keeps_true_dt": k})
            for n in range(seeds) for s, k in variants]


def main(case_file: Path, scales: list[float], seeds: int, keep_dt: bool = True) -> pd.DataFrame:
    base, _ = read_study_case(case_file)
    nan = {q: float("nan") for q in QUANTITIES}
    rows = run_missing(WORK, planned_runs(base, scales, seeds, keep_dt),
                       lambda f: {**run_metrics(f), **dust_columns(f)},
                       lambda f, reason: {"wall_s": engine_wall_time(f), **nan}, print, case_digest(base))
    runs = pd.DataFrame(rows)
    OUT.mkdir(parents=True, exist_ok=True)
    write_text(OUT / "runs.csv", runs.to_csv(index=False))       # every run first: a failed comparison loses none
    ok = runs[runs.state == "complete"] if not runs.empty else runs
    if ok.empty or not (ok.candidate == TRUE).any():
        raise SystemExit(f"no run at the true dust density completed: nothing to compare with ({OUT / 'runs.csv'})")
    table = bench_stats.compare(ok, TRUE, list(QUANTITIES))
    # a variant compared on its completed runs only: say how many failed (their reasons are in runs.csv)
    failed = runs[runs.state != "complete"].groupby("candidate").size()
    table["failed_runs"] = [int(failed.get(name, 0)) for name in table.candidate]
    write_text(OUT / "comparison.csv", table.to_csv(index=False))
    bench_stats.pareto_figure(table, OUT / "dust.png")
    pd.set_option("display.width", 200)
    print(table[["candidate", "quantity", "n_cand", "failed_runs", "speedup", "rel_error", "ci_lo", "ci_hi", "verdict"]]
          .to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    print(f"tables and figure: {OUT}")
    return table


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description="dust density scaling: run time against flow rate, wall "
                                     "pressures, solid fraction and coordination, paired by seed")
    parser.add_argument("case", nargs="?", type=Path, default=ROOT / "tests" / "data" / "clump_silo.yaml")
    parser.add_argument("--scales", type=float, nargs="+", default=[25.0, 200.0])
    parser.add_argument("--seeds", type=int, default=5, help="runs (seeds) per variant, the true density included")
    parser.add_argument("--no-keep-dt", action="store_true", help="skip the runs that keep the true density's "
                        "time step (they separate the dust's mass from the time step's effect)")
    args = parser.parse_args()
    if args.seeds < 2 or any(not (1.0 < s <= 1.0e6) for s in args.scales):
        parser.error("--seeds must be >= 2 and --scales within (1, 1e6]")
    main(args.case, args.scales, args.seeds, keep_dt=not args.no_keep_dt)
