"""Fill protocols and what they do to the static wall load (issue 18): on one case, with seeds,
the share of the bed's weight the wall carries by friction, the band-true Janssen fit (K, mu_eff,
mobilisation) and Janssen's own prediction of the wall-carried share from the measured K and the
case's wall friction.

    python benchmarks/fill_protocols.py [--case tests/data/small_silo.yaml] [--seeds 3] [--work DIR]
    (make bench-fill)

Protocols: ``rain`` (batches from a tall region, the default), ``pour`` (a slow continuous pour
from a thin layer at the top), ``frictionless`` (paper A: no grain friction while pouring,
restored before settling), ``mobilised`` (rain, then the floor lowered by 0.1 grain diameters and
the bed settled again: Ovarlez, Fond and Clement, PRE 67, 060302, 2003). Each run stops 0.1 s
after the orifice opens (only the static window matters here) and asks for the wall pressure,
the force balance and the bed's porosity (its bulk density goes into Janssen's law).

Janssen's wall-carried share of a bed of depth H in a cylinder of diameter D, with L = D/(4 mu K):
1 - (L/H)(1 - exp(-H/L)) (the weight not reaching the floor). Every finished run is kept in
``--work`` and its row in ``benchmarks/results/fill_protocols/runs.csv``: a second invocation
resumes. The table ``fill_protocols.csv`` gives the mean over seeds with its standard error.
"""
from __future__ import annotations

import argparse
import copy
import math
import os
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_runs import run_case  # noqa: E402

PROTOCOLS = ("rain", "pour", "frictionless", "mobilised")


def protocol_case(base: dict, protocol: str, seed: int) -> dict:
    data = copy.deepcopy(base)
    data["seed"] = seed
    data["name"] = f"{base['name']}_{protocol}_{seed}"
    data["discharge"] = {"duration": 0.1}
    # dumps one static window apart: the last before the opening shows the settled bed
    data["outputs"] = {"sample_interval": base.get("outputs", {}).get("sample_interval", 0.005),
                       "dump_interval": data["fill"]["settle"].get("static_window", 0.02),
                       "results": ["flow_rate", "force_balance", "wall_pressure", "porosity"]}
    fill = data["fill"]
    if protocol == "pour":
        fill["protocol"] = "pour"
        fill["pour_time"] = 2.0
    elif protocol == "frictionless":
        fill["frictionless"] = True
    elif protocol == "mobilised":
        fill["mobilise"] = {"floor_drop": 0.1, "time": 0.05}
    return data


def janssen_wall_share(K: float, mu: float, depth: float, diameter: float) -> float:
    """Janssen's share of a bed's weight carried by the wall: 1 - (L/H)(1 - exp(-H/L))."""
    L = diameter / (4.0 * mu * K)
    return 1.0 - (L / depth) * -math.expm1(-depth / L)


def row_of(protocol: str, seed: int, folder: Path, wall: float) -> dict:
    from siloflow.run_folder import RunFolder
    run = RunFolder(folder)
    s = run.read_summary()
    fa = s.get("frame_analyses", {})
    j = fa.get("janssen_static", {})
    plan = run.plan
    h = fa.get("settled_surface_height_m", float("nan"))
    D = 2 * plan.geometry.radius
    mu_w = plan.pairs["particle_wall"].friction
    K = j.get("K", float("nan"))
    share = s["force_balance"]["wall_friction_share"]
    predicted = janssen_wall_share(K, mu_w, h, D) if K == K and K > 0 else float("nan")
    return {"protocol": protocol, "seed": seed, "wall_s": wall, "wall_share": share,
            "force_balance": s["force_balance"]["ratio"], "K": K, "mu_eff": j.get("mu_eff"),
            "mobilisation": j.get("mobilisation"), "janssen_resolved": j.get("resolved"),
            "janssen_reason": j.get("reason", ""), "janssen_share_full_mobilisation": predicted,
            "share_over_janssen": share / predicted if predicted == predicted and predicted else float("nan"),
            "solid_fraction": fa.get("bulk_solid_fraction"), "surface_m": h}


def main(case_file: Path, seeds: int, work: Path, out: Path) -> None:
    import pandas as pd
    work.mkdir(parents=True, exist_ok=True)
    out.mkdir(parents=True, exist_ok=True)
    table = out / "runs.csv"
    rows = pd.read_csv(table).to_dict(orient="records") if table.is_file() else []
    have = {(r["protocol"], int(r["seed"])) for r in rows}
    base = yaml.safe_load(case_file.read_text())
    for seed in range(base.get("seed", 12345), base.get("seed", 12345) + seeds):
        for protocol in PROTOCOLS:
            if (protocol, seed) in have:
                continue
            folder, wall = run_case(protocol_case(base, protocol, seed), work)
            rows.append(row_of(protocol, seed, folder, wall))
            pd.DataFrame(rows).to_csv(table, index=False)
            print(f"{protocol} seed {seed}: wall share {rows[-1]['wall_share']:.3f}, K {rows[-1]['K']:.3g}, "
                  f"share / Janssen {rows[-1]['share_over_janssen']:.3f}")
    runs = pd.DataFrame(rows)
    stats = []
    for protocol, grp in runs.groupby("protocol", sort=False):
        line = {"protocol": protocol, "seeds": len(grp)}
        for col in ("wall_share", "K", "mu_eff", "mobilisation", "share_over_janssen", "solid_fraction"):
            v = pd.to_numeric(grp[col], errors="coerce").dropna()
            line[col] = v.mean() if len(v) else float("nan")
            line[f"{col}_se"] = v.std(ddof=1) / math.sqrt(len(v)) if len(v) > 1 else float("nan")
        line["janssen_resolved"] = int(grp.janssen_resolved.fillna(False).astype(bool).sum())
        stats.append(line)
    summary = pd.DataFrame(stats)
    summary.to_csv(out / "fill_protocols.csv", index=False)
    print(summary.to_string(index=False))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=Path, default=ROOT / "tests" / "data" / "small_silo.yaml")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--work", type=Path, default=Path(os.environ.get("TMPDIR", "/tmp")) / "siloflow-bench-fill")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "fill_protocols")
    args = parser.parse_args()
    main(args.case, args.seeds, args.work, args.out)
