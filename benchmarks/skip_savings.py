"""What skipping saves (issue 15), on the quick case: the speed-up of each saving against the same
run with everything on and no cache, and whether the answers stay the same.

    python benchmarks/skip_savings.py [--case decks/quick.yaml] [--out benchmarks/results/skip] [--work DIR]
    (make bench-skip)

Runs, one engine job at a time (2 ranks each, as the case says):

- ``full``: the case as it is (sensor bands, dumps, contacts, VTK), no cache;
- ``lean``: ``outputs.results: [flow_rate, force_balance]`` (one plain side wall, no dumps);
- ``early``: the full outputs with ``discharge.until_steady`` (precision 0.03, capped at the
  case's duration);
- ``cached``: the full case started from the full run's settled bed (fill cache hit);
- ``separate_<r>`` and ``sweep``: three orifice radii run separately without a cache, against
  the sweep of the same three (``siloflow.sweep.sweep``: one fill, two cache hits).

Each finished run is kept under ``--work`` (run folders, logs, caches; default
``$TMPDIR/siloflow-bench-skip``) and its row in ``--out``/``runs.csv``; a second invocation skips
what is there, so the benchmark resumes where it stopped. The table ``skip_savings.csv`` and the
figure ``skip_savings.png`` are written from all rows. Wall times are whole runs through the API,
in this process (``siloflow.runs.run``: render, engine, checks, first results; the sweep's
``siloflow.sweep.sweep``, whose runs go in worker processes), measured here, one at a time: the
machine is noisy, so a ratio is given with the spread of repeated runs where there are any (see
the note). No ``siloflow`` command is started.
"""
from __future__ import annotations

import argparse
import copy
import os
import sys
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from siloflow.errors import SiloflowError  # noqa: E402

#: three orifices that flow: D0/d = 5.3, 6 and 6.7 for the quick case's 3 mm beads (4 and 4.7 clog)
ORIFICES = (0.008, 0.009, 0.010)


def variants(base: dict) -> dict[str, dict]:
    """The case of every run, by name."""
    out = {"full": copy.deepcopy(base)}
    lean = copy.deepcopy(base)
    lean["outputs"] = {"sample_interval": base["outputs"].get("sample_interval", 0.005),
                       "results": ["flow_rate", "force_balance"]}
    out["lean"] = lean
    early = copy.deepcopy(base)
    early["discharge"] = {"until_steady": True, "precision": 0.03, "batch_time": 0.05,
                          "max_time": base["discharge"]["duration"]}
    out["early"] = early
    out["cached"] = copy.deepcopy(base)
    for r in ORIFICES:
        sep = copy.deepcopy(base)
        sep["geometry"]["orifice_radius"] = r
        out[f"separate_{r:g}"] = sep
    return out


def result_row(name: str, folder: Path, wall: float) -> dict:
    from siloflow.run_folder import RunFolder
    run = RunFolder(folder)
    s = run.read_summary()
    fb = s.get("force_balance") or {}
    return {"run": name, "wall_s": wall, "engine_s": run.record.wall_time,
            "flow_rate_kg_s": s["flow_rate"]["rate"], "flow_rate_stderr_kg_s": s["flow_rate"]["stderr"],
            "particles": s["particles_inserted"], "initial_mass_kg": s["initial_mass_kg"],
            "force_balance": fb.get("ratio"), "cache_hit": (run.record.fill_cache or {}).get("hit"),
            "stop": (run.record.discharge_stop or {}).get("reason"),
            "discharge_s": s["flow_rate"]["t_end"] - s["time_open_s"]}


def timed_run(case_path: Path, folder: Path, cache=None) -> float:
    """``siloflow.runs.run`` of a case file into ``folder`` (through the fill cache ``cache``), in this
    process: its wall time, s, render to first results. A refused or failed run stops the benchmark."""
    from siloflow.runs import run
    t0 = time.perf_counter()
    try:
        run(case_path, folder, cache=cache)
    except SiloflowError as exc:
        raise SystemExit(f"{case_path.stem} failed: {exc}") from None
    return time.perf_counter() - t0


def main(case_file: Path, out: Path, work: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    work.mkdir(parents=True, exist_ok=True)
    table = out / "runs.csv"
    import pandas as pd
    done = pd.read_csv(table) if table.is_file() else pd.DataFrame()
    rows = done.to_dict(orient="records")
    have = {r["run"] for r in rows}
    base = yaml.safe_load(case_file.read_text())
    cases = variants(base)
    for name, data in cases.items():
        if name in have:
            print(f"{name}: kept from an earlier invocation")
            continue
        case_path = work / f"{name}.yaml"
        case_path.write_text(yaml.safe_dump({**data, "name": f"{base['name']}_{name}".replace(".", "p")}))
        folder = work / "runs" / name
        cache_root = None
        if name == "cached":            # the full run's settled bed, published, then a hit
            from siloflow.case_file import load_case
            from siloflow.derived import derive
            from siloflow.engine import get_engine
            from siloflow.fill_cache import FillCache, fill_key, fill_key_inputs
            engine = get_engine("liggghts")
            plan = derive(load_case(case_path))
            cache = FillCache(work / "cache_cached")
            cache.put(fill_key(plan, engine), engine.fill_files(work / "runs" / "full"),
                      fill_key_inputs(plan, engine), source="full")
            cache_root = cache.root
        wall = timed_run(case_path, folder, cache_root)
        rows.append(result_row(name, folder, wall))
        pd.DataFrame(rows).to_csv(table, index=False)
        print(f"{name}: {wall:.1f} s")
    if "sweep" not in have:
        sweep_dir = work / "sweep"
        case_path = work / "sweep.yaml"
        case_path.write_text(yaml.safe_dump({**base, "name": f"{base['name']}_sweep"}))
        values = ",".join(f"{r:g}" for r in ORIFICES)
        from siloflow.sweep import sweep as run_sweep
        t0 = time.perf_counter()
        try:
            run_sweep(case_path, [f"geometry.orifice_radius={values}"], sweep_dir, cores=2)
        except SiloflowError as exc:
            raise SystemExit(f"the sweep failed: {exc}") from None
        wall = time.perf_counter() - t0
        sweep = pd.read_csv(sweep_dir / "sweep.csv")
        rows.append({"run": "sweep", "wall_s": wall, "engine_s": float(sweep.wall_s.sum()),
                     "flow_rate_kg_s": float("nan"), "cache_hit": int(sweep.fill_from_cache.sum())})
        pd.DataFrame(rows).to_csv(table, index=False)
        print(f"sweep: {wall:.1f} s")
    report(pd.DataFrame(rows), out)


def base_orifice(runs) -> float:
    """The orifice radius of the case itself (its separate run repeats the full run)."""
    return min(ORIFICES)


def report(runs, out: Path) -> None:
    """The savings table and figure from the runs."""
    import numpy as np
    import pandas as pd
    r = runs.set_index("run")
    full = r.loc["full"]
    # the full case runs twice ("full", and "separate" at the case's own orifice, the same deck):
    # the reference time is their mean, and half their difference the timing noise of this machine
    twin = r.loc[f"separate_{base_orifice(r):g}"] if f"separate_{base_orifice(r):g}" in r.index else full
    t_full, t_noise = 0.5 * (full.wall_s + twin.wall_s), 0.5 * abs(full.wall_s - twin.wall_s)
    e_full = 0.5 * (full.engine_s + twin.engine_s)
    lines = []
    for name in ("lean", "early", "cached"):
        row = r.loc[name]
        diff = row.flow_rate_kg_s - full.flow_rate_kg_s
        err = float(np.hypot(row.flow_rate_stderr_kg_s, full.flow_rate_stderr_kg_s))
        lines.append({"saving": name, "speedup_total": t_full / row.wall_s,
                      "speedup_total_noise": t_noise / row.wall_s,
                      "speedup_engine": e_full / row.engine_s,
                      "flow_rate_change": diff / full.flow_rate_kg_s, "change_in_stderr": diff / err if err else np.nan,
                      "particles_same": int(row.particles) == int(full.particles),
                      "mass_change": row.initial_mass_kg / full.initial_mass_kg - 1,
                      "force_balance_change": row.force_balance - full.force_balance
                      if pd.notna(row.force_balance) else np.nan})
    separate = sum(r.loc[f"separate_{x:g}"].wall_s for x in ORIFICES)
    if "sweep" in r.index:
        lines.append({"saving": "sweep_vs_separate", "speedup_total": separate / r.loc["sweep"].wall_s,
                      "speedup_total_noise": separate / r.loc["sweep"].wall_s * t_noise / t_full,
                      "cost_ratio": r.loc["sweep"].wall_s / separate})
    table = pd.DataFrame(lines)
    table.to_csv(out / "skip_savings.csv", index=False)
    print(table.to_string(index=False))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 3.6))
    ax.bar(table.saving, table.speedup_total, color="tab:blue", label="whole run")
    if "speedup_engine" in table:
        ax.plot(table.saving, table.speedup_engine, "ko", label="engine only")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set(ylabel="speed-up against the full run", title=f"skip what a scene does not need ({out.name})")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "skip_savings.png", dpi=120)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=Path, default=ROOT / "decks" / "quick.yaml")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "skip")
    parser.add_argument("--work", type=Path, default=Path(os.environ.get("TMPDIR", "/tmp")) / "siloflow-bench-skip")
    args = parser.parse_args()
    main(args.case, args.out, args.work)
