"""The fill cache: a settled bed is computed once and reused by every run it fits.

A fill is keyed by a SHA-256 of everything that defines it (:func:`fill_key_inputs`): the
species and their materials and contact parameters, the time step, the fill and settle
protocol, gravity and seed, the silo the fill sees (its walls' triangles; for a flat bottom the
floor is a plane whatever the orifice, since the bed rests on the closed plate), siloflow's
version and the engine's own parts (name, version, ranks and, for LIGGGHTS, the box). What
comes after the fill (the orifice of a flat bottom, the static window, the opening, the
discharge, the dumps and sampling) is not in the key; the walls' partition into sensor meshes is
(``outputs.results`` with or without ``wall_pressure`` are two fills).

Layout: ``<cache>/fills/<key>/`` holds the engine's files of the settled bed (LIGGGHTS: the
restart file, the log and the flow table up to it), ``key.json`` (what went into the key) and
``entry.json`` (source run, time, SHA-256 of every file). An entry is published by renaming a
finished folder into place, so a reader sees all of it or nothing; a lock per key
(``<key>.lock``, ``flock``) makes a second run of the same key wait for the first and then use
its bed instead of filling again. The cache is ``--cache DIR``, else ``$SILOFLOW_CACHE``, else
``~/.cache/siloflow``.
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional

import numpy as np

from .errors import SetupError

#: plan fields that come after the fill (or only name or describe it): not in the key
AFTER_FILL = ("name", "static_steps", "opening", "discharge", "outlet", "walls", "sensors", "outputs",
              "analysis", "design", "warnings", "run_length_fields", "plan_version",
              "guard", "profile")   # the guard watches a fill, the profile names it: neither makes another bed
#: wall roles that make up a flat floor (the bed rests on the closed plate either way)
FLOOR_ROLES = ("bottom", "plate")
ENTRY_NAME = "entry.json"
KEY_NAME = "key.json"


def default_root() -> Path:
    """``$SILOFLOW_CACHE``, else ``$XDG_CACHE_HOME/siloflow``, else ``~/.cache/siloflow``."""
    if os.environ.get("SILOFLOW_CACHE"):
        return Path(os.environ["SILOFLOW_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "siloflow"


def walls_digest(plan) -> str:
    """SHA-256 of the walls the fill touches, mesh by mesh (each mesh's triangles, m, float64,
    order-free; the meshes order-free); a flat floor (bottom and plate of a silo without hopper)
    counts as the plane z = 0. The partition into meshes is part of it: the same facets split
    into sensor meshes make another bed (LIGGGHTS counts a grain on an edge shared by two meshes
    once per mesh; measured: benchmarks/results/skip/seams.csv)."""
    flat = plan.geometry.hopper_height == 0
    digests = []
    for mesh in plan.meshes:
        if mesh.role == "outlet" or (flat and mesh.role in FLOOR_ROLES):
            continue
        tris = np.round(np.asarray(mesh.triangles, float).reshape(-1, 9), 12)
        tris = tris[np.lexsort(tris.T[::-1])]
        digests.append(hashlib.sha256(tris.tobytes()).hexdigest())
    digest = hashlib.sha256("".join(sorted(digests)).encode())
    digest.update(b"flat floor" if flat else b"")
    return digest.hexdigest()


def fill_key_inputs(plan, engine) -> dict:
    """What defines the plan's fill on ``engine`` (JSON-ready)."""
    data = plan.model_dump(mode="json", exclude=set(AFTER_FILL))
    geometry = dict(data["geometry"])
    if plan.geometry.hopper_height == 0:           # the orifice is closed by the plate during the fill
        geometry.pop("outlet_radius")
    data["geometry"] = geometry
    # the guard's limits do not make another bed, but a bed settled unwatched is not one a watched run may take
    data["guarded"] = plan.guard is not None and plan.guard.enabled
    data["walls_sha256"] = walls_digest(plan)
    data["engine"] = engine.fill_key_parts(plan)
    return data


def key_of(inputs: dict) -> str:
    """The cache key (hex SHA-256) of :func:`fill_key_inputs`."""
    return hashlib.sha256(json.dumps(inputs, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def fill_key(plan, engine) -> str:
    """The cache key of the plan's fill on ``engine``."""
    return key_of(fill_key_inputs(plan, engine))


def _sha256(path: Path) -> str:
    from .run_folder import sha256
    return sha256(path)


@dataclass(frozen=True)
class Entry:
    """A cached fill: its key, folder and record."""

    key: str
    folder: Path
    info: dict

    @property
    def files(self) -> dict[str, Path]:
        return {name: self.folder / name for name in self.info["files"]}


class FillCache:
    """The fill cache under ``root`` (see the module docstring)."""

    def __init__(self, root=None):
        self.root = Path(root) if root is not None else default_root()
        self.fills = self.root / "fills"

    def _ensure(self) -> None:
        try:
            self.fills.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SetupError(f"cannot make the fill cache {self.fills}: {exc.strerror or exc}") from None

    @contextmanager
    def lock(self, key: str) -> Iterator[None]:
        """Hold the key's lock (waits while another run fills the same key)."""
        self._ensure()
        with open(self.fills / f"{key}.lock", "a") as fh:
            fcntl.flock(fh, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)

    def get(self, key: str) -> Optional[Entry]:
        """The entry of ``key`` if it is cached and intact (every file matching its SHA-256)."""
        folder = self.fills / key
        try:
            info = json.loads((folder / ENTRY_NAME).read_text(encoding="utf-8"))
            files = info["files"]
        except (OSError, ValueError, KeyError, TypeError):
            return None
        for name, digest in files.items():
            path = folder / name
            if "/" in name or not path.is_file() or path.is_symlink() or _sha256(path) != digest:
                return None
        return Entry(key, folder, info)

    def put(self, key: str, files: dict[str, bytes], inputs: dict, source: str) -> Entry:
        """Publish the engine's fill ``files`` (name -> bytes) under ``key``; an entry already
        there (another run published it first) is kept."""
        self._ensure()
        tmp = self.fills / f".{key}.{os.getpid()}.tmp"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        try:
            for name, data in files.items():
                (tmp / name).write_bytes(data)
            (tmp / KEY_NAME).write_text(json.dumps(inputs, indent=1, sort_keys=True))
            info = {"key": key, "source": source, "time": time.time(),
                    "files": {name: _sha256(tmp / name) for name in files}}
            (tmp / ENTRY_NAME).write_text(json.dumps(info, indent=1))
            try:
                os.rename(tmp, self.fills / key)
            except OSError:
                if self.get(key) is None:          # a broken entry in the way: replace it
                    shutil.rmtree(self.fills / key, ignore_errors=True)
                    os.rename(tmp, self.fills / key)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        entry = self.get(key)
        if entry is None:
            raise SetupError(f"the fill cache {self.fills} did not keep the entry {key[:12]}")
        return entry

    def entries(self) -> list[Entry]:
        """Every intact entry, oldest first."""
        if not self.fills.is_dir():
            return []
        found = [self.get(p.name) for p in self.fills.iterdir() if p.is_dir() and not p.name.startswith(".")]
        return sorted((e for e in found if e is not None), key=lambda e: e.info.get("time", 0))

    def clear(self, key: Optional[str] = None) -> int:
        """Remove one entry (a key or a unique prefix of one), or all; return how many went."""
        if not self.fills.is_dir():
            return 0
        targets = [p for p in self.fills.iterdir() if p.is_dir() and (key is None or p.name.startswith(key))]
        if key is not None and len(targets) > 1:
            raise SetupError(f"{key!r} names {len(targets)} fills: give more of the key")
        for p in targets:
            shutil.rmtree(p)
            (self.fills / f"{p.name}.lock").unlink(missing_ok=True)
        return len(targets)


def run_with_cache(engine, folder, plan, cache: FillCache, progress=None, on_hit=None):
    """Run the rendered ``folder`` of ``plan`` on ``engine`` through the fill cache: from the
    cached settled bed when its key is there (``on_hit(key)`` is told first), else the whole
    run, whose bed is then published. A second run of the same key waits for the first. The
    run record says which (``fill_cache``). Returns the collected record."""
    from .run_folder import RunFolder
    inputs = fill_key_inputs(plan, engine)
    key = key_of(inputs)
    with cache.lock(key):
        entry = cache.get(key)
        if entry is not None:
            if on_hit is not None:
                on_hit(key)
            record = engine.start_from_fill(folder, entry.files, progress)
        else:
            engine.execute(folder, progress)
            record = engine.collect(folder)
            cache.put(key, engine.fill_files(folder), inputs, source=str(Path(folder).absolute()))
    record.fill_cache = {"key": key, "hit": entry is not None, "cache": str(cache.root)}
    RunFolder(folder).write_record(record)
    return record
