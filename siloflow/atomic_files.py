"""Atomic file and folder writes: a reader never sees half a file, and nothing is overwritten silently."""
from __future__ import annotations

import errno
import json
import os
import shutil
import stat
import tempfile
from contextlib import contextmanager
from pathlib import Path

from .errors import SetupError


def _umask() -> int:
    """The process' umask, read without changing it where Linux allows (``/proc/self/status``)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` (``.{name}.XXXXXXXX.tmp``, the pattern
    ``siloflow.run_folder`` knows as an interrupted write) for the block to write; it is renamed onto
    ``path`` if the block succeeds and removed if it fails. The file gets the mode a plain ``open``
    would give it (0666 less the umask), not ``mkstemp``'s owner-only 0600."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        try:
            os.fchmod(fd, 0o666 & ~_umask())
        except OSError:               # a file system without modes (vfat, some network mounts)
            pass
        finally:
            os.close(fd)
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text(path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (:func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def read_regular_bytes(path, limit: int, what: str = "the file") -> bytes:
    """The bytes of a regular file, at most ``limit``: a FIFO, a device such as /dev/zero or a
    directory is refused before it is read; the file is opened non-blocking (a FIFO swapped in
    after the check cannot hang) and read up to one byte past the limit, never whole. Raises
    ``ValueError`` with a message naming the file and why."""
    path = Path(path)

    def kind(mode) -> str:
        return ("a directory" if stat.S_ISDIR(mode) else "a FIFO (named pipe)" if stat.S_ISFIFO(mode)
                else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
                else "a socket" if stat.S_ISSOCK(mode) else "not a regular file")

    def opened() -> int:
        try:
            mode = os.stat(path).st_mode
            if stat.S_ISREG(mode):
                return os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0))
        except OSError as exc:
            raise ValueError(f"cannot read {path}: {exc.strerror or exc}") from None
        except ValueError as exc:                  # e.g. a NUL byte in the path
            raise ValueError(f"cannot read {path!r}: {exc}") from None
        raise ValueError(f"{path} is {kind(mode)}; {what} must be a regular file")

    fd = opened()
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):          # replaced between the stat and the open
            raise ValueError(f"{path} is {kind(mode)}; {what} must be a regular file")
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, limit + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise ValueError(f"cannot read {path}: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if size > limit:
        raise ValueError(f"{path} is larger than {limit} bytes")
    return b"".join(chunks)


def write_json(path, data) -> None:
    """Write ``data`` as indented JSON, atomically (NaN written as null)."""
    write_text(path, json.dumps(_nan_to_none(data), indent=2, sort_keys=False) + "\n")


def _nan_to_none(x):
    if isinstance(x, float) and x != x:
        return None
    if isinstance(x, dict):
        return {k: _nan_to_none(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_nan_to_none(v) for v in x]
    return x


def check_free_folder(folder, force: bool, keep=()) -> None:
    """Refuse an existing ``folder`` that is not an empty folder, unless ``force`` and siloflow
    may replace it (``siloflow.run_folder.check_replaceable``; ``keep``: files being read)."""
    from .run_folder import check_not_in_use, check_replaceable
    folder = Path(folder)
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise SetupError(f"{folder} exists and is not a folder (or is a symbolic link): choose another output folder")
    for parent in folder.absolute().parents:
        if parent.exists() and not parent.is_dir():
            raise SetupError(f"cannot make {folder}: {parent} is a file, not a folder")
    if not folder.is_dir():
        return
    check_not_in_use(folder, keep)            # the current directory, a mount point, a file being read
    if any(folder.iterdir()):
        if not force:
            raise SetupError(f"{folder} already exists and is not empty: choose another folder, "
                             "or pass --force to replace it (only a folder siloflow made, holding only its files)")
        check_replaceable(folder)


def os_error(exc: OSError, what, verb: str = "write") -> SetupError:
    """An OSError while writing, as a message in the user's terms (disk full, read-only, ...)."""
    reasons = {errno.ENOSPC: "the disk is full", errno.EDQUOT: "the disk quota is exceeded",
               errno.EROFS: "the file system is read-only", errno.EACCES: "permission denied",
               errno.EPERM: "permission denied", errno.EBUSY: "it is in use (a mount point?)"}
    reason = reasons.get(exc.errno, exc.strerror or str(exc))
    where = f" ({exc.filename})" if exc.filename else ""
    return SetupError(f"cannot {verb} {what}: {reason}{where}")


@contextmanager
def new_folder(folder, force: bool = False, keep=()):
    """Build a folder under a temporary name and move it into place only if the block succeeds.

    Yields the temporary path. An existing non-empty ``folder`` is refused unless ``force``
    and it is a siloflow folder holding only siloflow's files (``keep``: paths being read,
    never inside a replaced folder); it is replaced only after the new one is complete, and
    then only siloflow's files are deleted. An OSError (disk full, read-only, ...) becomes a
    ``SetupError`` and leaves no partial folder.
    """
    from .run_folder import remove_siloflow_files
    folder = Path(folder).absolute()
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
