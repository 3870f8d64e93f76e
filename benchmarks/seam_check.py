"""Does splitting the side wall into sensor meshes change the flow? (issue 15's "same answers")

    python benchmarks/seam_check.py [--case decks/quick.yaml] [--seeds 2] [--work DIR]

On the quick case, per seed: the lean deck (one plain side wall, ``results: [flow_rate,
force_balance]``) and the same with ``wall_pressure`` (the wall split into band x sector meshes,
as the full deck has; no dumps). Dumps and force sampling do not change the dynamics; the mesh
seams might (LIGGGHTS counts a grain touching an edge shared by two meshes once per mesh). Each
finished run is kept (``--work``) and its row in ``benchmarks/results/skip/seams.csv``; a second
invocation resumes. Prints the flow rate per variant and seed, and the mean difference with the
seed-to-seed spread.
"""
from __future__ import annotations

import argparse
import copy
import os
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_runs import run_case  # noqa: E402
VARIANTS = {"one_wall": ["flow_rate", "force_balance"], "sensor_meshes": ["flow_rate", "force_balance", "wall_pressure"]}


def main(case_file: Path, seeds: int, work: Path, out: Path) -> None:
    import numpy as np
    import pandas as pd
    from siloflow.run_folder import RunFolder
    work.mkdir(parents=True, exist_ok=True)
    table = out / "seams.csv"
    rows = pd.read_csv(table).to_dict(orient="records") if table.is_file() else []
    have = {(r["variant"], int(r["seed"])) for r in rows}
    base = yaml.safe_load(case_file.read_text())
    for k in range(seeds):
        seed = base.get("seed", 12345) + k
        for name, results in VARIANTS.items():
            if (name, seed) in have:
                continue
            data = copy.deepcopy(base)
            data.update(name=f"{base['name']}_{name}_{seed}", seed=seed)
            data["outputs"] = {"sample_interval": base["outputs"].get("sample_interval", 0.005), "results": results}
            folder, wall = run_case(data, work)
            s = RunFolder(folder).read_summary()
            rows.append({"variant": name, "seed": seed, "wall_s": wall,
                         "flow_rate_kg_s": s["flow_rate"]["rate"], "flow_rate_stderr_kg_s": s["flow_rate"]["stderr"],
                         "force_balance": s["force_balance"]["ratio"],
                         "wall_friction_share": s["force_balance"]["wall_friction_share"]})
            out.mkdir(parents=True, exist_ok=True)
            pd.DataFrame(rows).to_csv(table, index=False)
            print(f"{name} seed {seed}: {rows[-1]['flow_rate_kg_s'] * 1000:.2f} g/s")
    runs = pd.DataFrame(rows)
    print(runs.to_string(index=False))
    w = runs.pivot(index="seed", columns="variant", values="flow_rate_kg_s").dropna()
    if len(w) >= 1:
        diff = (w["sensor_meshes"] - w["one_wall"]) / w["one_wall"]
        spread = runs.groupby("variant").flow_rate_kg_s.std(ddof=1) / runs.groupby("variant").flow_rate_kg_s.mean()
        print(f"sensor meshes vs one wall, per seed: {', '.join(f'{v:+.1%}' for v in diff)}; mean {diff.mean():+.1%}; "
              f"seed-to-seed spread (relative sd): {', '.join(f'{k} {v:.1%}' for k, v in spread.items())}")
        print("(a difference inside the seed spread is not resolved)" if len(w) > 1 and
              abs(diff.mean()) < 2 * float(np.nanmax(spread)) / np.sqrt(len(w)) else "")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=Path, default=ROOT / "decks" / "quick.yaml")
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--work", type=Path, default=Path(os.environ.get("TMPDIR", "/tmp")) / "siloflow-bench-seams")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "skip")
    args = parser.parse_args()
    main(args.case, args.seeds, args.work, args.out)
