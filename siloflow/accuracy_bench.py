"""Run time against error (``siloflow bench``): candidate numerical settings of one case, each run
over an ensemble of seeds (hence of fills), compared with the reference (the papers' settings:
dt = t_c/50, full stiffness) by the difference of the ensemble means with a 95 % interval
(:mod:`siloflow.bench_stats`). The fastest candidate whose bounds are within the tolerances is the
recommended fast profile.

Resumable (``siloflow.run_table``): every finished run (complete, or stopped by the guard or the
engine) is a row of ``runs.csv`` in the bench folder, written as soon as the run ends; a second
invocation runs only the rows missing.
"""
from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

from .errors import SetupError
from .case import PROFILE_FIELDS
from .packaged_profile import BENCH_QUANTITIES, QUESTIONS
from .profiles import REFERENCE as REFERENCE_SETTINGS
from .run_row import LOADED_BAND  # noqa: F401  (a band counts as loaded above this fraction of the largest's)
from .run_table import run_name

#: the quantities compared, from each run's results (SI): steady flow rate (kg/s), static band
#: pressure and maximum dynamic band pressure (Pa, means over the bands the settled bed loads),
#: settled bulk solid fraction, settled coordination number
QUANTITIES = BENCH_QUANTITIES
#: the quantities of the discharge: a fill-only run (:func:`fill_only_case`) does not measure them
DISCHARGE_QUANTITIES = ("flow_rate", "flow_rate_fit_se", "flow_rate_batch_se", "dynamic_pressure_max")
#: fill-only seeds start this far from the case's seed (the new-seed check's this far from its first seed)
FILL_ONLY_SEED_OFFSET = 2000
#: whole runs' seeds start at the case's seed, the new-seed check's at + ``VALIDATION_SEED_OFFSET``:
#: each range holds at most this many seeds
SEED_RANGE = 1000
#: default tolerances of the recommendation (relative 95 % bounds)
TOLERANCES = {"flow_rate": 0.03, "static_pressure": 0.05}
#: tolerances of the quantities only the question "everything" bounds (relative 95 % bounds): the
#: peak dynamic band pressure is the noisiest (a seed's sd is about 20 % of it), the solid fraction
#: the steadiest (a 1 % error is 0.006 of a bed's 0.6)
OTHER_TOLERANCES = {"dynamic_pressure_max": 0.10, "solid_fraction": 0.01, "coordination": 0.05}


@dataclass(frozen=True)
class Candidate:
    """One set of numerical settings: time-step fraction of the critical time, stiffness scale
    (Young's moduli or springs), MPI ranks and engine (None: the case's)."""

    name: str
    timestep_fraction: float
    stiffness_scale: float = 1.0
    ranks: Optional[int] = None
    results: Optional[tuple[str, ...]] = None       # outputs.results (None: the case's); fewer: a leaner deck
    profile: bool = True            # can be a profile (time step and stiffness only: not ranks or outputs)
    max_overlap: Optional[float] = None     # engine.guard.max_overlap (None: the case's): to measure past the guard
    upscale: Optional[float] = None         # coarse-grained DEM: grains x this size (upscaled_case)
    engine: Optional[str] = None            # engine.name (None: the case's): the other engine's cost


REFERENCE = Candidate("reference", REFERENCE_SETTINGS["timestep_fraction"], REFERENCE_SETTINGS["stiffness_scale"])
#: the default candidates, reference first, then cheapest first (a stopped bench has the cheap ones)
CANDIDATES = (
    REFERENCE,
    Candidate("E1e-4_dt0.2", 0.2, 1e-4),
    Candidate("E1e-4_dt0.2_1rank", 0.2, 1e-4, ranks=1, profile=False),
    # the leanest deck (one plain side wall, no dumps): flow rate and force balance only
    Candidate("E1e-4_dt0.2_lean", 0.2, 1e-4, results=("flow_rate", "force_balance"), profile=False),
    Candidate("E1e-4_dt0.1", 0.1, 1e-4),
    # the guard stops E = 1e-4 in the fill (impacts overlap 0.6-0.9 of a radius): what it would cost
    Candidate("E1e-4_dt0.2_past_guard", 0.2, 1e-4, max_overlap=1.5, profile=False),
    Candidate("E1e-3_dt0.3", 0.3, 1e-3),
    Candidate("E1e-3_dt0.2", 0.2, 1e-3),
    Candidate("E3e-4_dt0.2", 0.2, 3e-4),
    Candidate("E1e-3_dt0.2_1rank", 0.2, 1e-3, ranks=1, profile=False),
    Candidate("E1e-3_dt0.2_lean", 0.2, 1e-3, results=("flow_rate", "force_balance"), profile=False),
    Candidate("E1e-3_dt0.1", 0.1, 1e-3),
    # the fast profile's stiffness at longer steps, and on the LAMMPS engine (a case's engine is its
    # user's choice, and LAMMPS refuses some cases: measured, never a profile)
    Candidate("E1e-2_dt0.3", 0.3, 1e-2),
    Candidate("E1e-2_dt0.2", 0.2, 1e-2),
    Candidate("E1e-2_dt0.2_lammps", 0.2, 1e-2, engine="lammps", profile=False),
    Candidate("E1e-2_dt0.1_lammps", 0.1, 1e-2, engine="lammps", profile=False),
    # particle upscaling on top of the fast profile (a different grain size: never a profile)
    Candidate("E1e-2_dt0.1_up1.25", 0.1, 1e-2, upscale=1.25, profile=False),
    Candidate("E1e-4_dt0.02", 0.02, 1e-4),
    Candidate("E1e-2_dt0.1", 0.1, 1e-2),
    # between the fast profile's 1/100 stiffness (static band pressure +3.4 %, resolved) and the full one
    Candidate("E3e-2_dt0.2", 0.2, 3e-2),
    Candidate("E3e-2_dt0.1", 0.1, 3e-2),
    # a tenth of the stiffness: full stiffness at dt 0.1 t_c keeps the static load, 3/100 of it does not
    Candidate("E1e-1_dt0.2", 0.2, 1e-1),
    # where between 1/10 and 3/100 the static over-load starts, and 1/10 at the shorter step
    Candidate("E5e-2_dt0.2", 0.2, 5e-2),
    Candidate("E1e-1_dt0.1", 0.1, 1e-1),
    Candidate("E1e-2_dt0.02", 0.02, 1e-2),
    Candidate("E1_dt0.1", 0.1, 1.0),
    Candidate("E1_dt0.05", 0.05, 1.0),
    # the longest tested step (0.3 t_c, 0.6 of the stability edge) at a tenth of the stiffness and at full
    # stiffness: whether the profile's 1/10 or the full contact can take a longer step for free
    Candidate("E1e-1_dt0.3", 0.3, 1e-1),
    Candidate("E1_dt0.3", 0.3, 1.0),
    # around 100x, where the static error changes sign (1/100: +3 to +6 %, 1/1000: -12 to -13 %, rained):
    # 3/1000 of the stiffness, and steps up to the stability edge (0.5 t_c, margin 1.4 to the first unstable)
    Candidate("E3e-3_dt0.3", 0.3, 3e-3),
    Candidate("E3e-3_dt0.5", 0.5, 3e-3),
    Candidate("E1e-2_dt0.5", 0.5, 1e-2),
)


def candidate_case(base: dict, cand: Candidate, seed: int) -> dict:
    """The case fields of one run: the base case with the candidate's settings (profile custom)
    and the seed; named ``<case>-<candidate>-s<seed>``."""
    data = copy.deepcopy(base)
    engine = {k: v for k, v in data.get("engine", {}).items() if k not in PROFILE_FIELDS}
    engine.update(profile="custom", timestep_fraction=cand.timestep_fraction, stiffness_scale=cand.stiffness_scale)
    if cand.ranks is not None:
        engine["ranks"] = cand.ranks
    if cand.engine is not None:
        engine["name"] = cand.engine
    if cand.max_overlap is not None:
        engine["guard"] = {**engine.get("guard", {}), "max_overlap": cand.max_overlap}
    if cand.results is not None:
        data["outputs"] = {k: v for k, v in data.get("outputs", {}).items() if k not in ("dump_interval", "vtk")}
        data["outputs"]["results"] = list(cand.results)
    dust = data["particles"].get("dust")
    if dust is not None:               # the bench compares time step and stiffness: the dust at its true
        data["particles"]["dust"] = {**dust, "density_scale": 1.0}    # density (make bench-dust: its scaling)
    data.update(engine=engine, seed=seed, name=run_name(base["name"], cand.name, f"s{seed}"))
    return upscaled_case(data, cand.upscale) if cand.upscale else data


def fill_only_case(data: dict) -> dict:
    """A run's case cut after its static stage, for the quantities of the settled bed (static band
    pressure, solid fraction, coordination): the whole run's plan but for the discharge, which is
    the shortest the case allows (one sample interval), so the same deck up to the opening (the
    fill, its settling, the static window: one seed makes the same bed and the same static loads)
    under the same guard (its speed limit counts the plate's speed). About half a whole run's cost on
    the accuracy case; its flow rate and dynamic loads are not measured (:func:`fill_only_metrics`)."""
    from .case_file import case_from_dict
    from .derived import auto_dump_interval, result_needs
    case = case_from_dict(data)
    out = copy.deepcopy(data)
    if case.outputs.dump_interval is None and result_needs(case)["dumps"]:
        # the automatic interval follows the discharge's length: pin the whole run's, for the same frames
        out.setdefault("outputs", {})["dump_interval"] = auto_dump_interval(case)
    out["discharge"] = {"duration": case.outputs.sample_interval,
                        **({"opening": data["discharge"]["opening"]} if "opening" in data.get("discharge", {}) else {})}
    return out


def upscaled_case(data: dict, factor: float) -> dict:
    """Coarse-grained DEM (particle upscaling; Thakur, Ooi and Ahmadian, Powder Technol. 293 (2016)
    130-137): every grain and dust radius x ``factor``, the count / factor^3 (the same bed), the same
    density, friction and restitution (damping ratio); Hertz and hooke keep Young's modulus (their
    contact is self-similar in size), linear springs scale as the size (kn, kt x factor). Spheres
    only: a clump's shape would need its own scaling."""
    out = copy.deepcopy(data)
    p = out["particles"]
    if p.get("kind") == "clumps":
        raise SetupError("particle upscaling is for spheres; a clump's shape is not scaled")
    # YAML numbers such as 1.6e5 arrive as text (the schema converts them): scale them as numbers
    if "radius" in p:
        p["radius"] = float(p["radius"]) * factor
    if "radii" in p:
        p["radii"] = [float(r) * factor for r in p["radii"]]
    if p.get("dust"):
        p["dust"] = {**p["dust"], "radius": float(p["dust"]["radius"]) * factor}
    if out["fill"].get("count") is not None:
        out["fill"] = {**out["fill"], "count": max(1, round(int(out["fill"]["count"]) / factor ** 3))}
    m = out["materials"]
    if m.get("model") == "linear":
        for pair in ("particle_particle", "particle_wall"):
            m[pair] = {**m[pair], **{k: float(m[pair][k]) * factor for k in ("kn", "kt") if m[pair].get(k) is not None}}
    return out


def run_metrics(folder: Path) -> dict:
    """The compared quantities of a finished, post-processed run folder (NaN where not measured):
    its row (:func:`siloflow.run_row.run_row`) cut to ``wall_s``, :data:`QUANTITIES` and the flow
    rate's two standard errors."""
    from .run_row import run_row
    row = run_row(folder)
    return {k: row[k] for k in ("wall_s", *QUANTITIES, "flow_rate_fit_se", "flow_rate_batch_se")}


def refuse_repeated_seeds(runs, out: Path) -> None:
    """SetupError when the complete runs of ``out/runs.csv`` repeat a candidate's seed: only a
    hand-merged table has them, and they would count one fill as two."""
    done = runs[runs.state == "complete"] if "state" in runs.columns else runs
    twice = done[done.duplicated(["candidate", "seed"], keep=False)]
    if not twice.empty:
        first = twice.iloc[0]
        raise SetupError(f"{out / 'runs.csv'} holds {first.candidate} with seed {int(first.seed)} more than once "
                         f"({len(twice)} rows repeat a candidate's seed): a seed repeats its run on the same deck "
                         "and rank count, so a second row is no new fill; keep one row per candidate and seed")


def check_seed_count(seeds: int, option: str, seed_offset: int = 0) -> None:
    """SetupError naming ``option`` when ``seeds`` seeds from the case's seed + ``seed_offset`` would
    run into the next range: a bench's whole runs, its new-seed check and its fill-only runs take
    their seeds from ``SEED_RANGE``-wide ranges, and one more would reuse another range's fill."""
    if seed_offset % SEED_RANGE + seeds > SEED_RANGE:
        raise SetupError(f"{option}: {seeds} is more than {SEED_RANGE - seed_offset % SEED_RANGE}: the whole runs, the "
                         f"new-seed check and the fill-only runs take seeds from {SEED_RANGE}-wide ranges (the case's "
                         f"seed, + {VALIDATION_SEED_OFFSET}, + {FILL_ONLY_SEED_OFFSET}); more would reuse another's fills")


def choose_candidates(names: Optional[str], option: str = "--candidates") -> list[Candidate]:
    """The candidates a comma-separated list of names chooses, the reference first (None: all of
    :data:`CANDIDATES`). An empty list, an empty name, an unknown or repeated one is a
    ``SetupError`` naming ``option``: a bench of every candidate takes hours, never a slip's default."""
    if names is None:
        return list(CANDIDATES)
    known = {c.name: c for c in CANDIDATES}
    chosen = [n.strip() for n in names.split(",")]
    if not any(chosen):
        raise SetupError(f"{option}: no candidate named in {names!r}; give names from: {', '.join(known)} "
                         f"(or leave {option} out for all of them)")
    if not all(chosen):
        raise SetupError(f"{option}: {names!r} has an empty name (two commas, or a comma at an end)")
    unknown = [n for n in chosen if n not in known]
    if unknown:
        raise SetupError(f"{option}: unknown {', '.join(unknown)}; known: {', '.join(known)}")
    repeated = sorted({n for n in chosen if chosen.count(n) > 1})
    if repeated:
        raise SetupError(f"{option}: {', '.join(repeated)} named more than once")
    return [REFERENCE] + [known[n] for n in chosen if n != REFERENCE.name]


def run_bench(case_file: Path, out: Path, seeds: int = 3, candidates=CANDIDATES,
              report: Callable[[str], None] = lambda s: None, skip_reference: bool = False,
              seed_offset: int = 0, fill_only_seeds: int = 0) -> list[dict]:
    """Run every candidate x seed not yet in ``out/runs.csv`` (the case's seed + ``seed_offset``, +1,
    ...), seed by seed (a stopped study keeps whole seeds: the reference and its candidates), then
    ``fill_only_seeds`` seeds more (from the case's seed + ``FILL_ONLY_SEED_OFFSET`` + ``seed_offset``) cut after the
    static stage (:func:`fill_only_case`, column ``fill_only`` true); return all rows
    (``siloflow.run_table``: a failed or guard-stopped run is a row with its reason)."""
    import pandas as pd
    from .run_table import PlannedRun, case_digest, engine_wall_time, read_rows, run_missing
    from .study_case import read_study_case
    check_seed_count(seeds, "seeds", seed_offset)
    check_seed_count(fill_only_seeds, "fill-only seeds", FILL_ONLY_SEED_OFFSET + seed_offset)
    if isinstance(candidates, str) or any(not isinstance(c, Candidate) for c in candidates):
        raise SetupError("candidates: give Candidate objects (choose_candidates('a,b') reads a list of names)")
    base, case = read_study_case(case_file)
    if REFERENCE.name not in [c.name for c in candidates]:
        raise SetupError("the bench needs the reference candidate (the papers' settings) to compare with")
    rows = pd.DataFrame(read_rows(out))
    if not rows.empty:
        refuse_repeated_seeds(rows, out)     # before hours of runs, not after them
    first_seed, ranks = case.seed + seed_offset, case.engine.ranks

    def plan(seeds_: list[int], fill_only: bool) -> list[PlannedRun]:
        return [PlannedRun(key={"candidate": c.name, "seed": seed},
                           case=fill_only_case(candidate_case(base, c, seed)) if fill_only
                           else candidate_case(base, c, seed),
                           columns={"timestep_fraction": c.timestep_fraction, "stiffness_scale": c.stiffness_scale,
                                    "ranks": c.ranks or ranks, "engine": c.engine or case.engine.name,
                                    "fill_only": fill_only})
                for seed in seeds_ for c in candidates if not (skip_reference and c is REFERENCE)]

    def failed(folder: Path, reason: str) -> dict:
        return {"wall_s": engine_wall_time(folder), **{q: float("nan") for q in QUANTITIES}}
    rows = run_missing(out, plan([first_seed + k for k in range(seeds)], False), run_metrics, failed, report,
                       case_digest(base))
    if fill_only_seeds:
        first = case.seed + FILL_ONLY_SEED_OFFSET + seed_offset
        rows = run_missing(out, plan([first + k for k in range(fill_only_seeds)], True), fill_only_metrics, failed,
                           report, case_digest(base))
    return rows


def fill_only_metrics(folder: Path) -> dict:
    """:func:`run_metrics` of a fill-only run (:func:`fill_only_case`): its one-interval discharge
    measures nothing, so the discharge's quantities are NaN."""
    return {**run_metrics(folder), **{q: float("nan") for q in DISCHARGE_QUANTITIES}}


#: a candidate re-run with new seeds to check the recommendation is named ``<candidate>_new_seeds``
VALIDATION = "_new_seeds"
#: the new seeds start this far from the case's seed
VALIDATION_SEED_OFFSET = 1000


def validate(case_file: Path, out: Path, recommended: str, seeds: int,
             report: Callable[[str], None] = lambda s: None, fill_only_seeds: int = 0) -> list[dict]:
    """Run the recommended candidate again with ``seeds`` new seeds and ``fill_only_seeds`` new
    fill-only ones (from + ``VALIDATION_SEED_OFFSET``: fills independent of those that chose it), as
    the candidate ``<name>_new_seeds``; :func:`conclude` then compares them with the reference like
    any candidate, and :func:`validation` says whether they agree with the bounds."""
    from dataclasses import replace
    cand = next(c for c in CANDIDATES if c.name == recommended)
    return run_bench(case_file, out, seeds, [REFERENCE, replace(cand, name=cand.name + VALIDATION)], report,
                     skip_reference=True, seed_offset=VALIDATION_SEED_OFFSET, fill_only_seeds=fill_only_seeds)


def validation(table, rec: dict) -> list[dict]:
    """For each bounded quantity: the new seeds' error against the reference, whether it lies
    within the recommendation's 95 % bound (``inside``), and whether their own 95 % interval reaches
    into [-bound, bound] (``consistent``: False when the new seeds contradict the bound, None when
    they have no interval, fewer than 2 fills; a few new seeds' point estimate may well fall outside a
    bound their interval does not refute), and how many of the new seeds' runs ``failed``."""
    name = rec["candidate"] + VALIDATION
    out = []
    for q, bound in rec["error_bounds"].items():
        row = table[(table.candidate == name) & (table.quantity == q)]
        if row.empty:
            continue
        r = row.iloc[0]
        out.append({"quantity": q, "rel_error": float(r.rel_error), "ci_lo": float(r.ci_lo), "ci_hi": float(r.ci_hi),
                    "bound": float(bound), "inside": bool(abs(r.rel_error) <= bound),
                    "consistent": (bool(r.ci_lo <= bound and r.ci_hi >= -bound)
                                   if math.isfinite(r.ci_lo) and math.isfinite(r.ci_hi) else None),
                    "n": int(r.n_cand), "failed": int(r.get("failed_runs", 0) + r.get("failed_fill_only", 0))})
    return out


def run_errors(runs):
    """Per candidate: a run's own stated errors of the flow rate against the spread of its seeds, all
    relative to the mean rate: the straight-line fit's standard error (``fit_se``), the batch-means
    error (``batch_se``) and the seeds' standard deviation (``seed_sd``); ``batch_se / seed_sd`` near 1
    says a single run's batch-means error can stand for the ensemble's spread."""
    import pandas as pd
    rows = []
    for name, g in runs.groupby("candidate", sort=False):
        mean = g.flow_rate.mean()
        fit = (g.flow_rate_fit_se / g.flow_rate).mean() if "flow_rate_fit_se" in g else float("nan")
        batch = (g.flow_rate_batch_se / g.flow_rate).mean() if "flow_rate_batch_se" in g else float("nan")
        sd = g.flow_rate.std(ddof=1) / mean if len(g) > 1 else float("nan")
        rows.append({"candidate": name, "runs": len(g), "fit_se": fit, "batch_se": batch, "seed_sd": sd,
                     "batch_se_over_seed_sd": batch / sd if sd and sd == sd else float("nan")})
    return pd.DataFrame(rows)


#: what a candidate changes of what a seed makes of its random insertion stream: runs pair by seed
#: with the reference only when none of these differ (another engine fills differently, another rank
#: count inserts differently, upscaled grains are other grains)
DESIGN = ("design_engine", "design_ranks", "design_grain_scale")


def design_columns(runs):
    """``runs`` with the ``DESIGN`` columns, from each row's candidate definition ("" where it keeps
    the case's; a candidate not defined here keeps everything)."""
    defs = {c.name: c for c in CANDIDATES}

    def of(name: str):
        c = defs.get(name[:-len(VALIDATION)] if name.endswith(VALIDATION) else name)
        if c is None:
            return "", "", ""
        return c.engine or "", "" if c.ranks is None else str(c.ranks), "" if c.upscale is None else repr(c.upscale)
    values = runs["candidate"].map(of)
    return runs.assign(**{col: values.map(lambda v, k=k: v[k]) for k, col in enumerate(DESIGN)})


def fill_only_rows(runs):
    """Boolean Series: which rows of a bench's run table are fill-only runs (column ``fill_only``;
    rows written before the column existed are whole runs)."""
    import pandas as pd
    if "fill_only" not in runs.columns:
        return pd.Series(False, index=runs.index, dtype=bool)
    return runs["fill_only"].map(lambda v: v is True or str(v).strip().lower() in ("true", "1", "1.0")).astype(bool)


def failing_candidates(table) -> set[str]:
    """The candidates of a bench's comparison (``table``) that failed on any seed of the benchmark's own
    case (stopped by the guard, a bed that never settled, the engine), whole or fill-only, and the
    recommendation whose new seeds did: such a setting is no profile, whatever its completed runs say
    (they are the survivors). A failure that was not the setting's (a full disk, a killed machine) is
    dropped from runs.csv by hand: the bench then runs that seed again."""
    failed = failed_totals(table)
    failing = set(failed.index[failed > 0])
    return failing | {name[: -len(VALIDATION)] for name in failing if name.endswith(VALIDATION)}


def failed_totals(table):
    """Per candidate of a bench's comparison: its failed runs, whole and fill-only (a pandas Series)."""
    rows = table.drop_duplicates("candidate").set_index("candidate")
    return (rows.failed_runs + rows.failed_fill_only).astype(int)


def run_counts(runs) -> Callable[[str, bool], int]:
    """``count(candidate, fill_only)``: how many rows of ``runs`` (a bench's run table) are that
    candidate's whole (False) or fill-only (True) runs."""
    counts = runs.groupby([runs.candidate, fill_only_rows(runs).rename("fill_only")]).size()
    return lambda name, fill: int(counts.get((name, fill), 0))


def pairs_lost(runs, table) -> list[int]:
    """Per row of a bench's comparison (``table``, from ``runs``, its run table): on a paired row,
    the reference's finite values of the row's quantity at seeds where the candidate's run failed
    (a guard stop, a crash) and no retry completed: pairs the failure took out. A failure that
    follows the fill (a looser bed escaping, say) leaves the pairs biased, so a count above 0 is
    worth reading; 0 on Welch rows (they use every value) and on the reference's."""
    import numpy as np
    complete = runs.state == "complete"
    ref = runs[complete & (runs.candidate == REFERENCE.name)].set_index("seed")
    done = set(zip(runs.candidate[complete], runs.seed[complete]))
    failed = runs[~complete]
    lost = {}
    for name, seed, fill in zip(failed.candidate, failed.seed, fill_only_rows(failed)):
        if (name, seed) not in done and seed in ref.index:
            lost.setdefault(name, set()).add((seed, fill))
    counts = []
    for r in table.itertuples():
        seeds = sorted({s for s, fill in lost.get(r.candidate, ()) if not (fill and r.quantity in DISCHARGE_QUANTITIES)})
        counts.append(int(np.isfinite(ref.loc[seeds, r.quantity].to_numpy(dtype=float)).sum())
                      if r.method == "paired" and seeds else 0)
    return counts


def conclude(out: Path, tolerances: dict = TOLERANCES, confidence: float = 0.95,
             case_file: Optional[Path] = None) -> tuple:
    """From ``out/runs.csv``: ``comparison.csv`` (every candidate x quantity: errors with their
    interval, speed-up, and for the bounded quantities the fills a side that would prove the
    tolerance if today's error and spread held, ``bench_stats.fills_needed``), ``pareto.png`` and
    ``recommended_profile.json``: the fastest candidate proven within the tolerances (the reference when none faster is), with its bounds, its softness
    as the impact overlap ratio in ``case_file``'s case, and the new seeds' check (``validation``)
    when :func:`validate` ran. Returns (table, recommendation)."""
    import pandas as pd
    from . import bench_stats
    from .atomic_files import write_text
    from .run_table import read_rows
    runs = pd.DataFrame(read_rows(out))
    if runs.empty:
        raise SetupError(f"{out / 'runs.csv'} holds no runs yet")
    ok = design_columns(runs[runs.state == "complete"])
    refuse_repeated_seeds(ok, out)
    fill_only = fill_only_rows(ok)
    # a fill-only run adds its fill to the settled bed's quantities; its time is not a whole run's
    table = bench_stats.compare(ok.assign(timed=~fill_only), REFERENCE.name, list(QUANTITIES), confidence,
                                design=DESIGN)
    failed = run_counts(runs[runs.state != "complete"])
    for column, fill in (("failed_runs", False), ("failed_fill_only", True)):     # whole runs, fill-only ones
        table[column] = [failed(name, fill) for name in table.candidate]
    table["pairs_lost"] = pairs_lost(runs, table)
    # fills a side that would prove each bounded quantity within its tolerance, at today's estimates
    table["fills_needed"] = [bench_stats.fills_needed(r, tolerances[r["quantity"]], confidence)
                             if r["quantity"] in tolerances else math.nan for _, r in table.iterrows()]
    write_text(out / "comparison.csv", table.to_csv(index=False))
    write_text(out / "run_errors.csv", run_errors(ok[~fill_only]).to_csv(index=False))
    barred = {c.name for c in CANDIDATES if not c.profile} | failing_candidates(table)
    choices = table[~table.candidate.str.endswith(VALIDATION) & ~table.candidate.isin(barred)]

    def recommendation(tols: dict) -> Optional[dict]:
        """The fastest candidate proven within ``tols`` whose new seeds, if it has any, put no bounded
        error outside its bound (a contradicted one is passed over: the next proven one stands)."""
        passed_over, left = [], choices
        while True:
            found = bench_stats.recommend(left, tols)
            if found is None:
                return None
            found = _completed(found, ok, table, out, confidence, case_file)
            if all(c["inside"] for c in found["validation"]):
                return {**found, "passed_over": passed_over} if passed_over else found
            passed_over.append({k: found[k] for k in ("candidate", "speedup", "error_bounds", "validation")})
            left = left[left.candidate != found["candidate"]]
    rec = recommendation(tolerances)
    notes = {name: f"({n} failed)" for name, n in failed_totals(table).items() if n > 0}
    bench_stats.pareto_figure(table, out / "pareto.png", tolerances, highlight=rec and rec["candidate"], notes=notes)
    if rec is not None:
        rec["questions"] = {name: recommendation(tols) for name, tols in question_tolerances(tolerances).items()}
    write_text(out / "recommended_profile.json", json.dumps(rec, indent=1) + "\n")
    return table, rec


def question_tolerances(tolerances: dict = TOLERANCES) -> dict[str, dict[str, float]]:
    """Per question a fast profile answers (``siloflow.packaged_profile.QUESTIONS``): the tolerance of
    each quantity it bounds, ``tolerances`` (the bench's flow rate and static pressure) over
    :data:`OTHER_TOLERANCES`."""
    every = {**OTHER_TOLERANCES, **tolerances}
    return {name: {q: every[q] for q in quantities} for name, quantities in QUESTIONS.items()}


def recommended_candidates(rec: Optional[dict]) -> list[str]:
    """The candidates a bench's recommendation names (its own, then its questions'), each once and
    none the reference: what ``validate`` checks with new seeds."""
    if rec is None:
        return []
    names = [rec["candidate"]] + [r["candidate"] for r in (rec.get("questions") or {}).values() if r]
    return [n for k, n in enumerate(names) if n != REFERENCE.name and n not in names[:k]]


def _completed(rec: dict, ok, table, out: Path, confidence: float, case_file: Optional[Path]) -> dict:
    """A recommendation of ``bench_stats.recommend`` with what publishing it needs: its settings,
    run counts, softness in ``case_file``'s case, the errors measured at it for every quantity
    (``measured``: [relative error, 95 % low, high]) and the new seeds' check."""
    cand = next((c for c in CANDIDATES if c.name == rec["candidate"]), None)
    row = ok[ok.candidate == rec["candidate"]].iloc[0]
    count = run_counts(ok)
    rows = table[table.candidate == rec["candidate"]].set_index("quantity")
    rec.update(meets_tolerances=True, timestep_fraction=float(row.timestep_fraction),
               stiffness_scale=float(row.stiffness_scale), confidence=confidence, error_bounds=rec.pop("bounds"),
               seeds=count(rec["candidate"], False), reference_seeds=count(REFERENCE.name, False),
               fill_only_seeds=count(rec["candidate"], True),
               ranks=int(row.ranks) if cand is None or cand.ranks is None else cand.ranks,
               measured={q: [float(rows.at[q, c]) for c in ("rel_error", "ci_lo", "ci_hi")] for q in QUANTITIES
                         if q in rows.index and all(math.isfinite(rows.at[q, c]) for c in ("rel_error", "ci_lo", "ci_hi"))},
               benchmark=f"{out.name}: {count(REFERENCE.name, False)} reference runs and "
                         f"{count(REFERENCE.name, True)} fill-only ones")
    if case_file is not None:
        from .case_file import load_case
        from .profiles import impact_overlap_ratio
        rec["overlap_ratio"] = impact_overlap_ratio(load_case(case_file), rec["stiffness_scale"])
    rec["validation"] = validation(table, rec)
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in rec.items()}
