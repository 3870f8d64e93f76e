"""LIGGGHTS 3.8 as a subprocess (``mpirun -np N`` for N > 1 ranks)."""
from __future__ import annotations

import os
import shutil
import subprocess
import time
from collections import deque
from pathlib import Path
from typing import Optional

from ...atomic_files import os_error, write_text
from ...case import Case
from ...deck import check_deck_file, verify_deck
from ...errors import CaseError, EngineRunError, ReadError, SetupError
from ...plan import RunPlan
from ...run_folder import (LIGGGHTS_FILES, LIGGGHTS_TABLES, RECORD_NAME, RESTART_FILE, RunFolder, check_plain_tree,
                           run_state, write_status)
from ...guard import RunGuard
from .. import get_engine
from ..base import Engine, ProgressCallback, RunRecord
from ..processes import FILL_LOSS_LIMIT, die_with_parent, not_settled, read_plan, stop
from . import deck as liggghts_deck
from .deck import ALLOWED_COMMANDS, DECK_NAME, RESUME_DECK_NAME
from .encoding import encode
from .insertion import short_batches_note
from ...fill_placement import fill_batches
from .log import LogState, decode, diagnose, parse_log_text
from .tables import FLOW_COLUMNS, neutral_flow, neutral_wall_forces, read_ave_time

LOG_NAME = LIGGGHTS_FILES["log"]
SCREEN_NAME = LIGGGHTS_FILES["screen"]
#: a resumed run's own log and screen (the first part's stay as they were)
RESUME_LOG_NAME = LIGGGHTS_FILES["resume_log"]
RESUME_SCREEN_NAME = LIGGGHTS_FILES["resume_screen"]
#: the ave/time tables a resumed run continues (the first part's rows are kept up to the restart)
CONTINUED_TABLES = LIGGGHTS_TABLES
#: the restart file LIGGGHTS' own signal handler writes into its working directory when SIGTERM (siloflow's
#: stop) or SIGINT reaches it, at its next output step, before it quits; a resume never reads it (it starts
#: from the settled bed's RESTART_FILE), so siloflow removes the ones its run left
FORCED_RESTART = "restart_forced_liggghts_*.data"


def forced_restarts(folder: Path) -> set[str]:
    """The names of the forced restart files (:data:`FORCED_RESTART`) in ``folder``."""
    return {p.name for p in Path(folder).glob(FORCED_RESTART) if p.is_file() and not p.is_symlink()}


def remove_forced_restarts(folder: Path, before: set[str]) -> None:
    """Delete the forced restart files the engine wrote into ``folder`` during a run: those not among
    ``before`` (the names there when it started; a file that was there is not siloflow's to delete)."""
    for name in forced_restarts(folder) - set(before):
        try:
            (Path(folder) / name).unlink()
        except OSError:
            pass


class LiggghtsEngine(Engine):
    """LIGGGHTS-PUBLIC 3.8 (Debian ``liggghts``).

    Its launch profile (:class:`~siloflow.engine.base.LaunchProfile`) is a property of this
    machine, never of a case file: the binary (default ``$SILOFLOW_LIGGGHTS`` or ``liggghts`` on
    PATH), the MPI launcher used when a case asks for more than one rank, and extra environment.
    """

    name = "liggghts"
    default_executable = "liggghts"
    executable_variable = "SILOFLOW_LIGGGHTS"

    # ------------------------------------------------------------------ set-up
    def _which(self, program: str, what: str) -> str:
        """The absolute path of ``program`` (a relative path is taken from the current directory,
        not from the run folder the engine runs in)."""
        path = shutil.which(program)
        if path is None:
            if program == self.profile.mpirun:
                fix = ("install Open MPI (Debian: apt-get install openmpi-bin), or set engine.ranks: 1 in the "
                       "case file")
            else:
                fix = ("install it with 'make install-engine' (Debian package liggghts), or name the binary with "
                       "--liggghts PATH or SILOFLOW_LIGGGHTS=PATH")
            where = "" if os.sep in program else " on PATH"
            raise SetupError(f"{what} '{program}' not found{where} (or not executable): {fix}")
        return os.path.abspath(path)

    def version(self) -> str:
        """The binary's version line. ``liggghts -h`` writes ``log.liggghts`` where it runs, so it
        runs in a scratch folder: never in the user's current directory, whose log it would replace."""
        import tempfile
        exe = self._which(self.profile.executable, "LIGGGHTS binary")
        with tempfile.TemporaryDirectory(prefix="siloflow-version-") as scratch:
            proc = subprocess.run([exe, "-h"], capture_output=True, timeout=60, stdin=subprocess.DEVNULL, cwd=scratch,
                                  env=self.profile.environment())
        for line in decode(proc.stdout).splitlines():
            if "LIGGGHTS" in line and ("version" in line.lower() or "(" in line):
                return line.strip()
        return "LIGGGHTS (version not reported)"

    def check(self, case: Case, plan: Optional[RunPlan] = None) -> list[tuple[str, str]]:
        """LIGGGHTS-PUBLIC's limits: its multisphere (clumps) runs on one MPI rank; its neighbour
        bins are counted in a C int; a plate that moves aside for clumps must still outrun them."""
        problems = []
        if case.particles.kind == "clumps" and case.engine.ranks != 1:
            problems.append(("engine.ranks", f"clumps (LIGGGHTS-PUBLIC multisphere) run on one rank only, "
                                             f"not {case.engine.ranks}: set engine.ranks: 1"))
        if plan is not None:
            try:
                encode(plan)
                if not plan.has_clumps:     # the deck reads the placed batches
                    fill_batches(plan)
            except CaseError as exc:
                problems += list(exc.problems)
        return problems

    def write_deck(self, plan: RunPlan, case: Case, folder: Path) -> None:
        liggghts_deck.write_deck(plan, case, folder)

    def check_deck_files(self, folder: Path, resume: bool = False) -> None:
        check_deck_file(Path(folder) / (RESUME_DECK_NAME if resume else DECK_NAME), ALLOWED_COMMANDS)

    def preflight(self, ranks: int) -> None:
        self.command(ranks)

    def command(self, ranks: int, deck: str = DECK_NAME, log: str = LOG_NAME) -> list[str]:
        """The command line that runs the deck in its folder."""
        exe = self._which(self.profile.executable, "LIGGGHTS binary")
        # '-screen none' segfaults when LIGGGHTS reads an STL (docs/engine_facts.md): keep the screen on a pipe
        base = [exe, "-in", deck, "-log", log]
        # LIGGGHTS' screen is block-buffered on a pipe, and an ERROR on one rank ends in MPI_Abort,
        # which loses the buffer (the message with it): line-buffer it (coreutils' stdbuf)
        stdbuf = shutil.which("stdbuf")
        if stdbuf:
            base = [stdbuf, "-oL"] + base
        if ranks == 1:
            return base
        if ranks > (os.cpu_count() or 1):
            raise SetupError(f"engine.ranks = {ranks} but this machine has {os.cpu_count()} cores: "
                             "lower engine.ranks")
        launcher = [self._which(self.profile.mpirun, "MPI launcher"), "-np", str(ranks)]
        if os.geteuid() == 0:
            launcher.insert(1, "--allow-run-as-root")
        return launcher + base

    # ------------------------------------------------------------------ run
    def execute(self, folder: Path, progress: Optional[ProgressCallback] = None, resume: bool = False) -> RunRecord:
        folder = Path(folder)
        plan = read_plan(folder)
        deck, log, screen_name = (RESUME_DECK_NAME, RESUME_LOG_NAME, RESUME_SCREEN_NAME) if resume else (
            DECK_NAME, LOG_NAME, SCREEN_NAME)
        missing = [w.file for w in plan.walls if not (folder / w.file).is_file()]
        if missing or not (folder / deck).is_file():
            raise SetupError(f"{folder} is incomplete: missing {', '.join(missing) or deck}; "
                             "re-render it with 'siloflow render'")
        check_plain_tree(folder)             # the engine writes by name: no link may lead it outside
        self.check_deck_files(folder, resume)   # defence in depth: only siloflow's commands reach the engine
        cmd = self.command(plan.engine.ranks, deck, log)
        planned = plan.planned_steps(encode(plan).open_steps)
        state = LogState(guard=RunGuard(plan.guard) if plan.guard is not None else None,
                         count_lost=not plan.has_clumps)
        tail: deque[str] = deque(maxlen=25)
        start = time.perf_counter()
        forced_before = forced_restarts(folder)
        proc = subprocess.Popen(cmd, cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, env=self.profile.environment(), start_new_session=True, preexec_fn=die_with_parent)
        write_status(folder, "running", command=cmd, engine_pid=proc.pid)     # siloflow's own pid: added there
        disk_full = None
        try:
            screen_fd = os.open(folder / screen_name, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o644)
            with open(screen_fd, "wb") as screen:
                checked = time.monotonic()
                for raw in proc.stdout:
                    screen.write(raw)
                    line = decode(raw)
                    tail.append(line.rstrip())
                    if state.feed(line) and progress is not None:
                        progress(state.stage or "start", state.step, state.total_steps(planned))
                    if state.fatal:                  # nothing good comes of running on
                        stop(proc)
                        break
                    if time.monotonic() - checked > DISK_CHECK_SECONDS:
                        checked = time.monotonic()
                        disk_full = _disk_full(folder)
                        if disk_full:                # the engine's writes fail silently: stop it
                            stop(proc)
                            break
            returncode = proc.wait()
        except OSError as exc:                   # screen.txt could not be written: the disk is full
            stop(proc)
            message = str(os_error(exc, f"the engine's output in {folder}"))
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, command=cmd, returncode=proc.returncode, folder=folder,
                                 fix=DISK_FIX, log_tail="\n".join(tail)) from None
        except BaseException:  # Ctrl-C or SIGTERM turned into an exception: stop the whole group
            stop(proc)
            write_status(folder, "interrupted", step=state.step, stage=state.stage)
            raise
        finally:                # a stopped LIGGGHTS wrote a restart of its own: the resume does not use it
            remove_forced_restarts(folder, forced_before)
        wall = time.perf_counter() - start
        disk_full = disk_full or _disk_full(folder)
        record = RunRecord(folder=str(folder), engine=self.name, command=cmd, returncode=returncode,
                           wall_time=wall, stage_steps=state.stage_steps, inserted=state.inserted,
                           settled_ke_pe=state.settled_ke_pe, completed=state.done,
                           warnings=state.warnings, guard=state.guard_trip_record(),
                           guard_peaks=state.guard.peak_record() if state.guard is not None else None)
        if disk_full:
            message = f"the disk is full ({disk_full}): the engine's outputs in {folder} are incomplete"
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, command=cmd, returncode=returncode, folder=folder, fix=DISK_FIX,
                                 log_tail="\n".join(tail))
        try:
            RunFolder(folder).write_record(record)
        except OSError as exc:
            message = str(os_error(exc, folder / RECORD_NAME))
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, command=cmd, returncode=returncode, folder=folder, fix=DISK_FIX) from None
        if state.guard_trip is not None:            # stopped by the guard: its own words
            t = state.guard_trip
            message = f"the run was stopped by siloflow's guard ({t.signal}): {t.message}"
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, command=cmd, returncode=returncode, folder=folder,
                                 cause=t.cause, fix=t.fix, log_tail="\n".join(tail))
        if returncode != 0 or state.errors:
            message, cause, fix = diagnose(state.errors, state.warnings, returncode, tuple(tail),
                                           folder=folder, files=(log, screen_name))
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, command=cmd, returncode=returncode, folder=folder,
                                 cause=cause, fix=fix, log_tail="\n".join(tail))
        if not (folder / log).is_file():
            message = f"the engine exited with code 0 but wrote no {log}: it did not run the deck"
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, command=cmd, returncode=returncode, folder=folder,
                                 cause="the binary is not LIGGGHTS, or it could not write in the run folder",
                                 fix="check --liggghts / SILOFLOW_LIGGGHTS, and read screen.txt in the run folder",
                                 log_tail="\n".join(tail))
        return record

    def resume(self, folder: Path, progress: Optional[ProgressCallback] = None) -> RunRecord:
        """Finish an interrupted run: from the settled bed's restart file if the run got that far
        (the static, opening and discharge stages are run again), else from the start."""
        folder = Path(folder)
        state = run_state(folder).get("state")
        if state in ("running", "complete"):
            raise SetupError(f"{folder} is {state}: there is nothing to resume")
        verify_deck(folder, get_engine)  # a folder can come from anyone: run only what its case renders
        restart = folder / RESTART_FILE
        step = _restart_step(folder)
        if not restart.is_file() or step is None:          # interrupted before the bed settled
            self.execute(folder, progress)
            return self.collect(folder)
        for name in CONTINUED_TABLES:                       # the first part's tables, kept aside
            if (folder / name).is_file():
                os.replace(folder / name, folder / (name + ".before_resume"))
        case = _load_folder_case(folder)
        liggghts_deck.write_resume_deck(read_plan(folder), case, folder)
        try:
            self.execute(folder, progress, resume=True)
        finally:
            for name in CONTINUED_TABLES:
                splice_table(folder / (name + ".before_resume"), folder / name, step)
        return self.collect(folder)

    # ------------------------------------------------------------------ fill cache
    def fill_key_parts(self, plan: RunPlan) -> dict:
        """What of this engine defines a fill (siloflow.fill_cache): its version, and the box and
        skin of the plan's encoding (the restart file carries the box)."""
        enc = encode(plan)
        return {"name": self.name, "version": self.version(), "ranks": plan.engine.ranks,
                "box": enc.box, "skin": enc.skin}

    def fill_files(self, folder: Path) -> dict[str, bytes]:
        """The settled bed of a finished run, as the files a later run starts from: the restart
        file, the log and the flow table up to it (``SetupError`` if the run wrote none)."""
        folder = Path(folder)
        lines = decode((folder / LOG_NAME).read_bytes()).splitlines() if (folder / LOG_NAME).is_file() else []
        mark = restart_mark(lines)
        restart = folder / RESTART_FILE
        if mark is None or not restart.is_file():
            raise SetupError(f"{folder} holds no settled bed to cache (no {RESTART_FILE})")
        flow = (folder / LIGGGHTS_TABLES[0]).read_text(errors="replace").splitlines(keepends=True)
        kept = [ln for ln in flow if ln.startswith("#") or (ln.endswith("\n") and ln.split()
                                                              and ln.split()[0].isdigit() and int(ln.split()[0]) <= mark[1])]
        return {"settled.restart": restart.read_bytes(), "log.liggghts": ("\n".join(lines[:mark[0] + 1]) + "\n").encode(),
                "flow.txt": "".join(kept).encode()}

    def start_from_fill(self, folder: Path, files: dict, progress: Optional[ProgressCallback] = None) -> RunRecord:
        """Run a rendered folder from a cached settled bed (``files``: :meth:`fill_files`'
        names -> paths) through the resume path: static, opening and discharge stages."""
        folder = Path(folder)
        for name, target in (("settled.restart", RESTART_FILE), ("log.liggghts", LOG_NAME),
                             ("flow.txt", LIGGGHTS_TABLES[0])):
            shutil.copyfile(files[name], folder / target)
        return self.resume(folder, progress)

    def _collect(self, folder: Path) -> RunRecord:
        """Check the run: every stage reached, insertion complete, no particle lost through a wall."""
        plan = read_plan(folder)
        enc = encode(plan)
        try:
            text = _log_text(folder)
            record = RunFolder(folder).record
        except (OSError, ReadError) as exc:
            raise ReadError(f"{folder} holds no finished LIGGGHTS run ({exc})") from None   # recorded by collect
        state = parse_log_text(text)
        record.stage_steps, record.inserted, record.completed = state.stage_steps, state.inserted, state.done
        record.settled_ke_pe, record.discharge_stop = state.settled_ke_pe, state.discharge_stop
        tail = "\n".join(text.splitlines()[-15:])

        def fail(message, cause="", fix=""):
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, returncode=record.returncode, folder=folder,
                                 cause=cause, fix=fix, log_tail=tail)

        # the insertion fixes count grains (a clump each) and dust spheres; the engine counts atoms
        requested = plan.expected_atoms
        templates = plan.fill.count + plan.fill.dust_count
        placed = sum(state.templates.values()) if state.templates else None
        record.templates_inserted = placed
        record.short_batches = {fix: len(got) for fix, got in state.short_batches.items()}
        for note in short_batches_note(state.batches, state.short_batches,
                                       {"ins": plan.fill.batch, "ins_dust": plan.fill.dust_batch}):
            if note not in record.warnings:
                record.warnings.append(note)
        if placed is not None and placed < templates:
            fail(f"insertion fell short: {placed} of {templates} grains and dust spheres inserted",
                 "the insertion region above the bed is too small or batches did not clear it",
                 "make the silo taller above the bed, lower fill.batch_volume_fraction or fill fewer particles")
        if state.inserted is not None and state.inserted < requested:
            lost = requested - state.inserted
            where = (f"{lost} of {requested} atoms (spheres) left the box during the fill" if placed is not None
                     else f"insertion fell short: {state.inserted} of {requested} atoms (spheres) in the box after the fill")
            if placed is None or lost > FILL_LOSS_LIMIT * requested:
                fail(where, "grains kicked out of the insertion region or through a wall while pouring "
                     "(overlapping insertions, impacts too fast for the time step)",
                     "lower fill.batch_volume_fraction, engine.timestep_fraction, or the pouring height")
            record.fill_losses = lost            # recorded: the bed is what settled, and it is reported
            record.warnings.append(f"siloflow: {where}; the bed settled without them")
        if state.not_settled_ke_pe is not None:
            fail(*not_settled(state.not_settled_ke_pe, plan))
        if not state.done:
            fail("the run ended before the discharge stage finished", "the engine stopped early",
                 "read the end of log.liggghts")
        flow = read_ave_time(folder / LIGGGHTS_TABLES[0], FLOW_COLUMNS)
        after_fill = flow[flow.step > state.stage_steps.get("settle", 0)]
        if any(w != 1.0 for w in enc.mass_weights):
            # clumps are not deleted at the outlet but fall out of the box later: until then they
            # are counted twice (in the box and through the outlet), never less than the bed
            settled = float(after_fill.mass_total.iloc[0]) if len(after_fill) else 0.0
            missing = settled - (after_fill.mass_total + after_fill.outlet_mass)
            lost = (missing > 1e-3 * settled).astype(int)
        else:
            lost = (state.inserted or requested) - after_fill.atoms - after_fill.deleted_count
        if len(lost) and lost.max() > 0:
            first = after_fill[lost > 0].iloc[0]
            fail(f"particles left the silo without passing the outlet (first seen at step {int(first.step)})",
                 "particles escaped through a wall: time step too large for the contact stiffness, or "
                 "walls too soft for the load", "lower engine.timestep_fraction or stiffen the walls")
        run = RunFolder(folder)
        run.write_flow(neutral_flow(flow, plan.dt))          # the engine-neutral tables
        run.write_wall_forces(neutral_wall_forces(folder / LIGGGHTS_TABLES[1], plan))
        run.write_record(record)
        write_status(folder, "complete")
        return record


_RESTART_MARK = "SILOFLOW_RESTART "
#: free bytes below which the disk counts as full during a run (the engine's writes fail silently)
DISK_RESERVE = 1 << 20
DISK_CHECK_SECONDS = 2.0
DISK_FIX = ("free space on that disk (or choose a run folder on another one) and run again; "
            "'siloflow run' estimates a run's output before it starts unless --allow-large-output is given")


def _disk_full(folder: Path) -> str:
    """A description of the disk's state if it is (nearly) full, else ''."""
    try:
        fs = os.statvfs(folder)
    except OSError:
        return ""
    # root may write into the blocks reserved for it, others only into the available ones
    free = (fs.f_bfree if os.geteuid() == 0 else fs.f_bavail) * fs.f_frsize
    return f"{free} bytes free" if free < DISK_RESERVE else ""



def restart_mark(lines: list[str]) -> Optional[tuple[int, int]]:
    """(line index, step) of the log's restart marker (the settled bed written), or None."""
    for k, line in enumerate(lines):
        if line.startswith(_RESTART_MARK):
            try:
                return k, int(float(line.split()[1]))
            except (IndexError, ValueError, OverflowError):
                return None                  # a marker cut short or not siloflow's: no restart point
    return None


def _restart_step(folder: Path) -> Optional[int]:
    """The step of the settled bed's restart file, from the first part's log (None if not written)."""
    try:
        mark = restart_mark(decode((folder / LOG_NAME).read_bytes()).splitlines())
    except OSError:
        return None
    return None if mark is None else mark[1]


def _log_text(folder: Path) -> str:
    """The run's log: the first part, and for a resumed run its part up to the restart followed by
    the resumed part's log."""
    text = decode((folder / LOG_NAME).read_bytes())
    resumed = folder / RESUME_LOG_NAME
    if not resumed.is_file():
        return text
    lines = text.splitlines()
    mark = restart_mark(lines)
    cut = len(lines) if mark is None else mark[0]
    return "\n".join(lines[:cut + 1]) + "\n" + decode(resumed.read_bytes())


def splice_table(before: Path, after: Path, step: int) -> None:
    """One ave/time table from the first part's rows and the resumed part's rows (headers of the
    first part), written atomically over ``after``. The first part's rows are kept up to the
    resumed part's first row, not only up to the restart ``step``: an average over several
    samples (``Nrepeat > 1``, the wall forces) is first written by the resumed part a sampling
    period or more after the step it starts from, and the first part had written those rows
    before it was stopped. A last line the first part did not finish is dropped."""
    if not before.is_file():
        return
    old_text = before.read_text(errors="replace")
    old = old_text.splitlines()
    if old and not old_text.endswith("\n"):
        old = old[:-1]                         # cut short when the first part was stopped
    new = after.read_text(errors="replace").splitlines() if after.is_file() else []

    def step_of(line):
        try:
            return int(line.split()[0])
        except (IndexError, ValueError):
            return None

    head = [ln for ln in old if ln.startswith("#")]
    resumed = [ln for ln in new if not ln.startswith("#") and step_of(ln) is not None]
    # without resumed rows, the first part's rows count up to the restart only
    keep_below = min(step_of(ln) for ln in resumed) if resumed else step + 1
    rows = [ln for ln in old if not ln.startswith("#") and step_of(ln) is not None and step_of(ln) < keep_below]
    write_text(after, "\n".join(head + rows + resumed) + "\n")
    before.unlink()


def _load_folder_case(folder: Path) -> Case:
    from ...case_file import load_case
    return load_case(RunFolder(folder).case_file)


