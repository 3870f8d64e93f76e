"""The Python entry point to run folders: ``siloflow.open_run(folder)`` and ``siloflow.run(case, folder)``.

For scripts and notebooks (sweeps)::

    import siloflow
    r = siloflow.open_run("runs/quick")
    r.state                          # 'complete', 'failed', ...
    r.summary["flow_rate"]["rate"]   # kg/s
    r.flow                           # discharge time series (DataFrame, SI)
    r.wall_pressure                  # band pressure per sample (DataFrame, Pa)
    for frame in r.frames(): ...     # the particle dumps, one frame at a time
    r.cg()                           # coarse-grained fields (xarray.Dataset): stored or computed
    r.to_universe()                  # the dumps of a window as an MDAnalysis Universe

The tables are read from what ``siloflow post`` wrote (``results/``); a folder not yet
post-processed is analysed on first access. docs/python_api.md has the whole API.
"""
from __future__ import annotations

import os
import time
import warnings
from contextlib import ExitStack
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Callable, Iterator, Optional

import pandas as pd

from .errors import CaseError, ReadError, SetupError
from .engine.tables import FLOW_COLUMNS, neutral_flow, neutral_wall_forces, read_ave_time
from .run_folder import (
    FLOW_SCHEMA,
    FLOW_TABLE,
    PLAN_NAME,
    RECORD_NAME,
    RESULT_TABLES,
    WALL_FORCE_SCHEMA,
    WALL_FORCES_TABLE,
    RunFolder,
    RunRecord,
    check_table,
    folder_lock,
)


class UnfinishedRunWarning(UserWarning):
    """The results read are those of a run that is not known to have finished (``Run(unfinished=True)``)."""


class _Unrecorded(RunFolder):
    """A run folder whose engine run left no run record yet (running, interrupted, killed): its
    record and engine-neutral tables as the engine's own files tell them now, read, never written."""

    def __init__(self, path, engine):
        super().__init__(path)
        self.engine = engine

    @cached_property
    def record(self) -> RunRecord:
        """What the engine's files tell of the run now (no stage at all when it left nothing readable)."""
        try:
            done = self.engine.finished(self.path, self.plan)
        except (OSError, ReadError) as exc:
            return RunRecord(folder=str(self.path), engine=self.engine.name, command=[], returncode=None,
                             wall_time=float("nan"), stage_steps={}, inserted=None, settled_ke_pe=None,
                             completed=False, warnings=[f"siloflow: the {self.engine.title} run left nothing "
                                                        f"readable ({exc})"])
        return RunRecord(folder=str(self.path), engine=self.engine.name, command=[], returncode=None,
                         wall_time=float("nan"), stage_steps=dict(done.stage_steps), inserted=done.inserted,
                         settled_ke_pe=done.settled_ke_pe, completed=done.completed, warnings=list(done.notes),
                         templates_inserted=done.templates_inserted, short_batches=dict(done.short_batches),
                         discharge_stop=done.discharge_stop)

    def flow(self):
        if (self.path / FLOW_TABLE).is_file():
            return super().flow()
        table = read_ave_time(self.path / self.engine.flow_table, FLOW_COLUMNS)
        return check_table(neutral_flow(table, self.plan.dt), FLOW_SCHEMA, str(self.path / self.engine.flow_table))

    def wall_forces(self):
        if (self.path / WALL_FORCES_TABLE).is_file():
            return super().wall_forces()
        path = self.path / self.engine.wall_forces_table
        return check_table(neutral_wall_forces(path, self.plan), WALL_FORCE_SCHEMA, str(path))


def _path(value, what: str) -> Path:
    """``value`` as a path (a str or os.PathLike, not empty), else ``SetupError`` naming ``what``."""
    if isinstance(value, (bytes, bytearray)) or not isinstance(value, (str, os.PathLike)) or not str(value):
        raise SetupError(f"{what} must be a folder path (a str or pathlib.Path), not {type(value).__name__} "
                         f"{value!r:.60}")
    return Path(value)


class Run:
    """A siloflow run folder, read-only: its state, plan, summary and tables (SI units).

    The results (``summary``, ``flow``, ``wall_pressure``, ``bands``) are those of a finished run:
    of a run in any other state (running, failed, interrupted, abandoned, or ``unknown`` when its
    status.json is missing) they are refused with a ``ReadError`` saying why, unless the folder is
    opened with ``unfinished=True``, which reads them with an :class:`UnfinishedRunWarning`; of a
    run that left no run record yet (running, or stopped before it wrote one) the record, summary
    and tables are then what the engine's files tell now, computed and not written."""

    def __init__(self, folder, unfinished: bool = False):
        self.folder = _path(folder, "the run folder")
        self.unfinished = bool(unfinished)
        self.run_folder = RunFolder(self.folder)
        if not self.run_folder.is_run_folder():
            raise ReadError(f"{self.folder} is not a siloflow run folder (no {PLAN_NAME})")

    def __repr__(self) -> str:
        return f"Run({str(self.folder)!r}, state={self.state!r})"

    @property
    def state(self) -> str:
        """rendered, running, complete, failed, interrupted, abandoned or unknown (status.json missing)."""
        return self.run_folder.state["state"]

    @property
    def status(self) -> dict:
        """The whole status: ``state`` and, where there is one, the ``reason``."""
        return self.run_folder.state

    def _finished(self) -> None:
        """Refuse (or, ``unfinished``, warn about) the results of a run not known to be complete."""
        status = self.status
        unrecorded = self._unrecorded()
        if status["state"] == "complete" and not unrecorded:
            return
        why = f"{self.folder} is {status['state']}" + (f" ({status['reason']})" if status.get("reason") else "")
        if not self.unfinished:
            raise ReadError(f"{why}: its results would not be those of a finished run; "
                            "siloflow.open_run(folder, unfinished=True) reads them anyway, with a warning")
        also = (f"; it has no {RECORD_NAME} yet: they are what the engine's files tell now, computed and not "
                "written" if unrecorded else "")
        warnings.warn(f"{why}: these results are not those of a finished run{also}", UnfinishedRunWarning,
                      stacklevel=3)

    def _unrecorded(self) -> bool:
        """Whether the results are read from what the engine left: ``unfinished``, no run record
        and no results written."""
        return (self.unfinished and not (self.folder / RECORD_NAME).is_file()
                and not self.run_folder.summary_file.is_file())

    @cached_property
    def _left(self) -> _Unrecorded:
        from .engine import get_engine
        return _Unrecorded(self.folder, get_engine(self.plan.engine.name))

    @cached_property
    def _computed(self):
        """The results of an unrecorded run (``postprocess.run_results.RunResults``), in memory."""
        from postprocess.first_results import analyse_run
        return analyse_run(self._left)

    @property
    def plan(self):
        """The run plan (``siloflow.plan.RunPlan``): species, contacts, time step, stages, walls."""
        return self.run_folder.plan

    @property
    def record(self):
        """The engine run's record (``siloflow.run_folder.RunRecord``: wall time s, stage steps, ...)."""
        if self.unfinished and not (self.folder / RECORD_NAME).is_file():
            self._finished()
            return self._left.record
        return self.run_folder.record

    def _results(self) -> Path:
        self._finished()
        if not self.run_folder.summary_file.is_file():
            if self._unrecorded():
                raise ReadError(f"{self.folder} has no {RECORD_NAME} yet: its coarse-grained fields need a "
                                "recorded run (finish it with siloflow run --resume); summary, flow, "
                                "wall_pressure and bands are computed from what the engine left")
            post_process(self.folder)              # recorded in the manifest: --force may replace them
        return self.run_folder.results

    @cached_property
    def summary(self) -> dict:
        """results/summary.json: flow rate (kg/s) with its standard error, bands, force balance, ..."""
        if self._unrecorded():
            self._finished()
            return self._computed.summary
        self._results()
        return self.run_folder.read_summary()

    def _table(self, name: str) -> pd.DataFrame:
        if self._unrecorded():
            self._finished()
            table = self._computed.tables.get(RESULT_TABLES[name])
            if table is None:
                raise ReadError(f"{self.folder}: no {name} table (its case samples no wall forces)")
            return table
        path = self._results() / RESULT_TABLES[name]
        try:
            return pd.read_csv(path)
        except (OSError, ValueError) as exc:
            raise ReadError(f"cannot read {path}: {exc}") from None

    @cached_property
    def flow(self) -> pd.DataFrame:
        """Discharge series: step, time (s), time since opening, outlet mass (kg), mass in the
        silo (kg), total mass (kg), particles."""
        return self._table("flow")

    @cached_property
    def wall_pressure(self) -> pd.DataFrame:
        """Band pressure per sample: band, step, time (s), z_mid (m), pressure (Pa), shear force (N)."""
        return self._table("wall_pressure")

    @cached_property
    def bands(self) -> pd.DataFrame:
        """Per band: static pressure and shear, maximum dynamic pressure, discharge factor."""
        return self._table("bands")

    def frames(self, columns: Optional[list[str]] = None, every: int = 1) -> Iterator:
        """The particle dump frames (``postprocess.dumps.Frame``), one at a time."""
        from postprocess.dumps import read_frames
        from postprocess.paraview import particle_dump_files
        return read_frames(particle_dump_files(self.run_folder), columns=columns, every=every)

    # ------------------------------------------------------------ coarse-graining and MDAnalysis
    def cg(self, stored: Optional[bool] = None, **settings):
        """The coarse-grained fields of the steady discharge (``siloflow cg``), an ``xarray.Dataset``
        (dimensions z, r of an (r, z) grid; rho, velocity, solid_fraction, kinetic_stress, ..., in SI;
        see docs/coarse_graining.md). Without ``settings``, the folder's results/cg/fields.nc, written
        by ``siloflow cg``, when there is one (loaded into memory, the file closed); else, or with
        ``settings``, computed now through the same code (``postprocess.cg_run.analyse_cg``, from the
        run's geometry and steady-flow window, as ``siloflow cg`` does) and not written. ``settings``
        are ``siloflow cg``'s options, by the same names and defaults: ``kernel`` ("gaussian"),
        ``width`` (2.0), ``unit`` ("radius"), ``nr`` (100), ``nz`` (300), ``grid`` ("rz"),
        ``method`` ("exact"), ``refine`` (2), ``species`` ("radius", or None), ``per_frame``
        (False), ``every`` (1). ``stored``: True, the stored fields only (``ReadError`` when there
        are none, or with ``settings``); False, always compute."""
        import xarray as xr

        from .run_folder import RESULTS
        known = {"kernel": "kernel_name", "width": "width", "unit": "unit", "nr": "nr", "nz": "nz",
                 "grid": "grid_kind", "method": "method", "refine": "refine", "species": "species",
                 "per_frame": "per_frame", "every": "every"}
        unknown = sorted(set(settings) - set(known))
        if unknown:
            raise SetupError(f"Run.cg: unknown setting(s) {', '.join(unknown)}; known: {', '.join(known)}")
        path = self.folder / RESULTS / "cg" / "fields.nc"
        if stored and settings:
            raise SetupError("Run.cg(stored=True) reads the stored fields: give no settings")
        if stored or (stored is None and not settings and path.is_file()):
            self._finished()
            if not path.is_file():
                raise ReadError(f"{self.folder} has no coarse-grained fields ({path.relative_to(self.folder)}): "
                                f"run `siloflow cg {self.folder}`, or call Run.cg() without stored=True to compute them")
            try:
                with xr.open_dataset(path) as ds:
                    return ds.load()
            except (OSError, ValueError) as exc:
                raise ReadError(f"cannot read {path}: {exc}") from None
        from postprocess.cg_run import analyse_cg, setup_from_run
        self._results()                                  # the steady-flow window is the summary's
        return analyse_cg(setup_from_run(self.run_folder), **{known[k]: v for k, v in settings.items()}).dataset

    def _stage_bounds(self, stages) -> tuple[int, Optional[int]]:
        """First step and the step after the last (None: the end) of the frames of ``stages``."""
        starts = {name: step for name, step in self.record.stage_steps.items() if isinstance(step, int)}
        order = sorted(starts, key=lambda name: starts[name])
        if stages is None:                              # the closed silo: after the fill, before the opening
            if "open" not in starts:
                raise ReadError(f"{self.folder}: the run's record has no opening (stages: {', '.join(order)}); "
                                "choose stages or steps")
            after_fill = [n for n in order if starts[n] > starts.get("fill", -1) and starts[n] < starts["open"]]
            if not after_fill:
                raise ReadError(f"{self.folder}: no stage between the fill and the opening (stages: {', '.join(order)})")
            stages = after_fill
        names = [stages] if isinstance(stages, str) else list(stages)
        missing = [n for n in names if n not in starts]
        if missing or not names:
            raise ReadError(f"{self.folder}: no stage {', '.join(missing) or '(none given)'} in this run; "
                            f"its stages are {', '.join(order)}")
        last = max(names, key=lambda n: starts[n])
        later = [starts[n] for n in order if starts[n] > starts[last]]
        return min(starts[n] for n in names), (min(later) if later else None)

    def to_universe(self, stages=None, steps: Optional[tuple] = None, every: int = 1, atoms: str = "fixed",
                    dimensions=None):
        """The particle dumps of a window as an MDAnalysis ``Universe`` (in memory), for MDAnalysis'
        own analyses (``InterRDF``, ``AtomNeighborSearch``, ...); see ``postprocess.universe`` for
        what it holds (SI units; ``radii``, ``types``, ``names`` (species), ``masses``, residues =
        rigid bodies (clumps), no unit cell unless ``dimensions``).

        The window: ``stages`` (a stage name or names of the run's record, ``Run.record.stage_steps``:
        fill, settle, static, open, discharge, ...; the frames from the first one's start to the
        next stage's) or ``steps`` ((first, last) engine steps, inclusive, None for open ends);
        by default the closed silo, every frame after the fill and before the opening (settle,
        static, ...), whose particles do not change. Every ``every``-th frame of the window.
        ``atoms``: "fixed", refuse a window whose particles change (``ReadError``: the fill inserts
        them, the discharge removes them); "common", keep the particles present in every frame of it
        (over the discharge, those still in the silo at the window's end). For a changing count,
        one Universe per frame: ``postprocess.universe.universe_from_frames([frame])`` over
        ``Run.frames()``."""
        import re

        from postprocess.dumps import read_frames
        from postprocess.universe import universe_from_frames
        if stages is not None and steps is not None:
            raise SetupError("Run.to_universe: give stages or steps, not both")
        if steps is None:
            lo, end = self._stage_bounds(stages)
            hi = None if end is None else end - 1
        else:
            lo, hi = steps
        files = self.run_folder.dump_files("particles")
        if files is None:
            list(self.frames())                          # raises the ReadError saying why there are none
        def step_of(path):
            return int(re.findall(r"\d+", path.name)[-1])
        chosen = [p for p in files if (lo is None or step_of(p) >= lo) and (hi is None or step_of(p) <= hi)]
        frames = [f for f in read_frames(chosen, every=every) if (lo is None or f.timestep >= lo)
                  and (hi is None or f.timestep <= hi)] if chosen else []
        if not frames:
            raise ReadError(f"{self.folder}: no particle dump between steps {lo} and {hi if hi is not None else 'the end'}"
                            f" (dumps every {self.plan.outputs.dump_every} steps)")
        types = {int(k): v for k, v in self.run_folder.dump_layout.types.items()}
        return universe_from_frames(frames, atoms=atoms, type_names=types, steps_to_time=self.plan.dt,
                                    dimensions=dimensions)


def open_run(folder, unfinished: bool = False) -> Run:
    """The run folder ``folder`` (made by ``siloflow run`` or ``siloflow.run``); ``unfinished``:
    read the results of a run not known to be complete, with a warning (see :class:`Run`)."""
    return Run(folder, unfinished=unfinished)


@dataclass
class PreparedRun:
    """A run ready to start (:func:`prepare_run`, :func:`prepare_resume`): its rendered folder, the
    case and plan it was rendered from, the engine that runs it, and what the command line reports
    before the run starts. :meth:`execute` runs it; :func:`post_process` computes its results.

    It holds the folder's lock (``siloflow.run_folder.folder_lock``: another siloflow command
    writing the folder is refused) until :meth:`release`, the end of a ``with`` block on it, or
    its collection."""

    folder: Path
    case: object                       # siloflow.case.Case
    plan: object                       # siloflow.plan.RunPlan
    engine: object                     # siloflow.engine.base.Engine
    output_estimate: dict = field(default_factory=dict)     # check_disk_space: bytes and frames
    profile_replaced: list = field(default_factory=list)    # the case's fields a --profile replaced
    resuming: bool = False
    state_before: str = "rendered"     # a resumed folder's state when it was opened
    lock: Optional[ExitStack] = field(default=None, repr=False, compare=False)    # the folder's lock, held

    def release(self) -> None:
        """Release the folder's lock (again: nothing happens)."""
        lock, self.lock = self.lock, None
        if lock is not None:
            lock.close()

    def __enter__(self) -> "PreparedRun":
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def __del__(self) -> None:
        try:
            self.release()
        except Exception:                   # at interpreter exit: the kernel releases the lock
            pass

    def execute(self, progress: Optional[Callable[[str, int, int], None]] = None, cache=None,
                on_cache_hit: Optional[Callable[[str], None]] = None,
                on_warning: Optional[Callable[[str], None]] = None):
        """Run the engine in the folder (through the fill cache folder ``cache``, when given: a cached
        settled bed of the same fill is reused, ``on_cache_hit(key)`` told), check what it left and
        return the run record; ``EngineRunError`` when it failed, ``KeyboardInterrupt`` (the engine
        stopped and the folder marked interrupted) when interrupted. A resumed run finishes from its
        last restart point (or fills again when it was stopped before its bed settled), never from the
        cache; given ``cache``, its settled bed is then published there if the cache has none of its
        fill (``fill_cache.run_with_cache``'s ``resume``)."""
        if self.resuming and cache is None:
            return self.engine.resume(self.folder, progress=progress)
        if cache is None:
            self.engine.execute(self.folder, progress=progress)
            return self.engine.collect(self.folder)
        from .fill_cache import FillCache, run_with_cache
        plan = self.plan
        if self.resuming:       # plan.json holds no wall triangles, and the fill key needs them: the case's
            from .derived import derive
            plan = derive(self.case)
        return run_with_cache(self.engine, self.folder, plan, FillCache(cache), progress,
                              on_hit=on_cache_hit, on_warning=on_warning, resume=self.resuming)


def _case_of(case) -> tuple[object, list, str]:
    """(Case, files to keep in the folder, where the case came from) of a Case, a dict of case fields
    or a case-file path."""
    from .case import Case
    from .case_file import case_from_dict, load_case
    if not isinstance(case, (Case, dict, str, os.PathLike)) or isinstance(case, str) and not case:
        raise CaseError([("(case)", f"give a Case, a dict of case fields or a case-file path, not "
                                    f"{type(case).__name__} {case!r:.60}")], "siloflow.run")
    if isinstance(case, dict):
        return case_from_dict(case), [], "case"
    if isinstance(case, Case):
        return case, [], "case"
    return load_case(case), [case], str(case)


def prepare_run(case, folder, force: bool = False, allow_long: bool = False, allow_large_output: bool = False,
                profile: Optional[str] = None, executable: Optional[str] = None, ranks: Optional[int] = None,
                runs_here: bool = True) -> PreparedRun:
    """Everything before the engine starts, as ``siloflow run`` does it: read ``case`` (a ``Case``, a
    dict of case fields or a case-file path, which is kept in the folder), apply the numerical
    ``profile`` (reference, fast or custom; None: the case's) and ``ranks`` (None: the case's
    ``engine.ranks``), check it against its engine (binary ``executable``, default the engine's own)
    and, when it ``runs_here`` (not in a cluster job), that engine's presence and this machine's cores,
    derive the run plan, refuse a run over the step cap (``allow_long``) or whose estimated output
    exceeds the free disk (``allow_large_output``), and render the folder (``force``: replace one
    siloflow made). Nothing is written when anything is refused."""
    from .derived import check_run_length, derive
    from .disk_estimate import check_disk_space
    from .engine import get_engine
    from .engine.base import check_case
    folder = _path(folder, "siloflow.run's folder")
    case, keep, source = _case_of(case)
    replaced = []
    if profile is not None:
        from .profiles import with_profile
        case, replaced = with_profile(case, profile)
    if ranks is not None and ranks != case.engine.ranks:
        case = case.with_changes({"engine.ranks": ranks})
    engine = get_engine(case.engine.name, executable=executable)
    check_case(case, engine)
    if runs_here:
        engine.preflight(case.engine.ranks)     # engine and launcher present before anything is written
    try:
        plan = derive(case)
    except CaseError as exc:
        raise CaseError(exc.problems, source) from None
    check_run_length(plan, allow_long)
    sizes = check_disk_space(case, plan, folder, allow_large_output)
    lock = ExitStack()
    with lock:              # released here if the render fails, else kept by the PreparedRun
        lock.enter_context(folder_lock(folder))
        folder = engine.prepare(case, folder, force=force, keep=keep, plan=plan)
        return PreparedRun(folder, case, plan, engine, sizes, list(replaced), lock=lock.pop_all())


def prepare_resume(folder, executable: Optional[str] = None) -> PreparedRun:
    """An interrupted (or failed, or rendered) run folder, to finish from its last restart point
    (``siloflow run --resume``): its own case, plan and engine (binary ``executable``)."""
    from .case_file import load_case
    from .engine import get_engine
    from .run_folder import run_state
    folder = _path(folder, "the run folder to resume")
    run_folder = RunFolder(folder)
    case = load_case(run_folder.case_file)
    engine = get_engine(case.engine.name, executable=executable)
    engine.preflight(case.engine.ranks)
    lock = ExitStack()
    with lock:              # held until the PreparedRun is released
        lock.enter_context(folder_lock(folder))
        state = run_state(folder).get("state")
        plan = run_folder.plan
        return PreparedRun(folder, case, plan, engine, resuming=True, state_before=str(state), lock=lock.pop_all())


def post_process(folder, measured_pressure=None) -> dict:
    """The first results of a finished run folder (``postprocess.report.post_process``: tables,
    figures, reports in results/), recorded in its manifest as siloflow's; returns the summary."""
    from postprocess.report import post_process as write_results
    from .run_folder import record_products
    since = time.time()
    try:
        return write_results(folder, measured_pressure)
    finally:                # what post wrote is siloflow's: --force may replace it later
        record_products(folder, RunFolder(folder).results, since)


def run(case, folder, force: bool = False, progress=None, allow_long: bool = False,
        allow_large_output: bool = False, profile: Optional[str] = None, cache=None,
        executable: Optional[str] = None, post: bool = True) -> Run:
    """Render ``case`` (a ``Case``, a dict of case fields or a case-file path) into ``folder``, run
    its engine, check the run and compute the first results, as ``siloflow run`` does (the same
    pipeline: :func:`prepare_run`, :meth:`PreparedRun.execute`, :func:`post_process`); return the
    ``Run``. ``progress(stage, step, total)`` is told the engine's progress; ``cache``: a fill cache
    folder; ``post``: compute the first results now (else on first access)."""
    with prepare_run(case, folder, force=force, allow_long=allow_long, allow_large_output=allow_large_output,
                     profile=profile, executable=executable) as prepared:
        prepared.execute(progress, cache=cache)
        if post:
            post_process(prepared.folder)
    return Run(prepared.folder)


def resume(folder, progress=None, executable: Optional[str] = None, post: bool = True) -> Run:
    """Finish an interrupted run folder from its last restart point (``siloflow run --resume``) and
    compute its first results; return the ``Run``."""
    with prepare_resume(folder, executable) as prepared:
        prepared.execute(progress)
        if post:
            post_process(prepared.folder)
    return Run(prepared.folder)
