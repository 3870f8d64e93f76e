"""Atomic file writes: a reader never sees half a file, and nothing is overwritten silently.

A whole folder built under a temporary name and moved into place (``new_folder``) is the run
folder's (``siloflow.run_folder``), which knows which folders siloflow may replace."""
from __future__ import annotations

import errno
import json
import os
import stat
import tempfile
from contextlib import contextmanager
from pathlib import Path

from .errors import ReadError, SetupError


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


def write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (:func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


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


#: JSON nested deeper than this is no file siloflow wrote (a fill's key, its deepest, nests 5 levels)
MAX_JSON_DEPTH = 64
#: bytes of a run's, sweep's or cache's JSON file read at most (a manifest of 1e5 files is about 10 MB)
JSON_LIMIT = 1 << 26


class _NotFinite(ValueError):
    """A NaN or infinite number in JSON that may not hold one."""


def _not_finite(text: str):
    raise _NotFinite(f"it holds {text}, where only finite numbers belong")


def _finite(text: str) -> float:
    value = float(text)
    if value - value != 0:                 # inf, -inf (1e999 overflows to inf)
        _not_finite(text)
    return value


def _json_depth(data, stop: int) -> int:
    """How deep ``data`` nests (lists and objects), counted up to ``stop`` without recursion."""
    deepest, stack = 0, [(data, 1)]
    while stack and deepest <= stop:
        node, depth = stack.pop()
        if isinstance(node, (dict, list)):
            deepest = max(deepest, depth)
            stack.extend((v, depth + 1) for v in (node.values() if isinstance(node, dict) else node))
    return deepest


def read_json(path, what: str, limit: int = JSON_LIMIT, kind: type | None = dict, allow_nan: bool = False):
    """The JSON value of the file ``path`` (``what``: what it is, for the message), checked: a regular
    file of at most ``limit`` bytes (:func:`read_regular_bytes`), UTF-8, JSON, nested at most
    :data:`MAX_JSON_DEPTH` deep, without NaN or Infinity unless ``allow_nan`` (siloflow's own writer
    may write them there), and of type ``kind`` at the top (None: any). Raises ``ReadError`` naming
    the file, what it is and what is wrong (the one reader of a run's, sweep's and cache's files)."""
    try:
        raw = read_regular_bytes(path, limit, what)
    except ValueError as exc:
        raise ReadError(f"{exc} ({what})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ReadError(f"{path} ({what}) is not UTF-8 text (byte {exc.start}): was it written by siloflow?") from None
    hooks = {} if allow_nan else {"parse_constant": _not_finite, "parse_float": _finite}
    try:
        data = json.loads(text, **hooks)
    except _NotFinite as exc:
        raise ReadError(f"{path} ({what}): {exc}: was it written by siloflow?") from None
    except json.JSONDecodeError as exc:
        raise ReadError(f"{path} ({what}) is not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}") from None
    except RecursionError:
        raise ReadError(f"{path} ({what}) nests lists or objects too deeply (more than {MAX_JSON_DEPTH} levels): "
                        "it is no file siloflow wrote") from None
    except ValueError as exc:              # e.g. an integer of more digits than Python converts
        raise ReadError(f"{path} ({what}) is not JSON siloflow reads: {exc}") from None
    if _json_depth(data, MAX_JSON_DEPTH) > MAX_JSON_DEPTH:
        raise ReadError(f"{path} ({what}) nests lists or objects too deeply (more than {MAX_JSON_DEPTH} levels): "
                        "it is no file siloflow wrote")
    if kind is not None and not isinstance(data, kind):
        def name(t) -> str:
            return {dict: "a JSON object", list: "a JSON list", str: "a JSON string", bool: "true or false",
                    type(None): "null"}.get(t, "a JSON number" if t in (int, float) else t.__name__)
        raise ReadError(f"{path} ({what}) holds {name(type(data))}, not {name(kind)}: was it written by siloflow?")
    return data


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


def os_error(exc: OSError, what, verb: str = "write") -> SetupError:
    """An OSError while writing, as a message in the user's terms (disk full, read-only, ...)."""
    reasons = {errno.ENOSPC: "the disk is full", errno.EDQUOT: "the disk quota is exceeded",
               errno.EROFS: "the file system is read-only", errno.EACCES: "permission denied",
               errno.EPERM: "permission denied", errno.EBUSY: "it is in use (a mount point?)"}
    reason = reasons.get(exc.errno, exc.strerror or str(exc))
    where = f" ({exc.filename})" if exc.filename else ""
    return SetupError(f"cannot {verb} {what}: {reason}{where}")
