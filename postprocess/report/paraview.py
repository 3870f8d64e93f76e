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
"""
from __future__ import annotations

import re
import time as clock
import xml.etree.ElementTree as ET
from pathlib import Path

from siloflow.atomic_files import atomic_path, write_json, write_text
from siloflow.errors import ReadError, SetupError
from siloflow.run_folder import RESULTS, RunFolder, record_products

from ..paraview import N_THETA, cg_grids, particle_series, vtk_modules, wall_series

#: the folder under results/ and its collections
PARAVIEW = "paraview"
RUN_PVD, PARTICLES_PVD, WALLS_PVD, PARAVIEW_JSON = "run.pvd", "particles.pvd", "walls.pvd", "paraview.json"
#: the files a previous ``siloflow vtk`` wrote in the series folders (replaced by the next)
_SERIES_FILE = re.compile(r"(particles|walls)_\d+\.vtp")


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


def _clear_series(folder: Path) -> None:
    """Remove the series files an earlier ``siloflow vtk`` left in ``folder`` (only those)."""
    if folder.is_dir():
        for p in folder.iterdir():
            if p.is_file() and _SERIES_FILE.fullmatch(p.name):
                p.unlink()


def write_series(snapshots, folder, stem: str) -> list[tuple[float, str]]:
    """Write each snapshot (``postprocess.paraview.Snapshot``) as ``<folder>/<stem>_<step>.vtp``;
    returns [(time s, file name)] in order."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    _clear_series(folder)
    written = []
    for snap in snapshots:
        name = f"{stem}_{snap.step:010d}.vtp"
        write_vtk(snap.data, folder / name)
        written.append((snap.time, name))
    return written


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


def write_run_paraview(folder, out=None, every: int = 1, wall_every: int = 1, n_theta: int = N_THETA,
                       cg: bool = True) -> dict:
    """Write a run folder's ParaView files (the module doc) into ``out`` (default
    results/paraview): the particle dumps (every ``every``-th frame), the walls (every
    ``wall_every``-th wall-force sample; none when the run sampled no wall forces), the three
    collections, and with ``cg`` every results/**/fields.nc as VTK beside it. What is written
    inside the run folder is recorded in its manifest. Returns the summary (paraview.json)."""
    run = folder if isinstance(folder, RunFolder) else RunFolder(folder)
    if not run.is_run_folder():
        raise ReadError(f"{run.path} is not a siloflow run folder (no plan.json)")
    vtk_modules()                                   # the optional package, before anything is written
    out = Path(out) if out is not None else run.results / PARAVIEW
    since = clock.time()
    try:
        out.mkdir(parents=True, exist_ok=True)
        particles = write_series(particle_series(run, every), out / "particles", "particles")
        parts = [("particles", [(t, f"particles/{f}") for t, f in particles])]
        summary: dict = {"run": str(run.path), "time_step_s": run.plan.dt,
                         "particles": {"frames": len(particles), "every": every,
                                       "times_s": [t for t, _ in particles], "collection": PARTICLES_PVD}}
        write_pvd(out / PARTICLES_PVD, [(t, 0, f, "particles") for t, f in parts[0][1]])
        if run.plan.outputs.wall_forces:
            walls = write_series(wall_series(run, wall_every), out / "walls", "walls")
            parts.append(("walls", [(t, f"walls/{f}") for t, f in walls]))
            write_pvd(out / WALLS_PVD, [(t, 0, f, "walls") for t, f in parts[1][1]])
            summary["walls"] = {"samples": len(walls), "every": wall_every, "collection": WALLS_PVD,
                                "first_time_s": walls[0][0] if walls else None,
                                "last_time_s": walls[-1][0] if walls else None}
        write_pvd(out / RUN_PVD, _combined(parts))
        summary["collection"] = RUN_PVD
        if cg:
            summary["cg"] = [str(p.relative_to(run.path)) for nc in sorted(run.results.rglob("fields.nc"))
                             for p in write_cg_vtk(nc, n_theta)]
        write_json(out / PARAVIEW_JSON, summary)
    except OSError as exc:
        raise SetupError(f"cannot write the ParaView files into {out}: {exc.strerror or exc}") from None
    finally:
        record_products(run.path, run.path / RESULTS, since)
    return summary
