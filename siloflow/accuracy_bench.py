"""Run time against error (``siloflow bench``): candidate numerical settings of one case, each run
over an ensemble of seeds (hence of fills), compared with the reference (the papers' settings:
dt = t_c/50, full stiffness) by the difference of the ensemble means with a 95 % interval
(:mod:`siloflow.bench_stats`). The fastest candidate whose bounds are within the tolerances is the
recommended fast profile.

Resumable: every finished run (complete, or stopped by the guard or the engine) is a row of
``runs.csv`` in the bench folder, written as soon as the run ends; a second invocation runs only
the rows missing. A run folder left half-done by an interruption is run again.
"""
from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

from .errors import SetupError, SiloflowError

#: the quantities compared, from each run's results (SI): steady flow rate (kg/s), static band
#: pressure and maximum dynamic band pressure (Pa, means over the bands the settled bed loads),
#: settled bulk solid fraction, settled coordination number
QUANTITIES = ("flow_rate", "static_pressure", "dynamic_pressure_max", "solid_fraction", "coordination")
#: default tolerances of the recommendation (relative 95 % bounds)
TOLERANCES = {"flow_rate": 0.03, "static_pressure": 0.05}
#: a band counts as loaded when its static pressure exceeds this fraction of the largest band's
LOADED_BAND = 0.05


@dataclass(frozen=True)
class Candidate:
    """One set of numerical settings: time-step fraction of the critical time, stiffness scale
    (Young's moduli or springs), MPI ranks (None: the case's)."""

    name: str
    timestep_fraction: float
    stiffness_scale: float = 1.0
    ranks: Optional[int] = None


REFERENCE = Candidate("reference", 0.02, 1.0)
#: the default candidates, reference first, then cheapest first (a stopped bench has the cheap ones)
CANDIDATES = (
    REFERENCE,
    Candidate("E1e-4_dt0.2", 0.2, 1e-4),
    Candidate("E1e-4_dt0.2_1rank", 0.2, 1e-4, ranks=1),
    Candidate("E1e-4_dt0.1", 0.1, 1e-4),
    Candidate("E1e-3_dt0.1", 0.1, 1e-3),
    Candidate("E1e-4_dt0.02", 0.02, 1e-4),
    Candidate("E1e-2_dt0.1", 0.1, 1e-2),
    Candidate("E1e-2_dt0.02", 0.02, 1e-2),
    Candidate("E1_dt0.1", 0.1, 1.0),
    Candidate("E1_dt0.05", 0.05, 1.0),
)


def candidate_case(base: dict, cand: Candidate, seed: int) -> dict:
    """The case fields of one run: the base case with the candidate's settings (profile custom)
    and the seed; named ``<case>-<candidate>-s<seed>``."""
    data = copy.deepcopy(base)
    engine = {k: v for k, v in data.get("engine", {}).items() if k not in ("profile", "timestep_fraction",
                                                                           "stiffness_scale")}
    engine.update(profile="custom", timestep_fraction=cand.timestep_fraction, stiffness_scale=cand.stiffness_scale)
    if cand.ranks is not None:
        engine["ranks"] = cand.ranks
    data.update(engine=engine, seed=seed, name=f"{base['name']}-{cand.name}-s{seed}")
    return data


def run_metrics(folder: Path) -> dict:
    """The compared quantities of a finished, post-processed run folder (NaN where not measured)."""
    from .run_folder import RunFolder
    s = RunFolder(folder).read_summary()
    nan = float("nan")
    out = {q: nan for q in QUANTITIES}
    out["wall_s"] = s.get("engine_wall_time_s", nan)
    out["flow_rate"] = (s.get("flow_rate") or {}).get("rate", nan)
    bands = [b for b in s.get("bands") or [] if b.get("static_pressure") is not None]
    if bands:
        top = max(b["static_pressure"] for b in bands)
        loaded = [b for b in bands if b["static_pressure"] > LOADED_BAND * top]
        out["static_pressure"] = sum(b["static_pressure"] for b in loaded) / len(loaded)
        dyn = [b.get("dynamic_max_pressure") for b in loaded if b.get("dynamic_max_pressure") is not None]
        out["dynamic_pressure_max"] = sum(dyn) / len(dyn) if dyn else nan
    frames = s.get("frame_analyses") or {}
    out["solid_fraction"] = frames.get("bulk_solid_fraction", nan)
    out["coordination"] = (frames.get("coordination_settled") or {}).get("z_mean", nan)
    # a measurement that could not be made is a dict with its reason, not a number
    return {k: float(v) if isinstance(v, (int, float)) else nan for k, v in out.items()}


def _read_rows(table: Path) -> list[dict]:
    import pandas as pd
    return pd.read_csv(table).to_dict(orient="records") if table.is_file() else []


def _write_rows(rows: list[dict], table: Path) -> None:
    import pandas as pd
    from .atomic_files import write_text
    write_text(table, pd.DataFrame(rows).to_csv(index=False))


def run_bench(case_file: Path, out: Path, seeds: int = 3, candidates=CANDIDATES,
              report: Callable[[str], None] = lambda s: None) -> list[dict]:
    """Run every candidate x seed not yet in ``out/runs.csv`` (the case's seed, +1, ...); return
    all rows. A run stopped by the guard or failing is a row too (state ``failed``, its reason):
    an unstable setting is a result, not an error of the bench."""
    from .case_file import case_from_dict, parse_case_yaml, read_case_bytes
    from .runs import run
    base = parse_case_yaml(read_case_bytes(case_file), str(case_file))
    case_from_dict(base, str(case_file))                      # the base case itself must be valid
    names = [c.name for c in candidates]
    if REFERENCE.name not in names:
        raise SetupError("the bench needs the reference candidate (the papers' settings) to compare with")
    out.mkdir(parents=True, exist_ok=True)
    table = out / "runs.csv"
    rows = _read_rows(table)
    done = {(r["candidate"], int(r["seed"])) for r in rows}
    first_seed = int(base.get("seed", 12345))
    for cand in candidates:
        for k in range(seeds):
            seed = first_seed + k
            if (cand.name, seed) in done:
                continue
            data = candidate_case(base, cand, seed)
            folder = _free_folder(out / "runs" / data["name"])
            row = {"candidate": cand.name, "seed": seed, "timestep_fraction": cand.timestep_fraction,
                   "stiffness_scale": cand.stiffness_scale, "ranks": cand.ranks or base.get("engine", {}).get("ranks", 1),
                   "folder": str(folder.relative_to(out))}
            report(f"{cand.name} seed {seed}: running")
            try:
                run(case_from_dict(data, data["name"]), folder)
                row.update(state="complete", reason="", **run_metrics(folder))
            except SiloflowError as exc:
                reason = str(exc).splitlines()[0]
                row.update(state="failed", reason=reason, wall_s=_engine_wall(folder),
                           **{q: float("nan") for q in QUANTITIES})
            rows.append(row)
            _write_rows(rows, table)
            report(f"{cand.name} seed {seed}: {row['state']} ({row.get('wall_s', float('nan')):.1f} s)"
                   + (f": {row['reason']}" if row["reason"] else ""))
    return rows


def _free_folder(folder: Path) -> Path:
    """``folder``, or ``folder-retryN`` when a run interrupted there (its row never written) left it:
    an interrupted run is run anew, and its folder is kept as it is."""
    k = 0
    path = folder
    while path.exists():
        k += 1
        path = folder.with_name(f"{folder.name}-retry{k}")
    return path


def _engine_wall(folder: Path) -> float:
    from .run_folder import RunFolder
    try:
        return float(RunFolder(folder).record.wall_time)
    except (SiloflowError, OSError, TypeError, ValueError):
        return float("nan")


def conclude(out: Path, tolerances: dict = TOLERANCES, confidence: float = 0.95) -> tuple:
    """From ``out/runs.csv``: ``comparison.csv`` (every candidate x quantity: errors with their
    interval, speed-up), ``pareto.png`` and ``recommended_profile.json``; returns (table,
    recommendation or None)."""
    import pandas as pd
    from . import bench_stats
    from .atomic_files import write_text
    runs = pd.DataFrame(_read_rows(out / "runs.csv"))
    if runs.empty:
        raise SetupError(f"{out / 'runs.csv'} holds no runs yet")
    ok = runs[runs.state == "complete"]
    table = bench_stats.compare(ok, REFERENCE.name, list(QUANTITIES), confidence)
    failed = runs[runs.state != "complete"].groupby("candidate").size()
    table["failed_runs"] = table.candidate.map(failed).fillna(0).astype(int)
    write_text(out / "comparison.csv", table.to_csv(index=False))
    bench_stats.pareto_figure(table, out / "pareto.png", tolerances)
    rec = bench_stats.recommend(table, tolerances)
    if rec is not None:
        cand = next((c for c in CANDIDATES if c.name == rec["candidate"]), None)
        row = ok[ok.candidate == rec["candidate"]].iloc[0]
        rec.update(timestep_fraction=float(row.timestep_fraction), stiffness_scale=float(row.stiffness_scale),
                   confidence=confidence, error_bounds=rec.pop("bounds"),
                   seeds=int((ok.candidate == rec["candidate"]).sum()),
                   reference_seeds=int((ok.candidate == REFERENCE.name).sum()),
                   ranks=int(row.ranks) if cand is None or cand.ranks is None else cand.ranks)
        rec = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in rec.items()}
    write_text(out / "recommended_profile.json", json.dumps(rec, indent=1) + "\n")
    return table, rec
