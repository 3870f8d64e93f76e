"""What every engine run does with its folder and its processes: read the plan, record a failure,
tie an engine's process to siloflow's life, stream its output into its screen file while watching
the disk, and stop its process group."""
from __future__ import annotations

import functools
import os
import signal
import subprocess
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

from ..atomic_files import os_error
from ..errors import EngineRunError, ReadError, SetupError
from ..plan import RunPlan
from ..run_folder import RunFolder, read_status, write_status

#: atoms that may leave the box during the fill (recorded) before the run counts as failed
FILL_LOSS_LIMIT = 0.01
#: a time-step fraction above which a bed may never come to rest (measured on the accuracy bench's case, hooke,
#: e = 0.88: at 0.3 of the critical time every bed settled, at 0.5 most kept jittering above KE/PE 1e-4)
RESTLESS_FRACTION = 0.3
#: free bytes below which the disk counts as full during a run (the engine's writes fail silently)
DISK_RESERVE = 1 << 20
#: how often a streamed run checks the disk, s
DISK_CHECK_SECONDS = 2.0
DISK_FIX = ("free space on that disk (or choose a run folder on another one) and run again; "
            "'siloflow run' estimates a run's output before it starts unless --allow-large-output is given")
#: lines of an engine's output kept for its failure message
TAIL_LINES = 25


def mpi_slots() -> tuple[int, str]:
    """How many MPI ranks this job may start, and where that number comes from: inside a Slurm
    allocation its task count (``SLURM_NTASKS``, over every node of the job), else this machine's cores."""
    tasks = os.environ.get("SLURM_NTASKS", "")
    if tasks.isdigit() and int(tasks) > 0:
        return int(tasks), f"this Slurm job has {tasks} tasks (SLURM_NTASKS)"
    cores = os.cpu_count() or 1
    return cores, f"this machine has {cores} cores"


def check_ranks(ranks: int) -> None:
    """``SetupError`` when ``ranks`` MPI ranks exceed what this job may start (:func:`mpi_slots`)."""
    slots, why = mpi_slots()
    if ranks > slots:
        raise SetupError(f"engine.ranks = {ranks} but {why}: lower engine.ranks (or, on a cluster, submit the run "
                         "with siloflow run --slurm)")


def launch_ranks(launcher: str, ranks: int) -> list[str]:
    """The launcher's words that start ``ranks`` MPI ranks: ``mpirun -np N`` (as root, Open MPI's needs
    ``--allow-run-as-root``, which MPICH's refuses), or Slurm's ``srun --ntasks=N``."""
    if Path(launcher).name == "srun":
        return [launcher, f"--ntasks={ranks}", "--cpus-per-task=1"]
    root = ["--allow-run-as-root"] if os.geteuid() == 0 and open_mpi(launcher) else []
    return [launcher, *root, "-np", str(ranks)]


@functools.lru_cache(maxsize=8)
def open_mpi(launcher: str) -> bool:
    """Whether ``launcher`` is Open MPI's (its ``--version`` says so); MPICH's hydra is not."""
    try:
        text = subprocess.run([launcher, "--version"], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return False
    return "Open MPI" in text or "OpenRTE" in text


def not_settled(ke_pe: float, plan: RunPlan) -> tuple[str, str, str]:
    """What, why and the fix of a bed still moving at ``fill.settle.max_time`` (kinetic/potential
    energy ``ke_pe``): a long time step near the stability edge keeps a bed jittering, so it is named
    first when the plan's step is above ``RESTLESS_FRACTION`` of the critical time."""
    what = (f"the bed did not settle: kinetic/potential energy {ke_pe:.3g} is still above the threshold "
            "after fill.settle.max_time")
    cause = "settling takes longer than allowed (soft contacts, high restitution, tall bed)"
    fix = "raise fill.settle.max_time or fill.settle.ke_pe_ratio"
    fraction = plan.timestep.fraction
    if fraction > RESTLESS_FRACTION:
        cause = (f"the time step, {fraction:g} of the critical time, is near the stability edge: the contacts "
                 f"gain energy each step and the bed keeps jittering; or {cause}")
        fix = f"lower engine.timestep_fraction to {RESTLESS_FRACTION:g} or less, or {fix}"
    return what, cause, fix


def read_plan(folder: Path) -> RunPlan:
    """The folder's plan (``SetupError`` when it is not a siloflow deck folder)."""
    try:
        return RunFolder(folder).plan
    except ReadError as exc:
        raise SetupError(f"{folder} is not a siloflow deck folder ({exc})") from None


def record_failure(folder: Path, reason: str) -> None:
    """Mark the run failed unless its status already says why (written by the check that failed)."""
    try:
        if read_status(folder).get("state") == "failed":
            return
    except ReadError:
        pass
    write_status(folder, "failed", reason=reason)


def die_with_parent() -> None:
    """In an engine's child process: ask Linux to SIGTERM it when siloflow dies, even by SIGKILL,
    so no engine is left running unattended. (Its output pipe closing also stops it at its next
    write; this covers long silent stretches.) mpirun passes the signal on to its ranks."""
    try:
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):  # not Linux: the SIGTERM/Ctrl-C handling still stops the engine
        pass


def stop(proc: subprocess.Popen, grace: float = 10.0) -> None:
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


def disk_full(folder: Path) -> str:
    """A description of the disk's state if it is (nearly) full, else ''."""
    try:
        fs = os.statvfs(folder)
    except OSError:
        return ""
    # root may write into the blocks reserved for it, others only into the available ones
    free = (fs.f_bfree if os.geteuid() == 0 else fs.f_bavail) * fs.f_frsize
    return f"{free} bytes free" if free < DISK_RESERVE else ""


@dataclass
class Streamed:
    """How a streamed engine process ended: its exit code, its last output lines, and the disk's
    state when it was stopped for a full disk ('' otherwise)."""

    returncode: int
    tail: list[str]
    disk_full: str = ""


def _utf8(raw: bytes) -> str:
    return raw.decode("utf-8", "replace")


def stream(command: list[str], folder: Path, screen: str, on_line: Callable[[str], bool],
           env: Optional[dict] = None, append: bool = False, decode: Callable[[bytes], str] = _utf8,
           interrupted: Callable[[], dict] = dict) -> Streamed:
    """Run ``command`` in ``folder`` (its own process group, stopped when siloflow dies), mark the
    folder running, copy its output into the file ``screen`` and hand each line (``decode``d) to
    ``on_line``, which returns True to stop the engine (a fatal line). The engine is stopped when the
    disk fills. A screen that cannot be written is an ``EngineRunError`` (status failed); Ctrl-C or
    SIGTERM stops the engine, marks the folder interrupted (with ``interrupted()``'s fields) and
    re-raises."""
    folder = Path(folder)
    tail: deque[str] = deque(maxlen=TAIL_LINES)
    proc = subprocess.Popen(command, cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, env=env, start_new_session=True, preexec_fn=die_with_parent)
    write_status(folder, "running", command=command, engine_pid=proc.pid)     # siloflow's own pid: added there
    full = ""
    try:
        flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | (os.O_APPEND if append else os.O_TRUNC)
        with open(os.open(folder / screen, flags, 0o644), "wb") as out:
            checked = time.monotonic()
            for raw in proc.stdout:
                out.write(raw)
                line = decode(raw)
                tail.append(line.rstrip())
                if on_line(line):                # nothing good comes of running on
                    stop(proc)
                    break
                if time.monotonic() - checked > DISK_CHECK_SECONDS:
                    checked = time.monotonic()
                    full = disk_full(folder)
                    if full:                     # the engine's writes fail silently: stop it
                        stop(proc)
                        break
        returncode = proc.wait()
    except OSError as exc:                       # the screen could not be written: the disk is full
        stop(proc)
        message = str(os_error(exc, f"the engine's output in {folder}"))
        write_status(folder, "failed", reason=message)
        raise EngineRunError(message, command=command, returncode=proc.returncode, folder=folder,
                             fix=DISK_FIX, log_tail="\n".join(tail)) from None
    except BaseException:  # Ctrl-C or SIGTERM turned into an exception: stop the whole group
        stop(proc)
        write_status(folder, "interrupted", **interrupted())
        raise
    return Streamed(returncode, list(tail), full)
