"""The engines siloflow knows, by name: ``"module:class"`` of each, imported only when a case asks
for it (``siloflow.engine.get_engine``), and the files each one writes in a run folder. The case
schema takes its ``engine.name`` values from here, so a new engine is its subpackage under
``siloflow/engine/`` plus its line in :data:`ENGINES` and in :data:`ENGINE_FILES`."""
from __future__ import annotations

from dataclasses import dataclass, field

ENGINES = {"liggghts": "siloflow.engine.liggghts.engine:LiggghtsEngine",
           "lammps": "siloflow.engine.lammps.engine:LammpsEngine"}


@dataclass(frozen=True)
class EngineFiles:
    """The files an engine writes in a run folder under fixed names, paths relative to the folder.

    ``names``: its deck, logs and screens by role (``deck``, ``resume_deck``, ``log``,
    ``resume_log``, ``screen``, ``resume_screen``; the roles it has); ``tables``: its own tables,
    from which the engine-neutral ones are made; ``outputs``: a regular expression of its further
    outputs (state, restarts, VTK). The run folder counts these as siloflow's (``--force`` may
    replace them) and as evidence that the engine ran; the engine reads its names from here. Any
    other file a run leaves is recorded in the folder's manifest as the run ends
    (``siloflow.run_folder.record_engine_outputs``): ``outputs`` is also the fallback for a folder
    run by an older siloflow, which recorded none."""

    names: dict[str, str]
    tables: tuple[str, ...] = ()
    outputs: str = ""
    evidence: tuple[str, ...] = field(default=())     # further files only a run leaves (e.g. a state)

    @property
    def ran(self) -> tuple[str, ...]:
        """The files only an engine run leaves: its logs, screens, tables and ``evidence``."""
        return tuple(v for k, v in self.names.items() if "deck" not in k) + self.tables + self.evidence


#: each engine's files (see :class:`EngineFiles`)
ENGINE_FILES = {
    "liggghts": EngineFiles(
        names={"deck": "in.liggghts", "resume_deck": "in.resume.liggghts", "log": "log.liggghts",
               "resume_log": "log.resume.liggghts", "screen": "screen.txt", "resume_screen": "screen.resume.txt"},
        tables=("output/flow.txt", "output/wall_forces.txt"),        # fix ave/time
        outputs=(r"output/(flow|wall_forces)\.txt\.before_resume|output/vtk/particles_(boundingBox_)?\d+\.vtk"
                 r"|restart_forced_liggghts_\d+\.data")),      # LIGGGHTS' own on SIGTERM (left by older siloflow)
    "lammps": EngineFiles(
        names={"log": "log.lammps", "resume_log": "log.lammps.resume", "screen": "screen.lammps.txt"},
        outputs=r"output/lammps_state\.json|output/insertion\.data",
        evidence=("output/lammps_state.json",)),
}
