"""ParaView files of a run folder (``siloflow vtk``), written from ``postprocess.paraview``'s
VTK objects with VTK's own XML writers (binary, zlib-compressed), each atomically:

    results/paraview/run.pvd                  particles and walls together, times in seconds
    results/paraview/particles.pvd            the particle dumps alone
    results/paraview/walls.pvd                the walls alone, at every wall-force sample
    results/paraview/particles/particles_<step>.vtp
    results/paraview/walls/walls_<step>.vtp
    results/paraview/paraview.json            what was written (frames, times, arrays)
    <beside each fields.nc>/fields.vts        an (r, z) coarse-graining revolved into 3D
    <beside each fields.nc>/fields_rz.vtr     ... and its meridian half-plane
    <beside each fields.nc>/fields.vti        a Cartesian coarse-graining

The ``.pvd`` collections are written with ``xml.etree``; each of their datasets carries its
physical time (step x the plan's time step, s) as ``timestep``. In run.pvd the particles (part 0)
and the walls (part 1) are listed at every time either has, each as its latest file at or before
that time, so that ParaView shows both at every time of the slider.

paraview.json records every file written with its SHA-256 (``files``): the marker by which the
next ``siloflow vtk`` replaces them, and removes those it does not write again. A folder holding
anything else (a file siloflow did not write, one recorded and changed since, a link) is refused
before anything is written, naming the files; inside a run folder the run's manifest
(``record_products``) counts as a record too. An empty particle dump is skipped, said as a
warning and listed in paraview.json (``particles.skipped_empty_dumps``).
"""
from __future__ import annotations

import os
import re
import time as clock
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

from siloflow.atomic_files import atomic_path, read_json, write_json, write_text
from siloflow.errors import ReadError, SetupError
from siloflow.run_folder import RESULTS, RunFolder, read_manifest, record_products, sha256

from ..paraview import N_THETA, cg_grids, particle_series, vtk_modules, wall_series

#: the folder under results/ and its collections
PARAVIEW = "paraview"
RUN_PVD, PARTICLES_PVD, WALLS_PVD, PARAVIEW_JSON = "run.pvd", "particles.pvd", "walls.pvd", "paraview.json"
#: the files ``siloflow vtk`` writes in its folder (relative paths): only these are ever replaced
#: or removed, and only when a record says siloflow wrote them and they are unchanged
_OWN_FILE = re.compile(r"(run|particles|walls)\.pvd|paraview\.json|particles/particles_\d+\.vtp|walls/walls_\d+\.vtp")
#: one of them cut short by an interrupted atomic write (``siloflow.atomic_files``): left alone
_OWN_TEMP = re.compile(r"(?P<dir>(?:particles/|walls/)?)\.(?P<name>[^/]+)\.[A-Za-z0-9_]{8}\.tmp")
#: the VTK files written beside a fields.nc
_CG_STEMS = ("fields.vts", "fields_rz.vtr", "fields.vti")


class EmptyDumpWarning(UserWarning):
    """A particle dump file held no frame and was skipped."""


def _writer(obj):
    """VTK's XML writer for ``obj`` and the file suffix it takes."""
    from vtkmodules import vtkIOXML
    _, dm, _ = vtk_modules()
    for cls, writer, suffix in ((dm.vtkPolyData, vtkIOXML.vtkXMLPolyDataWriter, ".vtp"),
                                (dm.vtkImageData, vtkIOXML.vtkXMLImageDataWriter, ".vti"),
                                (dm.vtkRectilinearGrid, vtkIOXML.vtkXMLRectilinearGridWriter, ".vtr"),
                                (dm.vtkStructuredGrid, vtkIOXML.vtkXMLStructuredGridWriter, ".vts"),
                                (dm.vtkUnstructuredGrid, vtkIOXML.vtkXMLUnstructuredGridWriter, ".vtu")):
        if isinstance(obj, cls):
            return writer(), suffix
    raise TypeError(f"no VTK XML writer for {type(obj).__name__}")


def write_vtk(obj, path) -> Path:
    """Write a VTK data object with its XML writer (binary, appended, zlib) to ``path``, whose
    suffix must be the writer's (``.vtp``, ``.vti``, ``.vtr``, ``.vts``, ``.vtu``), atomically."""
    path = Path(path)
    writer, suffix = _writer(obj)
    if path.suffix != suffix:
        raise ValueError(f"{path.name}: a {type(obj).__name__} is written as {suffix}")
    writer.SetInputData(obj)
    writer.SetDataModeToAppended()
    writer.EncodeAppendedDataOff()
    writer.SetCompressorTypeToZLib()
    with atomic_path(path) as tmp:
        writer.SetFileName(str(tmp))
        if writer.Write() != 1:
            raise SetupError(f"cannot write {path} (VTK's writer failed: disk full or not writable?)")
    return path


def write_pvd(path, datasets) -> Path:
    """Write a ParaView collection: ``datasets`` are (time s, part, file relative to ``path``'s
    folder, name) in order; atomically."""
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    collection = ET.SubElement(root, "Collection")
    for time, part, file, name in datasets:
        ET.SubElement(collection, "DataSet", timestep=repr(float(time)), group="", part=str(int(part)),
                      file=Path(file).as_posix(), name=name)
    ET.indent(root)
    write_text(path, '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n")
    return Path(path)


def write_series(snapshots, folder, stem: str, record: dict | None = None) -> list[tuple[float, str]]:
    """Write each snapshot (``postprocess.paraview.Snapshot``) as ``<folder>/<stem>_<step>.vtp``
    (replacing a file of that name); returns [(time s, file name)] in order. ``record``: gets
    each path written -> its SHA-256."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for snap in snapshots:
        name = f"{stem}_{snap.step:010d}.vtp"
        write_vtk(snap.data, folder / name)
        if record is not None:
            record[folder / name] = sha256(folder / name)
        written.append((snap.time, name))
    return written


def recorded_files(out) -> dict[str, str]:
    """The files an earlier ``siloflow vtk`` recorded in ``out``/paraview.json: {path relative to
    ``out``: SHA-256}; {} without a readable record."""
    try:
        data = read_json(Path(out) / PARAVIEW_JSON, "the record of siloflow vtk's files")
    except ReadError:
        return {}
    files = data.get("files") if isinstance(data, dict) else None
    if data.get("collection") != RUN_PVD or not isinstance(files, dict) or not all(
            isinstance(k, str) and isinstance(v, str) for k, v in files.items()):
        return {}
    return files


def _manifest_files(run: RunFolder, folder: Path) -> dict[str, str]:
    """The run manifest's record (files and products: SHA-256) of what is under ``folder``,
    relative to it; {} for a folder outside the run."""
    try:
        base = folder.resolve().relative_to(run.path.resolve()).as_posix()
    except (OSError, ValueError):
        return {}
    manifest = read_manifest(run.path)
    known = {**manifest.get("files", {}), **manifest.get("products", {})}
    prefix = "" if base == "." else base + "/"
    return {k[len(prefix):]: v for k, v in known.items() if k.startswith(prefix)}


def _refuse(folder: Path, foreign: list[str]) -> None:
    shown = ", ".join(foreign[:8]) + (f" and {len(foreign) - 8} more" if len(foreign) > 8 else "")
    raise SetupError(f"{folder} holds files siloflow did not write, or changed since it wrote them ({shown}): "
                     "siloflow vtk never overwrites or deletes them, and wrote nothing; move them out of the folder, "
                     "or give another output folder with -o")


def check_paraview_folder(out, run: RunFolder) -> set[str]:
    """Refuse (``SetupError``, naming them all) an output folder ``out`` holding anything siloflow
    may not replace: a file neither ``out``/paraview.json (:func:`recorded_files`) nor the run's
    manifest records, or one changed since (its SHA-256), a link or a special file; or ``out``
    being a file, a link, or below a file. Returns the files of siloflow's found there (relative)."""
    out = Path(out)
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise SetupError(f"{out} exists and is not a folder (or is a symbolic link): give another output folder with -o")
    for parent in out.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise SetupError(f"cannot make {out}: {parent} is a file, not a folder")
            break
    if not out.is_dir():
        return set()
    recorded, manifest = recorded_files(out), _manifest_files(run, out)
    ours, foreign = set(), []
    for root, dirs, files in os.walk(out, followlinks=False):
        base = Path(root).relative_to(out)
        for d in list(dirs):
            if (Path(root) / d).is_symlink():
                foreign.append((base / d).as_posix() + " (a symbolic link)")
                dirs.remove(d)
        for f in files:
            rel, p = (base / f).as_posix(), Path(root) / f
            if p.is_symlink() or not p.is_file():
                foreign.append(rel + " (not a regular file)")
                continue
            temp = _OWN_TEMP.fullmatch(rel)
            if temp and _OWN_FILE.fullmatch(temp["dir"] + temp["name"]):
                continue
            digests = {d for d in (recorded.get(rel), manifest.get(rel)) if d}
            if rel == PARAVIEW_JSON and recorded:
                ours.add(rel)
            elif not digests:
                foreign.append(rel)
            elif sha256(p) not in digests:
                foreign.append(rel + " (edited since siloflow wrote it)")
            else:
                ours.add(rel)
    if foreign:
        _refuse(out, sorted(foreign))
    return ours


def _check_cg_targets(run: RunFolder, fields: list[Path]) -> None:
    """Refuse the VTK files about to be written beside the run's fields.nc when one exists that
    the run's manifest does not record unchanged (a file of the user's)."""
    foreign = []
    for nc in fields:
        known = _manifest_files(run, nc.parent)
        for name in _CG_STEMS:
            p = nc.parent / name
            if os.path.lexists(p) and (p.is_symlink() or not p.is_file() or sha256(p) != known.get(name)):
                foreign.append(str(p.relative_to(run.path)))
    if foreign:
        _refuse(run.path, foreign)


def _combined(parts: list[tuple[str, list[tuple[float, str]]]]) -> list[tuple[float, int, str, str]]:
    """run.pvd's datasets: at every time any part has, each part's latest file at or before it."""
    times = sorted({t for _, series in parts for t, _ in series})
    out = []
    for t in times:
        for k, (name, series) in enumerate(parts):
            latest = [f for ts, f in series if ts <= t]
            if latest:
                out.append((t, k, latest[-1], name))
    return out


def write_cg_vtk(fields, n_theta: int = N_THETA) -> list[Path]:
    """Write a coarse-graining's NetCDF ``fields`` (fields.nc, or the folder holding it) as VTK
    beside it (``postprocess.paraview.cg_grids``); returns the paths written."""
    import xarray as xr
    path = Path(fields)
    if path.is_dir():
        path = path / "fields.nc"
    try:
        with xr.open_dataset(path) as ds:
            ds.load()
    except (OSError, ValueError) as exc:
        raise ReadError(f"cannot read the coarse-grained fields {path}: {exc}") from None
    written = []
    for stem, obj in cg_grids(ds, n_theta).items():
        _, suffix = _writer(obj)
        written.append(write_vtk(obj, path.with_name(stem + suffix)))
    return written


def _remove_stale(out: Path, before: set[str], written: set[str]) -> None:
    """Remove siloflow's files of an earlier ``siloflow vtk`` (``before``, checked as its own) that
    this one did not write again, and the series folders left empty."""
    for rel in sorted(before - written - {PARAVIEW_JSON}):
        if _OWN_FILE.fullmatch(rel):
            (out / rel).unlink(missing_ok=True)
    for sub in ("particles", "walls"):
        try:
            (out / sub).rmdir()                     # only when empty
        except OSError:
            pass


def write_run_paraview(folder, out=None, every: int = 1, wall_every: int = 1, n_theta: int = N_THETA,
                       cg: bool = True) -> dict:
    """Write a run folder's ParaView files (the module doc) into ``out`` (default
    results/paraview): the particle dumps (every ``every``-th frame; an empty dump file is skipped
    with an :class:`EmptyDumpWarning` naming it), the walls (every ``wall_every``-th wall-force
    sample; none when the run sampled no wall forces), the three collections, and with ``cg``
    every results/**/fields.nc as VTK beside it. ``out`` may hold only what an earlier
    ``siloflow vtk`` wrote (:func:`check_paraview_folder`, before anything is written); of that,
    what is not written again is removed. What is written inside the run folder is recorded in
    its manifest. Returns the summary (paraview.json)."""
    run = folder if isinstance(folder, RunFolder) else RunFolder(folder)
    if not run.is_run_folder():
        raise ReadError(f"{run.path} is not a siloflow run folder (no plan.json)")
    vtk_modules()                                   # the optional package, before anything is written
    out = Path(out) if out is not None else run.results / PARAVIEW
    before = check_paraview_folder(out, run)
    fields = sorted(run.results.rglob("fields.nc")) if cg else []
    _check_cg_targets(run, fields)
    series = particle_series(run, every)            # ReadError, naming where, without dumps
    since = clock.time()
    record: dict[Path, str] = {}
    summary: dict = {"run": str(run.path), "time_step_s": run.plan.dt}
    try:
        out.mkdir(parents=True, exist_ok=True)
        particles = write_series(series, out / "particles", "particles", record)
        parts = [("particles", [(t, f"particles/{f}") for t, f in particles])]
        empty = [str(p.relative_to(run.path)) for p in series.empty]
        summary["particles"] = {"frames": len(particles), "every": every, "times_s": [t for t, _ in particles],
                                "collection": PARTICLES_PVD, "skipped_empty_dumps": empty}
        if empty:
            warnings.warn(f"{run.path}: {len(empty)} empty particle dump file(s) skipped (no frame in them): "
                          f"{', '.join(empty[:10])}{' ...' if len(empty) > 10 else ''}; the series has "
                          f"{len(particles)} frames", EmptyDumpWarning, stacklevel=2)
        write_pvd(out / PARTICLES_PVD, [(t, 0, f, "particles") for t, f in parts[0][1]])
        if run.plan.outputs.wall_forces:
            walls = write_series(wall_series(run, wall_every), out / "walls", "walls", record)
            parts.append(("walls", [(t, f"walls/{f}") for t, f in walls]))
            write_pvd(out / WALLS_PVD, [(t, 0, f, "walls") for t, f in parts[1][1]])
            summary["walls"] = {"samples": len(walls), "every": wall_every, "collection": WALLS_PVD,
                                "first_time_s": walls[0][0] if walls else None,
                                "last_time_s": walls[-1][0] if walls else None}
        write_pvd(out / RUN_PVD, _combined(parts))
        summary["collection"] = RUN_PVD
        for name in (PARTICLES_PVD, RUN_PVD) + ((WALLS_PVD,) if "walls" in summary else ()):
            record[out / name] = sha256(out / name)
        if cg:
            summary["cg"] = [str(p.relative_to(run.path)) for nc in fields for p in write_cg_vtk(nc, n_theta)]
        written = {p.relative_to(out).as_posix() for p in record}
        _remove_stale(out, before, written)
        summary["files"] = {p.relative_to(out).as_posix(): d for p, d in sorted(record.items())}
        write_json(out / PARAVIEW_JSON, summary)
    except BaseException as exc:
        _record_interrupted(out, before, record)
        if isinstance(exc, OSError):
            raise SetupError(f"cannot write the ParaView files into {out}: {exc.strerror or exc}") from None
        raise
    finally:
        record_products(run.path, run.path / RESULTS, since)
    return summary


def _record_interrupted(out: Path, before: set[str], record: dict) -> None:
    """After a failed write, record in paraview.json what is siloflow's in ``out`` (the earlier
    files still there, and those written), so that the next ``siloflow vtk`` may replace them."""
    if not record:
        return
    files = {rel: d for rel, d in recorded_files(out).items() if rel in before and (out / rel).is_file()}
    files.update({p.relative_to(out).as_posix(): d for p, d in record.items()})
    try:
        write_json(out / PARAVIEW_JSON, {"collection": RUN_PVD, "complete": False,
                                         "note": "siloflow vtk was interrupted: run it again", "files": files})
    except OSError:
        pass
