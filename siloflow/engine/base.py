"""One engine interface, several implementations (as ASE's calculators).

``prepare`` writes the deck folder (needs no engine installed), ``execute`` runs the
engine in it (blocks, streams progress, keeps the log), ``collect`` reads what the run
left and checks it finished properly. ``run`` composes the three.
"""
from __future__ import annotations

import errno
import json
import os
import socket
import time
from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Optional

from ..atomic_files import write_json
from ..case import Case
from ..errors import ReadError

#: progress(stage, current_step, total_steps); total is the current upper bound
ProgressCallback = Callable[[str, int, int], None]

STATUS_NAME = "status.json"


@dataclass
class RunRecord:
    """What a finished run left behind, as read from its folder."""

    folder: str
    engine: str
    command: list[str]
    returncode: Optional[int]
    wall_time: float                       # s
    stage_steps: dict[str, int]            # step at which each stage began
    inserted: Optional[int]
    settled_ke_pe: Optional[float]
    completed: bool
    warnings: list[str] = field(default_factory=list)
    templates_inserted: Optional[int] = None   # grains + dust spheres the insertion fixes placed
    fill_losses: int = 0                       # atoms that left the box during the fill (recorded, < 1 %)

    def to_json(self) -> dict:
        return asdict(self)


STATES = ("rendered", "running", "complete", "failed", "interrupted")


def write_status(folder: Path, state: str, **extra) -> None:
    """Record the run state (``rendered``, ``running``, ``complete``, ``failed``, ``interrupted``).

    A ``running`` status names siloflow's process with its start time, so a PID reused by
    another process is not taken for the run. On a full disk the status is rewritten in place
    (its blocks are already allocated), so a failure can still be recorded."""
    if state == "running":
        extra = {"siloflow_pid": os.getpid(), "siloflow_start": process_start(os.getpid()),
                 "host": socket.gethostname(), **extra}
    path = Path(folder) / STATUS_NAME
    data = {"state": state, "time": time.time(), **extra}
    try:
        write_json(path, data)
    except OSError as exc:
        if exc.errno not in (errno.ENOSPC, errno.EDQUOT) or not path.is_file():
            raise
        text = json.dumps(data).encode()
        with open(path, "r+b") as fh:
            fh.write(text)
            fh.truncate(len(text))


def process_start(pid) -> Optional[int]:
    """The start time of process ``pid`` in clock ticks since boot (Linux /proc), or None."""
    try:
        stat = Path(f"/proc/{int(pid)}/stat").read_text()
        return int(stat.rsplit(")", 1)[1].split()[19])
    except (OSError, ValueError, IndexError, OverflowError):
        return None


def _alive(pid, start=None) -> bool:
    """Whether ``pid`` is a live process, and (when ``start`` is known) the same one that
    recorded it: a reused PID has another start time."""
    if isinstance(pid, bool) or not isinstance(pid, int) or not 0 < pid < 2 ** 22:
        return False
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, OverflowError):
        return False
    except PermissionError:
        pass
    if start is None:                    # a status written before start times were recorded
        try:
            command = Path(f"/proc/{pid}/cmdline").read_bytes()
        except OSError:
            return True
        return b"python" in command or b"siloflow" in command
    return process_start(pid) == start


def run_state(folder: Path) -> dict:
    """The run's status. A ``running`` run whose siloflow process is gone (or whose PID now
    belongs to another process) is reported as ``abandoned``; a deck folder without a status
    (``siloflow render``) as ``rendered``."""
    from ..run_folder import is_siloflow_folder
    folder = Path(folder)
    if not (folder / STATUS_NAME).exists() and is_siloflow_folder(folder) and not (folder / "log.liggghts").exists():
        return {"state": "rendered"}
    status = read_status(folder)
    host = status.get("host")
    if status["state"] == "running" and host not in (None, socket.gethostname()):
        return {**status, "reason": f"on host {host}: its process cannot be checked from here"}
    if status["state"] == "running" and not _alive(status.get("siloflow_pid"), status.get("siloflow_start")):
        status = {**status, "state": "abandoned",
                  "reason": "siloflow stopped without recording it (killed?); the engine was stopped with it"}
    return status


def read_status(folder: Path) -> dict:
    """The folder's status.json, checked: a JSON object with a known ``state``."""
    path = Path(folder) / STATUS_NAME
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ReadError(f"no readable {STATUS_NAME} in {folder}: {getattr(exc, 'strerror', None) or exc}") from None
    if not isinstance(data, dict) or data.get("state") not in STATES:
        raise ReadError(f"{path} is not a siloflow status (expected an object with a state of "
                        f"{', '.join(STATES)}); was the folder made by siloflow?")
    return data


def check_case(case: Case, engine: "Engine") -> None:
    """Raise ``CaseError`` listing what ``engine`` cannot do of ``case`` (``Engine.check``)."""
    from ..errors import CaseError
    problems = engine.check(case)
    if problems:
        raise CaseError(problems, f"case (engine {engine.name})")


class Engine(ABC):
    """A DEM engine siloflow can drive."""

    name: str = "abstract"

    def check(self, case: Case) -> list[tuple[str, str]]:
        """What this engine cannot do of ``case``: ``(field path, message)`` pairs, empty when it
        can run it. ``siloflow validate``, ``render`` and ``run`` refuse a case with problems."""
        return []

    @abstractmethod
    def prepare(self, case: Case, folder: Path, force: bool = False) -> Path:
        """Write the deck folder for ``case``; return its path. Needs no engine installed."""

    @abstractmethod
    def execute(self, folder: Path, progress: Optional[ProgressCallback] = None) -> RunRecord:
        """Run the engine in a prepared folder; raise ``EngineRunError`` if it fails."""

    @abstractmethod
    def resume(self, folder: Path, progress: Optional[ProgressCallback] = None) -> RunRecord:
        """Finish an interrupted run in ``folder`` from its last restart point; return its record."""

    @abstractmethod
    def collect(self, folder: Path) -> RunRecord:
        """Read a finished run's folder and check it completed; raise ``EngineRunError`` if not."""

    @abstractmethod
    def version(self) -> str:
        """The engine's version string; raise ``SetupError`` if it is not installed."""

    def run(self, case: Case, folder: Path, force: bool = False,
            progress: Optional[ProgressCallback] = None) -> RunRecord:
        """prepare, execute, collect."""
        folder = self.prepare(case, folder, force=force)
        self.execute(folder, progress=progress)
        return self.collect(folder)
