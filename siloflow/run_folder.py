"""What siloflow writes into a run folder, and when it may replace one.

A deck folder carries a manifest (``siloflow_manifest.json``) listing every file ``render``
wrote. The engine and post-processing add files whose names siloflow chose (the deck names
the engine's outputs; ``results/`` holds the tables, figures and report). ``--force`` replaces
a folder only when every file in it is one of those: a folder with anything else in it (a
user's notes, a case file being read, a foreign tree) is refused, never emptied.
"""
from __future__ import annotations

import fnmatch
import os
from pathlib import Path

from .errors import SetupError

MANIFEST_NAME = "siloflow_manifest.json"

#: files siloflow (or the engine, running siloflow's deck) writes at the top of a run folder
TOP_LEVEL_FILES = frozenset({
    MANIFEST_NAME, "in.liggghts", "in.resume.liggghts", "case.yaml", "derived.json", "status.json",
    "run_record.json", "log.liggghts", "log.resume.liggghts", "screen.txt", "screen.resume.txt",
    "log.lammps",          # LIGGGHTS writes it before it reads '-log' (ENGINE_NOTES)
})
#: the engine's outputs as the deck names them (template in.liggghts.j2), relative to the folder
OUTPUT_PATTERNS = ("output/flow.txt", "output/wall_forces.txt", "output/*.txt.before_resume",
                   "output/dumps/dump.*.txt", "output/dumps/contacts.*.txt",
                   "output/dumps/wall_contacts.*.txt", "output/vtk/particles_*.vtk",
                   "output/restart/*.restart", "meshes/*.stl")
#: what post-processing writes under results/ (tables, figures, report, fields, summaries)
RESULT_SUFFIXES = (".csv", ".parquet", ".png", ".json", ".md", ".nc", ".txt")
#: folders siloflow makes in a run folder
FOLDERS = frozenset({"meshes", "output", "output/dumps", "output/vtk", "output/restart", "results"})


def is_siloflow_file(rel: str) -> bool:
    """Whether the file at ``rel`` (a POSIX path relative to the run folder) is one siloflow writes."""
    name = rel.rsplit("/", 1)[-1]
    if name.startswith(".") and name.endswith(".tmp"):       # an atomic write cut short
        return True
    if "/" not in rel:
        return rel in TOP_LEVEL_FILES
    if rel.startswith("results/"):
        return rel.endswith(RESULT_SUFFIXES)
    return any(fnmatch.fnmatchcase(rel, p) for p in OUTPUT_PATTERNS)


def is_siloflow_folder(folder: Path) -> bool:
    """Whether ``folder`` carries siloflow's marker (a manifest; before manifests: derived.json
    beside in.liggghts)."""
    folder = Path(folder)
    return (folder / MANIFEST_NAME).is_file() or (
        (folder / "derived.json").is_file() and (folder / "in.liggghts").is_file())


def foreign_entries(folder: Path) -> list[str]:
    """Paths (relative) in ``folder`` that siloflow did not write: files, symlinks, special files."""
    folder = Path(folder)
    foreign = []
    for root, dirs, files in os.walk(folder, followlinks=False):
        base = Path(root).relative_to(folder)
        for d in list(dirs):
            rel = (base / d).as_posix()
            if (Path(root) / d).is_symlink() or not (rel in FOLDERS or rel.startswith("results/")):
                foreign.append(rel + "/")
                dirs.remove(d)                  # nothing below a foreign folder is looked at
        for f in files:
            rel = (base / f).as_posix()
            p = Path(root) / f
            if p.is_symlink() or not p.is_file() or not is_siloflow_file(rel):
                foreign.append(rel)
    return sorted(foreign)


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def check_replaceable(folder, keep=()) -> None:
    """Refuse to replace ``folder`` unless siloflow made it and everything in it is siloflow's.

    ``keep`` are paths siloflow is reading (the case file, its insert meshes): a folder that
    holds one of them is never replaced. Nor is the current directory or one of its ancestors,
    nor a mount point. Raises ``SetupError`` saying why and what to do.
    """
    folder = Path(folder).absolute()
    real = folder.resolve()
    cwd = Path.cwd().resolve()
    if _inside(cwd, real):
        raise SetupError(f"--force would replace {folder}, which is the current directory or holds it: "
                         "siloflow never replaces it; choose a new output folder")
    if os.path.ismount(real):
        raise SetupError(f"{folder} is a mount point and cannot be replaced: write into a new folder inside it")
    for path in keep:
        if _inside(Path(path).resolve(), real):
            raise SetupError(f"--force would replace {folder}, which holds {path}, a file this command reads: "
                             "choose another output folder")
    if not is_siloflow_folder(real):
        raise SetupError(f"{folder} is not a folder siloflow made (no {MANIFEST_NAME}): --force only replaces "
                         "siloflow's own run folders; choose another output folder or empty it yourself")
    foreign = foreign_entries(real)
    if foreign:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise SetupError(f"{folder} holds files siloflow did not write ({shown}): --force never deletes them; "
                         "move them out, or choose another output folder")


def remove_siloflow_files(folder: Path) -> list[str]:
    """Delete the siloflow files of a folder already moved aside, then its empty folders.
    Returns what is left (files that appeared after the check); the folder is kept if any."""
    folder = Path(folder)
    for root, dirs, files in os.walk(folder, topdown=False):
        base = Path(root).relative_to(folder)
        for f in files:
            p = Path(root) / f
            if not p.is_symlink() and p.is_file() and is_siloflow_file((base / f).as_posix()):
                p.unlink()
        try:
            os.rmdir(root)
        except OSError:
            pass
    return foreign_entries(folder) if folder.exists() else []
