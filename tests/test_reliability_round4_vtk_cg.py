"""Issue 55, round 4: ``siloflow vtk -o`` never overwrites or deletes a file siloflow did not write
(it replaces only its own earlier output, recorded in paraview.json or the run's manifest);
missing dumps are said to be missing, where; an empty dump is skipped with a warning and
recorded; and a coarse-graining grid (or a revolved VTK grid) too large for the machine's memory
is refused quickly, before it is allocated, naming the options and the estimate.

The run folder here is rendered (no engine) and given synthetic dumps, a summary and a
``complete`` status: enough for ``siloflow vtk`` and ``siloflow cg`` / ``Run.cg``."""
from __future__ import annotations

import json
import shutil
import time
import tracemalloc

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from conftest import QUICK, render

pytest.importorskip("vtk", reason="the vtk extra is not installed (pip install '.[vtk]')")

import postprocess.memory as memory  # noqa: E402
import postprocess.report.cg  # noqa: E402,F401  (siloflow cg's modules, imported before anything is timed)
import siloflow  # noqa: E402
from postprocess.cg_grids import AxisymmetricGrid  # noqa: E402
from postprocess.cg_kernels import make_kernel  # noqa: E402
from postprocess.coarse_grain import CoarseGraining  # noqa: E402
from postprocess.report.paraview import EmptyDumpWarning, write_run_paraview  # noqa: E402
from siloflow.atomic_files import write_json  # noqa: E402
from siloflow.case_file import load_case  # noqa: E402
from siloflow.cli import app  # noqa: E402
from siloflow.errors import ReadError, SetupError  # noqa: E402
from siloflow.run_folder import RunFolder, write_status  # noqa: E402

FRAMES = 13


def dump_text(step: int, rng, n: int = 300) -> str:
    """A LIGGGHTS text dump frame of ``n`` grains inside the quick silo (r < 13 mm)."""
    r, th = 0.013 * np.sqrt(rng.random(n)), rng.random(n) * 2 * np.pi
    z, v = rng.uniform(0.005, 0.15, n), rng.normal(scale=0.05, size=(n, 3))
    lines = ["ITEM: TIMESTEP", str(step), "ITEM: NUMBER OF ATOMS", str(n), "ITEM: BOX BOUNDS ff ff ff",
             "-0.016 0.016", "-0.016 0.016", "-0.01 0.31", "ITEM: ATOMS id type x y z vx vy vz radius"]
    lines += [f"{i + 1} 1 {r[i] * np.cos(th[i]):.8g} {r[i] * np.sin(th[i]):.8g} {z[i]:.8g} "
              f"{v[i, 0]:.6g} {v[i, 1]:.6g} {v[i, 2]:.6g} 0.0015" for i in range(n)]
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """The quick case rendered with dumps and no wall forces (results: porosity), given 13 dumps,
    a summary with its steady window and a complete status."""
    tmp = tmp_path_factory.mktemp("round4")
    data = yaml.safe_load(QUICK.read_text())
    data["outputs"] = {"results": ["porosity"], "dump_interval": 0.1}
    (tmp / "case.yaml").write_text(yaml.safe_dump(data))
    folder = render(load_case(tmp / "case.yaml"), tmp / "run")
    run = RunFolder(folder)
    every = run.plan.outputs.dump_every
    run.dumps.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    for k in range(FRAMES):
        (run.dumps / f"dump.{k * every}.txt").write_text(dump_text(k * every, rng))
    run.results.mkdir(exist_ok=True)
    write_json(run.summary_file, {"flow_rate": {"t_start": 0.0, "t_end": FRAMES * every * run.plan.dt}})
    write_status(folder, "complete")
    return folder


@pytest.fixture
def run_folder(rendered, tmp_path):
    copy = tmp_path / "run"
    shutil.copytree(rendered, copy)
    return copy


def cli(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def said(result) -> str:
    return " ".join(result.output.split())


def squeezed(result) -> str:
    """The output without any whitespace: a path the console wrapped is whole again."""
    return "".join(result.output.split())


# ---------------------------------------------------------------- vtk -o: the user's files
def test_vtk_refuses_a_folder_holding_the_users_files_and_replaces_its_own(run_folder, tmp_path):
    out = tmp_path / "pv"
    (out / "particles").mkdir(parents=True)
    mine = {"run.pvd": b"my own collection", "paraview.json": b'{"mine": true}',
            "particles/particles_0000000000.vtp": b"my frame", "notes.txt": b"notes"}
    for name, data in mine.items():
        (out / name).write_bytes(data)
    result = cli("vtk", run_folder, "-o", out)
    assert result.exit_code == 1 and "Traceback" not in result.output
    text = said(result)
    assert "holds files siloflow did not write" in text
    for name in mine:
        assert name in squeezed(result)
        assert (out / name).read_bytes() == mine[name]              # nothing overwritten
    assert not (out / "particles.pvd").exists()                     # nothing written

    # a new folder is written, and recorded; the next vtk replaces it (and removes frames it
    # no longer writes); a file the user changed since is refused
    out = tmp_path / "pv2"
    assert cli("vtk", run_folder, "-o", out).exit_code == 0
    record = json.loads((out / "paraview.json").read_text())["files"]
    assert {"run.pvd", "particles.pvd", "particles/particles_0000000000.vtp"} <= set(record)
    assert len(list((out / "particles").iterdir())) == FRAMES
    result = cli("vtk", run_folder, "-o", out, "--every", 2)
    assert result.exit_code == 0, result.output
    assert len(list((out / "particles").iterdir())) == (FRAMES + 1) // 2
    (out / "run.pvd").write_text("edited")
    result = cli("vtk", run_folder, "-o", out)
    assert result.exit_code == 1 and "run.pvd(editedsincesiloflowwroteit)" in squeezed(result)
    assert (out / "run.pvd").read_text() == "edited"

    # the default folder inside the run: written twice (its own record), then a user's file there is kept
    assert cli("vtk", run_folder).exit_code == 0
    assert cli("vtk", run_folder).exit_code == 0
    default = run_folder / "results" / "paraview"
    (default / "particles" / "notes.txt").write_text("mine")
    result = cli("vtk", run_folder)
    assert result.exit_code == 1 and "particles/notes.txt" in squeezed(result)
    assert (default / "particles" / "notes.txt").read_text() == "mine"


def test_vtk_refuses_a_users_file_where_the_fields_vtk_goes(run_folder):
    """The coarse-grained fields' VTK files beside results/cg/fields.nc: a user's file there is
    not overwritten either."""
    import xarray as xr
    cg = run_folder / "results" / "cg"
    cg.mkdir(parents=True)
    xr.Dataset({"rho": (("z", "r"), np.ones((3, 4)))},
               coords={"z": [0.01, 0.03, 0.05], "r": [0.001, 0.003, 0.005, 0.007]}).to_netcdf(cg / "fields.nc")
    (cg / "fields.vts").write_text("my revolved grid")
    result = cli("vtk", run_folder)
    assert result.exit_code == 1 and "results/cg/fields.vts" in squeezed(result)
    assert (cg / "fields.vts").read_text() == "my revolved grid"
    assert not (run_folder / "results" / "paraview").exists()


# ---------------------------------------------------------------- vtk: missing and empty dumps
def test_vtk_says_the_dumps_are_missing_and_where(run_folder):
    shutil.rmtree(run_folder / "output" / "dumps")
    result = cli("vtk", run_folder)
    text = said(result)
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert "particle dumps are missing" in text and "output/dumps/dump.*.txt" in squeezed(result)
    assert "was not set" not in text                 # the case did set it
    with pytest.raises(ReadError, match="particle dumps are missing"):
        siloflow.open_run(run_folder).cg()


def test_vtk_warns_of_an_empty_dump_and_records_it(run_folder):
    run = RunFolder(run_folder)
    middle = run.dumps / f"dump.{6 * run.plan.outputs.dump_every}.txt"
    middle.write_text("")
    result = cli("vtk", run_folder)
    assert result.exit_code == 0, result.output
    text = said(result)
    assert "warning: 1 empty particle dump file(s) skipped" in text and "output/dumps/" + middle.name in squeezed(result)
    summary = json.loads((run.results / "paraview" / "paraview.json").read_text())
    assert summary["particles"]["frames"] == FRAMES - 1
    assert summary["particles"]["skipped_empty_dumps"] == ["output/dumps/" + middle.name]
    with pytest.warns(EmptyDumpWarning, match=middle.name):
        write_run_paraview(run_folder, cg=False)


# ---------------------------------------------------------------- cg: memory
def _refused_quickly(call) -> str:
    """``call``'s SetupError, checked to come within a second and without allocating the grid."""
    tracemalloc.start()
    start = time.perf_counter()
    try:
        with pytest.raises(SetupError) as info:
            call()
    finally:
        took = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert took < 1.0, f"took {took:.2f} s"
    assert peak < 150e6, f"allocated {peak / 1e6:.0f} MB"
    return " ".join(str(info.value).split())


def test_an_absurd_grid_is_refused_before_it_is_allocated(run_folder):
    run = siloflow.open_run(run_folder)
    with pytest.raises(SetupError):                   # the imports and first read, not timed
        run.cg(nr=10 ** 5, nz=10 ** 5)
    text = _refused_quickly(lambda: run.cg(nr=10 ** 9, nz=10 ** 9))
    assert "(r, z) grid of 1000000000 x 1000000000 cells" in text and "GB of memory" in text
    assert "--nr and --nz" in text and "Run.cg(nr=..., nz=...)" in text and "available" in text
    text = _refused_quickly(lambda: run.cg(nr=3000, nz=3000, grid="cartesian"))
    assert "Cartesian grid of 3000 x 3000 x 3000" in text and "nr x nr x nz" in text
    text = _refused_quickly(lambda: run.cg(nr=3000, nz=3000, method="lattice", refine=8))
    assert "lattice" in text and "--refine" in text

    # the command line: a message, no traceback
    start = time.perf_counter()
    result = cli("cg", run_folder, "--nr", 100000, "--nz", 100000)
    assert time.perf_counter() - start < 1.0
    assert result.exit_code == 1 and "Traceback" not in result.output and "MemoryError" not in result.output
    text = said(result)
    assert "SetupError" in text and "100000 x 100000 cells" in text and "--nr and --nz" in text
    assert not (run_folder / "results" / "cg" / "fields.nc").exists()


def test_the_limit_is_half_the_available_memory(run_folder, monkeypatch):
    """A grid the machine could hold is refused when its estimate passes half of what is
    available (here made 400 MB), before allocating it; the same grid passes the check with more."""
    cg = CoarseGraining(AxisymmetricGrid(0.015, 0.0, 0.3, 1000, 3000), make_kernel("gaussian", 2.0, "radius", 0.0015),
                        2500.0, "radius")
    need = cg.memory_estimate(300, 0, 1)
    assert 1.5e9 < need < 4e9                          # 3e6 cells x 20 sums: GB, not MB nor TB
    monkeypatch.setattr(memory, "available_memory", lambda: 2 * need + 10)
    memory.check_memory(need, "it", "fix")             # fits: half of the available
    monkeypatch.setattr(memory, "available_memory", lambda: int(400e6))
    text = _refused_quickly(lambda: siloflow.open_run(run_folder).cg(nr=1000, nz=3000))
    assert "more than 50% of the 400 MB this machine has available (the limit, 200 MB)" in text
    assert f"about {memory.size_text(cg.memory_estimate(300, 0, 1))}" in text
    # --per-frame keeps every frame's sums: refused at the frame that would pass the limit
    monkeypatch.setattr(memory, "available_memory", lambda: int(2 * cg.memory_estimate(300, 0, 1, kept_frames=3)))
    cg.per_frame = True
    cg._memory = (memory.memory_budget(), 300, 0, 1)
    cg.frames = [None] * 3
    with pytest.raises(SetupError, match=r"--per-frame \(per_frame=True\) .* keeping the sums of 4 frames"):
        cg._check_memory(300, None, 1)


def test_a_revolved_vtk_grid_beyond_memory_is_refused(tmp_path):
    import xarray as xr
    xr.Dataset({"rho": (("z", "r"), np.ones((30, 10)))},
               coords={"z": np.arange(30) * 0.01, "r": np.arange(10) * 0.001 + 0.0005}).to_netcdf(tmp_path / "fields.nc")
    result = cli("vtk", tmp_path / "fields.nc", "--theta", 10 ** 9)
    assert result.exit_code == 1 and "Traceback" not in result.output
    text = said(result)
    assert "revolved VTK grid of 10 x 1000000000 x 30" in text and "--theta" in text
    assert not (tmp_path / "fields.vts").exists()
