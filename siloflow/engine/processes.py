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
#: a time-step fraction above which a bed may never come to rest (measured on the accuracy bench's case, hooke,
#: e = 0.88: at 0.3 of the critical time every bed settled, at 0.5 most kept jittering above KE/PE 1e-4)
RESTLESS_FRACTION = 0.3


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
