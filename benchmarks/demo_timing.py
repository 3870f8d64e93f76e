"""The demo timed beside the raw 3,000-grain LIGGGHTS deck (issue 56 item 5): ``make bench-demo``.

One call, alone on a quiet machine, one engine job at a time: the raw deck
(``../shared/tools/raw_engine_scale/make_decks.py``'s ``lig_3000.in``: 3,000 grains on a floor, 10,000 steps,
2 ranks), then each demo variant through ``siloflow run`` (engine time from the run record), each followed by
the raw deck again. The goal: the demo's engine time at most 120 s on a machine where the raw deck takes
10.8 s, i.e. at most 11.1x the raw deck's mean time of the same call.

Variants: ``demo`` (decks/demo.yaml as ``make demo`` runs it) and any ``--discharge S`` given (the demo with
``discharge.duration: S``). Rows are appended to ``benchmarks/results/demo_timing/runs.csv`` (call, order,
what, wall_s, engine_s, particle_steps, flow rate and its batch-means error, ratio to the call's raw mean).
"""
from __future__ import annotations

import argparse
import datetime
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "tools" / "raw_engine_scale"
OUT = ROOT / "benchmarks" / "results" / "demo_timing"
WORK = ROOT / "benchmarks" / "work" / "demo_timing"
#: the goal: the demo's engine time over the raw deck's (120 s against 10.8 s)
GOAL = 120.0 / 10.8


def raw_deck(folder: Path) -> Path:
    """``lig_3000.in`` written by the shared tool into ``folder``."""
    subprocess.run([sys.executable, str(SHARED / "make_decks.py")], cwd=folder, check=True, capture_output=True)
    return folder / "lig_3000.in"


def time_raw(deck: Path) -> float:
    """Wall seconds of the raw deck on 2 ranks."""
    mpirun = [shutil.which("mpirun", path="/usr/bin:/bin") or "mpirun"]
    root = ["--allow-run-as-root"] if os.geteuid() == 0 else []
    t = time.perf_counter()
    subprocess.run(mpirun + root + ["-np", "2", "liggghts", "-in", deck.name, "-log", "none"], cwd=deck.parent,
                   check=True, capture_output=True, stdin=subprocess.DEVNULL)
    return time.perf_counter() - t


def time_demo(name: str, discharge: float | None) -> dict:
    """``siloflow run`` of the demo (``discharge``: its duration, s) into the work folder."""
    data = yaml.safe_load((ROOT / "decks" / "demo.yaml").read_text())
    if discharge is not None:
        data["discharge"] = {**data.get("discharge", {}), "duration": discharge}
    data["name"] = name
    WORK.mkdir(parents=True, exist_ok=True)
    case = WORK / f"{name}.yaml"
    case.write_text(yaml.safe_dump(data))
    t = time.perf_counter()
    subprocess.run([str(Path(sys.executable).parent / "siloflow"), "run", str(case), "-o", str(WORK / name),
                    "--force"], check=True, capture_output=True)
    wall = time.perf_counter() - t
    from siloflow.run_folder import RunFolder
    import json
    run = RunFolder(WORK / name)
    summary = json.loads((WORK / name / "results" / "summary.json").read_text())
    flow = run.flow()
    steps = flow.step.diff().fillna(0).to_numpy()
    particle_steps = float((flow.atoms.shift(1).fillna(flow.atoms.iloc[0]) * steps).sum())
    return {"wall_s": round(wall, 2), "engine_s": round(run.record.wall_time, 2), "particle_steps": particle_steps,
            "flow_rate_g_s": round(1e3 * summary["flow_rate"]["rate"], 3),
            "flow_rate_stderr_g_s": round(1e3 * summary["flow_rate"]["stderr"], 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--discharge", type=float, nargs="*", default=[], help="demo variants: discharge durations, s")
    args = ap.parse_args()
    call = datetime.datetime.now().isoformat(timespec="seconds")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        deck = raw_deck(Path(tmp))

        def raw() -> None:
            rows.append({"call": call, "what": "raw 3000-grain deck (lig_3000.in, 10000 steps, 2 ranks)",
                         "wall_s": round(time_raw(deck), 2)})
            print(f"  raw deck: {rows[-1]['wall_s']} s", flush=True)

        raw()
        for duration in [None, *args.discharge]:
            name = "demo" if duration is None else f"demo_discharge_{duration:g}"
            rows.append({"call": call, "what": name, **time_demo(name, duration)})
            print(f"  {name}: engine {rows[-1]['engine_s']} s, flow {rows[-1]['flow_rate_g_s']} +/- "
                  f"{rows[-1]['flow_rate_stderr_g_s']} g/s", flush=True)
            raw()
    table = pd.DataFrame(rows)
    raw_mean = table[table.what.str.startswith("raw")].wall_s.mean()
    table["ratio_to_raw"] = (table.engine_s / raw_mean).round(2)
    table.insert(1, "order", range(1, len(table) + 1))
    OUT.mkdir(parents=True, exist_ok=True)
    csv = OUT / "runs.csv"
    table.to_csv(csv, mode="a", header=not csv.is_file(), index=False)
    for row in table.dropna(subset=["engine_s"]).itertuples():
        print(f"{row.what}: {row.engine_s} s in the engine = {row.ratio_to_raw}x the raw deck's {raw_mean:.2f} s "
              f"(goal <= {GOAL:.1f}x)")
    print(f"rows appended to {csv}")


if __name__ == "__main__":
    main()
