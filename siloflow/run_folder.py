"""The run folder: one owner of its layout (:class:`RunFolder`), and when siloflow may replace one.

Every file name of a run folder is defined here, with the readers and writers of its plan,
status, record and the two engine-neutral tables every engine writes:

- ``flow`` (``output/flow.csv``, :data:`FLOW_SCHEMA`): per sample, time, atoms, mass in the box
  and in the silo, mass and count discharged through the outlet, kinetic and potential energy;
- ``wall_forces`` (``output/wall_forces.csv``, :data:`WALL_FORCE_SCHEMA`): per sample and wall,
  the force the grains exert on it (N), averaged over the plan's ``outputs.sample_steps``.

A deck folder carries a manifest (``siloflow_manifest.json``) with the SHA-256 of every file
``render`` wrote; post-processing adds what it writes under ``results/`` (``record_products``),
and every engine run the files it left that have no fixed name (``record_engine_outputs``: new
ones, and ones siloflow recorded before that the run rewrote). siloflow's own records and the
engine's usual outputs have fixed names (the deck names the latter; the names are also the fallback
of a folder run by an older siloflow, whose manifest lists no engine output). ``--force`` replaces a
folder only when every file in it is one of those and unchanged since siloflow wrote it: a folder
with anything else in it (a user's notes, an edited case, a symlink, a case file being read) is
refused, never emptied.

One siloflow command at a time writes a run folder: ``render``, ``run`` and ``run --resume`` hold
its lock (:func:`folder_lock`, ``flock`` on ``.<name>.siloflow-lock`` beside it) from before the
folder check until they are done; a second command is refused.
"""
from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import re
import shutil
import socket
import stat
import tempfile
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Optional

from .atomic_files import os_error, read_json, write_json, write_text
from .engines import ENGINE_FILES
from .errors import ReadError, SetupError

# ------------------------------------------------------------------ file names
MANIFEST_NAME = "siloflow_manifest.json"
CASE_NAME = "case.yaml"
PLAN_NAME = "plan.json"
STATUS_NAME = "status.json"
RECORD_NAME = "run_record.json"
#: what an engine's dumps hold: atom type -> species, contact dump columns (:class:`DumpLayout`)
DUMP_LAYOUT_NAME = "dump_layout.json"
FLOW_TABLE = "output/flow.csv"
WALL_FORCES_TABLE = "output/wall_forces.csv"
DUMPS = "output/dumps"
PARTICLE_DUMPS = "dump.*.txt"
CONTACT_DUMPS = "contacts.*.txt"
WALL_CONTACT_DUMPS = "wall_contacts.*.txt"
#: the touching grains of a primitive wall (LIGGGHTS: side walls), ``primitive_<fix>.<step>.txt``
PRIMITIVE_CONTACT_DUMPS = "primitive_*.*.txt"
#: the settled bed, written once settling (and shrinking) ended; --resume starts there
RESTART_FILE = "output/restart/settled.restart"
RESULTS = "results"
SUMMARY_NAME = "summary.json"
CG_SUMMARY_NAME = "cg_summary.json"
#: what a run of siloflow's before the run plan holds instead of plan.json (such folders are re-rendered)
OLD_PLAN_NAME = "derived.json"
#: what ``siloflow post`` writes under results/ (besides the summary), read back by ``siloflow.runs``
RESULT_TABLES = {"flow": "discharge.csv", "wall_pressure": "wall_pressure.csv",
                 "wall_pressure_sectors": "wall_pressure_sectors.csv", "bands": "bands.csv",
                 "sectors": "sectors.csv"}
#: files siloflow writes at the top of a run folder besides the manifest's (status and records),
#: and the engines' decks, logs and screens (each engine's, siloflow.engines.ENGINE_FILES)
TOP_LEVEL_FILES = frozenset({MANIFEST_NAME, STATUS_NAME, RECORD_NAME}
                            | {name for files in ENGINE_FILES.values() for name in files.names.values()})
#: the engine-neutral outputs the decks name, relative to the folder, then each engine's own
ENGINE_OUTPUTS = re.compile("|".join(
    [r"output/(flow|wall_forces)\.csv|output/dumps/(dump|contacts|wall_contacts|primitive_[A-Za-z0-9_]+)\.\d+\.txt"
     r"|output/restart/settled\.restart"]
    + [re.escape(t) for files in ENGINE_FILES.values() for t in files.tables]
    + [files.outputs for files in ENGINE_FILES.values() if files.outputs]))
#: an atomic write cut short: ``.{name}.{8 random characters}.tmp`` (tempfile.mkstemp)
_TEMP = re.compile(r"(?P<dir>(?:.*/)?)\.(?P<name>[^/]+)\.[A-Za-z0-9_]{8}\.tmp")
#: folders siloflow makes in a run folder (results/ may hold sub-folders, e.g. results/cg)
FOLDERS = frozenset({"meshes", "fill", "output", "output/dumps", "output/vtk", "output/restart", "results"})


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
        data = read_json(Path(folder) / MANIFEST_NAME, "a run folder's manifest")
    except ReadError:
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


def snapshot(folder) -> dict:
    """What ``folder`` holds before an engine run, for :func:`record_engine_outputs`: each regular
    file's relative path -> (size, mtime ns, inode), and each folder's relative path -> None."""
    folder = Path(folder)
    seen: dict = {}
    for root, dirs, files in os.walk(folder, followlinks=False):
        base = Path(root).relative_to(folder)
        seen.update({(base / d).as_posix(): None for d in dirs})
        for f in files:
            try:
                info = (Path(root) / f).lstat()
            except OSError:
                continue
            if stat.S_ISREG(info.st_mode):
                seen[(base / f).as_posix()] = (info.st_size, info.st_mtime_ns, info.st_ino)
    return seen


def record_engine_outputs(folder, before: dict) -> None:
    """Add to the manifest of run folder ``folder`` (as ``products``, with their SHA-256) the files
    an engine run left that have no fixed name: those that were not in ``before`` (its
    :func:`snapshot` from before the run) and those siloflow recorded before that the run rewrote.
    A file that was there before and is not siloflow's stays the user's, and nothing is looked at
    below a folder that was there and is not siloflow's. Nothing happens without a manifest."""
    folder = Path(folder)
    manifest = read_manifest(folder)
    if not manifest:
        return
    known = {**manifest.get("files", {}), **manifest.get("products", {})}
    known_dirs = _folders_of(known)
    products = dict(manifest.get("products", {}))
    for root, dirs, files in os.walk(folder, followlinks=False):
        base = Path(root).relative_to(folder)
        dirs[:] = [d for d in dirs if (base / d).as_posix() not in before or _siloflow_folder((base / d).as_posix(),
                                                                                              known_dirs)]
        for f in files:
            rel, p = (base / f).as_posix(), Path(root) / f
            if _fixed_name(rel) or _TEMP.fullmatch(f):
                continue
            try:
                info = p.lstat()
                if stat.S_ISREG(info.st_mode) and (rel not in before or (
                        rel in known and before[rel] != (info.st_size, info.st_mtime_ns, info.st_ino))):
                    products[rel] = sha256(p)
            except OSError:                # gone meanwhile: nothing to record
                continue
    if products != manifest.get("products", {}):
        write_json(folder / MANIFEST_NAME, {**manifest, "products": products})


def _folders_of(paths) -> set:
    """Every folder above the relative paths ``paths``."""
    return {parent.as_posix() for rel in paths for parent in Path(rel).parents if parent != Path(".")}


def _siloflow_folder(rel: str, known_dirs: set) -> bool:
    """Whether folder ``rel`` is one siloflow makes, or holds a file the manifest lists."""
    return rel in FOLDERS or rel.startswith("results/") or rel in known_dirs


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
    known_dirs = _folders_of(known)
    foreign = []
    for root, dirs, files in os.walk(folder, followlinks=False):
        base = Path(root).relative_to(folder)
        for d in list(dirs):
            rel = (base / d).as_posix()
            if (Path(root) / d).is_symlink() or not _siloflow_folder(rel, known_dirs):
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
    """Whether ``folder`` carries siloflow's marker (a manifest)."""
    return (Path(folder) / MANIFEST_NAME).is_file()


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
    folder = Path(folder).absolute()
    real = folder.resolve()
    if not (real / MANIFEST_NAME).is_file():
        raise SetupError(f"{folder} is not a folder siloflow made (no {MANIFEST_NAME}): --force only replaces "
                         "siloflow's own run folders; choose another output folder or empty it yourself")
    try:
        live = (real / STATUS_NAME).exists() and run_state(real)["state"] == "running"
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


def check_free_folder(folder, force: bool, keep=()) -> None:
    """Refuse an existing ``folder`` that is not an empty folder, unless ``force`` and siloflow
    may replace it (:func:`check_replaceable`; ``keep``: files being read)."""
    folder = Path(folder)
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise SetupError(f"{folder} exists and is not a folder (or is a symbolic link): choose another output folder")
    _check_parents(folder)
    if not folder.is_dir():
        return
    check_not_in_use(folder, keep)            # the current directory, a mount point, a file being read
    if any(folder.iterdir()):
        if not force:
            raise SetupError(f"{folder} already exists and is not empty: choose another folder, "
                             "or pass --force to replace it (only a folder siloflow made, holding only its files)")
        check_replaceable(folder)


def _check_parents(folder: Path) -> None:
    """Refuse (``SetupError``) a ``folder`` that cannot be made because a file is in its way."""
    for parent in Path(folder).absolute().parents:
        if parent.exists() and not parent.is_dir():
            raise SetupError(f"cannot make {folder}: {parent} is a file, not a folder")


# ------------------------------------------------------------------ one command per folder
#: the lock file beside a run folder ``<name>``: ``.<name>.siloflow-lock``
LOCK_SUFFIX = ".siloflow-lock"
#: the folder locks this process holds: (pid, lock path) -> [file descriptor, depth]
_HELD: dict = {}


def lock_path(folder) -> Path:
    """The lock file of run folder ``folder``: beside it (its parent resolved), so that it is the
    same file whichever path names the folder, and survives the folder being replaced."""
    folder = Path(os.path.abspath(folder))
    return folder.parent.resolve() / f".{folder.name}{LOCK_SUFFIX}"


@contextmanager
def folder_lock(folder):
    """Hold siloflow's lock on the run folder ``folder`` (made or not yet) for the block: a second
    siloflow command (another process) asking for it is refused at once with a ``SetupError``
    naming the folder. Taken again in the same process it nests. The lock (``flock`` on
    :func:`lock_path`, its parent folders made if missing) is released and its file removed at the
    end, with the parent folders it made when no folder was made in them; the kernel releases it
    when the process dies."""
    path = lock_path(folder)
    key = (os.getpid(), str(path))
    if key in _HELD:
        _HELD[key][1] += 1
        try:
            yield
        finally:
            _HELD[key][1] -= 1
        return
    made = [p for p in path.parents if not p.exists()]       # deepest first
    fd = _take_lock(Path(folder), path)
    _HELD[key] = [fd, 1]
    try:
        yield
    finally:
        del _HELD[key]
        try:
            if _same_file(path, fd):
                os.unlink(path)           # while still held: a waiting opener sees the path is gone and retries
        except OSError:
            pass
        os.close(fd)
        for parent in made:               # a refused command leaves no empty folders behind
            try:
                os.rmdir(parent)
            except OSError:
                break


def _same_file(path: Path, fd: int) -> bool:
    try:
        info, mine = os.stat(path, follow_symlinks=False), os.fstat(fd)
    except OSError:
        return False
    return (info.st_dev, info.st_ino) == (mine.st_dev, mine.st_ino)


def _take_lock(folder: Path, path: Path) -> int:
    """The locked file descriptor of ``path``, the lock of ``folder``; ``SetupError`` when another
    process holds it or it cannot be made."""
    _check_parents(folder)
    for _ in range(50):
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
        except FileNotFoundError:              # a parent another command made was removed meanwhile
            continue
        except OSError as exc:
            raise os_error(exc, f"{folder}'s lock file") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                holder = os.read(fd, 64).decode("ascii", "replace").split()
            except OSError:
                holder = []
            os.close(fd)
            by = f" (process {holder[0]}{f' on {holder[1]}' if len(holder) > 1 else ''})" if holder else ""
            raise SetupError(f"{folder} is in use by another siloflow command{by}: a render, run or --resume "
                             "writes it now; wait until it ends, or choose another output folder") from None
        except OSError as exc:
            os.close(fd)
            raise os_error(exc, f"{folder}'s lock file {path}", "lock") from None
        if _same_file(path, fd):               # else its holder removed it meanwhile: take the new one
            try:
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()} {socket.gethostname()}\n".encode())
            except OSError:
                pass                           # who holds it is only told, not needed
            return fd
        os.close(fd)
    raise SetupError(f"cannot lock {folder}: its lock file {path} keeps being replaced; try again")


@contextmanager
def new_folder(folder, force: bool = False, keep=()):
    """Build a folder under a temporary name and move it into place only if the block succeeds.

    Yields the temporary path. An existing non-empty ``folder`` is refused unless ``force``
    and it is a siloflow folder holding only siloflow's files (``keep``: paths being read,
    never inside a replaced folder); it is replaced only after the new one is complete, and
    then only siloflow's files are deleted. An OSError (disk full, read-only, ...) becomes a
    ``SetupError`` and leaves no partial folder. The folder's lock (:func:`folder_lock`) is held
    throughout: another siloflow command writing it is refused.
    """
    folder = Path(folder).absolute()
    with folder_lock(folder):                 # held from the check until the folder is in place
        with _new_folder(folder, force, keep) as tmp:
            yield tmp


@contextmanager
def _new_folder(folder: Path, force: bool, keep):
    check_free_folder(folder, force, keep)
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=folder.parent, prefix=f".{folder.name}.", suffix=".partial"))
    except OSError as exc:
        raise os_error(exc, str(folder)) from None
    try:
        yield tmp
        old = None
        if folder.exists():
            old = folder.with_name(f".{folder.name}.replaced-{os.getpid()}")
            os.replace(folder, old)
        try:
            os.replace(tmp, folder)
        except OSError:
            if old is not None:
                os.replace(old, folder)          # put the old folder back as it was
            raise
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise os_error(exc, str(folder)) from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if old is not None and remove_siloflow_files(old):
        # files that appeared after the check are never deleted: the old folder stays, visibly
        os.replace(old, folder.with_name(f"{folder.name}.kept-{os.getpid()}"))


def case_differences(mine, theirs, fields) -> list[tuple[str, str]]:
    """``(field path, message)`` for each dotted case field of ``fields`` (a section or a value)
    in which the cases ``mine`` and ``theirs`` differ, down to the leaf that differs."""
    def dump(case, path):
        value = case.model_dump(mode="json")
        for key in path.split("."):
            value = value.get(key) if isinstance(value, dict) else None
        return value

    def walk(a, b, path):
        if isinstance(a, dict) and isinstance(b, dict):
            return [d for k in dict.fromkeys([*a, *b]) for d in walk(a.get(k), b.get(k), f"{path}.{k}")]
        return [] if a == b else [(path, f"{_shown(a)} here, {_shown(b)} in the run's case")]
    return [d for f in fields for d in walk(dump(mine, f), dump(theirs, f), f)]


def _shown(value) -> str:
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


# ------------------------------------------------------------------ status and record
STATES = ("rendered", "running", "complete", "failed", "interrupted")


def slurm_run() -> dict:
    """The Slurm job this process runs in and how often Slurm has restarted it (``SLURM_JOB_ID``,
    ``SLURM_RESTART_COUNT``); empty outside Slurm."""
    job = os.environ.get("SLURM_JOB_ID", "")
    restarts = os.environ.get("SLURM_RESTART_COUNT", "0")
    return {"slurm_job": job, "slurm_restart": int(restarts) if restarts.isdigit() else 0} if job else {}


def restarted_by_slurm(status: dict) -> bool:
    """Whether the ``running`` status was written by an earlier start of the Slurm job this process runs
    in (Slurm requeued it, after a node failure or a hard kill, perhaps onto another node): that start is over."""
    now = slurm_run()
    return bool(now and status.get("slurm_job") == now["slurm_job"]
                and isinstance(status.get("slurm_restart"), int) and status["slurm_restart"] < now["slurm_restart"])


def write_status(folder: Path, state: str, **extra) -> None:
    """Record the run state (``rendered``, ``running``, ``complete``, ``failed``, ``interrupted``).

    A ``running`` status names siloflow's process with its start time, so a PID reused by
    another process is not taken for the run. On a full disk the status is rewritten in place
    (its blocks are already allocated), so a failure can still be recorded."""
    if state == "running":
        extra = {"siloflow_pid": os.getpid(), "siloflow_start": process_start(os.getpid()),
                 "host": socket.gethostname(), **slurm_run(), **extra}
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
        stat_line = Path(f"/proc/{int(pid)}/stat").read_text()
        return int(stat_line.rsplit(")", 1)[1].split()[19])
    except (OSError, ValueError, IndexError, OverflowError):
        return None


def process_alive(pid, start=None) -> bool:
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


def read_status(folder: Path) -> dict:
    """The folder's status.json, checked: a JSON object with a known ``state``."""
    path = Path(folder) / STATUS_NAME
    try:
        data = read_json(path, "a run's status", kind=None)
    except ReadError as exc:
        raise ReadError(f"no readable {STATUS_NAME} in {folder}: {exc}") from None
    if not isinstance(data, dict) or data.get("state") not in STATES:
        raise ReadError(f"{path} is not a siloflow status (expected an object with a state of "
                        f"{', '.join(STATES)}); was the folder made by siloflow?")
    return data


#: what an engine run (or its post-processing) leaves in a run folder, which ``render`` never writes
RUN_EVIDENCE = (RECORD_NAME, FLOW_TABLE, WALL_FORCES_TABLE, RESTART_FILE, f"{RESULTS}/{SUMMARY_NAME}",
                *(name for files in ENGINE_FILES.values() for name in files.ran))


def run_state(folder: Path) -> dict:
    """The run's status. A ``running`` run whose siloflow process is gone (or whose PID now
    belongs to another process) is reported as ``abandoned``; a deck folder without a status
    (``siloflow render``) as ``rendered``, unless an engine ran in it (its status was lost):
    ``unknown``, with the reason and what its run record says."""
    folder = Path(folder)
    if not (folder / STATUS_NAME).exists() and is_siloflow_folder(folder):
        ran = [name for name in RUN_EVIDENCE if (folder / name).is_file()]
        if not ran:
            return {"state": "rendered"}
        try:
            said = read_json(folder / RECORD_NAME, "a run record", allow_nan=True).get("completed")
        except ReadError:
            said = None
        record = {True: f"; its {RECORD_NAME} says the engine run completed",
                  False: f"; its {RECORD_NAME} says the engine run did not complete"}.get(said, "")
        return {"state": "unknown",
                "reason": f"{STATUS_NAME} is missing, but an engine ran here ({', '.join(ran[:3])}"
                          f"{' ...' if len(ran) > 3 else ''}){record}: whether the run finished and was checked "
                          "cannot be told"}
    status = read_status(folder)
    host = status.get("host")
    if status["state"] == "running" and restarted_by_slurm(status):
        return {**status, "state": "abandoned",
                "reason": f"Slurm restarted job {status['slurm_job']} (on host {host}) before siloflow recorded "
                          "how the run ended"}
    if status["state"] == "running" and host not in (None, socket.gethostname()):
        return {**status, "reason": f"on host {host}: its process cannot be checked from here"}
    if status["state"] == "running" and not process_alive(status.get("siloflow_pid"), status.get("siloflow_start")):
        status = {**status, "state": "abandoned",
                  "reason": "siloflow stopped without recording it (killed?); the engine was stopped with it"}
    return status


@dataclass
class RunRecord:
    """What a finished engine run left behind (``run_record.json``)."""

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
    templates_inserted: Optional[int] = None   # grains + dust spheres the insertion placed
    short_batches: dict = field(default_factory=dict)   # per insertion fix: batches placed short (LIGGGHTS)
    fill_losses: int = 0                       # atoms that left the box during the fill (recorded, < 1 %)
    fill_cache: Optional[dict] = None          # {"key", "hit", "published", "warning"}: the settled bed came from (or went to) the cache
    discharge_stop: Optional[dict] = None      # until_steady: why it stopped (steady, empty, max_time), rate error
    guard: Optional[dict] = None               # the guard stopped the run: signal, stage, step, value, limit
    guard_peaks: Optional[dict] = None         # the fastest grain (m/s) and deepest pair overlap (m) the guard saw

    def to_json(self) -> dict:
        return asdict(self)


def checked_record(data: dict, path) -> RunRecord:
    """``run_record.json``'s object as a :class:`RunRecord`, its fields the results read checked:
    ``stage_steps`` whole steps >= 0 by stage name, counts whole or null, ``completed`` true or false,
    ``warnings`` texts (``ReadError`` naming the field; ``TypeError`` for fields it lacks or does not know)."""
    def whole(v) -> bool:
        return isinstance(v, int) and not isinstance(v, bool) and v >= 0

    stages = data.get("stage_steps")
    problems = []
    if not isinstance(stages, dict) or not all(isinstance(k, str) and whole(v) for k, v in stages.items()):
        bad = {k: v for k, v in stages.items() if not whole(v)} if isinstance(stages, dict) else stages
        problems.append(f"stage_steps must map each stage to a whole step >= 0, not {str(bad)[:120]}")
    for name in ("inserted", "templates_inserted", "returncode"):
        v = data.get(name)
        if v is not None and not (isinstance(v, int) and not isinstance(v, bool)):
            problems.append(f"{name} must be a whole number or null, not {str(v)[:60]}")
    if not isinstance(data.get("completed"), bool):
        problems.append(f"completed must be true or false, not {str(data.get('completed'))[:60]}")
    warnings = data.get("warnings", [])
    if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
        problems.append("warnings must be a list of texts")
    if problems:
        raise ReadError(f"{path} is not a run record siloflow wrote (edited, or damaged?): " + "; ".join(problems))
    return RunRecord(**data)


# ------------------------------------------------------------------ engine-neutral tables
#: ``flow``: one row per sample; masses kg, energies J, time s
FLOW_SCHEMA = {"step": "int64", "time": "float64", "atoms": "int64", "mass_total": "float64",
               "mass_silo": "float64", "discharged_mass": "float64", "discharged_count": "int64",
               "ke": "float64", "pe": "float64"}
#: ``wall_forces``: one row per sample and wall (plan order); fx, fy, fz the force the grains
#: exert on the wall, N, averaged over the sample
WALL_FORCE_SCHEMA = {"step": "int64", "time": "float64", "wall": "object", "fx": "float64", "fy": "float64",
                     "fz": "float64"}


def check_table(table, schema: dict, what: str):
    """``table`` with exactly the columns of ``schema``, in its order and types (``ReadError``)."""
    import pandas as pd
    missing = [c for c in schema if c not in table.columns]
    if missing:
        raise ReadError(f"{what} lacks column(s) {', '.join(missing)} (expected {', '.join(schema)})")
    out = table[list(schema)].copy()
    for c, dtype in schema.items():
        if dtype != "object":
            try:
                out[c] = pd.to_numeric(out[c], errors="raise").astype(dtype)
            except (ValueError, TypeError) as exc:
                raise ReadError(f"{what}: column {c} is not {dtype} ({exc})") from None
    return out


@dataclass(frozen=True)
class DumpLayout:
    """What an engine's dumps hold: the species of each atom type, the column names of its
    pair-contact and wall-contact dumps (empty when it writes none), how the ``mass`` column
    carries a clump's mass (``"body"``: every sphere the whole body's; ``"sum"``: each its share),
    and the primitive walls whose touching grains are dumped beside the wall contacts
    (``primitive_walls``: ``{"name", "style", "args"}`` each, ``postprocess.dumps.primitive_wall_contacts``)."""

    engine: str
    types: dict[int, str]
    contact_columns: list[str]
    wall_contact_columns: list[str]
    clump_mass: str = "body"
    primitive_walls: list[dict] = field(default_factory=list)

    def to_json(self) -> dict:
        return {**asdict(self), "types": {str(k): v for k, v in self.types.items()}}

    @classmethod
    def from_json(cls, data: dict, source: str) -> "DumpLayout":
        try:
            return cls(engine=str(data["engine"]), types={int(k): str(v) for k, v in data["types"].items()},
                       contact_columns=[str(c) for c in data["contact_columns"]],
                       wall_contact_columns=[str(c) for c in data["wall_contact_columns"]],
                       clump_mass=str(data["clump_mass"]),
                       primitive_walls=[{"name": str(w["name"]), "style": str(w["style"]),
                                         "args": [float(a) for a in w["args"]]}
                                        for w in data.get("primitive_walls", [])])
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise ReadError(f"{source} is not a dump layout ({exc})") from None


# ------------------------------------------------------------------ the folder
class RunFolder:
    """A siloflow run folder: its file names, and typed readers and writers of what is in it.

    Post-processing reads runs only through this class and the dump reader."""

    def __init__(self, path):
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"RunFolder({str(self.path)!r})"

    # -------------------------------------------------------------- names
    @property
    def case_file(self) -> Path:
        return self.path / CASE_NAME

    @property
    def plan_file(self) -> Path:
        return self.path / PLAN_NAME

    @property
    def results(self) -> Path:
        return self.path / RESULTS

    @property
    def summary_file(self) -> Path:
        return self.results / SUMMARY_NAME

    @property
    def dumps(self) -> Path:
        return self.path / DUMPS

    def is_run_folder(self) -> bool:
        return self.plan_file.is_file()

    # -------------------------------------------------------------- plan, layout, status, record
    @cached_property
    def plan(self):
        """The run plan (``siloflow.plan.RunPlan``) the folder was rendered from."""
        from .plan import RunPlan
        try:
            text = self.plan_file.read_text(encoding="utf-8")
        except OSError as exc:
            raise ReadError(f"{self.path} is not a siloflow run folder (no readable {PLAN_NAME}: "
                            f"{exc.strerror or exc})") from None
        return RunPlan.from_json(text, str(self.plan_file))

    def write_plan(self, plan) -> None:
        write_text(self.plan_file, plan.to_json())

    @cached_property
    def dump_layout(self) -> DumpLayout:
        path = self.path / DUMP_LAYOUT_NAME
        try:
            data = read_json(path, "the dumps' layout", kind=None)
        except ReadError as exc:
            raise ReadError(f"{self.path}: no readable {DUMP_LAYOUT_NAME} ({exc})") from None
        return DumpLayout.from_json(data, str(path))

    def write_dump_layout(self, layout: DumpLayout) -> None:
        write_json(self.path / DUMP_LAYOUT_NAME, layout.to_json())

    def species_densities(self) -> dict[int, float]:
        """Particle density (kg/m3) per atom type of the dumps."""
        density = {sp.name: sp.density for sp in self.plan.species}
        return {t: density[name] for t, name in self.dump_layout.types.items() if name in density}

    @property
    def state(self) -> dict:
        """The run's status (``run_state``): rendered, running, complete, failed, interrupted, abandoned."""
        return run_state(self.path)

    @cached_property
    def record(self) -> RunRecord:
        """The engine run's record."""
        try:
            return checked_record(read_json(self.path / RECORD_NAME, "the engine run's record", allow_nan=True),
                                  self.path / RECORD_NAME)
        except (ReadError, TypeError) as exc:
            raise ReadError(f"{self.path} has no readable {RECORD_NAME}: {exc}") from None

    def write_record(self, record: RunRecord) -> None:
        write_text(self.path / RECORD_NAME, json.dumps(record.to_json(), indent=2))

    # -------------------------------------------------------------- tables
    def write_flow(self, table) -> None:
        self._write_table(FLOW_TABLE, check_table(table, FLOW_SCHEMA, "the flow table"))

    def write_wall_forces(self, table) -> None:
        self._write_table(WALL_FORCES_TABLE, check_table(table, WALL_FORCE_SCHEMA, "the wall-force table"))

    def flow(self):
        """The ``flow`` table (:data:`FLOW_SCHEMA`), a pandas DataFrame."""
        return self._read_table(FLOW_TABLE, FLOW_SCHEMA, "flow")

    def wall_forces(self):
        """The ``wall_forces`` table (:data:`WALL_FORCE_SCHEMA`), long: one row per sample and wall."""
        return self._read_table(WALL_FORCES_TABLE, WALL_FORCE_SCHEMA, "wall-force")

    def _write_table(self, name: str, table) -> None:
        write_text(self.path / name, table.to_csv(index=False, float_format="%.17g"))

    def _read_table(self, name: str, schema: dict, what: str):
        import pandas as pd
        path = self.path / name
        try:
            table = pd.read_csv(path, dtype={"wall": str})
        except (OSError, ValueError) as exc:
            raise ReadError(f"cannot read the {what} table {path}: {exc} (did the engine run finish?)") from None
        return check_table(table, schema, str(path))

    # -------------------------------------------------------------- dumps and results
    def dump_files(self, kind: str = "particles") -> Optional[list[Path]]:
        """The dump files of ``kind`` (``particles``, ``contacts``, ``wall_contacts``, ``primitive_walls``) in step
        order, or None when the run wrote none."""
        pattern = {"particles": PARTICLE_DUMPS, "contacts": CONTACT_DUMPS, "wall_contacts": WALL_CONTACT_DUMPS,
                   "primitive_walls": PRIMITIVE_CONTACT_DUMPS}[kind]
        files = [p for p in self.dumps.glob(pattern) if p.is_file()] if self.dumps.is_dir() else []
        return sorted(files, key=lambda p: int(re.findall(r"\d+", p.name)[-1])) or None

    def read_summary(self, name: str = SUMMARY_NAME, folder: Optional[Path] = None) -> dict:
        """A summary JSON of the results (``results/summary.json`` by default)."""
        path = (folder or self.results) / name
        try:
            data = read_json(path, "a summary of results", kind=None, allow_nan=True)
        except ReadError as exc:
            if path.exists():
                raise ReadError(f"{self.path}: no readable {path.relative_to(self.path) if self.path in path.parents else path}"
                                f" ({exc}; run `siloflow post {self.path}` again)") from None
            raise ReadError(f"{self.path}: no readable {path.relative_to(self.path) if self.path in path.parents else path}"
                            f" (run `siloflow post {self.path}` first)") from None
        if not isinstance(data, dict):
            raise ReadError(f"{path} is not a summary")
        return data
