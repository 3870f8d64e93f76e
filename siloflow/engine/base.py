"""One engine interface, several implementations (as ASE's calculators).

``prepare`` writes the deck folder (needs no engine installed), ``execute`` runs the
engine in it (blocks, streams progress, keeps the log), ``collect`` reads what the run
left and checks it finished properly. ``run`` composes the three.
"""
from __future__ import annotations

import os
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

from ..case import Case
from ..run_folder import RunRecord, write_status

#: progress(stage, current_step, total_steps); total is the current upper bound
ProgressCallback = Callable[[str, int, int], None]


@dataclass(frozen=True)
class LaunchProfile:
    """How an engine is launched on this machine (never set by a case file): the binary (None:
    the engine's ``$SILOFLOW_<ENGINE>`` variable, else its usual name on PATH), the MPI launcher
    for runs on more than one rank, and environment variables added to the engine's."""

    executable: Optional[str] = None
    mpirun: str = "mpirun"
    env: dict = field(default_factory=dict)

    def environment(self) -> Optional[dict]:
        """The engine's environment (None: siloflow's own)."""
        return {**os.environ, **self.env} if self.env else None


def check_case(case: Case, engine: "Engine", plan=None) -> None:
    """Raise ``CaseError`` listing what ``engine`` cannot do of ``case`` (``Engine.check``)."""
    from ..errors import CaseError
    problems = engine.check(case, plan)
    if problems:
        raise CaseError(problems, f"case (engine {engine.name})")


class Engine(ABC):
    """A DEM engine siloflow can drive."""

    name: str = "abstract"
    default_executable: str = ""
    executable_variable: str = ""

    def __init__(self, executable: Optional[str] = None, mpirun: str = "mpirun", env: Optional[dict] = None,
                 profile: Optional[LaunchProfile] = None):
        profile = profile or LaunchProfile(executable, mpirun, dict(env or {}))
        if profile.executable is None:
            profile = LaunchProfile(os.environ.get(self.executable_variable) or self.default_executable,
                                    profile.mpirun, profile.env)
        self.profile = profile

    def check(self, case: Case, plan=None) -> list[tuple[str, str]]:
        """What this engine cannot do of ``case`` (and of its ``plan``, when given): ``(field path,
        message)`` pairs, empty when it can run it. ``siloflow validate``, ``render`` and ``run``
        refuse a case with problems before anything is written."""
        return []

    def plan_warnings(self, case: Case, plan) -> list[str]:
        """What this engine will do differently from ``plan`` without refusing it (each names its
        field and consequence); recorded with the plan's own warnings in the run folder."""
        return []

    def preflight(self, ranks: int) -> None:
        """Refuse (``SetupError``) to start when the engine, or the MPI launcher ``ranks`` > 1 needs,
        is not installed here: checked before anything is written."""

    @abstractmethod
    def write_deck(self, plan, case: Case, folder: Path) -> None:
        """Write this engine's deck of ``plan`` (and the meshes and dump layout it needs) into
        the run folder being rendered."""

    @abstractmethod
    def check_deck_files(self, folder: Path, resume: bool = False) -> None:
        """Refuse (``SetupError``) a folder whose deck holds a command siloflow does not write."""

    def prepare(self, case: Case, folder: Path, force: bool = False, keep=(), plan=None) -> Path:
        """Check ``case`` against this engine and write its run folder; return its path. Needs
        no engine installed. ``plan``: the case's run plan, if already derived."""
        from ..deck import render
        from ..derived import derive
        plan = plan if plan is not None else derive(case)
        check_case(case, self, plan)
        extra = [w for w in self.plan_warnings(case, plan) if w not in plan.warnings]
        if extra:
            plan = plan.model_copy(update={"warnings": [*plan.warnings, *extra]})
        folder = render(case, folder, force=force, keep=keep, plan=plan, engine=self)
        write_status(folder, "rendered")
        return folder

    @abstractmethod
    def execute(self, folder: Path, progress: Optional[ProgressCallback] = None) -> RunRecord:
        """Run the engine in a prepared folder; raise ``EngineRunError`` if it fails."""

    @abstractmethod
    def resume(self, folder: Path, progress: Optional[ProgressCallback] = None) -> RunRecord:
        """Finish an interrupted run in ``folder`` from its last restart point; return its record."""

    def collect(self, folder: Path) -> RunRecord:
        """Read a finished run's folder and check it completed (:meth:`_collect`); raise
        ``EngineRunError`` if not. Any failure to read or write the folder is recorded as ``failed``
        with its reason."""
        from ..atomic_files import os_error
        from ..errors import SiloflowError
        from .processes import record_failure
        folder = Path(folder)
        try:
            return self._collect(folder)
        except OSError as exc:
            error = os_error(exc, f"the run record in {folder}")
            record_failure(folder, str(error))
            raise error from None
        except SiloflowError as exc:
            record_failure(folder, str(exc).splitlines()[0])
            raise

    @abstractmethod
    def _collect(self, folder: Path) -> RunRecord:
        """The engine's checks of a finished run and its engine-neutral tables (see :meth:`collect`)."""

    @abstractmethod
    def version(self) -> str:
        """The engine's version string; raise ``SetupError`` if it is not installed."""

    def run(self, case: Case, folder: Path, force: bool = False,
            progress: Optional[ProgressCallback] = None) -> RunRecord:
        """prepare, execute, collect."""
        folder = self.prepare(case, folder, force=force)
        self.execute(folder, progress=progress)
        return self.collect(folder)
