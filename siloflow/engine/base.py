"""One engine interface, several implementations (as ASE's calculators).

``prepare`` writes the deck folder (needs no engine installed), ``execute`` runs the
engine in it (blocks, streams progress, keeps the log), ``collect`` reads what the run
left and checks it finished properly. ``run`` composes the three.
"""
from __future__ import annotations

import json
import os
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


def write_status(folder: Path, state: str, **extra) -> None:
    """Record the run state (``rendered``, ``running``, ``complete``, ``failed``, ``interrupted``)."""
    write_json(Path(folder) / STATUS_NAME, {"state": state, "time": time.time(), **extra})


def _alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except (ProcessLookupError, ValueError, TypeError):
        return False
    except PermissionError:
        return True
    return True


def run_state(folder: Path) -> dict:
    """The run's status, with a ``running`` run whose siloflow process is gone reported as
    ``abandoned`` (siloflow was killed without a chance to record it)."""
    status = read_status(folder)
    if status.get("state") == "running" and not _alive(status.get("siloflow_pid")):
        status = {**status, "state": "abandoned",
                  "reason": "siloflow stopped without recording it (killed?); the engine was stopped with it"}
    return status


def read_status(folder: Path) -> dict:
    path = Path(folder) / STATUS_NAME
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ReadError(f"no readable {STATUS_NAME} in {folder}: {exc}") from None


class Engine(ABC):
    """A DEM engine siloflow can drive."""

    name: str = "abstract"

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
