"""What every engine run does with its folder and its processes: read the plan, record a failure,
tie an engine's process to siloflow's life, and stop its process group."""
from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path

from ..errors import ReadError, SetupError
from ..plan import RunPlan
from ..run_folder import RunFolder, read_status, write_status


#: atoms that may leave the box during the fill (recorded) before the run counts as failed
FILL_LOSS_LIMIT = 0.01


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
