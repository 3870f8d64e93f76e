"""What siloflow writes into a run folder, and when it may replace one.

A deck folder carries a manifest (``siloflow_manifest.json``) with the SHA-256 of every file
``render`` wrote; post-processing adds what it writes under ``results/`` (``record_products``).
The engine's outputs and siloflow's own records have fixed names (the deck names the former).
``--force`` replaces a folder only when every file in it is one of those and unchanged since
siloflow wrote it: a folder with anything else in it (a user's notes, an edited case, a
symlink, a case file being read) is refused, never emptied.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import stat
from pathlib import Path

from .errors import SetupError

MANIFEST_NAME = "siloflow_manifest.json"

#: files siloflow (or the engine, running siloflow's deck) writes at the top of a run folder
#: besides the manifest's: status and records, the engine's logs and screens, the resumed deck
TOP_LEVEL_FILES = frozenset({
    MANIFEST_NAME, "status.json", "run_record.json", "log.liggghts", "log.resume.liggghts",
    "screen.txt", "screen.resume.txt", "in.resume.liggghts",
})
#: the engine's outputs as the deck names them (template in.liggghts.j2), relative to the folder
ENGINE_OUTPUTS = re.compile(r"output/(flow|wall_forces)\.txt(\.before_resume)?"
                            r"|output/dumps/(dump|contacts|wall_contacts)\.\d+\.txt"
                            r"|output/vtk/particles_\d+\.vtk|output/restart/settled\.restart")
#: an atomic write cut short: ``.{name}.{8 random characters}.tmp`` (tempfile.mkstemp)
_TEMP = re.compile(r"(?P<dir>(?:.*/)?)\.(?P<name>[^/]+)\.[A-Za-z0-9_]{8}\.tmp")
#: folders siloflow makes in a run folder (results/ may hold sub-folders, e.g. results/cg)
FOLDERS = frozenset({"meshes", "output", "output/dumps", "output/vtk", "output/restart", "results"})


def sha256(path: Path) -> str:
    """SHA-256 of a file's bytes, hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_manifest(folder: Path) -> dict:
    """The folder's manifest ({} if it has none or it is not readable JSON of the right shape)."""
    try:
        data = json.loads((Path(folder) / MANIFEST_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict) or not isinstance(data.get("files", {}), dict) or not isinstance(
            data.get("products", {}), dict):
        return {}
    return data


def record_products(folder, out_dir, since: float) -> None:
    """Add to the manifest of run folder ``folder`` the files under ``out_dir`` (inside it)
    written since ``since`` (a ``time.time()``), with their SHA-256: post-processing's tables,
    figures and reports, which ``--force`` may then replace. Nothing happens for a folder without
    a manifest or an ``out_dir`` outside it."""
    from .atomic_files import write_json
    folder, out_dir = Path(folder).resolve(), Path(out_dir).resolve()
    manifest = read_manifest(folder)
    if not manifest or folder not in out_dir.parents and out_dir != folder:
        return
    products = dict(manifest.get("products", {}))
    for root, _, files in os.walk(out_dir):
        for f in files:
            p = Path(root) / f
            info = p.lstat()
            if stat.S_ISREG(info.st_mode) and info.st_mtime >= since - 1e-3 and not _TEMP.fullmatch(f):
                products[p.relative_to(folder).as_posix()] = sha256(p)
    write_json(folder / MANIFEST_NAME, {**manifest, "products": products})


def _fixed_name(rel: str) -> bool:
    """Whether ``rel`` is a file siloflow writes under a fixed name (records, engine outputs)."""
    return rel in TOP_LEVEL_FILES or bool(ENGINE_OUTPUTS.fullmatch(rel))


def foreign_entries(folder: Path) -> list[str]:
    """What in ``folder`` siloflow did not write, or changed since it wrote it: files not in the
    manifest and without a fixed siloflow name, listed files whose bytes changed ('(edited)'),
    symlinks and special files, folders siloflow does not make. Relative paths."""
    folder = Path(folder)
    manifest = read_manifest(folder)
    known = {**manifest.get("files", {}), **manifest.get("products", {})}
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
            if p.is_symlink() or not p.is_file():
                foreign.append(rel + " (not a regular file)")
            elif rel in known:
                if sha256(p) != known[rel]:
                    foreign.append(rel + " (edited since siloflow wrote it)")
            elif not _fixed_name(rel):
                temp = _TEMP.fullmatch(rel)
                if not (temp and (temp["dir"] + temp["name"] in known or _fixed_name(temp["dir"] + temp["name"]))):
                    foreign.append(rel)
    return sorted(foreign)


def check_plain_tree(folder: Path) -> None:
    """Refuse a run folder holding a symlink or a special file (FIFO, device) anywhere: the engine
    and siloflow write into it by name, and a link would send their writes outside the folder.
    Raises ``SetupError``."""
    folder = Path(folder)
    if folder.is_symlink():
        raise SetupError(f"{folder} is a symbolic link: give the folder it points to")
    for root, dirs, files in os.walk(folder, followlinks=False):
        for name in dirs + files:
            p = Path(root) / name
            mode = p.lstat().st_mode
            if stat.S_ISLNK(mode) or not (stat.S_ISDIR(mode) or stat.S_ISREG(mode)):
                raise SetupError(f"{p} is a symbolic link or a special file: siloflow writes into this folder "
                                 "and will not follow it out; remove it, or render the case anew")


def is_siloflow_folder(folder: Path) -> bool:
    """Whether ``folder`` carries siloflow's marker (a manifest; before manifests: derived.json
    beside in.liggghts)."""
    folder = Path(folder)
    return (folder / MANIFEST_NAME).is_file() or (
        (folder / "derived.json").is_file() and (folder / "in.liggghts").is_file())


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def check_not_in_use(folder, keep=()) -> None:
    """Refuse an existing ``folder`` (empty or not) that is the current directory or one of its
    ancestors, a mount point, a symbolic link, or holds a path of ``keep``. ``SetupError``."""
    folder = Path(folder).absolute()
    if folder.is_symlink():
        raise SetupError(f"{folder} is a symbolic link: siloflow does not replace it; give the folder it points to")
    real = folder.resolve()
    if _inside(Path.cwd().resolve(), real):
        raise SetupError(f"{folder} is the current directory or holds it: siloflow never replaces it; "
                         "choose a new output folder")
    if os.path.ismount(real):
        raise SetupError(f"{folder} is a mount point and cannot be replaced: write into a new folder inside it")
    for path in keep:
        if _inside(Path(path).resolve(), real):
            raise SetupError(f"{folder} holds {path}, a file this command reads: choose another output folder")


def check_replaceable(folder) -> None:
    """Refuse to replace ``folder`` (already past :func:`check_not_in_use`) unless siloflow made
    it, no run is live in it, and everything in it is siloflow's and unchanged (see
    :func:`foreign_entries`). Raises ``SetupError``."""
    from .engine.base import run_state
    from .errors import ReadError
    folder = Path(folder).absolute()
    real = folder.resolve()
    if not (real / MANIFEST_NAME).is_file():
        raise SetupError(f"{folder} is not a folder siloflow made (no {MANIFEST_NAME}): --force only replaces "
                         "siloflow's own run folders; choose another output folder or empty it yourself")
    try:
        live = (real / "status.json").exists() and run_state(real)["state"] == "running"
    except ReadError:                   # an unreadable status is not a live run
        live = False
    if live:
        raise SetupError(f"{folder} holds a run that is still running: stop it first (Ctrl-C in its terminal)")
    foreign = foreign_entries(real)
    if foreign:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise SetupError(f"{folder} holds files siloflow did not write ({shown}): --force never deletes them; "
                         "move them out, or choose another output folder")


def remove_siloflow_files(folder: Path) -> list[str]:
    """Delete a folder (already moved aside) checked by :func:`check_replaceable`: its files
    siloflow wrote, then its empty folders. Returns what is left (anything that appeared after
    the check); the folder is kept then."""
    folder = Path(folder)
    foreign = {entry.split(" (")[0].rstrip("/") for entry in foreign_entries(folder)}
    for root, dirs, files in os.walk(folder, topdown=False):
        base = Path(root).relative_to(folder)
        for f in files:
            p = Path(root) / f
            rel = (base / f).as_posix()
            if not p.is_symlink() and p.is_file() and not any(rel == x or rel.startswith(x + "/") for x in foreign):
                p.unlink()
        try:
            os.rmdir(root)
        except OSError:
            pass
    return foreign_entries(folder) if folder.exists() else []
