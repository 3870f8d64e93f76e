"""Does a mobilised bed hang the same share of its weight on the wall in LIGGGHTS and in LAMMPS? (issue 35)

    python benchmarks/mobilise_engines.py [--case benchmarks/cases/coverage_small.yaml] [--seeds 5]
        [--engines liggghts lammps] [--discharge 0.1 | --full] [--work DIR] [--out DIR] [--dry-run]

The case must have ``fill.mobilise`` (the floor lowered after settling, the bed settled again; the
default case lowers it by 0.1 grain diameters). Each seed (the case's seed, +1, ...) is run on each
engine, one run at a time (``siloflow run`` into ``WORK/runs/<engine>_s<seed>``), and the static
force balance of the settled bed is read from its ``results/summary.json``: ``force_balance.
wall_friction_share``, the share of the bed's weight the side wall carries by friction (and the
balance's ``ratio``, walls and floor over the weight, which should be 1).

siloflow has no fill-only run: the static window is measured before the orifice opens, so each run's
discharge is cut to ``--discharge`` seconds (default 0.1 s; ``--full`` keeps the case's).

Writes ``OUT/runs.csv`` (a row a run; a second call skips the engine-seed pairs already in it, refuses
a table of another case, and takes a finished run folder of the same case without running it again) and ``OUT/comparison.csv``:
per engine the seeds, mean, standard deviation and standard error of the wall share, and a row
``lammps - liggghts`` with the difference of the means, its standard error (Welch), the difference
in standard errors and in pooled seed standard deviations, and whether it lies within 2 standard
errors (the engines agree within the seeds' spread).
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import os
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

ENGINES = ("liggghts", "lammps")
COLUMNS = ("case", "engine", "seed", "folder", "wall_s", "wall_share", "force_balance_ratio", "weight_N",
           "settled_ke_pe", "mobilise_step", "resettle_step", "static_step")
#: the engines agree when their means differ by less than this many standard errors of the difference
AGREE_SE = 2.0


def engine_case(base: dict, engine: str, seed: int, discharge: float | None) -> dict:
    """The case of one run: ``base`` on ``engine`` with ``seed``, its discharge cut to ``discharge`` s."""
    data = copy.deepcopy(base)
    data["name"] = f"{engine}_s{seed}"
    data["seed"] = seed
    data["engine"] = {**data.get("engine", {}), "name": engine}
    if discharge is not None:
        data["discharge"] = {"duration": discharge}
    return data


def row_of(case: str, engine: str, seed: int, folder: Path, wall: float) -> dict:
    """A run's row: the static force balance of its settled bed and where its stages began."""
    s = json.loads((folder / "results" / "summary.json").read_text())
    fb = s.get("force_balance") or {}
    stages = json.loads((folder / "run_record.json").read_text()).get("stage_steps", {})
    return {"case": case, "engine": engine, "seed": seed, "folder": str(folder), "wall_s": wall,
            "wall_share": fb.get("wall_friction_share", float("nan")), "force_balance_ratio": fb.get("ratio", float("nan")),
            "weight_N": fb.get("weight_N", float("nan")), "settled_ke_pe": s.get("settled_ke_pe"),
            "mobilise_step": stages.get("mobilise"), "resettle_step": stages.get("resettle"),
            "static_step": stages.get("static")}


def comparison(runs, engines=ENGINES):
    """Per engine: seeds, mean, sd, se of the wall share (and the force balance's mean); then the
    difference of the last engine from the first in standard errors and pooled seed sds."""
    import pandas as pd
    rows, stats = [], {}
    for engine in engines:
        v = pd.to_numeric(runs.loc[runs.engine == engine, "wall_share"], errors="coerce").dropna()
        fb = pd.to_numeric(runs.loc[runs.engine == engine, "force_balance_ratio"], errors="coerce").dropna()
        n = len(v)
        sd = float(v.std(ddof=1)) if n > 1 else float("nan")
        stats[engine] = (n, float(v.mean()) if n else float("nan"), sd)
        rows.append({"engine": engine, "seeds": n, "wall_share_mean": stats[engine][1], "wall_share_sd": sd,
                     "wall_share_se": sd / math.sqrt(n) if n > 1 else float("nan"),
                     "force_balance_ratio_mean": float(fb.mean()) if len(fb) else float("nan")})
    if len(engines) == 2:
        (na, ma, sa), (nb, mb, sb) = stats[engines[0]], stats[engines[1]]
        diff = mb - ma
        se = math.sqrt(sa * sa / na + sb * sb / nb) if na > 1 and nb > 1 else float("nan")
        pooled = (math.sqrt(((na - 1) * sa * sa + (nb - 1) * sb * sb) / (na + nb - 2))
                  if na > 1 and nb > 1 else float("nan"))
        rows.append({"engine": f"{engines[1]} - {engines[0]}", "seeds": min(na, nb), "wall_share_mean": diff,
                     "wall_share_sd": pooled, "wall_share_se": se,
                     "difference_in_se": diff / se if se > 0 else float("nan"),
                     "difference_in_sd": diff / pooled if pooled > 0 else float("nan"),
                     "agree_within_2se": bool(abs(diff) < AGREE_SE * se) if se == se else None})
    return pd.DataFrame(rows)


def plan_runs(base: dict, seeds: int, engines) -> list[tuple[int, str]]:
    first = int(base.get("seed", 12345))
    return [(seed, engine) for seed in range(first, first + seeds) for engine in engines]


def main(args) -> None:
    base = yaml.safe_load(args.case.read_text())
    if not (base.get("fill") or {}).get("mobilise"):
        raise SystemExit(f"{args.case} has no fill.mobilise: this benchmark compares mobilised beds")
    discharge = None if args.full else args.discharge
    todo = plan_runs(base, args.seeds, args.engines)
    table = args.out / "runs.csv"
    if args.dry_run:
        print(f"case {args.case} ({base.get('name')}), discharge "
              f"{'as the case' if discharge is None else f'{discharge:g} s'}, work {args.work}, out {args.out}")
        for seed, engine in todo:
            data = engine_case(base, engine, seed, discharge)
            print(f"  {data['name']}: engine {engine}, seed {seed}, ranks {data['engine'].get('ranks', 1)}")
        return
    import pandas as pd
    from error_coverage import check_same_case, complete
    from siloflow.atomic_files import write_text
    from bench_runs import run_case
    args.work.mkdir(parents=True, exist_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = pd.read_csv(table).to_dict(orient="records") if table.is_file() else []
    name = str(base.get("name"))
    if any(str(r.get("case")) != name for r in rows):
        raise SystemExit(f"{table} holds runs of another case than {name}: give another --out")
    have = {(str(r["engine"]), int(r["seed"])) for r in rows}
    for seed, engine in todo:
        if (engine, seed) in have:
            continue
        data = engine_case(base, engine, seed, discharge)
        folder = args.work / "runs" / data["name"]
        if complete(folder):
            check_same_case(folder, data)
            wall = float("nan")          # ran by an earlier call that stopped before writing its row
        else:
            folder, wall = run_case(data, args.work, force=folder.exists())
        rows.append(row_of(name, engine, seed, folder, wall))
        write_text(table, pd.DataFrame(rows, columns=list(COLUMNS)).to_csv(index=False))
        r = rows[-1]
        print(f"{engine} seed {seed}: wall share {r['wall_share']:.3f}, force balance {r['force_balance_ratio']:.3f}, "
              f"{wall:.0f} s", flush=True)
    runs = pd.DataFrame(rows, columns=list(COLUMNS))
    summary = comparison(runs, [e for e in args.engines if (runs.engine == e).any()])
    write_text(args.out / "comparison.csv", summary.to_csv(index=False))
    print(summary.to_string(index=False))


def parse(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=Path, default=ROOT / "benchmarks" / "cases" / "coverage_small.yaml")
    parser.add_argument("--seeds", type=int, default=5, help="seeds per engine (the case's seed, +1, ...)")
    parser.add_argument("--engines", nargs="+", choices=ENGINES, default=list(ENGINES),
                        help="engines to run, in this order (default: both)")
    parser.add_argument("--discharge", type=float, default=0.1,
                        help="discharge time after the opening, s (the static window comes before it)")
    parser.add_argument("--full", action="store_true", help="keep the case's own discharge")
    parser.add_argument("--work", type=Path,
                        default=Path(os.environ.get("TMPDIR", "/tmp")) / "siloflow-bench-mobilise")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "mobilise_engines")
    parser.add_argument("--dry-run", action="store_true", help="list the runs, run nothing")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error("--seeds must be at least 1")
    if not args.full and not (args.discharge > 0 and math.isfinite(args.discharge)):
        parser.error("--discharge must be a positive number of seconds")
    return args


if __name__ == "__main__":
    main(parse())
