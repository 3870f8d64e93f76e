"""ParaView files (``siloflow vtk``; ``postprocess.paraview`` computes, ``postprocess.report.paraview``
writes): every file is read back with VTK's own readers and each .pvd with xml.etree. On a real
LIGGGHTS run and a real LAMMPS run: the particle series has the dumps' physical times and, frame
by frame, their particles and values; the walls' per-band mean pressure is results/wall_pressure.csv
at the same time; the coarse-grained fields integrate to the NetCDF's mass. On synthetic fields:
a Cartesian grid as an image, and the revolved (r, z) grid's vectors and tensors turned to x, y, z."""
from __future__ import annotations

import json
import math
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from conftest import needs_liggghts

vtk = pytest.importorskip("vtk", reason="the vtk extra is not installed (pip install '.[vtk]')")

from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402
from vtkmodules.vtkFiltersParallel import vtkIntegrateAttributes  # noqa: E402
from vtkmodules.vtkIOXML import (vtkXMLImageDataReader, vtkXMLPolyDataReader,  # noqa: E402
                                 vtkXMLRectilinearGridReader, vtkXMLStructuredGridReader)

from siloflow.cli import app  # noqa: E402
from siloflow.run_folder import RunFolder, read_manifest  # noqa: E402

from postprocess.dumps import read_frames  # noqa: E402


# ---------------------------------------------------------------- readers
def read_pvd(path: Path) -> list[tuple[float, int, str, str]]:
    """(timestep, part, file, name) of each DataSet of a collection."""
    root = ET.parse(path).getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    return [(float(d.get("timestep")), int(d.get("part")), d.get("file"), d.get("name"))
            for d in root.find("Collection").iter("DataSet")]


def read(path: Path):
    reader = {".vtp": vtkXMLPolyDataReader, ".vti": vtkXMLImageDataReader, ".vtr": vtkXMLRectilinearGridReader,
              ".vts": vtkXMLStructuredGridReader}[path.suffix]()
    assert reader.CanReadFile(str(path)), path
    reader.SetFileName(str(path))
    reader.Update()
    return reader.GetOutput()


def point_array(obj, name: str) -> np.ndarray:
    arr = obj.GetPointData().GetArray(name)
    assert arr is not None, f"no point array {name}"
    return vtk_to_numpy(arr)


def cell_array(obj, name: str) -> np.ndarray:
    arr = obj.GetCellData().GetArray(name)
    assert arr is not None, f"no cell array {name}"
    return vtk_to_numpy(arr)


def integral(obj, name: str) -> float:
    """The volume integral of a cell array (VTK's vtkIntegrateAttributes, ParaView's Integrate Variables)."""
    f = vtkIntegrateAttributes()
    f.SetInputData(obj)
    f.Update()
    return float(vtk_to_numpy(f.GetOutput().GetCellData().GetArray(name))[0])


def invoke(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.output


# ---------------------------------------------------------------- one run folder, checked
def check_run_folder(folder: Path) -> None:
    run = RunFolder(folder)
    dt = run.plan.dt
    invoke("cg", folder, "--nr", 6, "--nz", 12)
    output = invoke("vtk", folder)
    pv = folder / "results" / "paraview"
    assert "run.pvd" in output

    # particles: the dumps' frames at step x dt, N and values frame by frame
    frames = list(read_frames(run.dump_files("particles")))
    series = read_pvd(pv / "particles.pvd")
    assert [t for t, *_ in series] == pytest.approx([f.timestep * dt for f in frames], rel=1e-12, abs=0)
    assert {p for _, p, _, _ in series} == {0}
    flow = run.flow()                               # the engine's own clock agrees (its samples' step and time)
    inside = [(f.timestep, t) for f, (t, *_) in zip(frames, series) if flow.step.min() <= f.timestep <= flow.step.max()]
    assert len(inside) >= 3
    np.testing.assert_allclose([t for _, t in inside], np.interp([s for s, _ in inside], flow.step, flow.time),
                               rtol=1e-9, atol=1e-12)
    for frame, (t, _, file, _) in zip(frames, series):
        poly = read(pv / file)
        assert poly.GetNumberOfPoints() == frame.n and poly.GetNumberOfVerts() == frame.n
        assert vtk_to_numpy(poly.GetFieldData().GetArray("TimeValue"))[0] == pytest.approx(t, rel=1e-12)
        np.testing.assert_array_equal(point_array(poly, "id"), frame.column("id"))
        np.testing.assert_array_equal(point_array(poly, "type"), frame.column("type"))
        np.testing.assert_allclose(vtk_to_numpy(poly.GetPoints().GetData()), frame.positions(), rtol=1e-15)
        np.testing.assert_allclose(point_array(poly, "radius"), frame.radii(), rtol=1e-15)
        for name, cols in (("velocity", ["vx", "vy", "vz"]), ("force", ["fx", "fy", "fz"]),
                           ("omega", ["omegax", "omegay", "omegaz"])):
            np.testing.assert_allclose(point_array(poly, name), frame.data[cols].to_numpy(float), rtol=1e-15)

    # walls: per-band mean of the sensor sections = wall_pressure.csv at the same time
    expected = pd.read_csv(run.results / "wall_pressure.csv")
    walls = read_pvd(pv / "walls.pvd")
    times = sorted(expected.time.unique())
    assert [t for t, *_ in walls] == pytest.approx(times, rel=1e-12)
    plan_walls = [w for w in run.plan.walls if w.is_wall]
    for t, _, file, _ in walls[:: max(1, len(walls) // 12)] + walls[-1:]:
        poly = read(pv / file)
        names = poly.GetFieldData().GetAbstractArray("wall_names")
        assert [names.GetValue(k) for k in range(names.GetNumberOfValues())] == [w.name for w in plan_walls]
        wall, band = cell_array(poly, "wall"), cell_array(poly, "band")
        pressure, band_p = cell_array(poly, "pressure"), cell_array(poly, "band_pressure")
        assert cell_array(poly, "force").shape == (poly.GetNumberOfCells(), 3)
        per_wall = pd.DataFrame({"wall": wall, "band": band, "pressure": pressure}).groupby("wall").first()
        sensors = per_wall[per_wall.band >= 0]
        assert sensors.pressure.notna().all() and per_wall[per_wall.band < 0].pressure.isna().all()
        mine = sensors.groupby("band").pressure.mean()
        row = expected[np.isclose(expected.time, t, rtol=1e-12, atol=0)].set_index("band").pressure
        assert len(row) == len(mine) > 0
        np.testing.assert_allclose(mine.to_numpy(), row.loc[mine.index].to_numpy(), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(band_p[band >= 0], row.loc[band[band >= 0]].to_numpy(), rtol=1e-9, atol=1e-9)

    # run.pvd: both parts at every time either has, each its latest file at or before it
    combined = read_pvd(pv / "run.pvd")
    all_times = sorted({t for t, *_ in series} | {t for t, *_ in walls})
    assert sorted({t for t, *_ in combined}) == pytest.approx(all_times, rel=1e-12)
    for t, part, file, name in combined:
        source = series if part == 0 else walls
        assert name == ("particles", "walls")[part]
        assert file == [f for ts, _, f, _ in source if ts <= t][-1]
    assert (pv / "paraview.json").is_file() and json.loads((pv / "paraview.json").read_text())["particles"][
        "frames"] == len(frames)

    # the coarse-grained fields: the same mass as the NetCDF's, 3D and on the meridian plane
    import xarray as xr
    with xr.open_dataset(folder / "results" / "cg" / "fields.nc") as ds:
        rho = ds.rho.transpose("z", "r").values
        r, z = ds.r.values, ds.z.values
    dr, dz = r[1] - r[0], z[1] - z[0]
    edges = np.arange(len(r) + 1) * dr
    mass = float((rho * (math.pi * np.diff(edges ** 2) * dz)[None, :]).sum())
    assert mass > 0
    revolved = read(folder / "results" / "cg" / "fields.vts")
    assert revolved.GetNumberOfCells() == rho.size * 48
    assert integral(revolved, "rho") == pytest.approx(mass, rel=1e-9)
    plane = read(folder / "results" / "cg" / "fields_rz.vtr")
    assert plane.GetNumberOfCells() == rho.size
    assert float((cell_array(plane, "rho") * cell_array(plane, "ring_volume")).sum()) == pytest.approx(mass, rel=1e-12)
    np.testing.assert_allclose(cell_array(plane, "rho"), rho.ravel(), rtol=1e-15)

    # what was written is siloflow's (recorded in the manifest)
    products = read_manifest(folder)["products"]
    assert {"results/paraview/run.pvd", "results/cg/fields.vts", "results/cg/fields_rz.vtr",
            f"results/paraview/{series[-1][2]}"} <= set(products)


@needs_liggghts
def test_paraview_files_of_a_liggghts_run(small_run, tmp_path):
    _, folder, _, _ = small_run
    copy = tmp_path / "liggghts_run"
    shutil.copytree(folder, copy)
    check_run_folder(copy)


def test_paraview_files_of_a_lammps_run(tmp_path):
    """A few hundred grains on LAMMPS, 1 rank (about 15 s), post-processed as `siloflow run` does."""
    import siloflow
    from test_lammps_engine import tiny
    data = tiny(discharge={"duration": 0.15}, outputs={"sample_interval": 0.005, "dump_interval": 0.02})
    run = siloflow.run(data, tmp_path / "lammps_run")
    assert RunFolder(run.folder).dump_layout.engine == "lammps"
    check_run_folder(tmp_path / "lammps_run")


# ---------------------------------------------------------------- synthetic fields
def test_a_cartesian_coarse_graining_is_an_image_with_the_same_mass(tmp_path):
    from postprocess.cg_grids import CartesianGrid
    from postprocess.cg_kernels import make_kernel
    from postprocess.coarse_grain import CoarseGraining
    from postprocess.dumps import Frame
    from postprocess.report.files import write_netcdf

    rng = np.random.default_rng(3)
    n = 300
    pos = rng.uniform([-0.02, -0.02, 0.0], [0.02, 0.02, 0.05], (n, 3))
    data = pd.DataFrame({"id": np.arange(1, n + 1), "type": 1, "x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2],
                         "vx": 0.1, "vy": -0.2, "vz": rng.normal(size=n), "radius": rng.choice([0.001, 0.0015], n),
                         "mass": 0.0})
    data["mass"] = 2500.0 * 4 / 3 * math.pi * data.radius ** 3
    frame = Frame(100, np.array([[-0.03, 0.03], [-0.03, 0.03], [-0.01, 0.06]]), data)
    grid = CartesianGrid([-0.03, -0.03, -0.01], [0.03, 0.03, 0.06], (8, 8, 10))
    cg = CoarseGraining(grid, make_kernel("gaussian", 1.0, "radius", 0.00125), 2500.0, "radius").run([frame])
    ds = cg.dataset()
    write_netcdf(ds, tmp_path / "fields.nc")
    invoke("vtk", tmp_path / "fields.nc")
    img = read(tmp_path / "fields.vti")
    assert img.GetDimensions() == (9, 9, 11) and img.GetNumberOfCells() == 8 * 8 * 10
    assert img.GetSpacing() == pytest.approx((0.0075, 0.0075, 0.007))
    assert img.GetOrigin() == pytest.approx((-0.03, -0.03, -0.01))
    mass = float(ds.rho.values.sum() * grid.cell_volume)
    assert integral(img, "rho") == pytest.approx(mass, rel=1e-9)
    np.testing.assert_allclose(cell_array(img, "velocity"), ds.velocity.values.reshape(-1, 3), rtol=1e-15)
    # a symmetric tensor (xx yy zz xy xz yz) as VTK's full 9 components, row-major
    sym = ds.kinetic_stress.values.reshape(-1, 6)
    full = cell_array(img, "kinetic_stress")
    np.testing.assert_allclose(full[:, [0, 4, 8, 1, 2, 5]], sym, rtol=1e-15)
    np.testing.assert_allclose(full[:, [3, 6, 7]], sym[:, [3, 4, 5]], rtol=1e-15)
    # one array per species, and their values in the field data
    assert {"rho_species_0", "rho_species_1"} <= {img.GetCellData().GetArrayName(k)
                                                 for k in range(img.GetCellData().GetNumberOfArrays())}
    np.testing.assert_allclose(vtk_to_numpy(img.GetFieldData().GetArray("species")), [0.001, 0.0015])


def test_the_revolved_grid_turns_vectors_and_tensors_to_cartesian():
    import xarray as xr

    from postprocess.paraview import revolved_grid

    nz, nr = 3, 4
    r = (np.arange(nr) + 0.5) * 0.01
    z = (np.arange(nz) + 0.5) * 0.02
    vel = np.zeros((nz, nr, 3))
    vel[..., 0], vel[..., 1], vel[..., 2] = 1.0, 0.5, -2.0           # v_r, v_theta, v_z
    tensor = np.zeros((nz, nr, 9))
    tensor[..., 0], tensor[..., 4], tensor[..., 8] = 3.0, 1.0, 7.0    # rr, tt, zz
    ds = xr.Dataset({"rho": (("z", "r"), np.ones((nz, nr))), "velocity": (("z", "r", "component"), vel),
                     "contact_stress": (("z", "r", "tensor"), tensor)},
                    coords={"z": z, "r": r, "component": list("rtz"),
                            "tensor": [a + b for a in "rtz" for b in "rtz"]})
    n_theta = 8
    grid = revolved_grid(ds, n_theta)
    v = cell_array(grid, "velocity").reshape(nz, n_theta, nr, 3)
    s = cell_array(grid, "contact_stress").reshape(nz, n_theta, nr, 3, 3)
    for j in range(n_theta):
        th = (j + 0.5) * 2 * math.pi / n_theta
        er, et = np.array([math.cos(th), math.sin(th), 0]), np.array([-math.sin(th), math.cos(th), 0])
        np.testing.assert_allclose(v[1, j, 2], 1.0 * er + 0.5 * et + [0, 0, -2.0], atol=1e-14)
        np.testing.assert_allclose(s[0, j, 0], 3 * np.outer(er, er) + np.outer(et, et) + np.diag([0, 0, 7.0]),
                                   atol=1e-14)
    # the annuli keep their areas: the revolved grid's volume is the cylinder's
    assert integral(grid, "rho") == pytest.approx(math.pi * 0.04 ** 2 * 0.06, rel=1e-12)


def test_without_vtk_the_message_says_what_to_install(monkeypatch):
    import sys

    from postprocess.paraview import vtk_modules
    from siloflow.errors import SetupError
    monkeypatch.setitem(sys.modules, "vtkmodules", None)
    with pytest.raises(SetupError, match=r"siloflow\[vtk\]"):
        vtk_modules()


def test_vtk_refuses_what_is_not_a_run_or_fields(tmp_path):
    result = CliRunner().invoke(app, ["vtk", str(tmp_path)])
    assert result.exit_code == 1 and "neither a siloflow run folder" in " ".join(result.output.split())
