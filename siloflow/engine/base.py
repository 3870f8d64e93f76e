"""One engine interface, several implementations (as ASE's ``GenericFileIOCalculator``).

The base class owns the run: ``prepare`` writes the run folder (needs no engine installed),
``execute`` checks the folder, launches the engine once (:meth:`Engine.launch`, the engine's own),
records the run and turns a guard trip or a failure into ``EngineRunError``; ``collect`` reads what
the run left (:meth:`Engine.finished`, the engine's own), checks it finished properly and writes the
engine-neutral tables; ``resume`` and the fill cache's ``start_from_fill`` go on from a settled bed.
An engine supplies only its own parts: its deck (``write_deck``), one launch, and the reading of
its state. The recipe for a new engine: docs/new_engine.md.
"""
from __future__ import annotations

import os
import shutil
import time
from abc import ABC, abstractmethod
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from ..case import Case
from ..errors import EngineRunError, SetupError
from ..run_folder import (
    RECORD_NAME,
    RunFolder,
    RunRecord,
    check_plain_tree,
    folder_lock,
    record_engine_outputs,
    run_state,
    snapshot,
    write_status,
)
from .processes import DISK_FIX, FILL_LOSS_LIMIT, disk_full, not_settled, read_plan
from .tables import FLOW_COLUMNS, neutral_flow, neutral_wall_forces, read_ave_time

#: progress(stage, current_step, total_steps); total is the current upper bound
ProgressCallback = Callable[[str, int, int], None]


#: the environment variable naming the MPI launcher of every engine (default: mpirun; ``siloflow run --slurm``
#: scripts set it to the launcher asked for)
LAUNCHER_VARIABLE = "SILOFLOW_MPIRUN"


@dataclass(frozen=True)
class LaunchProfile:
    """How an engine is launched on this machine (never set by a case file): the binary (None:
    the engine's ``$SILOFLOW_<ENGINE>`` variable, else its usual name on PATH), the MPI launcher
    for runs on more than one rank, and environment variables added to the engine's."""

    executable: Optional[str] = None
    mpirun: str = "mpirun"
    env: dict = field(default_factory=dict)

    def environment(self) -> Optional[dict]:
        """The engine's environment (None: siloflow's own)."""
        return {**os.environ, **self.env} if self.env else None


@contextmanager
def engine_writes(folder: Path):
    """The block writes ``folder`` as siloflow and its engine: under the folder's lock (another
    siloflow command is refused), and whatever new file it leaves (or file of siloflow's it
    rewrites) is recorded in the manifest as siloflow's when it ends, even interrupted, so that
    ``--force`` replaces an engine's output of any name and still refuses a user's file."""
    folder = Path(folder)
    with folder_lock(folder):
        before = snapshot(folder)
        try:
            yield
        finally:
            try:
                record_engine_outputs(folder, before)
            except OSError:              # unrecorded, the files stay the user's: --force refuses, never deletes
                pass


def check_case(case: Case, engine: "Engine", plan=None) -> None:
    """Raise ``CaseError`` listing what ``engine`` cannot do of ``case`` (``Engine.check``)."""
    from ..errors import CaseError
    problems = engine.check(case, plan)
    if problems:
        raise CaseError(problems, f"case (engine {engine.name})")


@dataclass
class Launched:
    """What one launch of an engine left (:meth:`Engine.launch`): its command and exit code, the run
    record's fields it read (``stage_steps``, ``inserted``, ``settled_ke_pe``, ``completed``,
    ``warnings``, ``guard``, ...), the guard's trip (``siloflow.guard.GuardTrip``) if the guard stopped
    it, its failure as (message, cause, fix) if it failed, the end of its output, and the disk's state
    if it was stopped for a full disk."""

    command: list
    returncode: Optional[int]
    fields: dict = field(default_factory=dict)
    guard_trip: object = None
    failure: Optional[tuple[str, str, str]] = None
    tail: str = ""
    disk_full: str = ""


@dataclass
class Finished:
    """What an engine read of a run that ended (:meth:`Engine.finished`), engine-neutral: what
    :meth:`Engine.collect` checks and records. Counts: ``inserted`` atoms (spheres) in the box after
    the fill, ``templates_inserted`` grains and dust spheres the insertion placed (None: the engine
    does not tell), ``escaped`` particles lost through a wall after the fill (None: the engine counts
    them from the flow table, :meth:`Engine.escaped`)."""

    stage_steps: dict
    completed: bool
    inserted: Optional[int]
    templates_inserted: Optional[int] = None
    settled_ke_pe: Optional[float] = None
    not_settled_ke_pe: Optional[float] = None
    discharge_stop: Optional[dict] = None
    short_batches: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)        # warnings for the record (each once)
    escaped: Optional[int] = None
    log_tail: str = ""


@dataclass(frozen=True)
class SettledBed:
    """A cached settled bed as the engine itself read it back from its restart file
    (:meth:`Engine.fill_bed`): per atom its type (the plan's species k is type k + 1), radius (m)
    and grain mass (kg; a clump's sphere carries its clump's), and the simulation box (``xlo`` ...
    ``zhi``, m)."""

    types: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    box: dict


class Engine(ABC):
    """A DEM engine siloflow can drive: the run is the base class's, an engine supplies its deck
    (:meth:`write_deck`), one launch (:meth:`launch`) and the reading of what a run left
    (:meth:`finished`), and for the fill cache :meth:`fill_key_parts` and :meth:`fill_files`."""

    name: str = "abstract"
    #: the engine's name in messages
    title: str = "the engine"
    default_executable: str = ""
    executable_variable: str = ""
    #: whether the engine runs a binary (an ``executable`` to give); an engine in a Python module refuses one
    runs_binary: bool = True
    #: the deck the engine runs, and the one a resumed run runs (relative to the run folder)
    deck_name: str = ""
    resume_deck_name: str = ""
    #: the file a failed run's reader is sent to
    log_name: str = "the engine's log"
    #: the engine's sampled tables, in the layout of ``siloflow.engine.tables``
    flow_table: str = "output/flow.txt"
    wall_forces_table: str = "output/wall_forces.txt"
    #: a cached settled bed's files (:meth:`fill_files`' names) -> where they go in a run folder
    fill_targets: dict = {}

    def __init__(self, executable: Optional[str] = None, mpirun: str = "mpirun", env: Optional[dict] = None,
                 profile: Optional[LaunchProfile] = None):
        if executable is not None and not self.runs_binary:
            raise SetupError(f"{self.title} runs through its Python module, not a binary: an engine executable "
                             f"({executable!r}, --engine-executable) does not apply; leave it out")
        profile = profile or LaunchProfile(executable, mpirun, dict(env or {}))
        if profile.executable is None:
            profile = LaunchProfile(os.environ.get(self.executable_variable) or self.default_executable,
                                    profile.mpirun, profile.env)
        if profile.mpirun == "mpirun" and os.environ.get(LAUNCHER_VARIABLE):    # a Slurm job's srun, a site's mpirun
            profile = LaunchProfile(profile.executable, os.environ[LAUNCHER_VARIABLE], profile.env)
        self.profile = profile

    # ------------------------------------------------------------------ set-up (the engine's)
    def check(self, case: Case, plan=None) -> list[tuple[str, str]]:
        """What this engine cannot do of ``case`` (and of its ``plan``, when given): ``(field path,
        message)`` pairs, empty when it can run it. ``siloflow validate``, ``render`` and ``run``
        refuse a case with problems before anything is written."""
        return []

    def plan_warnings(self, case: Case, plan) -> list[str]:
        """What this engine will do differently from ``plan`` without refusing it (each names its
        field and consequence); recorded with the plan's own warnings in the run folder."""
        return []

    def preflight(self, ranks: int) -> None:
        """Refuse (``SetupError``) to start when the engine, or the MPI launcher ``ranks`` > 1 needs,
        is not installed here: checked before anything is written."""

    @abstractmethod
    def version(self) -> str:
        """The engine's version string; raise ``SetupError`` if it is not installed."""

    @abstractmethod
    def write_deck(self, plan, folder: Path) -> None:
        """Write this engine's deck of ``plan`` (and the meshes and dump layout it needs) into
        the run folder being rendered."""

    @abstractmethod
    def check_deck_files(self, folder: Path, resume: bool = False) -> None:
        """Refuse (``SetupError``) a folder whose deck holds a command siloflow does not write."""

    # ------------------------------------------------------------------ run (the engine's parts)
    @abstractmethod
    def launch(self, folder: Path, plan, progress: Optional[ProgressCallback], resume: bool) -> Launched:
        """Run the engine once in the checked ``folder`` (``resume``: from the settled bed's restart
        file), telling ``progress``; mark the folder ``running`` when it starts, and ``interrupted``
        (re-raising) on Ctrl-C or SIGTERM. Through ``self.profile`` (:meth:`stream` runs a command)."""

    @abstractmethod
    def finished(self, folder: Path, plan) -> Finished:
        """What the run in ``folder`` left (``OSError``/``ReadError`` when it left nothing readable)."""

    def escaped(self, plan, finished: Finished, flow) -> Optional[tuple[Optional[int], Optional[int]]]:
        """(count or None, first step or None) of the particles that left the silo through a wall after
        the fill, None when none did; ``flow``: the engine's flow table (``FLOW_COLUMNS``). By default
        the engine's own count (``finished.escaped``)."""
        return (finished.escaped, None) if finished.escaped else None

    def restart_step(self, folder: Path) -> Optional[int]:
        """The step of the settled bed's restart point in ``folder``, None when the run left none."""
        return None

    def before_resume(self, folder: Path, plan, step: int) -> None:
        """Ready ``folder`` for a run from its settled bed at ``step`` (a resume deck, tables kept aside)."""

    def after_resume(self, folder: Path, step: int) -> None:
        """Put ``folder`` together after a run from its settled bed (tables spliced), even a failed one."""

    # ------------------------------------------------------------------ fill cache (the engine's parts)
    def fill_key_parts(self, plan) -> dict:
        """What of this engine defines the fill of ``plan`` (siloflow.fill_cache): its name, version
        and whatever of its encoding the restart file carries; ``SetupError`` when it has no fill cache."""
        raise SetupError(f"the {self.name} engine has no fill cache: run without --cache")

    def fill_files(self, folder: Path) -> dict[str, bytes]:
        """The settled bed of a finished run, as the files a later run starts from (names of
        :attr:`fill_targets`); ``SetupError`` when the run wrote none."""
        raise SetupError(f"the {self.name} engine has no fill cache: run without --cache")

    def fill_bed(self, files: dict, plan) -> SettledBed:
        """The settled bed of a cached fill (``files``: :meth:`fill_files`' names -> paths) as the
        engine reads its restart file, for the cache to compare with ``plan`` before a run starts from
        it (``ReadError`` when the engine cannot read it)."""
        raise SetupError(f"the {self.name} engine has no fill cache: run without --cache")

    # ------------------------------------------------------------------ the run (the base's)
    def prepare(self, case: Case, folder: Path, force: bool = False, keep=(), plan=None) -> Path:
        """Check ``case`` against this engine and write its run folder; return its path. Needs
        no engine installed. ``plan``: the case's run plan, if already derived."""
        from ..deck import render
        from ..derived import derive
        plan = plan if plan is not None else derive(case)
        check_case(case, self, plan)
        extra = [w for w in self.plan_warnings(case, plan) if w not in plan.warnings]
        if extra:
            plan = plan.model_copy(update={"warnings": [*plan.warnings, *extra]})
        with folder_lock(folder):              # the status too is written before another command may look
            folder = render(case, folder, force=force, keep=keep, plan=plan, engine=self)
            write_status(folder, "rendered")
        return folder

    def check_folder(self, folder: Path, plan, resume: bool = False) -> None:
        """Refuse (``SetupError``) a folder the engine may not run: a wall mesh or the deck missing, a
        link or special file in it (the engine writes by name), a deck command siloflow does not write."""
        deck = (self.resume_deck_name or self.deck_name) if resume else self.deck_name
        missing = [w.file for w in plan.walls if not (folder / w.file).is_file()]
        if missing or not (folder / deck).is_file():
            raise SetupError(f"{folder} is incomplete: missing {', '.join(missing) or deck}; "
                             "re-render it with 'siloflow render'")
        check_plain_tree(folder)
        self.check_deck_files(folder, resume)   # defence in depth: only siloflow's commands reach the engine

    def stream(self, command: list[str], folder: Path, screen: str, on_line, env: Optional[dict] = None,
               **options):
        """Run ``command`` in ``folder`` with this machine's launch profile (its environment, with
        ``env`` added), its output streamed into ``screen`` (``siloflow.engine.processes.stream``)."""
        from .processes import stream
        base = self.profile.environment()
        if env:
            base = {**(base or os.environ), **env}
        return stream(command, folder, screen, on_line, env=base, **options)

    def execute(self, folder: Path, progress: Optional[ProgressCallback] = None, resume: bool = False) -> RunRecord:
        """Run the engine in a prepared folder (``resume``: from its settled bed) and write the run
        record; raise ``EngineRunError`` if it fails (the folder's status says why)."""
        folder = Path(folder)
        with engine_writes(folder):
            return self._execute(folder, progress, resume)

    def _execute(self, folder: Path, progress: Optional[ProgressCallback], resume: bool) -> RunRecord:
        plan = read_plan(folder)
        self.check_folder(folder, plan, resume)
        start = time.perf_counter()
        run = self.launch(folder, plan, progress, resume)
        record = RunRecord(folder=str(folder), engine=self.name, command=run.command, returncode=run.returncode,
                           wall_time=time.perf_counter() - start, **{
                               "stage_steps": {}, "inserted": None, "settled_ke_pe": None, "completed": False,
                               **run.fields})

        def failed(message, cause="", fix="", tail=run.tail):
            write_status(folder, "failed", reason=message)
            return EngineRunError(message, command=run.command, returncode=run.returncode, folder=folder,
                                  cause=cause, fix=fix, log_tail=tail)

        full = run.disk_full or disk_full(folder)
        if full:
            raise failed(f"the disk is full ({full}): the engine's outputs in {folder} are incomplete", fix=DISK_FIX)
        try:
            RunFolder(folder).write_record(record)
        except OSError as exc:
            from ..atomic_files import os_error
            raise failed(str(os_error(exc, folder / RECORD_NAME)), fix=DISK_FIX, tail="") from None
        if run.guard_trip is not None:            # stopped by the guard: its own words
            t = run.guard_trip
            raise failed(f"the run was stopped by siloflow's guard ({t.signal}): {t.message}", t.cause, t.fix)
        if run.failure is not None:
            raise failed(*run.failure)
        return record

    def collect(self, folder: Path) -> RunRecord:
        """Read a finished run's folder and check it completed (:meth:`_collect`); raise
        ``EngineRunError`` if not. Any failure to read or write the folder is recorded as ``failed``
        with its reason."""
        from ..atomic_files import os_error
        from ..errors import SiloflowError
        from .processes import record_failure
        folder = Path(folder)
        try:
            return self._collect(folder)
        except OSError as exc:
            error = os_error(exc, f"the run record in {folder}")
            record_failure(folder, str(error))
            raise error from None
        except SiloflowError as exc:
            record_failure(folder, str(exc).splitlines()[0])
            raise

    def _collect(self, folder: Path) -> RunRecord:
        """Check the run: every grain inserted, none lost through a wall, the bed settled, every stage
        run; then write the engine-neutral tables, the record and the status ``complete``."""
        from ..errors import ReadError
        plan = read_plan(folder)
        try:
            done = self.finished(folder, plan)
            record = RunFolder(folder).record
        except (OSError, ReadError) as exc:
            raise ReadError(f"{folder} holds no finished {self.title} run ({exc})") from None   # recorded by collect
        record.stage_steps, record.inserted, record.completed = done.stage_steps, done.inserted, done.completed
        record.settled_ke_pe, record.discharge_stop = done.settled_ke_pe, done.discharge_stop

        def fail(message, cause="", fix=""):
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, returncode=record.returncode, folder=folder,
                                 cause=cause, fix=fix, log_tail=done.log_tail)

        # the insertion counts grains (a clump each) and dust spheres; the engine counts atoms
        requested = plan.expected_atoms
        templates = plan.fill.count + plan.fill.dust_count
        placed = done.templates_inserted
        record.templates_inserted = placed
        record.short_batches = dict(done.short_batches)
        for note in done.notes:
            if note not in record.warnings:
                record.warnings.append(note)
        if placed is not None and placed < templates:
            fail(f"insertion fell short: {placed} of {templates} grains and dust spheres inserted",
                 "the insertion region above the bed is too small or batches did not clear it",
                 "make the silo taller above the bed, lower fill.batch_volume_fraction or fill fewer particles")
        if done.inserted is not None and done.inserted < requested:
            lost = requested - done.inserted
            where = (f"{lost} of {requested} atoms (spheres) left the box during the fill" if placed is not None
                     else f"insertion fell short: {done.inserted} of {requested} atoms (spheres) in the box after the fill")
            if placed is None or lost > FILL_LOSS_LIMIT * requested:
                fail(where, "grains kicked out of the insertion region or through a wall while pouring "
                     "(overlapping insertions, impacts too fast for the time step)",
                     "lower fill.batch_volume_fraction, engine.timestep_fraction, or the pouring height")
            record.fill_losses = lost            # recorded: the bed is what settled, and it is reported
            record.warnings.append(f"siloflow: {where}; the bed settled without them")
        if done.not_settled_ke_pe is not None:
            fail(*not_settled(done.not_settled_ke_pe, plan))
        if not done.completed:
            fail("the run ended before the discharge stage finished", "the engine stopped early",
                 f"read the end of {self.log_name}")
        flow = read_ave_time(folder / self.flow_table, FLOW_COLUMNS)
        escaped = self.escaped(plan, done, flow)
        if escaped is not None:
            count, step = escaped
            fail(f"{f'{count} ' if count else ''}particles left the silo without passing the outlet"
                 f"{f' (first seen at step {step})' if step is not None else ''}",
                 "particles escaped through a wall: time step too large for the contact stiffness, or "
                 "walls too soft for the load", "lower engine.timestep_fraction or stiffen the walls")
        run = RunFolder(folder)
        run.write_flow(neutral_flow(flow, plan.dt))          # the engine-neutral tables
        run.write_wall_forces(neutral_wall_forces(folder / self.wall_forces_table, plan))
        run.write_record(record)
        write_status(folder, "complete")
        return record

    def resume(self, folder: Path, progress: Optional[ProgressCallback] = None) -> RunRecord:
        """Finish an interrupted run: from the settled bed's restart point if the run got that far
        (the static, opening and discharge stages are run again), else from the start."""
        folder = Path(folder)
        with engine_writes(folder):
            return self._resume(folder, progress)

    def _resume(self, folder: Path, progress: Optional[ProgressCallback]) -> RunRecord:
        from ..deck import verify_deck
        from .registry import get_engine
        state = run_state(folder).get("state")
        if state in ("running", "complete"):
            raise SetupError(f"{folder} is {state}: there is nothing to resume")
        verify_deck(folder, get_engine)  # a folder can come from anyone: run only what its case renders
        step = self.restart_step(folder)
        if step is None:                                    # interrupted before the bed settled
            self.execute(folder, progress)
        else:
            self.before_resume(folder, read_plan(folder), step)
            try:
                self.execute(folder, progress, resume=True)
            finally:
                self.after_resume(folder, step)
        return self.collect(folder)

    def start_from_fill(self, folder: Path, files: dict, progress: Optional[ProgressCallback] = None) -> RunRecord:
        """Run a rendered folder from a cached settled bed (``files``: :meth:`fill_files`' names ->
        paths, placed as :attr:`fill_targets` says) through the resume path: static, opening and
        discharge stages."""
        folder = Path(folder)
        with engine_writes(folder):
            for name, target in self.fill_targets.items():
                shutil.copyfile(files[name], folder / target)
            return self.resume(folder, progress)

    def run(self, case: Case, folder: Path, force: bool = False,
            progress: Optional[ProgressCallback] = None) -> RunRecord:
        """prepare, execute, collect (under the folder's lock throughout)."""
        with folder_lock(folder):
            folder = self.prepare(case, folder, force=force)
            self.execute(folder, progress=progress)
            return self.collect(folder)
