"""Atomic file and folder writes: a reader never sees half a file, and nothing is overwritten silently."""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

from .errors import SetupError


def write_text(path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same folder and a rename."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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


def check_free_folder(folder, force: bool) -> None:
    """Refuse a non-empty existing ``folder`` unless ``force``."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise SetupError(f"{folder} exists and is not a folder")
    if folder.is_dir() and any(folder.iterdir()) and not force:
        raise SetupError(f"{folder} already exists and is not empty: choose another folder, "
                         "or pass --force to replace it")


@contextmanager
def new_folder(folder, force: bool = False):
    """Build a folder under a temporary name and move it into place only if the block succeeds.

    Yields the temporary path. An existing non-empty ``folder`` is refused unless
    ``force``, in which case it is replaced only after the new one is complete.
    """
    folder = Path(folder).absolute()
    check_free_folder(folder, force)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=folder.parent, prefix=f".{folder.name}.", suffix=".partial"))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if folder.exists():
        old = folder.with_name(f".{folder.name}.replaced-{os.getpid()}")
        os.replace(folder, old)
    os.replace(tmp, folder)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
