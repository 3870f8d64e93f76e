"""LIGGGHTS 3.8 as a subprocess (``mpirun -np N`` for N > 1 ranks)."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import time
from collections import deque
from pathlib import Path
from typing import Optional

from ..case import Case
from ..deck import DECK_NAME, DERIVED_NAME, render
from ..engine_output import FLOW_COLUMNS, read_ave_time
from ..errors import EngineRunError, ReadError, SetupError
from .base import Engine, ProgressCallback, RunRecord, write_status
from .liggghts_log import LogState, decode, diagnose, parse_log_text

LOG_NAME = "log.liggghts"
SCREEN_NAME = "screen.txt"
RECORD_NAME = "run_record.json"


class LiggghtsEngine(Engine):
    """LIGGGHTS-PUBLIC 3.8 (Debian ``liggghts``).

    Parameters
    ----------
    executable : str
        the LIGGGHTS binary (default: ``$SILOFLOW_LIGGGHTS`` or ``liggghts`` on PATH).
        It is a property of this machine, never of a case file.
    mpirun : str
        the MPI launcher used when a case asks for more than one rank.
    """

    name = "liggghts"

    def __init__(self, executable: Optional[str] = None, mpirun: str = "mpirun"):
        self.executable = executable or os.environ.get("SILOFLOW_LIGGGHTS", "liggghts")
        self.mpirun = mpirun

    # ------------------------------------------------------------------ set-up
    def _which(self, program: str, what: str) -> str:
        path = shutil.which(program)
        if path is None:
            raise SetupError(f"{what} '{program}' not found on PATH: install it with "
                             "'make install-engine' (Debian package liggghts) or set SILOFLOW_LIGGGHTS")
        return path

    def version(self) -> str:
        exe = self._which(self.executable, "LIGGGHTS binary")
        proc = subprocess.run([exe, "-h"], capture_output=True, timeout=60, stdin=subprocess.DEVNULL)
        for line in decode(proc.stdout).splitlines():
            if "LIGGGHTS" in line and ("version" in line.lower() or "(" in line):
                return line.strip()
        return "LIGGGHTS (version not reported)"

    def prepare(self, case: Case, folder: Path, force: bool = False) -> Path:
        folder = render(case, folder, force=force)
        write_status(folder, "rendered")
        return folder

    def command(self, ranks: int) -> list[str]:
        """The command line that runs the deck in its folder."""
        exe = self._which(self.executable, "LIGGGHTS binary")
        # '-screen none' segfaults when LIGGGHTS reads an STL (ENGINE_NOTES.md): keep the screen on a pipe
        base = [exe, "-in", DECK_NAME, "-log", LOG_NAME]
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
        launcher = [self._which(self.mpirun, "MPI launcher"), "-np", str(ranks)]
        if os.geteuid() == 0:
            launcher.insert(1, "--allow-run-as-root")
        return launcher + base

    # ------------------------------------------------------------------ run
    def execute(self, folder: Path, progress: Optional[ProgressCallback] = None) -> RunRecord:
        folder = Path(folder)
        derived = _read_derived(folder)
        missing = [w["file"] for w in derived["walls"] if not (folder / w["file"]).is_file()]
        if missing or not (folder / DECK_NAME).is_file():
            raise SetupError(f"{folder} is incomplete: missing {', '.join(missing) or DECK_NAME}; "
                             "re-render it with 'siloflow render'")
        cmd = self.command(int(derived["engine_ranks"]))
        planned = {k: int(v) for k, v in derived["planned_steps"].items()}
        state = LogState()
        tail: deque[str] = deque(maxlen=25)
        start = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True, preexec_fn=_die_with_parent)
        write_status(folder, "running", command=cmd, engine_pid=proc.pid, siloflow_pid=os.getpid())
        try:
            with open(folder / SCREEN_NAME, "wb") as screen:
                for raw in proc.stdout:
                    screen.write(raw)
                    line = decode(raw)
                    tail.append(line.rstrip())
                    if state.feed(line) and progress is not None:
                        progress(state.stage or "start", state.step, state.total_steps(planned))
                    if state.fatal:                  # nothing good comes of running on
                        _stop(proc)
                        break
            returncode = proc.wait()
        except BaseException:  # Ctrl-C or SIGTERM turned into an exception: stop the whole group
            _stop(proc)
            write_status(folder, "interrupted", step=state.step, stage=state.stage)
            raise
        wall = time.perf_counter() - start
        record = RunRecord(folder=str(folder), engine=self.name, command=cmd, returncode=returncode,
                           wall_time=wall, stage_steps=state.stage_steps, inserted=state.inserted,
                           settled_ke_pe=state.settled_ke_pe, completed=state.done,
                           warnings=state.warnings)
        (folder / RECORD_NAME).write_text(json.dumps(record.to_json(), indent=2))
        if returncode != 0 or state.errors:
            message, cause, fix = diagnose(state.errors, state.warnings, returncode, tuple(tail))
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, command=cmd, returncode=returncode, folder=folder,
                                 cause=cause, fix=fix, log_tail="\n".join(tail))
        return record

    def collect(self, folder: Path) -> RunRecord:
        """Check the run: every stage reached, insertion complete, no particle lost through a wall."""
        folder = Path(folder)
        derived = _read_derived(folder)
        try:
            text = decode((folder / LOG_NAME).read_bytes())
            record = RunRecord(**json.loads((folder / RECORD_NAME).read_text()))
        except (OSError, ValueError, TypeError) as exc:
            raise ReadError(f"{folder} holds no finished LIGGGHTS run ({exc})") from None
        state = parse_log_text(text)
        tail = "\n".join(text.splitlines()[-15:])

        def fail(message, cause="", fix=""):
            write_status(folder, "failed", reason=message)
            raise EngineRunError(message, returncode=record.returncode, folder=folder,
                                 cause=cause, fix=fix, log_tail=tail)

        requested = int(derived["particle_count"])
        if state.inserted is not None and state.inserted < requested:
            fail(f"insertion fell short: {state.inserted} of {requested} particles inserted",
                 "the insertion region above the bed is too small or batches did not clear it",
                 "make the silo taller above the bed, lower fill.batch_volume_fraction or fill fewer particles")
        if state.not_settled_ke_pe is not None:
            fail(f"the bed did not settle: kinetic/potential energy {state.not_settled_ke_pe:.3g} is still "
                 f"above the threshold after fill.settle.max_time",
                 "settling takes longer than allowed (soft contacts, high restitution, tall bed)",
                 "raise fill.settle.max_time or fill.settle.ke_pe_ratio")
        if not state.done:
            fail("the run ended before the discharge stage finished", "the engine stopped early",
                 "read the end of log.liggghts")
        flow = read_ave_time(folder / "output" / "flow.txt", FLOW_COLUMNS)
        after_fill = flow[flow.step > state.stage_steps.get("settle", 0)]
        lost = requested - after_fill.atoms - after_fill.deleted_count
        if len(lost) and lost.max() > 0:
            first = after_fill[lost > 0].iloc[0]
            fail(f"{int(lost.max())} particle(s) left the silo without passing the outlet (first seen "
                 f"at step {int(first.step)})",
                 "particles escaped through a wall: time step too large for the contact stiffness, or "
                 "walls too soft for the load", "lower engine.timestep_fraction or stiffen the walls")
        write_status(folder, "complete")
        return record


def _read_derived(folder: Path) -> dict:
    try:
        return json.loads((Path(folder) / DERIVED_NAME).read_text())
    except (OSError, ValueError) as exc:
        raise SetupError(f"{folder} is not a siloflow deck folder (no readable {DERIVED_NAME}: {exc})") from None


def _die_with_parent() -> None:
    """In the engine's child process: ask Linux to SIGTERM it when siloflow dies, even by SIGKILL,
    so no engine is left running unattended. (Its output pipe closing also stops it at its next
    write; this covers long silent stretches.) mpirun passes the signal on to its ranks."""
    try:
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):  # not Linux: the SIGTERM/Ctrl-C handling still stops the engine
        pass


def _stop(proc: subprocess.Popen, grace: float = 10.0) -> None:
    """SIGTERM the engine's process group, then SIGKILL it after ``grace`` seconds."""
    for sig, wait in ((signal.SIGTERM, grace), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=wait)
            return
        except subprocess.TimeoutExpired:
            continue
