"""ParaView's view of a run: VTK objects built from what a run folder holds, for either engine.

- :func:`particle_series`: one ``vtkPolyData`` per particle dump frame (read with
  ``postprocess.dumps``; an empty dump file is skipped and listed), points at the centres, one
  vertex each, with the point arrays ``id``, ``type``, ``radius`` and, where the dump has them,
  ``mass``, ``body`` (a clump's ``mol``), ``velocity``, ``force`` and ``omega`` (vectors); the
  same arrays whichever engine wrote the dumps;
- :func:`wall_series`: one ``vtkPolyData`` of the walls (``meshes/*.stl`` of the plan's walls)
  per wall-force sample, with the cell arrays ``wall`` (index into the field data's
  ``wall_names``), ``band`` and ``sector`` (-1 off the sensors), ``pressure`` (Pa, the sensor
  section's own mean normal pressure, NaN off the sensors), ``band_pressure`` (Pa, the mean of the
  band's sections: what results/wall_pressure.csv says at that time) and ``force`` (N, the net
  force the grains exert on that wall, from the engine-neutral ``wall_forces`` table);
- :func:`cg_grids`: the coarse-grained fields of ``siloflow cg`` (its NetCDF Dataset) as VTK
  structured data: a Cartesian grid as ``vtkImageData``; an axisymmetric (r, z) grid as its
  meridian half-plane (``vtkRectilinearGrid`` at y = 0, with a ``ring_volume`` cell array) and
  revolved into 3D (``vtkStructuredGrid``, vectors and tensors turned to x, y, z cell by cell).

Times are physical: a dump's or sample's step times the plan's time step (s). Everything here is
data only; ``postprocess.report.paraview`` writes the files and the ``.pvd`` collections.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from siloflow.errors import ReadError
from siloflow.extras import require
from siloflow.run_folder import PARTICLE_DUMPS, RunFolder

from .dumps import Frame, read_frames
from .memory import check_memory
from .wall_pressure import band_mean, band_pressures, wide_forces

#: the dump's vector columns and their names in VTK
VECTORS = {"velocity": ("vx", "vy", "vz"), "force": ("fx", "fy", "fz"), "omega": ("omegax", "omegay", "omegaz")}
#: the dump's scalar columns and their names in VTK (``radius`` is added from ``diameter`` too)
SCALARS = {"id": "id", "type": "type", "mass": "mass", "mol": "body"}
#: how many sectors an axisymmetric grid is revolved into, by default
N_THETA = 48


def vtk_modules():
    """The vtk modules used here (``siloflow.extras.MissingExtra``, a ``SetupError`` naming the
    extra, when the optional ``vtk`` package is missing)."""
    require("vtk", module="vtkmodules", purpose="ParaView files (siloflow vtk)")
    from vtkmodules import vtkCommonCore, vtkCommonDataModel
    from vtkmodules.util import numpy_support
    return vtkCommonCore, vtkCommonDataModel, numpy_support


def _array(values, name: str):
    """A VTK data array named ``name`` holding a copy of ``values`` ((n,) or (n, k))."""
    _, _, ns = vtk_modules()
    a = np.ascontiguousarray(values)
    if a.dtype.kind in "iu":
        a = a.astype(np.int64)
    elif a.dtype.kind != "f":
        a = a.astype(float)
    arr = ns.numpy_to_vtk(a, deep=True)
    arr.SetName(name)
    return arr


def _points(xyz):
    core, _, ns = vtk_modules()
    pts = core.vtkPoints()
    pts.SetData(ns.numpy_to_vtk(np.ascontiguousarray(xyz, dtype=float), deep=True))
    return pts


def _field(data_object, name: str, values) -> None:
    """Field data (one tuple, or a string array for text)."""
    core, _, _ = vtk_modules()
    if isinstance(values, (list, tuple)) and values and isinstance(values[0], str):
        arr = core.vtkStringArray()
        arr.SetName(name)
        for v in values:
            arr.InsertNextValue(v)
    else:
        arr = _array(np.atleast_1d(np.asarray(values)), name)
    data_object.GetFieldData().AddArray(arr)


# ----------------------------------------------------------------------------- particles

def particle_polydata(frame: Frame, time: float | None = None):
    """One dump frame as ``vtkPolyData``: a vertex per particle, the point arrays of the module
    doc (the dump's columns that are present), and ``TimeValue`` (s) in the field data."""
    _, dm, ns = vtk_modules()
    n = frame.n
    poly = dm.vtkPolyData()
    poly.SetPoints(_points(frame.positions() if n else np.zeros((0, 3))))
    verts = dm.vtkCellArray()
    verts.SetData(ns.numpy_to_vtkIdTypeArray(np.arange(n + 1, dtype=np.int64), deep=True),
                  ns.numpy_to_vtkIdTypeArray(np.arange(n, dtype=np.int64), deep=True))
    poly.SetVerts(verts)
    pd = poly.GetPointData()
    data = frame.data
    for column, name in SCALARS.items():
        if column in data:
            pd.AddArray(_array(data[column].to_numpy(), name))
    if "radius" in data or "diameter" in data:
        pd.AddArray(_array(frame.radii(), "radius"))
        pd.SetActiveScalars("radius")
    for name, columns in VECTORS.items():
        if all(c in data for c in columns):
            pd.AddArray(_array(data[list(columns)].to_numpy(dtype=float), name))
    if "velocity" in (pd.GetArrayName(k) for k in range(pd.GetNumberOfArrays())):
        pd.SetActiveVectors("velocity")
    if time is not None:
        _field(poly, "TimeValue", float(time))
    _field(poly, "timestep", int(frame.timestep))
    return poly


@dataclass
class Snapshot:
    """One VTK object of a series: its step, physical time (s) and the object."""

    step: int
    time: float
    data: object


def particle_dump_files(run: RunFolder) -> list[Path]:
    """The run's particle dump files in step order; ``ReadError`` saying why there are none: the
    case asked for none, or the files the plan says the run wrote are missing from output/dumps/."""
    files = run.dump_files("particles")
    if files is not None:
        return files
    if run.plan.outputs.dump_every is None:
        raise ReadError(f"{run.path}: no particle dumps: its case asked for none (no outputs.dump_interval and no "
                        "result that needs frames in outputs.results)")
    raise ReadError(f"{run.path}: the particle dumps are missing: the run was to write one every "
                    f"{run.plan.outputs.dump_every} steps as {run.dumps / PARTICLE_DUMPS}, and there is none "
                    f"(deleted or moved, or the run stopped before the first)")


class ParticleSeries:
    """The run's particle dumps, frame by frame (streamed: one frame in memory), as
    :func:`particle_polydata` at time = step x the plan's time step; every ``every``-th frame.
    ``ReadError`` (:func:`particle_dump_files`) when there are none. A dump file that holds no
    frame (empty) is skipped and listed in :attr:`empty` as the iteration passes it."""

    def __init__(self, run: RunFolder, every: int = 1):
        self.run, self.every = run, every
        self.files = particle_dump_files(run)
        self.empty: list[Path] = []

    def __iter__(self) -> Iterator[Snapshot]:
        dt = self.run.plan.dt
        self.empty = []
        k = 0
        for path in self.files:
            frames = 0
            for frame in read_frames(path):
                if k % self.every == 0:
                    time = frame.timestep * dt
                    yield Snapshot(frame.timestep, time, particle_polydata(frame, time))
                k += 1
                frames += 1
            if not frames:
                self.empty.append(path)


def particle_series(folder, every: int = 1) -> ParticleSeries:
    """The run folder ``folder``'s :class:`ParticleSeries`."""
    return ParticleSeries(folder if isinstance(folder, RunFolder) else RunFolder(folder), every)


# ----------------------------------------------------------------------------- walls

def _read_stl(path: Path):
    """Triangles of an STL file as (points (m, 3), triangles (k, 3)), points merged."""
    from stl import mesh as stl_mesh
    try:
        tri = stl_mesh.Mesh.from_file(str(path)).vectors.reshape(-1, 3).astype(float)
    except (OSError, ValueError, AssertionError) as exc:
        raise ReadError(f"cannot read the wall mesh {path}: {exc}") from None
    points, index = np.unique(np.round(tri, 12), axis=0, return_inverse=True)
    return points, index.reshape(-1, 3)


class WallMeshes:
    """The plan's walls (those grains touch: not the outlet's counting disc) as one surface:
    points, triangles, and per triangle the wall's index in ``walls``."""

    def __init__(self, run: RunFolder):
        self.walls = [w for w in run.plan.walls if w.is_wall]
        points, triangles, owner, offset = [], [], [], 0
        for k, w in enumerate(self.walls):
            p, t = _read_stl(run.path / w.file)
            points.append(p)
            triangles.append(t + offset)
            owner.append(np.full(len(t), k))
            offset += len(p)
        if not self.walls:
            raise ReadError(f"{run.path}: the plan has no walls")
        self.points = np.concatenate(points)
        self.triangles = np.concatenate(triangles)
        self.owner = np.concatenate(owner)

    def polydata(self):
        """The surface with its fixed cell arrays (``wall``, ``band``, ``sector``) and the
        walls' names and roles in the field data."""
        _, dm, ns = vtk_modules()
        poly = dm.vtkPolyData()
        poly.SetPoints(_points(self.points))
        n = len(self.triangles)
        polys = dm.vtkCellArray()
        polys.SetData(ns.numpy_to_vtkIdTypeArray(np.arange(0, 3 * n + 1, 3, dtype=np.int64), deep=True),
                      ns.numpy_to_vtkIdTypeArray(self.triangles.ravel().astype(np.int64), deep=True))
        poly.SetPolys(polys)
        cd = poly.GetCellData()
        cd.AddArray(_array(self.owner, "wall"))
        cd.AddArray(_array(self.per_cell([-1 if w.band is None else w.band for w in self.walls]), "band"))
        cd.AddArray(_array(self.per_cell([-1 if w.sector is None else w.sector for w in self.walls]), "sector"))
        _field(poly, "wall_names", [w.name for w in self.walls])
        _field(poly, "wall_roles", [w.role for w in self.walls])
        return poly

    def per_cell(self, per_wall) -> np.ndarray:
        """A per-wall value ((walls,) or (walls, k)) spread over the walls' triangles."""
        return np.asarray(per_wall)[self.owner]


@dataclass
class WallTables:
    """The per-sample values painted on the walls: ``forces`` (wide: ``step`` and
    ``<wall>_fx/fy/fz``, N), ``sectors`` and ``bands`` (``wall_pressure``'s tidy tables: per
    step and sensor section, per step and band; None without sensors)."""

    forces: object
    sectors: object = None
    bands: object = None


def wall_tables(run: RunFolder) -> WallTables:
    """The run's wall forces and sensor pressures, computed as ``siloflow post`` computes
    results/wall_pressure.csv (``postprocess.wall_pressure``); ``ReadError`` when the run sampled
    no wall forces."""
    plan = run.plan
    if not plan.outputs.wall_forces:
        raise ReadError(f"{run.path}: the run sampled no wall forces")
    try:
        forces = wide_forces(run.wall_forces(), plan.walls)
    except ValueError as exc:
        raise ReadError(f"{run.path}: {exc}") from None
    if not any(w.role == "band" for w in plan.walls):
        return WallTables(forces)
    sectors = band_pressures(forces, plan.walls)
    return WallTables(forces, sectors, band_mean(sectors))


def wall_series(folder, every: int = 1) -> Iterator[Snapshot]:
    """The walls at every ``every``-th wall-force sample, as ``vtkPolyData`` with the cell arrays
    of the module doc, at time = step x the plan's time step."""
    run = folder if isinstance(folder, RunFolder) else RunFolder(folder)
    meshes = WallMeshes(run)
    tables = wall_tables(run)
    base = meshes.polydata()
    walls = meshes.walls
    dt = run.plan.dt
    forces = tables.forces
    sensors = [k for k, w in enumerate(walls) if w.role == "band"]
    sector_p = band_p = None
    if tables.sectors is not None:
        key = {(walls[k].band, walls[k].sector): k for k in sensors}
        sec = tables.sectors.assign(wall=[key[(b, s)] for b, s in zip(tables.sectors.band, tables.sectors.sector)])
        sector_p = sec.pivot(index="step", columns="wall", values="pressure")
        band_p = tables.bands.pivot(index="step", columns="band", values="pressure")
    fcols = np.array([[f"{w.name}_{c}" for c in ("fx", "fy", "fz")] for w in walls])
    _, dm, _ = vtk_modules()
    for row in range(0, len(forces), every):
        step = int(forces.step.iloc[row])
        time = step * dt
        poly = dm.vtkPolyData()
        poly.ShallowCopy(base)
        # the arrays of the base stay shared; the per-sample ones are new
        cd = poly.GetCellData()
        f = forces.iloc[row][fcols.ravel()].to_numpy(float).reshape(-1, 3)
        cd.AddArray(_array(meshes.per_cell(f), "force"))
        pressure = np.full(len(walls), np.nan)
        band_pressure = np.full(len(walls), np.nan)
        if sector_p is not None:
            for k in sensors:
                pressure[k] = sector_p.at[step, k]
                band_pressure[k] = band_p.at[step, walls[k].band]
        cd.AddArray(_array(meshes.per_cell(pressure), "pressure"))
        cd.AddArray(_array(meshes.per_cell(band_pressure), "band_pressure"))
        cd.SetActiveScalars("pressure")
        _field(poly, "TimeValue", float(time))
        _field(poly, "timestep", step)
        yield Snapshot(step, time, poly)


# ----------------------------------------------------------------------------- coarse-grained fields

def _edges(centres) -> np.ndarray:
    """Cell edges of a regular axis given its cell centres."""
    c = np.asarray(centres, float)
    if len(c) == 1:
        raise ReadError("a one-cell axis has no spacing to rebuild its edges from")
    h = (c[-1] - c[0]) / (len(c) - 1)
    return np.concatenate([c - 0.5 * h, [c[-1] + 0.5 * h]])


def _components(ds, name: str, spatial: tuple) -> list[tuple[str, np.ndarray, str]]:
    """A data variable as VTK arrays: [(name, values (..., k), kind)] with kind ``scalar``,
    ``vector`` (3, in the grid's component order) or ``tensor`` (9, row-major in that order); a
    ``species`` dimension gives one array per species, ``<name>_<k>``."""
    var = ds[name]
    extra = [d for d in var.dims if d not in spatial]
    var = var.transpose(*spatial, *extra)
    if "species" in extra:
        rest = [d for d in extra if d != "species"]
        out = []
        for k in range(var.sizes["species"]):
            sub = var.isel(species=k).to_dataset(name=f"{name}_{k}")
            sub = sub.assign_coords({c: ds[c] for c in rest if c in ds.coords})
            out += _components(sub, f"{name}_{k}", spatial)
        return out
    values = var.values
    if not extra:
        return [(name, values, "scalar")]
    if extra == ["component"]:
        return [(name, values, "vector")]
    if extra == ["tensor"]:
        return [(name, values, "tensor")]
    if extra == ["sym"]:
        names = [str(s) for s in ds["sym"].values]
        letters = "".join(dict.fromkeys("".join(names)))       # e.g. "rtz" or "xyz", in order
        full = np.empty(values.shape[:-1] + (9,))
        for a in range(3):
            for b in range(3):
                pair = letters[a] + letters[b]
                k = names.index(pair) if pair in names else names.index(letters[b] + letters[a])
                full[..., 3 * a + b] = values[..., k]
        return [(name, full, "tensor")]
    return [(f"{name}_{k}", values[..., k], "scalar") for k in range(values.shape[-1])]


def _flat(values, kind: str):
    """Cell values (spatial..., [k]) as VTK's cell order: the first spatial dimension (z)
    slowest, the last (x or r) fastest, which is numpy's C order."""
    ncomp = {"scalar": 1, "vector": 3, "tensor": 9}[kind]
    a = np.asarray(values, float)
    return a.reshape(-1) if ncomp == 1 else a.reshape(-1, ncomp)


def _add_fields(cell_data, arrays) -> None:
    for name, values, kind in arrays:
        cell_data.AddArray(_array(values, name))
        if name == "rho":
            cell_data.SetActiveScalars(name)
        if name == "velocity":
            cell_data.SetActiveVectors(name)


def _species_field(obj, ds) -> None:
    if "species" in ds.coords:
        _field(obj, "species", np.asarray(ds["species"].values, float))


def cartesian_image(ds):
    """A Cartesian grid's fields (dims z, y, x) as ``vtkImageData`` with cell data."""
    _, dm, _ = vtk_modules()
    spatial = ("z", "y", "x")
    edges = [_edges(ds[d].values) if ds.sizes[d] > 1 else None for d in "xyz"]
    spacing, origin = [], []
    for a, d in enumerate("xyz"):
        if edges[a] is not None:
            spacing.append(float(edges[a][1] - edges[a][0]))
            origin.append(float(edges[a][0]))
        else:                       # one cell (a slab): its thickness from the dataset
            thickness = float(ds.attrs.get("slab_thickness_m", 0.0)) or 1.0
            spacing.append(thickness)
            origin.append(float(ds[d].values[0]) - 0.5 * thickness)
    img = dm.vtkImageData()
    img.SetDimensions(ds.sizes["x"] + 1, ds.sizes["y"] + 1, ds.sizes["z"] + 1)
    img.SetOrigin(*origin)
    img.SetSpacing(*spacing)
    arrays = [(n, _flat(v, k), k) for var in ds.data_vars for n, v, k in _components(ds, var, spatial)]
    _add_fields(img.GetCellData(), arrays)
    _species_field(img, ds)
    return img


def ring_volumes(r_edges, z_edges) -> np.ndarray:
    """Volumes (nz, nr) of the annular cells, m3: pi (r_out^2 - r_in^2) dz."""
    ring = np.pi * np.diff(np.asarray(r_edges) ** 2)
    return np.diff(np.asarray(z_edges))[:, None] * ring[None, :]


def meridian_grid(ds):
    """An (r, z) grid's fields on its meridian half-plane, x = r >= 0 at y = 0, as
    ``vtkRectilinearGrid`` (2D cells); (r, theta, z) components are (x, y, z) there. The cell
    array ``ring_volume`` (m3) is each cell's ring: sum(rho ring_volume) is the mass."""
    _, dm, _ = vtk_modules()
    r_e, z_e = _edges(ds["r"].values), _edges(ds["z"].values)
    grid = dm.vtkRectilinearGrid()
    grid.SetDimensions(len(r_e), 1, len(z_e))
    grid.SetXCoordinates(_array(r_e, "r"))
    grid.SetYCoordinates(_array(np.zeros(1), "y"))
    grid.SetZCoordinates(_array(z_e, "z"))
    arrays = [(n, _flat(v, k), k) for var in ds.data_vars for n, v, k in _components(ds, var, ("z", "r"))]
    arrays.append(("ring_volume", ring_volumes(r_e, z_e).ravel(), "scalar"))
    _add_fields(grid.GetCellData(), arrays)
    _species_field(grid, ds)
    return grid


def revolved_bytes(ds, n_theta: int) -> int:
    """Bytes (float64) :func:`revolved_grid` holds at once for ``ds`` in ``n_theta`` sectors: each
    array's values in every 3D cell twice (turned or broadcast and flattened, then VTK's copy; a
    symmetric tensor as 9 components) and the points five times (mesh, stack, order, VTK's copy)."""
    nr, nz = int(ds.sizes["r"]), int(ds.sizes["z"])
    comps = 0
    for name in ds.data_vars:
        var = ds[name]
        n = math.prod(int(var.sizes[d]) for d in var.dims if d not in ("z", "r"))
        comps += n // 6 * 9 if "sym" in var.dims else n
    return 8 * (2 * nz * nr * int(n_theta) * comps + 15 * (nr + 1) * (int(n_theta) + 1) * (nz + 1))


def revolved_grid(ds, n_theta: int = N_THETA):
    """An (r, z) grid's fields revolved about the z axis into ``n_theta`` sectors, as
    ``vtkStructuredGrid`` of hexahedra (prisms on the axis), vectors and tensors turned from
    (r, theta, z) to (x, y, z) at each sector's middle angle. Each ring of points is drawn at
    r sqrt(dtheta / sin dtheta) (0.07 % out at 48 sectors), so that the polygon's annuli keep the
    circle's areas: integrating over the cells (ParaView's Integrate Variables) gives the
    NetCDF's integrals (the mass, from rho) to round-off."""
    if n_theta < 3:
        raise ValueError("a revolved grid needs at least 3 sectors")
    check_memory(revolved_bytes(ds, n_theta), f"the revolved VTK grid of {ds.sizes['r']} x {n_theta} x "
                 f"{ds.sizes['z']} (r, theta, z) cells",
                 "revolve into fewer sectors (siloflow vtk --theta; Python n_theta=...), or coarse-grain on "
                 "fewer cells (siloflow cg --nr, --nz)")
    _, dm, _ = vtk_modules()
    r_e, z_e = _edges(ds["r"].values), _edges(ds["z"].values)
    nr, nz = len(r_e) - 1, len(z_e) - 1
    dth = 2 * math.pi / n_theta
    scale = math.sqrt(dth / math.sin(dth))
    phi = np.arange(n_theta + 1) * dth
    # points: r fastest, then theta, then z
    R, P, Z = np.meshgrid(r_e * scale, phi, z_e, indexing="ij")
    xyz = np.stack([R * np.cos(P), R * np.sin(P), Z], axis=-1).transpose(2, 1, 0, 3).reshape(-1, 3)
    grid = dm.vtkStructuredGrid()
    grid.SetDimensions(nr + 1, n_theta + 1, nz + 1)
    grid.SetPoints(_points(xyz))
    tc = (np.arange(n_theta) + 0.5) * dth
    c, s = np.cos(tc), np.sin(tc)
    rot = np.zeros((n_theta, 3, 3))
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = c, -s, s, c, 1.0
    arrays = []
    for var in ds.data_vars:
        for name, v, kind in _components(ds, var, ("z", "r")):
            v = np.asarray(v, float)[:, None]                  # (nz, 1, nr, ...)
            if kind == "scalar":
                out = np.broadcast_to(v, (nz, n_theta, nr))
            elif kind == "vector":
                out = np.einsum("tij,zxrj->ztri", rot, v)
            else:
                t = v.reshape(nz, 1, nr, 3, 3)
                out = np.einsum("tij,zxrjk,tlk->ztril", rot, t, rot).reshape(nz, n_theta, nr, 9)
            arrays.append((name, _flat(out, kind), kind))
    _add_fields(grid.GetCellData(), arrays)
    _species_field(grid, ds)
    _field(grid, "n_theta", n_theta)
    return grid


def cg_grids(ds, n_theta: int = N_THETA) -> dict:
    """The VTK objects of a coarse-graining's Dataset, by file stem: ``fields`` (an image for a
    Cartesian grid, the revolved structured grid for an (r, z) grid) and, for (r, z),
    ``fields_rz`` (the meridian half-plane)."""
    if "r" in ds.dims:
        return {"fields": revolved_grid(ds, n_theta), "fields_rz": meridian_grid(ds)}
    if all(d in ds.dims for d in "xyz"):
        return {"fields": cartesian_image(ds)}
    raise ReadError(f"not a coarse-graining's fields (dimensions {', '.join(map(str, ds.dims))})")


def cg_mass(ds) -> float:
    """The mass (kg) the NetCDF fields hold: rho integrated over the grid's cells."""
    rho = ds["rho"]
    if "r" in ds.dims:
        vol = ring_volumes(_edges(ds["r"].values), _edges(ds["z"].values))
        return float((rho.transpose("z", "r").values * vol).sum())
    spacing = []
    for d in "xyz":
        if ds.sizes[d] > 1:
            e = _edges(ds[d].values)
            spacing.append(e[1] - e[0])
        else:
            spacing.append(float(ds.attrs.get("slab_thickness_m", 0.0)) or 1.0)
    return float(rho.values.sum() * np.prod(spacing))
