"""Does a silo from STL answer as the same silo built by siloflow? (issue 39, item 4)

    python benchmarks/mesh_vs_cylinder.py [--case tests/data/small_silo.yaml] [--seeds 4242 101 202 303]
        [--work DIR] [--out DIR]

The case's cylinder is exported to STL (its band, wall and floor meshes, in mm, as a CAD model would
be) and run as ``geometry.kind: mesh`` with the same orifice; each seed runs both silos on LIGGGHTS,
one run at a time (``siloflow.runs.run`` into ``WORK/runs/<silo>_s<seed>``; a finished folder is read, not
run again). From each ``results/summary.json``: the settled bed's force balance, the steady flow rate
(and its batch-means error), and each band's static pressure.

Writes ``OUT/runs.csv`` (a row per run and band), ``OUT/comparison.csv`` (per quantity: each silo's
seed mean, seed standard deviation and standard error, the difference mesh - cylinder with its Welch
standard error, and whether it lies within 2 of them) and ``OUT/mesh_vs_cylinder.png``.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

SILOS = ("cylinder", "mesh")
#: the silos agree on a quantity when their seed means differ by less than this many standard errors
AGREE_SE = 2.0


def case_files(base: Path, work: Path, seed: int) -> dict[str, Path]:
    """The two case files of one seed: ``base`` as it is and its cylinder as an STL silo."""
    import yaml
    from test_mesh_silo import export_walls

    from siloflow.case_file import load_case
    from siloflow.derived import derive
    data = yaml.safe_load(base.read_text())
    walls = work / "walls.stl"
    if not walls.exists():
        export_walls(derive(load_case(base)), walls)
    radius = data["geometry"]["orifice_radius"] * 1000.0
    files = {}
    for silo in SILOS:
        case = copy.deepcopy(data)
        case.update(name=f"{silo}_s{seed}", seed=seed)
        if silo == "mesh":
            case["geometry"] = {"kind": "mesh", "files": ["walls.stl"], "scale": 0.001,
                                "outlet": {"z": 0.0, "center": [0.0, 0.0], "radius": radius}}
        files[silo] = work / f"{silo}_s{seed}.yaml"
        files[silo].write_text(yaml.safe_dump(case))
    return files


def rows_of(silo: str, seed: int, folder: Path) -> list[dict]:
    s = json.loads((folder / "results" / "summary.json").read_text())
    clogged = s.get("clogged") is not None
    common = {"silo": silo, "seed": seed, "force_balance": s["force_balance"]["ratio"], "clogged": clogged,
              "flow_rate_g_s": 1e3 * s["flow_rate"]["rate"], "flow_stderr_g_s": 1e3 * s["flow_rate"]["stderr"],
              "engine_s": s.get("engine_wall_time_s")}
    return [{**common, "band": b["band"], "z_mid": b["z_mid"], "static_pressure": b["static_pressure"],
             "static_sector_stderr": b["static_pressure_sector_stderr"]} for b in s["bands"]]


def compare(table) -> list[dict]:
    """Per quantity, each silo's seed statistics and their difference."""
    import pandas as pd
    per_run = table.drop_duplicates(["silo", "seed"]).set_index(["silo", "seed"])
    flowing = per_run[~per_run.clogged]             # a clogged run has no steady rate: counted apart
    quantities = {"force_balance": per_run.force_balance, "flow_rate_g_s": flowing.flow_rate_g_s}
    for band, grp in table.groupby("band"):
        if grp.static_pressure.mean() > 20.0:          # bands under the bed
            quantities[f"static_pressure_band{band}"] = grp.set_index(["silo", "seed"]).static_pressure
    rows = []
    for name, values in quantities.items():
        row = {"quantity": name}
        stats = {}
        for silo in SILOS:
            x = values.xs(silo, level="silo").to_numpy(float)
            sd = float(np.std(x, ddof=1)) if len(x) > 1 else float("nan")
            stats[silo] = (float(x.mean()), sd / math.sqrt(len(x)), len(x))
            row.update({f"{silo}_mean": stats[silo][0], f"{silo}_seed_sd": sd, f"{silo}_stderr": stats[silo][1],
                        f"{silo}_seeds": len(x)})
        diff = stats["mesh"][0] - stats["cylinder"][0]
        se = math.hypot(stats["mesh"][1], stats["cylinder"][1])
        row.update({"mesh_minus_cylinder": diff, "difference_stderr": se,
                    "clogged_runs": {s: int(per_run.clogged.xs(s, level="silo").sum()) for s in SILOS}
                    if name == "flow_rate_g_s" else "",
                    "relative_difference": diff / stats["cylinder"][0], "agree": bool(abs(diff) < AGREE_SE * se)})
        rows.append(row)
    return pd.DataFrame(rows)


def figure(table, comparison, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    for silo, marker in zip(SILOS, "os"):
        grp = table[table.silo == silo].groupby("z_mid").static_pressure
        mean, se = grp.mean(), grp.std(ddof=1) / np.sqrt(grp.count())
        ax.errorbar(mean.to_numpy(), 1e3 * mean.index.to_numpy(), xerr=se.to_numpy(), marker=marker, capsize=3,
                    label=f"kind: {silo}")
    ax.set(xlabel="static wall pressure (Pa), seed mean +/- standard error", ylabel="band centre z (mm)")
    ax.legend()
    runs = table.drop_duplicates(["silo", "seed"])
    for k, silo in enumerate(SILOS):
        w = runs[(runs.silo == silo) & ~runs.clogged]
        bx.errorbar(np.full(len(w), k) + np.linspace(-0.15, 0.15, len(w)), w.flow_rate_g_s, yerr=w.flow_stderr_g_s,
                    ls="none", marker="o", capsize=3)
        row = comparison.set_index("quantity").loc["flow_rate_g_s"]
        bx.errorbar([k + 0.3], [row[f"{silo}_mean"]], yerr=[row[f"{silo}_stderr"]], marker="D", color="k", capsize=4)
    clogs = runs.groupby("silo").clogged.sum()
    bx.set(xticks=[0, 1], xticklabels=[f"kind: {s}\n({int(clogs.get(s, 0))} clogged)" for s in SILOS],
           ylabel="steady flow rate (g/s)", title="runs (batch-means error) and seed mean")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv=None) -> None:
    import pandas as pd

    from siloflow.runs import run
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", type=Path, default=ROOT / "tests" / "data" / "small_silo.yaml")
    ap.add_argument("--seeds", type=int, nargs="+", default=[4242, 101, 202, 303])
    ap.add_argument("--work", type=Path, default=ROOT / "runs" / "bench-mesh")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "mesh_silo")
    args = ap.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for seed in args.seeds:
        for silo, case in case_files(args.case, args.work, seed).items():
            folder = args.work / "runs" / f"{silo}_s{seed}"
            if not (folder / "results" / "summary.json").exists():
                print(f"running {silo} seed {seed}", flush=True)
                run(case, folder, force=True)
            rows += rows_of(silo, seed, folder)
    table = pd.DataFrame(rows)
    table.to_csv(args.out / "runs.csv", index=False)
    comparison = compare(table)
    comparison.to_csv(args.out / "comparison.csv", index=False)
    figure(table, comparison, args.out / "mesh_vs_cylinder.png")
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(comparison[["quantity", "cylinder_mean", "mesh_mean", "mesh_minus_cylinder", "difference_stderr",
                          "relative_difference", "agree"]].to_string(index=False))


if __name__ == "__main__":
    main()
