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

from postprocess.dumps import read_dump, read_frames
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


def _band_janssen_least_squares(z0, z1, h, pressure, rho_b, D, g):
    """Independent of postprocess.janssen: each band's sensor reads Janssen's
    p(d) = rho_b g D / (4 mu) (1 - exp(-4 mu K d / D)) (depth d = h - z) averaged over its whole
    height, zero above the surface h, by numerical quadrature; fitted by scipy's least_squares
    from a grid of starts. Returns ((cost, K, mu), residual)."""
    from scipy.integrate import quad
    from scipy.optimize import least_squares

    def model(K, mu):
        out = []
        for a, b in zip(z0, z1):
            top = min(b, h)
            integral = quad(lambda z: rho_b * g * D / (4 * mu) * -np.expm1(-4 * mu * K * (h - z) / D), a, top)[0] \
                if top > a else 0.0
            out.append(integral / (b - a))
        return np.array(out)

    def residual(x):
        return model(*x) - pressure
    best = None
    for K0 in (0.2, 0.5, 1.0, 2.0):
        for mu0 in (0.05, 0.2, 0.5, 1.0):
            r = least_squares(residual, [K0, mu0], bounds=([1e-3, 1e-3], [3.0, 2.0]), xtol=1e-12, ftol=1e-12)
            if best is None or r.cost < best[0]:
                best = (r.cost, *r.x)
    return best, residual


def test_janssen_fit_of_the_settled_profile(small_run):
    """The run's static band pressures, fitted band by band (each sensor's model value is Janssen
    averaged over the band's height, cut at the settled surface, the floor's corner band left out):
    * the reported K and mu_eff are the least-squares optimum: an independent refit (quadrature,
      another optimiser, 16 starts) finds no lower cost;
    * the fit says whether it is resolved, and why not: a fit outside 0.2 <= K <= 1.0 or with
      fewer than 3 bands is never reported as resolved;
    * a resolved fit's mobilisation mu_eff / mu_w does not exceed 1 beyond its interval, and K lies
      between Rankine's active and passive ratios for the grains' friction (mu 0.5: phi = 26.6 deg,
      K_a = 0.382, K_p = 2.618) within its interval."""
    from siloflow.run_folder import RunFolder
    case, folder, record, summary = small_run
    fa = summary["frame_analyses"]
    fit = fa["janssen_static"]
    assert "resolved" in fit and ("reason" in fit), fit
    h = fa["settled_surface_height_m"]
    plan = RunFolder(folder).plan
    extents = {w.band: (w.z0, w.z1) for w in plan.walls if w.role == "band"}
    used = fit["bands_used"]
    assert fit["n_bands_used"] == len(used) and min(extents) not in used      # the corner band is left out
    bands = pd.DataFrame(summary["bands"]).set_index("band").loc[used]
    z0, z1 = zip(*(extents[b] for b in used))
    rho_b, D = fa["cross_section_bulk_density_kg_m3"], 2 * case.geometry.radius
    (cost, K, mu), residual = _band_janssen_least_squares(z0, z1, h, bands.static_pressure.to_numpy(float),
                                                          rho_b, D, case.gravity)
    if np.isfinite(fit["K"]):
        reported = 0.5 * float((residual([fit["K"], fit["mu_eff"]]) ** 2).sum())
        p2 = float((bands.static_pressure ** 2).sum())
        assert reported <= cost * (1 + 1e-4) + 1e-9 * p2, (reported, cost, fit)
    if not (0.2 <= fit["K"] <= 1.0) or fit["n_bands_used"] < 3:
        assert not fit["resolved"] and fit["flags"], fit
    if fit["resolved"]:
        assert fit["mobilisation_ci"][0] <= 1.0, fit
        phi = math.atan(0.5)
        k_a, k_p = (1 - math.sin(phi)) / (1 + math.sin(phi)), (1 + math.sin(phi)) / (1 - math.sin(phi))
        assert fit["K_ci"][1] >= k_a and fit["K_ci"][0] <= k_p, fit


def test_post_on_the_run_dumps_as_foreign_files(small_run, tmp_path):
    case, folder, record, summary = small_run
    dumps = folder / "output" / "dumps"
    result = CliRunner().invoke(app, ["post", str(dumps / "dump.*.txt"), "--contacts", str(dumps / "contacts.*.txt"),
                                      "--contact-keywords", "pos,id,force,force_normal,delta", "-o", str(tmp_path / "p")])
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


def _settled_frame(folder: Path):
    """The settled bed's dump frame: the last at or before the outlet opened (as dump_results picks it)."""
    stages = json.loads((folder / "run_record.json").read_text())["stage_steps"]
    steps = pd.read_csv(folder / "results" / "porosity_regions.csv").step
    step = int(steps[steps <= int(stages["open"])].max())
    return next(read_frames(str(folder / "output" / "dumps" / "dump.*.txt"), steps=[step]))


def _sampled_solid_fraction(frame, points) -> float:
    """Share of ``points`` inside some grain (the union of the spheres), by a KD-tree: an
    estimate independent of postprocess.overlap_volume."""
    from scipy.spatial import cKDTree
    pos, rad = frame.positions(), frame.radii()
    d, idx = cKDTree(pos).query(points, k=4, distance_upper_bound=rad.max())
    found = np.isfinite(d)
    inside = np.zeros(d.shape, bool)
    inside[found] = d[found] < rad[idx[found]]
    return float(inside.any(axis=1).mean())


def test_case_measurement_regions(small_run):
    """The case's own regions: a sphere in the core and a mid-plane circle (2D area porosity,
    which by Delesse's principle estimates the volume fraction), converted 2D -> 3D.

    * Each region's porosity is checked against an independent Monte Carlo estimate on the
      settled frame: 10^6 random points in the region, inside a grain or not (binomial standard
      error sqrt(0.24 / 10^6) = 4.9e-4; bound 2.5e-3, 5 standard errors; the soft overlaps the
      module counts twice are ~1e-5 of the volume here).
    * Against the bulk porosity, the bound is the regions' own measured spread: the porosity of
      10 circles like mid_circle (planes x = 0 and y = 0, 5 heights in the bed) and 5 spheres like
      core_sphere (on the axis; they overlap, so their spread is if anything too small), 3 sample
      standard deviations, plus 0.01 for the part of each region beyond the bulk core's radius
      (R - 2 d = 7.5 mm: 8 % of the circle's area, 4 % of the sphere's volume)."""
    from postprocess.porosity import MeasureRegion, Porosity
    case, folder, record, summary = small_run
    fa = summary["frame_analyses"]
    regions = fa["porosity_regions"]
    bulk_porosity = 1 - fa["bulk_solid_fraction"]
    settled = _settled_frame(folder)
    spec = {r.name: r for r in case.analysis.porosity_regions}
    sph, cir = spec["core_sphere"], spec["mid_circle"]
    assert sph.shape == "sphere" and cir.shape == "circle" and cir.axis == "y"
    rng = np.random.default_rng(13)
    n = 1_000_000
    # core_sphere: uniform points in the ball
    u = rng.normal(size=(n, 3))
    ball = u / np.linalg.norm(u, axis=1)[:, None] * sph.radius * rng.random(n)[:, None] ** (1 / 3) + sph.center
    sphere_mc = 1 - _sampled_solid_fraction(settled, ball)
    assert regions["core_sphere"]["porosity"] == pytest.approx(sphere_mc, abs=2.5e-3)
    # mid_circle: uniform points in the disc, in its plane y = plane
    rr, th = cir.radius * np.sqrt(rng.random(n)), rng.uniform(0, 2 * np.pi, n)
    disc = np.column_stack([cir.center[0] + rr * np.cos(th), np.full(n, cir.plane), cir.center[2] + rr * np.sin(th)])
    circle_mc = 1 - _sampled_solid_fraction(settled, disc)
    assert regions["mid_circle"]["porosity"] == pytest.approx(circle_mc, abs=2.5e-3)

    h, d = fa["settled_surface_height_m"], fa["grain_diameter_m"]
    z_c = np.linspace(cir.radius + 2 * d, h - cir.radius - 2 * d, 5)
    z_s = np.linspace(sph.radius + 2 * d, h - sph.radius - 2 * d, 5)
    assert z_c[-1] > z_c[0] and z_s[-1] > z_s[0], h
    circles = [MeasureRegion(f"c{axis}_{k}", "circle", (0.0, 0.0, z), cir.radius, axis=axis, plane=0.0)
               for axis in (0, 1) for k, z in enumerate(z_c)]
    spheres = [MeasureRegion(f"s{k}", "sphere", (0.0, 0.0, z), sph.radius) for k, z in enumerate(z_s)]
    table = Porosity(circles + spheres).run([settled]).table.set_index("region")
    spread_c = float(table.loc[[c.name for c in circles], "porosity"].std(ddof=1))
    spread_s = float(table.loc[[s.name for s in spheres], "porosity"].std(ddof=1))
    assert regions["mid_circle"]["porosity"] == pytest.approx(bulk_porosity, abs=3 * spread_c + 0.01), spread_c
    assert regions["core_sphere"]["porosity"] == pytest.approx(bulk_porosity, abs=3 * spread_s + 0.01), spread_s
    # paper A's Eq. 36-37 as printed, written out: eps3d = 1 - xi (1 - eps2d), xi = a + Dr (a - b)
    a, b = 2 / math.sqrt(math.pi * math.sqrt(3)), math.sqrt(2) / math.sqrt(math.pi * math.sqrt(3))
    xi = a + case.analysis.relative_density * (a - b)
    eps3d = regions["mid_circle"]["porosity_3d"]
    if math.isfinite(eps3d):
        assert eps3d == pytest.approx(1 - xi * (1 - regions["mid_circle"]["porosity"]), rel=1e-9)
    table = pd.read_csv(folder / "results" / "porosity_regions.csv")
    assert set(table.region) == {"core_sphere", "mid_circle"} and table.step.nunique() == fa["dump_frames"]


def test_measured_pressure_comparison(small_run, tmp_path):
    """A 'measurement' 10 % above the run's own band pressures gives W = 0.1/1.1 (Eq. 34).
    `post` rewrites results/, so it runs on a copy: the session's shared run stays as the other
    tests expect it, whatever order they run in."""
    case, shared, record, summary = small_run
    folder = tmp_path / "run"
    shutil.copytree(shared, folder)
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
    # the fast lattice sums give the same fields on real frames, within their stated error:
    # max |lattice - exact| / max |exact| per field. Measured on 10-frame averages of synthetic
    # frames of this run's size and grid (2500 grains, R 12.5 mm, 20 x 60, w = 1.5 radii, with a
    # converging jet): rho 5.5e-4, contact pressure 2.7e-4, kinetic pressure 1.0e-3. Coarser grids
    # relative to the kernel (the benchmark's dr / w = 0.45, here 0.33) and sparser sources give
    # up to 2.3e-3, 2.6e-3 and 3.3e-3. Bounds: rho 2.5e-3 (4.5x the emulation), the pressures
    # 1e-2 (10-40x the emulation, 3x the worst elsewhere). Not yet measured on this run itself.
    fast = tmp_path / "cg_lattice"
    result = CliRunner().invoke(app, ["cg", str(folder), "--nr", "20", "--nz", "60", "--width", "1.5", "-o", str(fast),
                                      "--method", "lattice"])
    assert result.exit_code == 0, result.output
    assert json.loads((fast / "cg_summary.json").read_text())["method"] == "lattice"
    with xr.open_dataset(out / "fields.nc") as a, xr.open_dataset(fast / "fields.nc") as b:
        for name, tol in (("rho", 2.5e-3), ("contact_pressure", 1e-2), ("kinetic_pressure", 1e-2)):
            err = float(abs(a[name] - b[name]).max() / abs(a[name]).max())
            assert err < tol, (name, err)


def test_disk_estimate_bounds_what_the_run_wrote(small_run):
    from siloflow.derived import derive
    from siloflow.disk_estimate import estimate_bytes
    case, folder, record, summary = small_run
    written = sum(p.stat().st_size for p in (folder / "output").rglob("*") if p.is_file())
    estimate = estimate_bytes(case, derive(case))["total"]
    assert written <= estimate <= 3 * written, (written, estimate)


@pytest.mark.engine
def test_open_run_gives_the_summarys_flow_rate_and_band_pressures(small_run, tmp_path):
    """The Python entry point: siloflow.open_run reads a finished run folder; its tables give back
    the summary's numbers (the steady flow rate refitted from Run.flow, the static band pressures
    from Run.wall_pressure over the static window)."""
    import shutil

    import siloflow
    from postprocess.discharge import steady_flow_rate

    folder = tmp_path / "run"
    shutil.copytree(small_run[1], folder)
    r = siloflow.open_run(folder)
    assert r.state == "complete" and "complete" in repr(r)
    t_open = r.summary["time_open_s"]
    after = r.flow[r.flow.time >= t_open]
    initial = float(r.flow.loc[r.flow.time <= t_open, "mass_total"].iloc[-1])
    rate = steady_flow_rate(after.time, after.outlet_mass, t_open, mass_in_silo=after.mass_in_silo,
                            initial_mass=initial)
    assert rate.rate == pytest.approx(r.summary["flow_rate"]["rate"], rel=1e-9)
    static = {b["band"]: b["static_pressure"] for b in r.summary["bands"]}
    assert dict(zip(r.bands.band, r.bands.static_pressure)) == pytest.approx(static, rel=1e-9)
    assert set(r.wall_pressure.band) == set(static)
    frames = list(r.frames(every=5))
    steps = [f.timestep for f in frames]
    assert len(frames) > 2 and steps == sorted(steps) and max(len(f.data) for f in frames) > 0
