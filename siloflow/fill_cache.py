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
import math
import os
import shutil
import time
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional

import numpy as np

from .atomic_files import read_json
from .errors import ReadError, SetupError, SiloflowError

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


#: the plan silo's fields that place or shape its outlet (a flat floor's plate closes it for the fill)
OUTLET_PLACE = ("outlet_offset", "outlet", "outlet_half_y", "outlet_offset_y")
#: the plan silo's fields added after fills were first cached: left out of the key while unset
LATER_SILO_FIELDS = ("outlet_offset", "periodic_depth", "depth", "outlet", "outlet_half_y", "outlet_offset_y",
                     "outer_radius", "section_area", "section_perimeter")


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
        for k in ("outlet_radius",) + OUTLET_PLACE:
            geometry.pop(k, None)
    for k in LATER_SILO_FIELDS:                    # keys made before these fields existed stay valid
        if geometry.get(k, None) in (None, 0.0, False):
            geometry.pop(k, None)
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


@dataclass(frozen=True)
class Cleared:
    """What :meth:`FillCache.clear` did: the keys it removed, and what it left in place
    (name under ``fills/`` -> why)."""

    removed: list[str]
    left: dict[str, str]


def _is_key(name: str) -> bool:
    return len(name) == 64 and all(c in "0123456789abcdef" for c in name)


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
    def lock(self, key: str, wait: bool = True) -> Iterator[bool]:
        """Hold the key's lock (waits while another run fills the same key); with ``wait=False``
        it yields False at once if another process holds it. A lock file siloflow did not make
        (a symlink, a folder) is refused."""
        self._ensure()
        path = self.fills / f"{key}.lock"
        if path.is_symlink() or path.exists() and not path.is_file():
            raise SetupError(f"{path} is in the fill cache's way (it is not a lock file siloflow made): "
                             "move it away")
        with open(path, "a") as fh:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
            except BlockingIOError:
                yield False
                return
            try:
                yield True
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)

    def check(self, name: str) -> tuple[Optional[Entry], str]:
        """The entry stored as ``fills/<name>`` if siloflow wrote it and nothing in it changed
        since, else ``(None, why not)``. An entry is siloflow's when the folder (not a link)
        holds exactly ``entry.json``, ``key.json`` and the files ``entry.json`` lists, each
        matching its SHA-256, and both its record and ``key.json`` (whose hash is the key) give
        the folder's own name as the key: an entry copied or moved under another key is none."""
        folder = self.fills / name
        if folder.is_symlink():
            return None, "a symbolic link, not a folder siloflow wrote"
        if not folder.is_dir():
            return None, "not a folder" if folder.exists() else "no such entry"
        if not _is_key(name):
            return None, "its name is not a fill key"
        try:
            info = read_json(folder / ENTRY_NAME, "a fill cache entry's record")
            files = info["files"]
            stored_key = info["key"]
            inputs = read_json(folder / KEY_NAME, "a fill cache entry's key", kind=None, allow_nan=True)
        except (ReadError, KeyError) as exc:
            why = f": {exc}" if isinstance(exc, ReadError) else ""
            return None, f"no readable {ENTRY_NAME} and {KEY_NAME} of a fill{why}"
        if not isinstance(files, dict) or not all(isinstance(n, str) and isinstance(d, str) for n, d in files.items()):
            return None, f"{ENTRY_NAME} does not list files with their SHA-256"
        if stored_key != name or not isinstance(inputs, dict) or key_of(inputs) != name:
            return None, f"stored under another key ({ENTRY_NAME} or {KEY_NAME} names another fill)"
        expected = set(files) | {ENTRY_NAME, KEY_NAME}
        present = {p.name for p in folder.iterdir()}
        if present != expected:
            extra, missing = sorted(present - expected), sorted(expected - present)
            return None, ("holds files siloflow did not write: " + ", ".join(extra[:5]) if extra
                          else "files are missing: " + ", ".join(missing[:5]))
        for file_name, digest in files.items():
            path = folder / file_name
            if path.is_symlink() or not path.is_file():
                return None, f"{file_name} is not a plain file"
            if _sha256(path) != digest:
                return None, f"{file_name} changed since siloflow wrote it"
        return Entry(name, folder, info), ""

    def get(self, key: str) -> Optional[Entry]:
        """The entry of ``key`` if it is cached and intact (:meth:`check`)."""
        return self.check(key)[0]

    def put(self, key: str, files: dict[str, bytes], inputs: dict, source: str) -> Entry:
        """Publish the engine's fill ``files`` (name -> bytes) under ``key``; an intact entry
        already there (another run published it first) is kept. A folder in the key's place that
        is not an intact entry is left as it is and the fill is not published (SetupError)."""
        if key_of(inputs) != key:
            raise SetupError(f"the fill cache's key {key[:12]} is not the hash of its inputs")
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
                pass                               # a folder is in the way: checked below
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        entry, why = self.check(key)
        if entry is None:
            raise SetupError(f"the fill cache did not take the entry {key[:12]}: {self.fills / key} is in its way "
                             f"({why}); it is left as it is")
        return entry

    def survey(self) -> tuple[list[Entry], dict[str, str]]:
        """The intact entries (oldest first), and everything else under ``fills/`` that is
        neither an entry nor a lock or temporary of siloflow's (name -> why it is no entry)."""
        if not self.fills.is_dir():
            return [], {}
        found, other = [], {}
        for p in sorted(self.fills.iterdir()):
            if p.name.endswith(".lock") and _is_key(p.name[:-5]) and p.is_file() and not p.is_symlink():
                continue
            if p.name.startswith(".") and p.name.endswith(".tmp"):
                continue                           # a publication under way (or cut short)
            entry, why = self.check(p.name)
            if entry is None:
                other[p.name] = why
            else:
                found.append(entry)
        return sorted(found, key=lambda e: e.info.get("time", 0)), other

    def entries(self) -> list[Entry]:
        """Every intact entry, oldest first."""
        return self.survey()[0]

    def clear(self, key: Optional[str] = None) -> Cleared:
        """Remove one entry (a key or a unique prefix of one), or all. Only intact entries are
        removed (:meth:`check`), file by file, and one in use by a running run is left; anything
        else under ``fills/`` is left in place and reported with the reason."""
        entries, other = self.survey()
        if key is not None:
            if not key:
                raise SetupError("an empty key names every fill: leave it out to clear them all")
            entries = [e for e in entries if e.key.startswith(key)]
            other = {n: why for n, why in other.items() if n.startswith(key)}
            if len(entries) > 1:
                raise SetupError(f"{key!r} names {len(entries)} fills: give more of the key")
        removed, left = [], dict(other)
        for entry in entries:
            with self.lock(entry.key, wait=False) as held:
                if not held:
                    left[entry.key] = "in use by a running run"
                    continue
                fresh, why = self.check(entry.key)     # changed before it was locked?
                if fresh is None:
                    left[entry.key] = why
                    continue
                for name in [ENTRY_NAME, *entry.info["files"], KEY_NAME]:
                    (entry.folder / name).unlink(missing_ok=True)
                try:
                    entry.folder.rmdir()
                except OSError:
                    left[entry.key] = "a file appeared in it while it was cleared; the rest is left"
                    continue
                (self.fills / f"{entry.key}.lock").unlink(missing_ok=True)
                removed.append(entry.key)
        return Cleared(removed, left)


#: relative tolerance of a sphere's radius and mass read back from a restart file (the engine keeps them as set)
SPHERE_TOLERANCE = 1e-6
#: of a clump's mass: LIGGGHTS integrates a clump's mass by Monte Carlo (measured: 0.035 % below the plan's)
CLUMP_MASS_TOLERANCE = 0.01
#: standard deviations a size class's count may stray from its share of the grains (each grain's class
#: is drawn at random in a rain fill or paper B's shrinking; a placed fill gives the exact mix)
COUNT_SIGMAS = 5.0


def bed_problems(plan, bed, box: Optional[dict] = None) -> list[str]:
    """What of the settled ``bed`` an engine read back from a cached restart file
    (``siloflow.engine.base.SettledBed``) is not the bed ``plan`` fills, each naming what differs:
    the atom count (up to ``FILL_LOSS_LIMIT`` of it may be lost in a fill), atom types that are no
    species, each species' radii and grain masses (the density they give), its count against its
    share of the grains, and the simulation box (``box``: the engine's, m). Empty when it fits."""
    from .engine.processes import FILL_LOSS_LIMIT
    problems = []
    n, expected = len(bed.types), plan.expected_atoms
    least = math.ceil(expected * (1 - FILL_LOSS_LIMIT))
    if not least <= n <= expected:
        problems.append(f"it holds {n} atoms where this case's bed holds {expected}"
                        + (f" (at least {least}, if some were lost in the fill)" if least < expected else ""))
    species = {k + 1: sp for k, sp in enumerate(plan.species)}
    foreign = sorted(set(np.unique(bed.types).tolist()) - set(species))
    if foreign:
        problems.append(f"atom type{'s' if len(foreign) > 1 else ''} {', '.join(map(str, foreign[:5]))} "
                        f"{'are' if len(foreign) > 1 else 'is'} no species of this case (types 1-{len(species)})")
    grains = {t: np.count_nonzero(bed.types == t) / sp.n_spheres for t, sp in species.items() if sp.stream == "grains"}
    total = sum(grains.values())
    for t, sp in species.items():
        sel = bed.types == t
        radius, mass = bed.radius[sel], bed.mass[sel]
        where = f"species '{sp.name}' (atom type {t})"
        radii = [sp.radius] if sp.kind == "sphere" else sorted({s[3] for s in sp.spheres})
        off = ~np.isclose(radius[:, None], np.asarray(radii, float)[None, :], rtol=SPHERE_TOLERANCE, atol=0).any(axis=1)
        if off.any():
            problems.append(f"{where}: {np.count_nonzero(off)} of {len(radius)} atoms have a radius of "
                            f"{radius[off][0]:.6g} m where this case's {'is' if len(radii) == 1 else 'are'} "
                            f"{', '.join(f'{r:.6g}' for r in radii)} m")
        off = ~np.isclose(mass, sp.mass, rtol=SPHERE_TOLERANCE if sp.kind == "sphere" else CLUMP_MASS_TOLERANCE, atol=0)
        if off.any():
            k = np.flatnonzero(off)[0]
            volume = 4.0 / 3.0 * math.pi * radius[k] ** 3 if sp.kind == "sphere" else sp.volume
            problems.append(f"{where}: {np.count_nonzero(off)} of {len(mass)} grains weigh {mass[k]:.6g} kg (a density "
                            f"of {mass[k] / volume:.6g} kg/m3) where this case's weigh {sp.mass:.6g} kg "
                            f"({sp.density:.6g} kg/m3)")
        if sp.stream == "grains":
            share, count = total * sp.number_fraction, grains[t]
            slack = COUNT_SIGMAS * math.sqrt(total * sp.number_fraction * (1 - sp.number_fraction)) \
                + FILL_LOSS_LIMIT * plan.fill.count + 1
        else:
            share, count, slack = plan.fill.dust_count, np.count_nonzero(sel), FILL_LOSS_LIMIT * expected + 1
        if abs(count - share) > slack:
            problems.append(f"{where}: {count:.0f} grains where this case's mix gives {share:.0f} (+/- {slack:.0f})")
    if isinstance(box, dict) and bed.box:
        scale = max(abs(float(v)) for v in box.values())
        off = [k for k, v in box.items() if not abs(float(bed.box.get(k, math.nan)) - float(v)) <= 1e-5 * scale]
        if off:
            problems.append("its simulation box is not this case's (" + ", ".join(
                f"{k} {bed.box.get(k, math.nan):.6g} m, not {box[k]:.6g}" for k in off) + ")")
    return problems


def bed_refusal(engine, entry: Entry, plan, inputs: dict) -> str:
    """Why the settled bed of ``entry`` is not ``plan``'s ('' when it is): the engine reads its restart
    file back (``Engine.fill_bed``) and :func:`bed_problems` compares it with the plan and the box of
    the key's ``inputs``. An entry's hashes prove only that nothing changed since it was stored, not
    what was stored: a bed copied under another key, with a key and record written for it, passes them."""
    try:
        bed = engine.fill_bed(entry.files, plan)
    except (OSError, SiloflowError) as exc:
        return f"its restart file cannot be read back: {exc}"
    engine_parts = inputs.get("engine")
    return "; ".join(bed_problems(plan, bed, engine_parts.get("box") if isinstance(engine_parts, dict) else None))


def run_with_cache(engine, folder, plan, cache: FillCache, progress=None, on_hit=None, on_warning=None,
                   resume: bool = False):
    """Run the rendered ``folder`` of ``plan`` on ``engine`` through the fill cache: from the
    cached settled bed when its key is there (``on_hit(key)`` is told first), else the whole
    run, whose bed is then published. A second run of the same key waits for the first. The
    cache is an optimisation: a cache that cannot be locked, read or written (a full disk, say)
    costs the run its reuse, not its results; ``on_warning(message)`` is told, and the run
    record says so (``fill_cache``: key, hit, published, warning). Returns the collected record.

    ``resume``: finish the interrupted ``folder`` (``engine.resume``: from its own restart point,
    or filling again when it was stopped before its bed settled), never from the cache (the folder
    holds its first part's outputs), under the key's lock; its settled bed is then published when
    the cache holds none of the key, so the runs of the same fill after it start from it. The
    record's ``hit`` is False when it filled again, None when it went on from its restart point
    (whether its first part took that bed from the cache is not recorded)."""
    from .atomic_files import os_error
    from .run_folder import RunFolder
    inputs = fill_key_inputs(plan, engine)
    key = key_of(inputs)
    warnings: list[str] = []

    def warn(what: str, exc: Exception) -> None:
        why = str(os_error(exc, "it", "use")) if isinstance(exc, OSError) else str(exc)
        warnings.append(f"{what} ({why}); the run's results are not affected")
        if on_warning is not None:
            on_warning(warnings[-1])

    entry, published = None, False
    hit = False if not resume or engine.restart_step(folder) is None else None
    with ExitStack() as stack:
        try:
            stack.enter_context(cache.lock(key))
            entry = cache.get(key)
            usable = True
        except (OSError, SiloflowError) as exc:
            warn(f"the fill cache {cache.root} cannot be used: this run fills its own bed", exc)
            usable = False
        refused = bed_refusal(engine, entry, plan, inputs) if entry is not None and not resume else ""
        if refused:                     # its place is taken: this run's bed is not published either
            warn(f"the fill cache's entry {key[:12]} ({entry.folder}) does not hold this case's settled bed, so this "
                 f"run fills its own; the entry is left as it is ('siloflow cache clear {key[:12]}' removes it)",
                 SetupError(refused))
            entry, usable = None, False
        if entry is not None and not resume:
            if on_hit is not None:
                on_hit(key)
            hit = True
            record = engine.start_from_fill(folder, entry.files, progress)
        else:
            if resume:
                record = engine.resume(folder, progress)
            else:
                engine.execute(folder, progress)
                record = engine.collect(folder)
            if usable and entry is None:
                try:
                    cache.put(key, engine.fill_files(folder), inputs, source=str(Path(folder).absolute()))
                    published = True
                except (OSError, SiloflowError) as exc:
                    warn(f"the settled bed was not stored in the fill cache {cache.fills}", exc)
    record.fill_cache = {"key": key, "hit": hit, "cache": str(cache.root), "published": published,
                         **({"resumed": True} if resume else {}),
                         **({"warning": "; ".join(warnings)} if warnings else {})}
    RunFolder(folder).write_record(record)
    return record
