"""Real LIGGGHTS runs of the particle systems beyond monodisperse spheres (issue 3)."""
from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

from postprocess.dumps import read_frames
from siloflow.case_file import load_case
from siloflow.derived import derive
from siloflow.engine import LiggghtsEngine
from siloflow.engine.liggghts.encoding import encode
from siloflow.engine.tables import FLOW_COLUMNS, read_ave_time
from siloflow.run_folder import RunFolder

from conftest import ROOT, engine_run, hooke_materials

pytestmark = [pytest.mark.engine,
              pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS not installed "
                                 "(make install-engine); CI installs it, so CI never skips this")]
POLY = ROOT / "tests" / "data" / "poly_silo.yaml"


def run_case(path, tmp_path_factory, name: str, post: bool = False):
    """(case, folder, run record) of a real run of the case file at ``path``; ``post``: also
    compute its results."""
    run = engine_run(tmp_path_factory, path, name, post=post)
    return load_case(path), run.folder, run.record


@pytest.fixture(scope="module")
def poly_run(tmp_path_factory):
    return run_case(POLY, tmp_path_factory, "poly")


def test_inserted_size_distribution_matches_the_request(poly_run):
    case, folder, record = poly_run
    settled = [f for f in read_frames(folder / "output" / "dumps") if f.timestep <= record.stage_steps["open"]][-1]
    assert settled.n == case.fill.count
    radii = np.round(settled.radii(), 9)
    n = len(radii)
    for r, want in zip(case.particles.radii, case.particles.number_fractions):
        got = float(np.mean(radii == round(r, 9)))
        assert abs(got - want) < 3 * math.sqrt(want * (1 - want) / n), (r, got, want)
    # masses follow the particle density and each grain's own radius
    rho = case.materials.particle.density
    np.testing.assert_allclose(settled.column("mass"), rho * 4 / 3 * np.pi * settled.radii() ** 3, rtol=1e-5)


def test_mass_is_conserved_through_settling_and_the_criterion_stopped_it(poly_run):
    case, folder, record = poly_run
    flow = read_ave_time(folder / "output" / "flow.txt", FLOW_COLUMNS)
    steps = record.stage_steps
    settling = flow[(flow.step >= steps["settle"]) & (flow.step <= steps["open"])]
    assert settling.mass_total.max() == pytest.approx(settling.mass_total.min(), rel=1e-9)
    assert record.settled_ke_pe < case.fill.settle.ke_pe_ratio
    d = derive(case)
    assert steps["static"] - steps["settle"] < d.settle.max_chunks * d.settle.chunk_steps   # not the cap
    log = (folder / "log.liggghts").read_text(errors="replace")
    printed = [ln for ln in log.splitlines() if ln.startswith("SILOFLOW_")]     # the deck's echo is indented
    assert any(ln.startswith("SILOFLOW_SETTLED ") for ln in printed)
    assert not any(ln.startswith("SILOFLOW_NOT_SETTLED") for ln in printed)
    plan = RunFolder(folder).plan
    assert plan.fill.mass_fractions == pytest.approx(case.particles.mass_fractions)


SHRINK = ROOT / "tests" / "data" / "shrink_silo.yaml"


def test_paper_b_protocol_shrinks_a_settled_bed_to_seven_sizes(tmp_path):
    from siloflow.case import paper_b_radii
    case = load_case(SHRINK)
    assert case.particles.radii == pytest.approx(paper_b_radii(case.particles.max_radius))
    folder = tmp_path / "run"
    record = LiggghtsEngine().run(case, folder)
    steps = record.stage_steps
    assert steps["settle"] < steps["shrink"] < steps["static"]
    frames = list(read_frames(folder / "output" / "dumps"))
    before = [f for f in frames if f.timestep <= steps["shrink"]][-1]
    after = [f for f in frames if f.timestep <= steps["open"]][-1]
    assert np.allclose(before.radii(), case.particles.max_radius)          # poured as one size
    classes = np.asarray(case.particles.radii)
    nearest = np.abs(after.radii()[:, None] - classes[None, :]).argmin(axis=1)
    assert np.allclose(after.radii(), classes[nearest], rtol=1e-5)       # dumps print 6 digits
    n = after.n
    for k, want in enumerate(case.particles.number_fractions):
        got = float(np.mean(nearest == k))
        assert abs(got - want) < 3.5 * math.sqrt(want * (1 - want) / n), (classes[k], got, want)
    rho = case.materials.particle.density
    np.testing.assert_allclose(after.column("mass"), rho * 4 / 3 * np.pi * after.radii() ** 3, rtol=5e-5)  # 6 digits
    # no grain lost; the mass fell by exactly what the shrinking took away
    flow = read_ave_time(folder / "output" / "flow.txt", FLOW_COLUMNS)
    settled = flow[(flow.step > steps["shrink"]) & (flow.step <= steps["open"])]
    assert settled.atoms.min() == case.fill.count
    assert settled.mass_total.iloc[-1] == pytest.approx(after.column("mass").sum(), rel=1e-5)  # 6-digit tables
    printed = [ln for ln in (folder / "log.liggghts").read_text(errors="replace").splitlines()
               if ln.startswith("SILOFLOW_")]
    assert sum(ln.startswith("SILOFLOW_SETTLED ") for ln in printed) == 2     # settled, shrunk, settled again
    assert "SILOFLOW_SHRUNK" in printed


def test_frictionless_fill_packs_denser_then_friction_is_restored(small_run, tmp_path):
    """Paper A's fill: particle-particle friction 0 while pouring, restored before settling.
    Compared with the same case poured with friction (the shared small run)."""
    import yaml

    from postprocess.report import post_process as analyse
    from siloflow.case_file import case_from_dict
    from conftest import SMALL

    data = yaml.safe_load(SMALL.read_text())
    data["fill"]["frictionless"] = True
    data["discharge"] = {"duration": 0.05}
    case = case_from_dict(data)
    folder = tmp_path / "frictionless"
    LiggghtsEngine().run(case, folder)
    summary = analyse(folder)
    with_friction = small_run[3]["frame_analyses"]
    without = summary["frame_analyses"]
    assert without["bulk_solid_fraction"] > with_friction["bulk_solid_fraction"] + 0.01
    assert without["coordination_settled"]["z_mean"] > with_friction["coordination_settled"]["z_mean"]
    mu = case.materials.particle_particle.friction
    deck = (folder / "in.liggghts").read_text()
    assert "coefficientFriction peratomtypepair 2 0 " in deck            # poured without friction
    printed = [ln for ln in (folder / "log.liggghts").read_text(errors="replace").splitlines()
               if ln.startswith("SILOFLOW_")]
    restored = [ln for ln in printed if ln.startswith("SILOFLOW_FRICTION_RESTORED")]
    assert restored and float(restored[0].split()[1]) == mu
    assert printed.index(restored[0]) < next(k for k, ln in enumerate(printed) if ln.startswith("SILOFLOW_STAGE settle"))


def test_hooke_contact_law_runs_per_size_pair(tmp_path):
    """Paper B's linear law (hooke/stiffness with kn, kt, damping per pair of size classes) on the
    polydisperse case: it runs, every grain is inserted and settles, the bed's weight is carried."""
    import yaml

    from postprocess.report import post_process as analyse
    from siloflow.case_file import case_from_dict

    data = yaml.safe_load(POLY.read_text())
    data["materials"] = hooke_materials(2500.0, 5.0e6, 0.5)
    case = case_from_dict(data)
    folder = tmp_path / "hooke"
    record = LiggghtsEngine().run(case, folder)
    assert record.completed and record.inserted == case.fill.count
    summary = analyse(folder)
    assert summary["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.02)
    d = derive(case)
    kn_line = next(ln for ln in (folder / "in.liggghts").read_text().splitlines() if " kn peratomtypepair" in ln)
    kn = np.array([float(v) for v in kn_line.split()[7:]]).reshape(4, 4)   # after "... peratomtypepair 4"
    type_pairs = encode(d).type_pairs                    # keyed by (atom type i, atom type j), i <= j
    assert kn[0, 1] == pytest.approx(type_pairs[(1, 2)].kn, rel=1e-9)
    assert kn[2, 3] == pytest.approx(type_pairs[(3, 4)].kn, rel=1e-9)


# --------------------------------------------------------------------------- clumps + dust
CLUMPS = ROOT / "tests" / "data" / "clump_silo.yaml"


@pytest.fixture(scope="module")
def clump_run(tmp_path_factory):
    return run_case(CLUMPS, tmp_path_factory, "clumps", post=True)


def _settled(folder, record):
    return [f for f in read_frames(folder / "output" / "dumps") if f.timestep <= record.stage_steps["open"]][-1]


def test_clumps_and_dust_are_inserted_as_requested(clump_run):
    case, folder, record = clump_run
    settled = _settled(folder, record)
    types, mol = settled.column("type").astype(int), settled.column("mol").astype(int)
    clump_rows = types == 1
    assert clump_rows.sum() == 3 * case.fill.count                      # three spheres per grain
    assert len(np.unique(mol[clump_rows])) == case.fill.count           # one body each
    assert np.all(np.bincount(mol[clump_rows])[np.unique(mol[clump_rows])] == 3)
    assert (types == 2).sum() == round(case.particles.dust.number_ratio * case.fill.count)
    assert np.all(mol[types == 2] <= 0)                                  # dust: no body
    # each body keeps the template's shape (rigid): sphere spacing (length - width) / 2
    order = np.argsort(mol[clump_rows])
    pos = settled.positions()[clump_rows][order].reshape(-1, 3, 3)
    spacing = np.linalg.norm(pos[:, 1:] - pos[:, :-1], axis=2)
    np.testing.assert_allclose(np.sort(spacing, axis=1)[:, 0], 0.5 * (case.particles.length - case.particles.width),
                               rtol=1e-3)


def test_clump_mass_is_density_times_union_volume(clump_run):
    case, folder, record = clump_run
    settled = _settled(folder, record)
    want = case.materials.particle.density * case.particles.clump.volume
    mass = settled.column("mass")[settled.column("type").astype(int) == 1]
    np.testing.assert_allclose(mass, want, rtol=0.01)                   # LIGGGHTS' Monte Carlo vs exact union
    assert abs(mass.mean() / want - 1) < 0.01
    sum_of_spheres = case.materials.particle.density * case.particles.clump.sphere_volume_sum
    assert mass.mean() < 0.7 * sum_of_spheres                           # overlaps are not double counted
    dust = case.particles.dust
    np.testing.assert_allclose(settled.column("mass")[settled.column("type").astype(int) == 2],
                               dust.run_density * 4 / 3 * np.pi * dust.radius ** 3, rtol=1e-5)


def test_clump_run_conserves_mass_and_balances_the_weight(clump_run):
    case, folder, record = clump_run
    d = derive(case)
    flow = read_ave_time(folder / "output" / "flow.txt", FLOW_COLUMNS)
    steps = record.stage_steps
    settling = flow[(flow.step >= steps["settle"]) & (flow.step <= steps["open"])]
    # the deck weighs each clump once (multisphere gives every sphere the clump's mass)
    assert settling.mass_total.iloc[-1] == pytest.approx(d.total_mass, rel=0.002)
    assert settling.mass_total.max() == pytest.approx(settling.mass_total.min(), rel=1e-9)
    assert record.settled_ke_pe < case.fill.settle.ke_pe_ratio
    assert steps["static"] - steps["settle"] < d.settle.max_chunks * d.settle.chunk_steps
    summary = json.loads((folder / "results" / "summary.json").read_text())
    # the walls and bottom carry the weight of the clumps and the dust (measured by the meshes)
    assert summary["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.01)
    # grains left through the outlet and the discharged mass adds up
    assert summary["discharged_mass_kg"] > 0.2 * d.total_mass
    fa = summary["frame_analyses"]
    # union-volume solid fraction of the bed: a dense random packing of grains
    assert 0.55 < fa["bulk_solid_fraction"] < 0.72
    # Wr (free surface x union-volume solid fraction) agrees with Wf (outlet count)
    assert fa["flow_rate_surface_over_outlet"] == pytest.approx(1.0, abs=0.15)
    assert fa["coordination_convention"] == "per_body"


def test_clump_run_coarse_grains_bodies_not_spheres(clump_run, tmp_path):
    """siloflow cg on a clump run: each grain is one rigid body at its centroid with its mass
    (not three spheres each carrying it), contacts reach the bodies' centroids."""
    from typer.testing import CliRunner
    import xarray as xr
    from siloflow.cli import app
    case, folder, record = clump_run
    out = tmp_path / "cg"
    result = CliRunner().invoke(app, ["cg", str(folder), "--nr", "12", "--nz", "40", "--width", "1.5", "-o", str(out)])
    assert result.exit_code == 0, result.output
    fa = json.loads((folder / "results" / "summary.json").read_text())["frame_analyses"]
    s = json.loads((out / "cg_summary.json").read_text())
    assert s["frames"] >= 3 and s["contacts"]
    with xr.open_dataset(out / "fields.nc") as ds:
        assert ds.sizes["species"] == 2                                   # grains and dust
        h = fa["settled_surface_height_m"]
        mid = ds.sel(z=0.5 * h, method="nearest").isel(r=slice(0, 4)).mean("r")
        # the flowing bed's solid fraction, from the bodies' mass: near the settled bed's union-volume
        # value, below it by the discharge's dilation (averaged over every frame, the emptying ones too:
        # measured 0.75-0.8 of it with sensor-mesh side walls, 0.72 with primitive ones); three spheres each
        # with the grain's mass would give about 3x, a third of it each about 0.33x
        assert 0.6 * fa["bulk_solid_fraction"] < float(mid.solid_fraction) < 1.1 * fa["bulk_solid_fraction"]
        assert float(mid.contact_pressure) > 20 * float(mid.kinetic_pressure) > 0
        axis = ds.contact_pressure.isel(r=0)
        assert float(axis.sel(z=0.3 * h, method="nearest")) > float(axis.sel(z=0.7 * h, method="nearest"))


def test_clump_contact_stress_carries_the_settled_beds_weight(clump_run):
    """Momentum balance of the coarse-grained settled bed (bodies at rest to 0.3 %, no wall
    friction to speak of): over a horizontal plane, the integral of sigma_zz is the weight of
    the bed above it. The clumps' branches through their centroids give it (measured 0.95-0.99);
    sphere-to-sphere branches would give 0.87-0.91."""
    from postprocess.cg_kernels import gaussian
    from postprocess.coarse_grain import CartesianGrid, CoarseGraining
    case, folder, record = clump_run
    layout = RunFolder(folder).dump_layout
    settled = _settled(folder, record)
    dumps = folder / "output" / "dumps"
    pairs = next(read_frames(dumps / "contacts.*.txt", columns=layout.contact_columns, steps=[settled.timestep]))
    walls = next(read_frames(dumps / "wall_contacts.*.txt", columns=layout.wall_contact_columns,
                             steps=[settled.timestep]))
    k = gaussian(0.0025)
    half = case.geometry.radius + k.cutoff                 # the whole bed and its kernels' reach
    grid = CartesianGrid([-half, -half, -0.01], [half, half, 0.16], (36, 36, 85))
    f = CoarseGraining(grid, k).run([settled], [pairs], [walls]).fields()
    area, dz = grid.spacing[0] * grid.spacing[1], grid.spacing[2]
    mass_per_height = f["rho"].sum(axis=(1, 2)) * area                    # kg/m
    weight_above = 9.81 * (np.cumsum(mass_per_height[::-1])[::-1] - 0.5 * mass_per_height) * dz
    load = f["contact_stress"][..., 8].sum(axis=(1, 2)) * area
    z = grid.axes()["z"]
    surface = float(settled.positions()[:, 2].max())
    inside = (z > 0.2 * surface) & (z < 0.75 * surface)                 # away from the kernel's reach of both ends
    assert inside.sum() >= 4
    ratio = load[inside] / weight_above[inside]
    assert np.all(np.abs(ratio - 1.0) < 0.07), ratio


# --------------------------------------------------------------------------- dust in a slab
SLAB_DUST = ROOT / "tests" / "data" / "slab_dust.yaml"


@pytest.fixture(scope="module")
def slab_dust_run(tmp_path_factory):
    return run_case(SLAB_DUST, tmp_path_factory, "slab_dust", post=True)


def test_dust_in_a_slab_is_all_inserted_stays_in_the_plane_and_comes_to_rest(slab_dust_run):
    """Dust among clumps in a slab (paper A's multi-element model): inserted before the grains of
    each batch (none lost: overlapping insertions shoot particles out of the box), held in the
    mid-plane (free dust rattled in the gaps beside the faces), and at rest once settled."""
    case, folder, record = slab_dust_run
    n_dust = round(case.particles.dust.number_ratio * case.fill.count)
    assert record.templates_inserted == case.fill.count + n_dust
    assert record.inserted == 3 * case.fill.count + n_dust and record.fill_losses == 0
    frames = [f for f in read_frames(folder / "output" / "dumps") if len(f.data)]
    for f in frames:
        dust = f.column("type").astype(int) == 2
        # poured within 1e-3 dust radii of the mid-plane, and never off it
        assert np.abs(f.positions()[dust, 1]).max() <= 1.0001e-3 * case.particles.dust.radius
    settled = _settled(folder, record)
    dust = settled.column("type").astype(int) == 2
    assert record.settled_ke_pe < case.fill.settle.ke_pe_ratio
    assert np.linalg.norm(settled.velocities()[dust], axis=1).max() < 0.05     # m/s: no rattlers
    summary = json.loads((folder / "results" / "summary.json").read_text())
    assert summary["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.01)
