"""Post-processing on real LIGGGHTS output: the small siloflow run (shared with
test_engine_run.py) and two unmodified LIGGGHTS tutorials from liggghts-doc."""
from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from postprocess.dumps import read_dump
from siloflow.cli import app

from test_dumps import compare_with_mdanalysis

TUTORIALS = Path("/usr/share/doc/liggghts/examples/LIGGGHTS/Tutorials_public")
pytestmark = [pytest.mark.engine,
              pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS not installed "
                                 "(make install-engine); CI installs it, so CI never skips this")]


def test_settled_bed_solid_fraction_and_coordination(small_run):
    case, folder, record, summary = small_run
    fa = summary["frame_analyses"]
    assert 0.55 < fa["bulk_solid_fraction"] < 0.65
    # the cross-section, wall layers included, is looser than the core
    assert fa["cross_section_solid_fraction"] < fa["bulk_solid_fraction"]
    z = fa["coordination_settled"]
    assert 3.0 < z["z_mean"] < 7.0 and z["z_mech"] >= z["z_mean"]
    coord = pd.read_csv(folder / "results" / "coordination.csv")
    assert coord.step.nunique() == fa["dump_frames"]                # contact count over time
    for name in ("force_chains_settled.png", "force_chains_discharge.png", "coordination.png",
                 "free_surface.png", "porosity.parquet", "flow_rates.csv"):
        assert (folder / "results" / name).is_file(), name


def test_outlet_and_free_surface_flow_rates_agree(small_run):
    """Wf (mass through the outlet) and Wr (free-surface speed x area x rho_p x phi) in steady flow."""
    case, folder, record, summary = small_run
    wf = summary["flow_rate"]["rate"]
    wr = summary["frame_analyses"]["flow_rate_surface"]["rate"]
    assert wf > 0 and wr == pytest.approx(wf, rel=0.10)
    steady = summary["steady_window_detected"]
    assert steady["t_start"] > summary["time_open_s"] and steady["median_rate"] == pytest.approx(wf, rel=0.1)


def test_janssen_fit_of_the_settled_profile_is_reported(small_run):
    fit = small_run[3]["frame_analyses"]["janssen_static"]
    assert "K" in fit, fit
    assert math.isfinite(fit["K"]) and math.isfinite(fit["mu_w"]) and fit["n_points"] >= 3


def test_post_on_the_run_dumps_as_foreign_files(small_run, tmp_path):
    case, folder, record, summary = small_run
    dumps = folder / "output" / "dumps"
    result = CliRunner().invoke(app, ["post", str(dumps / "dump.*.txt"), "--contacts", str(dumps / "contacts.*.txt"),
                                      "--contact-keywords", "pos,id,force,force_normal", "-o", str(tmp_path / "p")])
    assert result.exit_code == 0, result.output
    s = json.loads((tmp_path / "p" / "summary.json").read_text())
    assert s["coordination_last"]["source"] == "dump_local"
    frames = pd.read_csv(tmp_path / "p" / "frames.csv")
    # grains deleted at the outlet: the count falls during the discharge
    assert frames.particles.iloc[-1] < frames.particles.max()
    assert frames.contacts.notna().all()


def run_tutorial(tmp_path, name: str, deck: str) -> Path:
    source = TUTORIALS / name
    assert source.is_dir(), f"{source} missing: apt-get install liggghts-doc (make install-engine does)"
    work = tmp_path / Path(name).name
    shutil.copytree(source, work)
    (work / "post" / "restart").mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["liggghts", "-in", deck], cwd=work, capture_output=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:]
    return work


def test_post_on_an_unmodified_tutorial_text_dump(tmp_path):
    """ParScale/fluidizedBedTempParScale's in.liggghts_init writes a plain dump custom."""
    work = run_tutorial(tmp_path, "ParScale/fluidizedBedTempParScale", "in.liggghts_init")
    dump = work / "post" / "dump.liggghts_init"
    frames = read_dump(dump)
    assert len(frames) == 50 and [f.timestep for f in frames[:2]] == [4000, 8000]
    for f in frames:
        p = f.positions()
        # x, y periodic (a grain may sit a little outside until re-neighbouring); z walls
        assert f.n == 10 and np.all((p[:, 2] >= f.box[2, 0]) & (p[:, 2] <= f.box[2, 1]))
        assert np.all((p[:, :2] > f.box[:2, 0] - 1e-3) & (p[:, :2] < f.box[:2, 1] + 1e-3))
        assert np.allclose(f.radii(), 1e-3)
    assert compare_with_mdanalysis(dump) == 50
    result = CliRunner().invoke(app, ["post", str(dump), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["frames"] == 50 and s["particles_last"] == 10
    assert "porosity_skipped" in s                # ten grains: no meaningful measurement sphere


def test_post_on_an_unmodified_tutorial_vtk_packing(tmp_path):
    """packing/in.packing grows 2 sizes of grains to a volume fraction of 0.67 of its box
    (0.1 x 0.1 x 0.15 m) and writes dump custom/vtk files."""
    work = run_tutorial(tmp_path, "packing", "in.packing")
    result = CliRunner().invoke(app, ["post", str(work / "post" / "packing_[0-9]*.vtk"), "--every", "10",
                                      "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    frames = pd.read_csv(tmp_path / "out" / "frames.csv")
    box = 0.1 * 0.1 * 0.15
    assert frames.solid_volume.iloc[-1] / box == pytest.approx(0.67, rel=0.02)
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    phi = 1 - s["porosity_last"]["sphere_1"]
    assert 0.62 < phi < 0.80                      # the interior, away from the box walls
    assert 4.0 < s["coordination_last"]["z_mean"] < 9.0


def test_case_measurement_regions(small_run):
    """The case's own regions: a sphere in the core and a mid-plane circle (2D area porosity,
    which by Delesse's principle estimates the volume fraction), converted 2D -> 3D."""
    case, folder, record, summary = small_run
    fa = summary["frame_analyses"]
    regions = fa["porosity_regions"]
    bulk_porosity = 1 - fa["bulk_solid_fraction"]
    assert regions["core_sphere"]["porosity"] == pytest.approx(bulk_porosity, abs=0.06)
    assert regions["mid_circle"]["porosity"] == pytest.approx(bulk_porosity, abs=0.12)
    assert "porosity_3d" in regions["mid_circle"]
    table = pd.read_csv(folder / "results" / "porosity_regions.csv")
    assert set(table.region) == {"core_sphere", "mid_circle"} and table.step.nunique() == fa["dump_frames"]


def test_measured_pressure_comparison(small_run, tmp_path):
    """A 'measurement' 10 % above the run's own band pressures gives W = 0.1/1.1 (Eq. 34)."""
    case, folder, record, summary = small_run
    p = pd.read_csv(folder / "results" / "wall_pressure.csv")
    t_open = summary["time_open_s"]
    after = p[p.time >= t_open]
    wide = after.pivot_table(index="time", columns="band", values="pressure")[[1, 2]]
    measured = pd.DataFrame({"time": wide.index - t_open, "band_1": 1.1 * wide[1].to_numpy(),
                             "band_2": 1.1 * wide[2].to_numpy()})
    path = tmp_path / "measured.csv"
    measured.to_csv(path, index=False)
    result = CliRunner().invoke(app, ["post", str(folder), "--measured", str(path)])
    assert result.exit_code == 0, result.output
    table = pd.read_csv(folder / "results" / "pressure_comparison.csv").set_index("band")
    assert table.loc[1, "W"] == pytest.approx(0.1 / 1.1, rel=1e-6)
    assert table.loc[2, "relative_difference"] == pytest.approx(1 / 1.1 - 1, rel=1e-6)
    assert "W (Eq. 34)" in (folder / "results" / "report.md").read_text()


def test_coarse_graining_of_the_real_run(small_run, tmp_path):
    """siloflow cg on the run folder: fields in the steady window, paper B's outlet profile."""
    case, folder, record, summary = small_run
    out = tmp_path / "cg"
    result = CliRunner().invoke(app, ["cg", str(folder), "--nr", "20", "--nz", "60", "--width", "1.5", "-o", str(out)])
    assert result.exit_code == 0, result.output
    import xarray as xr
    s = json.loads((out / "cg_summary.json").read_text())
    assert s["frames"] >= 10 and s["contacts"] and s["wall_contacts"]
    assert s["v_z_centre_outlet"] < 0                                 # grains leave downwards
    assert 0.3 < s["janda_fit"]["exponent"] < 0.8                     # Janda: 1/2
    with xr.open_dataset(out / "fields.nc") as ds:
        mid = ds.sel(z=0.5 * summary["frame_analyses"]["settled_surface_height_m"], method="nearest").isel(r=0)
        assert 0.5 < float(mid.solid_fraction) < 0.68
        # the contact pressure dominates the kinetic pressure in the bulk (paper B: by orders of magnitude)
        assert float(mid.contact_pressure) > 20 * float(mid.kinetic_pressure)
        # and grows with depth: deeper on the axis, more contact pressure (above the outlet region)
        axis = ds.contact_pressure.isel(r=0)
        h = summary["frame_analyses"]["settled_surface_height_m"]
        assert float(axis.sel(z=0.3 * h, method="nearest")) > float(axis.sel(z=0.7 * h, method="nearest"))
    for name in ("cg_maps.png", "cg_outlet_profiles.png", "cg_axial_pressure.png", "outlet_profiles.csv"):
        assert (out / name).is_file(), name
    # the fast lattice sums give the same fields on real frames, within their stated error
    fast = tmp_path / "cg_lattice"
    result = CliRunner().invoke(app, ["cg", str(folder), "--nr", "20", "--nz", "60", "--width", "1.5", "-o", str(fast),
                                      "--method", "lattice"])
    assert result.exit_code == 0, result.output
    assert json.loads((fast / "cg_summary.json").read_text())["method"] == "lattice"
    with xr.open_dataset(out / "fields.nc") as a, xr.open_dataset(fast / "fields.nc") as b:
        for name, tol in (("rho", 5e-3), ("contact_pressure", 3e-2), ("kinetic_pressure", 3e-2)):
            err = float(abs(a[name] - b[name]).max() / abs(a[name]).max())
            assert err < tol, (name, err)


def test_disk_estimate_bounds_what_the_run_wrote(small_run):
    from siloflow.derived import derive
    from siloflow.disk_estimate import estimate_bytes
    case, folder, record, summary = small_run
    written = sum(p.stat().st_size for p in (folder / "output").rglob("*") if p.is_file())
    estimate = estimate_bytes(case, derive(case))["total"]
    assert written <= estimate <= 3 * written, (written, estimate)
