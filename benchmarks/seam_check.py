"""Do sensor meshes change the flow? One side wall against the same facets as band x sector meshes.

    make bench-seams        (python benchmarks/seam_check.py [--case decks/quick.yaml] [--seeds 10])

On the quick case, per seed: the lean deck (one plain side wall, ``results: [flow_rate,
force_balance]``) and the same with ``wall_pressure`` (the wall split into band x sector meshes,
as the full deck has; no dumps). Dumps and force sampling do not change the dynamics; the mesh
seams might (LIGGGHTS counts a grain touching an edge shared by two meshes once per mesh). Since
issue 36 both variants of a seed start from the same placed grains (``siloflow.fill_placement``).
One engine job at a time; each finished run is kept (``--work``) with its row in
``benchmarks/results/seams/runs.csv``, and a second invocation resumes. Writes summary.csv
(sensor meshes against one wall over the runs that did not clog: Welch's 95 % interval,
``siloflow.bench_stats``; the share of runs that clogged; engine wall time as a speed ratio) and
seams.png. The 2-seed check on the inserted fill (before issue 36) is kept in
benchmarks/results/skip/seams.csv.
"""
from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_runs import clogged, run_case  # noqa: E402
VARIANTS = {"one_wall": ["flow_rate", "force_balance"], "sensor_meshes": ["flow_rate", "force_balance", "wall_pressure"]}


#: compared quantities: summary.json's flow rate (kg/s), the settled bed's force balance and wall
#: friction share (dimensionless)
QUANTITIES = ("flow_rate_kg_s", "force_balance", "wall_friction_share")


def main(case_file: Path, seeds: int, work: Path, out: Path) -> None:
    import pandas as pd

    from siloflow import bench_stats
    from siloflow.atomic_files import write_text
    from siloflow.run_folder import RunFolder
    work.mkdir(parents=True, exist_ok=True)
    table = out / "runs.csv"
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
                         "wall_friction_share": s["force_balance"]["wall_friction_share"],
                         "discharged_kg": s["discharged_mass_kg"]})
            out.mkdir(parents=True, exist_ok=True)
            write_text(table, pd.DataFrame(rows).to_csv(index=False))
            print(f"{name} seed {seed}: {rows[-1]['flow_rate_kg_s'] * 1000:.2f} g/s")
    runs = pd.DataFrame(rows)
    runs["clogged"] = [clogged(work / "runs" / f"{base['name']}_{v}_{int(seed)}")
                       for v, seed in zip(runs.variant, runs.seed)]
    write_text(table, runs.to_csv(index=False))
    flowing = runs[~runs.clogged]
    one, sensed = (flowing[flowing.variant == v] for v in VARIANTS)
    summary = [{"quantity": q, **bench_stats.difference(one[q], sensed[q])} for q in QUANTITIES]
    summary.append({"quantity": "clogged", "n_ref": int((runs.variant == "one_wall").sum()),
                    "n_cand": int((runs.variant == "sensor_meshes").sum()),
                    "ref_mean": runs[runs.variant == "one_wall"].clogged.mean(),
                    "cand_mean": runs[runs.variant == "sensor_meshes"].clogged.mean(),
                    "verdict": "share of runs that clogged (left out of the other rows)"})
    speed = bench_stats.speedup(sensed.wall_s, one.wall_s)
    summary.append({"quantity": "wall_s", "n_ref": len(one), "n_cand": len(sensed), "ref_mean": one.wall_s.mean(),
                    "cand_mean": sensed.wall_s.mean(), "verdict": f"one wall {speed['speedup']:.2f}x faster "
                    f"({speed['lo']:.2f}-{speed['hi']:.2f})"})
    summary = pd.DataFrame(summary)
    write_text(out / "summary.csv", summary.to_csv(index=False))
    print(summary[["quantity", "n_ref", "n_cand", "rel_error", "ci_lo", "ci_hi", "verdict"]].to_string(index=False))
    figure(runs, summary, out / "seams.png")


def figure(runs, summary, path: Path) -> None:
    """Flow rate per seed of both variants, with each variant's mean and the difference's interval."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from siloflow.atomic_files import atomic_path
    fig, ax = plt.subplots(figsize=(6, 3.5))
    for x, (name, colour) in enumerate(zip(VARIANTS, ("C0", "C1"))):
        mine = runs[runs.variant == name]
        rates = mine[~mine.clogged].flow_rate_kg_s * 1000
        ax.plot([x] * len(rates), rates, "o", color=colour, alpha=0.6)
        ax.hlines(rates.mean(), x - 0.25, x + 0.25, color=colour)
    row = summary.set_index("quantity").loc["flow_rate_kg_s"]
    ax.set_xticks([0, 1], [f"{n}\n(n = {int((runs.variant == n).sum())}, flowing {int(((runs.variant == n) & ~runs.clogged).sum())})"
                           for n in VARIANTS])
    ax.set_xlim(-0.6, 1.6)
    ax.set_ylabel("flow rate (g/s)")
    ax.set_title(f"sensor meshes against one wall: {row.rel_error:+.1%} (95 %: {row.ci_lo:+.1%} to {row.ci_hi:+.1%})",
                 fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=Path, default=ROOT / "decks" / "quick.yaml")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--work", type=Path, default=ROOT / "runs" / "bench_seams")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "seams")
    args = parser.parse_args()
    main(args.case, args.seeds, args.work, args.out)
