"""Memory and speed against size (issue 41 item 4): peak memory and particle-steps per second of each
engine at 3e3, 3e4 and 3e5 grains on 2 MPI ranks, so that a user can plan a paper-scale run (paper B:
393,216 grains) and see when it belongs on a cluster (``siloflow run --slurm``).

    python benchmarks/scale_memory.py            # make bench-scale; resumable: a row already in the table is kept

Each size is decks/quick.yaml (3 mm glass beads, Hertz, a flat-bottomed cylinder with 6 x 4 sensor
bands on LIGGGHTS, region walls on LAMMPS) with every length of the silo x (N / 1000)^(1/3), so the
bed keeps its shape, filled in ONE batch: the grains are placed at a solid fraction of 0.25 in the
lower half of the silo (``fill.batch_volume_fraction``; random placement jams near 0.38) and
collapse into a bed. The run is siloflow's own deck through siloflow's engine interface, with the
guard off (the collapse of so loose a column overlaps soft grains past its limit; the guard's checks
are not part of the timed rate); a burst of it is timed while every grain is in, then the engine is
stopped (the run is not finished and not kept):

- the rate is particle-steps over wall time between the engine's log lines (LIGGGHTS' thermo rows,
  LAMMPS' chunks, every ``LOG_EVERY_STEPS`` steps), seen as they are written (looked at every
  ``POLL`` s), from the first one with all N grains over the next ``WINDOW_STEPS`` steps, the same
  stretch of the collapse at every size: what a user's run does per second, the driver and fixes
  included;
- peak memory is the largest summed resident set (RSS) of the engine's processes (mpirun and its
  ranks; LAMMPS' ranks are Python workers holding the library), sampled every ``POLL`` s.

A collapsing column has fewer contacts than a settled bed (coordination ~6), so the rates here are
for a loose, flowing bed; ``bench-engines`` times a whole 3000-grain run.

Writes benchmarks/results/scale/scale.csv and scale.png.
"""
from __future__ import annotations

import copy
import re
import sys
import threading
import time
from pathlib import Path

import pandas as pd
import psutil
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

OUT = ROOT / "benchmarks" / "results" / "scale"
WORK = ROOT / "benchmarks" / "work" / "scale"
SIZES = (3_000, 30_000, 300_000)
ENGINES = ("liggghts", "lammps")
RANKS = 2
#: the grains of decks/quick.yaml's silo at scale 1
BASE_GRAINS = 1_000
#: steps the burst is timed over, from the first log line with every grain in
WINDOW_STEPS = 1000
#: how often the processes' memory and the log are looked at, s
POLL = 0.05
#: steps between the engine's log lines (the settle check interval, in steps)
LOG_EVERY_STEPS = 200
#: paper B's grains (REFERENCES.md), for the extrapolation printed at the end
PAPER_B_GRAINS = 393_216
#: a LIGGGHTS thermo row: step, time, atoms, ...
THERMO = re.compile(r"^\s*(\d+)\s+\S+\s+(\d+)\s")
#: LAMMPS' per-run line
LOOP = re.compile(r"^Loop time of (\S+) on (\d+) procs for (\d+) steps with (\d+) atoms", re.M)


def case(engine: str, grains: int, check_interval: float | None = None) -> dict:
    """decks/quick.yaml at ``grains`` grains, its silo scaled to hold them in one batch."""
    data = copy.deepcopy(yaml.safe_load((ROOT / "decks" / "quick.yaml").read_text()))
    s = (grains / BASE_GRAINS) ** (1.0 / 3.0)
    g = data["geometry"]
    for key in ("radius", "height", "orifice_radius"):
        g[key] = round(float(g[key]) * s, 6)
    data["name"] = f"scale_{engine}_{grains}"
    data["fill"] = {"count": grains, "batch_volume_fraction": 0.25, "insertion_z_min": round(0.003 * s, 6),
                    "insertion_z_max": round(0.5 * float(g["height"]), 6),
                    "settle": {**data["fill"]["settle"], "max_time": 1.5,
                               **({"check_interval": check_interval} if check_interval else {})}}
    data["outputs"] = {"sample_interval": check_interval or 0.005}
    data["engine"] = {**data["engine"], "name": engine, "ranks": RANKS, "guard": {"enabled": False}}
    return data


def planned(engine: str, grains: int):
    """The case and its plan, with the log written every ``LOG_EVERY_STEPS`` steps."""
    from siloflow.case_file import case_from_dict
    from siloflow.derived import derive
    first = derive(case_from_dict(case(engine, grains)))
    c = case_from_dict(case(engine, grains, check_interval=float(f"{LOG_EVERY_STEPS * first.dt:.3g}")))
    plan = derive(c)
    if plan.fill.batch < grains:
        raise SystemExit(f"{grains} grains: one batch holds {plan.fill.batch}; the burst needs them all at once")
    return c, plan


class Watch:
    """Samples the engine's processes' summed RSS and the log's progress until told to stop."""

    def __init__(self, log: Path, engine: str, grains: int):
        self.log, self.engine, self.grains = log, engine, grains
        self.peak_rss = 0
        self.events: list[tuple[float, int]] = []      # (wall time seen, step) with every grain in
        self._offset, self._step, self._text = 0, 0, ""

    def rss(self) -> int:
        total = 0
        for p in psutil.Process().children(recursive=True):
            try:
                total += p.memory_info().rss
            except psutil.Error:
                pass
        return total

    def read_log(self, now: float) -> None:
        if not self.log.is_file():
            return
        with open(self.log, errors="replace") as fh:
            fh.seek(self._offset)
            chunk = fh.read()
            self._offset = fh.tell()
        self._text += chunk
        *lines, self._text = self._text.split("\n")
        for line in lines:
            if self.engine == "liggghts":
                m = THERMO.match(line)
                if m and int(m.group(2)) >= self.grains:
                    self.events.append((now, int(m.group(1))))
            else:
                m = LOOP.match(line)
                if m:
                    self._step += int(m.group(3))
                    if int(m.group(4)) >= self.grains:
                        self.events.append((now, self._step))

    def enough(self) -> bool:
        return bool(self.events) and self.events[-1][1] - self.events[0][1] >= WINDOW_STEPS


def stop_engine() -> None:
    procs = psutil.Process().children(recursive=True)
    for p in procs:
        try:
            p.terminate()
        except psutil.Error:
            pass
    gone, alive = psutil.wait_procs(procs, timeout=10)
    for p in alive:
        p.kill()


def burst(engine: str, grains: int) -> dict:
    from siloflow.engine import get_engine
    c, plan = planned(engine, grains)
    folder = WORK / c.name
    eng = get_engine(engine)
    t0 = time.perf_counter()
    eng.prepare(c, folder, force=True, plan=plan)
    prepare_s = time.perf_counter() - t0
    watch = Watch(folder / ("log.liggghts" if engine == "liggghts" else "log.lammps"), engine, grains)
    outcome: dict = {}

    def run() -> None:
        try:
            outcome["record"] = eng.execute(folder)
        except Exception as exc:             # the engine stopped by us (or failed): said below
            outcome["error"] = exc
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    while thread.is_alive() and not watch.enough():
        time.sleep(POLL)
        watch.peak_rss = max(watch.peak_rss, watch.rss())
        watch.read_log(time.perf_counter())
    stopped_by_us = thread.is_alive()
    stop_engine()
    thread.join(timeout=60)
    if not stopped_by_us or not watch.enough():
        raise SystemExit(f"{c.name}: the engine ended before the burst was timed: {outcome.get('error')}")
    (t_a, s_a), (t_b, s_b) = watch.events[0], watch.events[-1]
    steps = s_b - s_a
    return {"engine": engine, "grains": grains, "ranks": RANKS, "silo_radius_m": c.geometry.radius,
            "silo_height_m": c.geometry.height, "dt_s": plan.dt, "steps_timed": steps, "wall_timed_s": t_b - t_a,
            "particle_steps_per_s": grains * steps / (t_b - t_a), "peak_rss_mb": watch.peak_rss / 2**20,
            "rss_per_grain_kb": watch.peak_rss / 1024 / grains, "prepare_s": prepare_s, "version": eng.version()}


def figure(table: pd.DataFrame) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.6))
    for engine, g in table.groupby("engine"):
        g = g.sort_values("grains")
        a.plot(g.grains, g.particle_steps_per_s, "o-", label=engine)
        b.plot(g.grains, g.peak_rss_mb, "o-", label=engine)
    for ax, label in ((a, "particle-steps per second"), (b, "peak memory (RSS, MB)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("grains")
        ax.set_ylabel(label)
        ax.axvline(PAPER_B_GRAINS, color="k", ls=":", lw=1)
        ax.legend(fontsize=8)
    a.set_title(f"{RANKS} MPI ranks, a falling bed", fontsize=9)
    b.set_title(f"dotted: paper B ({PAPER_B_GRAINS:,} grains)", fontsize=9)
    fig.tight_layout()
    fig.savefig(OUT / "scale.png", dpi=120)


def extrapolated(table: pd.DataFrame) -> pd.DataFrame:
    """Per engine, memory at paper B's size from a straight line through the measured sizes (RSS =
    a + b N, least squares) and the rate at the largest size measured."""
    import numpy as np
    rows = []
    for engine, g in table.groupby("engine"):
        b, a = np.polyfit(g.grains.to_numpy(float), g.peak_rss_mb.to_numpy(float), 1)
        largest = g.loc[g.grains.idxmax()]
        rows.append({"engine": engine, "fixed_mb": a, "kb_per_grain": b * 1024,
                     "paper_b_rss_mb": a + b * PAPER_B_GRAINS,
                     "rate_at_largest": largest.particle_steps_per_s, "largest": int(largest.grains)})
    return pd.DataFrame(rows)


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    WORK.mkdir(parents=True, exist_ok=True)
    path = OUT / "scale.csv"
    table = pd.read_csv(path) if path.is_file() else pd.DataFrame()
    for grains in SIZES:
        for engine in ENGINES:
            if len(table) and ((table.engine == engine) & (table.grains == grains)).any():
                continue
            row = burst(engine, grains)
            print(f"{engine} {grains}: {row['particle_steps_per_s']:.3g} particle-steps/s, peak "
                  f"{row['peak_rss_mb']:.0f} MB ({row['rss_per_grain_kb']:.2f} kB a grain)", flush=True)
            table = pd.concat([table, pd.DataFrame([row])], ignore_index=True)
            table.to_csv(path, index=False)           # kept after every size: the benchmark resumes
    figure(table)
    ext = extrapolated(table)
    ext.to_csv(OUT / "paper_b_estimate.csv", index=False)
    print(table[["engine", "grains", "particle_steps_per_s", "peak_rss_mb", "rss_per_grain_kb"]].to_string(index=False))
    print(ext.to_string(index=False))


if __name__ == "__main__":
    main()
