"""Sweeps run here: the variants of a sweep (:mod:`siloflow.sweep_plan`) run through the run API
within a core budget, and the table of their results, ``sweep.csv``.

:func:`run_sweep` runs each variant in a worker process of its own (:mod:`siloflow.scheduler`:
forked from this one, calling :func:`run_variant`, which calls :mod:`siloflow.runs`; no
``siloflow`` command is started): each fill group's first before the rest of its group
(:class:`FillOrder`), in parallel while the engine ranks of the running ones add up to at most the
core budget; it writes ``sweep.csv`` (:func:`sweep_table`). Run again on the same folder, it
resumes the sweep: finished runs are kept (their results read into the table), interrupted ones
resumed, missing ones run. :func:`sweep` is the whole of ``siloflow sweep`` from Python.

The sweep folder ``OUT`` (:mod:`siloflow.sweep_folder`) holds ``sweep.json``,
``cases/<name>.yaml``, ``runs/<name>/`` (each run folder), ``logs/`` (each run's output),
``sweep.csv`` and the sweep's page ``report.html`` (``siloflow.cli.study_commands.write_sweep_report``,
which ``siloflow sweep`` writes after the table); :mod:`siloflow.slurm` writes the sweep as Slurm job arrays instead.
"""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Callable, Optional

from .errors import ReadError, SetupError
from .run_row import run_row
from .scheduler import Job, Outcome, run_jobs
from .slurm import DEFAULT_MAX_ARRAY_SIZE, write_slurm  # noqa: F401  (siloflow.sweep's names, as before)
from .study_case import read_study_case
from .sweep_folder import (RECORD_NAME, check_cases, check_owned, check_sweep_folder, open_record,  # noqa: F401
                           previous_runs, read_record, save_record, write_cases, write_owned)
from .sweep_plan import (StageProgress, Variant, check_engine, expand, group_by_fill, parse_set,  # noqa: F401
                         sweep_engine, variant_keys, variant_name)

#: progress(done, total, names of the running variants)
SweepProgress = Callable[[int, int, list], None]
#: a variant's run, called in its worker: (case file or None when resuming, run folder, fill cache, resuming)
Runner = Callable[[Optional[Path], Path, Path, bool], object]
#: the table of results, and the sweep's page (``postprocess.report.sweep_page``)
TABLE_NAME, PAGE_NAME = "sweep.csv", "report.html"
#: columns of the sweep table before the ``--set`` paths, and after them
TABLE_HEAD = ("run", "name")
TABLE_TAIL = ("seed", "fill_key", "fill_from_cache", "status", "returncode", "wall_s", "flow_rate_kg_s",
              "flow_rate_stderr_kg_s", "clogged", "steady_t_start_s", "steady_t_end_s", "force_balance_ratio",
              "bulk_solid_fraction", "log")
#: sweep table column <- run_row key
ROW_COLUMNS = {"fill_from_cache": "fill_from_cache", "wall_s": "wall_s", "flow_rate_kg_s": "flow_rate",
               "flow_rate_stderr_kg_s": "flow_rate_stderr", "clogged": "clogged",
               "steady_t_start_s": "steady_t_start_s", "steady_t_end_s": "steady_t_end_s",
               "force_balance_ratio": "force_balance_ratio", "bulk_solid_fraction": "solid_fraction"}


def prepare_sweep(case_file, set_specs: list[str], seeds: int, out, force: bool = False, need_binary: bool = True,
                  progress: Optional[StageProgress] = None) -> tuple[list[Variant], dict[str, list[Variant]]]:
    """What ``siloflow sweep`` does before it runs or writes anything: read the case, expand the
    ``--set`` specs and seeds, check the sweep folder, the engine and every variant's plan
    (``progress`` as :func:`group_by_fill`). Returns the variants and their fill groups."""
    data, _ = read_study_case(case_file)
    variants = expand(data, [parse_set(spec) for spec in set_specs], seeds)
    check_sweep_folder(out, variants, force)
    engine = sweep_engine(variants, need_binary)
    check_engine(variants, engine)
    return variants, group_by_fill(variants, engine, progress)


# ------------------------------------------------------------------ one run, in its worker
def run_variant(case_file: Optional[Path], folder: Path, cache: Path, resuming: bool = False) -> None:
    """One run of a sweep through the run API, as ``siloflow run CASE -o FOLDER --cache CACHE`` (or
    ``siloflow run --resume FOLDER``) does it: render, run, check, first results; what the command
    would print about it goes to stdout (the run's log). A resumed run's settled bed is published to
    the cache when it has none of its fill (an interrupted fill computed again), so its group's
    other runs start from it. Raises ``SiloflowError`` when it fails."""
    from .runs import post_process, prepare_resume, prepare_run
    if resuming:
        prepared = prepare_resume(folder)
        print(f"resuming {folder} (it was {prepared.state_before})", flush=True)
    else:
        prepared = prepare_run(case_file, folder)
        print(f"run folder: {prepared.folder}", flush=True)
    stages = []

    def progress(stage: str, step: int, total: int) -> None:
        if not stages or stages[-1] != stage:
            stages.append(stage)
            print(f"{stage}: {total} steps", flush=True)

    def hit(key: str) -> None:
        print(f"fill from the cache {cache} (key {key[:12]}): the settled bed is reused, the run starts at its "
              "static stage", flush=True)

    def warn(message: str) -> None:
        print(f"warning: {message}", flush=True)

    # a resumed run goes through the cache too: the group's fill it computes is published for the rest
    record = prepared.execute(progress, cache=cache, on_cache_hit=hit, on_warning=warn)
    print(f"engine finished in {record.wall_time:.1f} s", flush=True)
    post_process(prepared.folder)
    print(f"results: {prepared.folder / 'results'}", flush=True)


def _log_line(log: Path, text: str) -> None:
    try:
        with open(log, "a", encoding="utf-8") as fh:       # appended: an older log is never truncated
            fh.write(text + "\n")
    except OSError as exc:
        raise SetupError(f"cannot write the log {log}: {exc.strerror or exc}") from None


# ------------------------------------------------------------------ running here
class FillOrder:
    """Which variants may start. Until a fill group has a finished run (its settled bed is then
    in the cache), one of its variants at a time runs, computing the fill; a failed one hands
    the fill to the next. Afterwards the rest of the group may start, from the cached bed.
    A resumed sweep leaves out the ``finished`` runs (name -> exit code; a group with a complete
    one is filled) and lets the ``resuming`` ones (interrupted runs, resumed from their own
    folders) start at once, first. A resumed run of a group not yet filled computes its fill
    (its bed goes to the cache when it completes): the group's others wait for it as for a fill."""

    def __init__(self, groups: dict[str, list[Variant]], jobs: dict[str, Job], finished: Optional[dict] = None,
                 resuming: Optional[set] = None):
        finished, resuming = finished or {}, resuming or set()
        self.jobs = jobs
        self.keys = {v.name: key for key, members in groups.items() for v in members}
        self.variants = {v.name: v for members in groups.values() for v in members}
        self.waiting = {key: [v for v in members if v.name not in finished and v.name not in resuming]
                        for key, members in groups.items()}
        self.resuming = sorted(((key, v) for key, members in groups.items() for v in members if v.name in resuming),
                               key=lambda kv: kv[1].index)
        self.filling: dict[str, str] = {}       # key -> name of the run computing its fill
        self.filled = {key for key, members in groups.items() if any(finished.get(v.name) == 0 for v in members)}

    def _ready(self) -> list[tuple[str, Variant]]:
        """(key, variant) that may start: the resumed runs, the fills (group order), then the
        others (variant order)."""
        fills, others = [], []
        resumed = {key for key, _ in self.resuming}      # each fills its group first, if not filled
        for key, members in self.waiting.items():
            if key in self.filled:
                others += [(key, v) for v in members]
            elif members and key not in self.filling and key not in resumed:
                fills.append((key, members[0]))
        return list(self.resuming) + fills + sorted(others, key=lambda kv: kv[1].index)

    def ready(self) -> list[Job]:
        return [self.jobs[v.name] for _, v in self._ready()]

    def started(self, job: Job) -> None:
        key, variant = self.keys[job.name], self.variants[job.name]
        self.resuming = [(k, v) for k, v in self.resuming if v.name != variant.name]
        self.waiting[key] = [v for v in self.waiting[key] if v.name != variant.name]
        if key not in self.filled and key not in self.filling:
            self.filling[key] = variant.name

    def finished(self, job: Job, outcome: Outcome) -> None:
        key = self.keys[job.name]
        if self.filling.get(key) == job.name:
            del self.filling[key]
            if outcome.ok:
                self.filled.add(key)


def check_cores(variants: list[Variant], cores: int) -> None:
    """Refuse a core budget below 1 or below a variant's ``engine.ranks`` (``SetupError``)."""
    if isinstance(cores, bool) or not isinstance(cores, int) or cores < 1:
        raise SetupError(f"--cores {cores!r}: the core budget must be a whole number >= 1")
    wide = [v for v in variants if v.case.engine.ranks > cores]
    if wide:
        v = max(wide, key=lambda v: v.case.engine.ranks)
        raise SetupError(f"{v.name} needs engine.ranks = {v.case.engine.ranks} but --cores is {cores}: "
                         "raise --cores or lower engine.ranks")




def run_sweep(variants: list[Variant], out: Path, cores: int, cache: Path, runner: Optional[Runner] = None,
              progress: Optional[SweepProgress] = None, groups: Optional[dict[str, list[Variant]]] = None):
    """Run the variants here and return their table (:func:`sweep_table`, also ``out/sweep.csv``).

    Each variant's case is written to ``out/cases/<name>.yaml`` and run in a worker process of its
    own as ``runner(case file, out/runs/<name>, cache, False)`` (default :func:`run_variant`: the
    run API), its output appended to ``out/logs/<name>.log``. A fill group's first variant runs
    before the rest of its group, which then starts from its cached bed; runs go in parallel while
    their ``engine.ranks`` add up to at most ``cores``. A failed run does not stop the others.
    ``groups`` are the fill groups (:func:`group_by_fill`; default: with the cases' engine).
    ``progress(done, total, running_names)`` is told of every change.

    Resuming: on a folder of this sweep (``sweep.json``) the runs already finished are kept and
    read into the table, interrupted ones are resumed as ``runner(None, run folder, cache, True)``
    and the others run. Ctrl-C (``KeyboardInterrupt``) stops the running runs (each marks its
    folder interrupted), writes ``sweep.csv`` of the runs finished so far (the others
    ``unfinished``) and is raised again: calling this again resumes the sweep.

    Raises
    ------
    SetupError
        before anything runs: for a folder of another sweep, a run needing more ranks than
        ``cores``, run folders that are running or not siloflow's, a ``sweep.csv`` or a
        ``report.html`` siloflow did not write (or that changed since: the page is written after
        the table, ``siloflow.cli.study_commands.write_sweep_report``); or a log that cannot be written, a worker that
        cannot be started.
    """
    import shlex
    out = Path(out).absolute()
    cache = Path(cache).absolute()
    check_cores(variants, cores)
    if groups is None:
        groups = group_by_fill(variants, sweep_engine(variants))
    keys = variant_keys(groups, variants)
    record = open_record(out, variants)
    check_owned(out, record, {TABLE_NAME: None, PAGE_NAME: None})
    finished, resuming = previous_runs(out, variants)
    check_cases(out, variants)
    out.mkdir(parents=True, exist_ok=True)
    save_record(out, record)
    case_files = write_cases(variants, out, checked=True)
    for sub in ("runs", "logs"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    runner = runner or run_variant
    logs = {v.name: out / "logs" / f"{v.name}.log" for v in variants}
    jobs = {}
    for v in variants:
        folder, again = out / "runs" / v.name, v.name in resuming
        case_file = None if again else case_files[v.name]
        jobs[v.name] = Job(v.name, _bound(runner, case_file, folder, cache, again), v.case.engine.ranks, logs[v.name])
    returncodes: dict[str, Optional[int]] = dict(finished)
    said = shlex.join

    class Logged(FillOrder):
        """The fill order, each start logged as the command it stands for."""

        def started(self, job: Job) -> None:
            folder = out / "runs" / job.name
            what = (["siloflow", "run", "--resume", str(folder)] if job.name in resuming else
                    ["siloflow", "run", str(case_files[job.name]), "-o", str(folder), "--cache", str(cache)])
            _log_line(job.log, f"# siloflow sweep, {time.strftime('%Y-%m-%d %H:%M:%S')}: {said(what)} "
                               "(siloflow.runs in a worker process)")
            super().started(job)

    def ended(job: Job, outcome: Outcome) -> None:
        _log_line(job.log, f"# siloflow sweep: exit code {outcome.returncode}")
        returncodes[job.name] = outcome.returncode

    def changed(running: list[str]) -> None:
        if progress is not None:
            progress(len(returncodes), len(variants), running)

    try:
        if progress is not None:
            progress(len(returncodes), len(variants), [])
        run_jobs(Logged(groups, jobs, finished, resuming), cores, ended, changed)
    except KeyboardInterrupt:                  # the runs finished so far; the sweep resumes from its folders
        try:
            write_owned(out, record, {TABLE_NAME: sweep_table(variants, out, keys, returncodes).to_csv(index=False)})
        except (OSError, SetupError, ReadError):
            pass
        raise
    table = sweep_table(variants, out, keys, returncodes)
    write_owned(out, record, {TABLE_NAME: table.to_csv(index=False)})
    return table


def _bound(runner: Runner, case_file: Optional[Path], folder: Path, cache: Path, resuming: bool):
    def work():
        return runner(case_file, folder, cache, resuming)
    return work


def sweep(case_file, set_specs: list[str], out, seeds: int = 1, cores: Optional[int] = None, cache=None,
          force: bool = False, progress: Optional[SweepProgress] = None):
    """``siloflow sweep`` from Python: prepare (:func:`prepare_sweep`) and run (:func:`run_sweep`)
    the sweep of ``case_file`` over the ``--set`` specs and ``seeds`` in folder ``out``, within
    ``cores`` (default: this machine's), through the fill cache ``cache`` (default ``out/cache``);
    return its table. Called again on the same folder, it resumes the sweep."""
    out = Path(out)
    variants, groups = prepare_sweep(case_file, set_specs, seeds, out, force)
    return run_sweep(variants, out, cores or os.cpu_count() or 1, Path(cache) if cache else out / "cache",
                     progress=progress, groups=groups)


# ------------------------------------------------------------------ the table
def _results(folder: Path) -> dict:
    """What the table takes from a run folder (:func:`siloflow.run_row.run_row`; nan/None where it
    holds nothing readable)."""
    row = run_row(folder)
    return {column: row[key] for column, key in ROW_COLUMNS.items()}


def sweep_table(variants: list[Variant], out: Path, keys: dict[str, str], returncodes: dict[str, Optional[int]]):
    """One row per variant: ``run`` (its run folder), ``name``, each ``--set`` path, ``seed``,
    ``fill_key`` (first 12 hex digits), ``fill_from_cache`` (the run record's ``fill_cache``
    hit, None if unknown), ``status`` (complete: exit code 0; failed: another or an unknown
    one; unfinished: not in ``returncodes``, the sweep was stopped first), ``returncode``,
    ``wall_s`` (engine wall time, s), ``flow_rate_kg_s`` and ``flow_rate_stderr_kg_s`` (steady
    flow rate, kg/s), ``clogged`` (whether the discharge clogged; None if unknown),
    ``steady_t_start_s`` and ``steady_t_end_s`` (the steady window detected in the discharge, s:
    ``siloflow beverloo`` leaves out a run that clogged or has none), ``force_balance_ratio``
    (settled bed's supports over its weight),
    ``bulk_solid_fraction`` and ``log``; nan where a run left no value. A pandas DataFrame."""
    import pandas as pd
    out = Path(out)
    paths = [path for path in (variants[0].values if variants else {}) if path != "seed"]
    rows = []
    for v in variants:
        folder = out / "runs" / v.name
        code = returncodes.get(v.name)
        row = {"run": str(folder), "name": v.name, **{path: v.values[path] for path in paths}, "seed": v.seed,
               "fill_key": keys[v.name][:12], "returncode": code,
               "status": "complete" if code == 0 else "failed" if v.name in returncodes else "unfinished",
               "log": str(out / "logs" / f"{v.name}.log")}
        rows.append({**row, **_results(folder)})
    return pd.DataFrame(rows, columns=[*TABLE_HEAD, *paths, *TABLE_TAIL])


def table_summary(table) -> dict:
    """Counts of a sweep table: runs ``complete``, ``failed`` and ``unfinished``, fills
    ``computed`` (runs that made their bed) and ``reused`` (runs that started from a cached one)."""
    fills = table["fill_from_cache"].map({True: "reused", False: "computed"})
    return {**{status: int((table["status"] == status).sum()) for status in ("complete", "failed", "unfinished")},
            "computed": int((fills == "computed").sum()), "reused": int((fills == "reused").sum())}

