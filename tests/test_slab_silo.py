"""The quasi-2D slab silo (paper A's geometry): meshes, derived values, deck, and a real run."""
from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pandas as pd
import pytest
from conftest import ROOT, engine_run, set_path

from postprocess.dumps import read_frames
from siloflow.case_file import case_from_dict, load_case
from siloflow.derived import bed_volume, derive, wall_meshes
from siloflow.engine.liggghts.deck import render_deck_text
from siloflow.engine.liggghts.encoding import encode
from siloflow.engines import ENGINE_FILES
from siloflow.errors import CaseError
from siloflow.run_folder import RunFolder

SLAB = ROOT / "tests" / "data" / "slab_silo.yaml"


def slab_dict():
    import yaml
    return yaml.safe_load(SLAB.read_text())


def _area(tris) -> float:
    return float(0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum())


def test_slab_meshes_close_the_silo_and_sense_both_side_walls():
    case = load_case(SLAB)
    g = case.geometry
    d = derive(case)
    walls = {w.name: w for w in wall_meshes(case, d, sensors=True)}
    bands = [w for w in walls.values() if w.role == "band"]
    assert len(bands) == 2 * case.sensors.bands                       # every section on both sides
    for w in bands:
        x = w.triangles[..., 0]
        side = -1.0 if w.sector == 0 else 1.0
        np.testing.assert_allclose(x, side * g.half_width)
        assert w.normal == (side, 0.0)
        assert w.area == pytest.approx(g.thickness * (w.z1 - w.z0), rel=1e-12) == w.projected_area
    # the sections tile the vertical walls from the hopper's top to the silo's top
    assert sum(w.area for w in bands) == pytest.approx(2 * g.thickness * g.height, rel=1e-12)
    # each face is the silo's outline: the wedge's trapezoid plus the rectangle above
    outline = (0.5 * (g.outlet_width + g.width) * g.hopper_height + g.width * g.height)
    for name in ("face_s00", "face_s01"):
        assert walls[name].area == pytest.approx(outline, rel=1e-12)
    assert bed_volume(case, g.hopper_height + g.height) == pytest.approx(outline * g.thickness, rel=1e-12)
    # hopper planes at the half angle from the vertical, reaching the slot's edges
    hop = walls["hopper_s01"].triangles.reshape(-1, 3)
    assert hop[:, 0].min() == pytest.approx(g.outlet_width / 2) and hop[:, 2].max() == pytest.approx(g.hopper_height)
    assert math.degrees(math.atan2(g.half_width - g.outlet_width / 2, g.hopper_height)) == pytest.approx(g.half_angle_deg)


def test_slab_deck_faces_have_their_own_friction_and_clumps_stay_flat():
    case = load_case(SLAB)
    d = derive(case)
    enc = encode(d)
    assert enc.face_type == enc.wall_type + 1 == 3 and enc.n_types == 3
    text = render_deck_text(d)
    assert "create_box      3 domain" in text
    assert "face_s00.stl type 3" in text and "primitive type 2 xplane -0.03" in text     # side walls: type 2
    mu = case.materials.particle_particle.friction, case.materials.particle_wall.friction
    assert f"coefficientFriction peratomtypepair 3 {mu[0]:g} {mu[1]:g} 0 " in text      # faces: 0
    assert "read_dump" in text and "insert/rate/region" not in text      # spheres: placed by siloflow
    # wheat clumps in a slab: inserted flat, moving in the plane only
    data = slab_dict()
    data["particles"] = {"kind": "clumps", "length": 0.003, "width": 0.002, "monte_carlo_tries": 100000}
    data["geometry"]["thickness"] = 0.0022
    data["engine"]["ranks"] = 1
    case = case_from_dict(data)
    d = derive(case)
    text = render_deck_text(d)
    assert "fflag on off on tflag off on off" in text and "orientation template" in text
    assert "region          insertion block" in text and "all_in no" in text
    assert d.fill.region.yhi == pytest.approx(0.5 * 0.0022 - 0.001)
    # dust in a slab: poured into the mid-plane and held there; inserted before the grains of
    # the same step, whose overlap check (unlike the dust's) sees the other fix's particles
    pair = {"friction": 0.3, "restitution": 0.5}
    data["particles"]["dust"] = {"radius": 0.0002, "density": 2000.0, "number_ratio": 0.1, "youngs_modulus": 5e6,
                                 "dust_dust": pair, "dust_particle": pair, "dust_wall": pair}
    case = case_from_dict(data)
    d = derive(case)
    text = render_deck_text(d)
    lines = text.splitlines()
    first = {key: next(k for k, line in enumerate(lines) if line.startswith(key))
             for key in ("fix             ins_dust", "fix             ins all", "region          insertion_dust")}
    assert first["region          insertion_dust"] < first["fix             ins_dust"] < first["fix             ins all"]
    assert "region insertion_dust" in lines[first["fix             ins_dust"]]
    plane = next(line for line in lines if line.startswith("region          insertion_dust")).split()
    assert abs(float(plane[5])) < 1e-6 and abs(float(plane[6])) < 1e-6       # y range: the mid-plane
    assert "fix             dust_in_plane dust setforce NULL 0.0 NULL" in text


@pytest.mark.parametrize("path,value,field", [
    ("geometry.thickness", 0.0025, "geometry.thickness"),          # not wider than a grain
    ("geometry.outlet_width", 0.002, "geometry.outlet_width"),     # narrower than a grain
    ("sensors.heights", [0.0, 0.05, 0.2], "sensors.heights"),      # above the side walls
])
def test_slab_input_is_refused_naming_the_field(path, value, field):
    data = slab_dict()
    if path == "sensors.heights":
        data["sensors"] = {"heights": value}
    else:
        set_path(data, path, value)
    with pytest.raises(CaseError) as info:
        case_from_dict(data)
    assert any(field in f"{p} {m}" for p, m in info.value.problems), info.value.problems


# ---------------------------------------------------------------- a real run
@pytest.fixture(scope="module")
def slab_run(tmp_path_factory):
    run = engine_run(tmp_path_factory, SLAB, "slab")
    return load_case(SLAB), run.folder, run.record, run.summary


@pytest.mark.engine
@pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS not installed (make install-engine); "
                    "CI installs it, so CI never skips this")
def test_slab_run_keeps_grains_in_the_slab_and_senses_both_walls(slab_run):
    case, folder, record, summary = slab_run
    g = case.geometry
    assert record.inserted == derive(case).fill.count
    # the walls, hopper, faces and plate carry the settled bed's weight
    assert summary["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.01)
    for frame in read_frames(folder / "output" / "dumps"):
        inside = frame.positions()[:, 2] > 0.0                              # not yet out of the slot
        y, r = frame.positions()[inside, 1], frame.radii()[inside]
        assert np.all(np.abs(y) + r <= 0.5 * g.thickness + 0.05 * r)     # one layer, between the faces
        assert np.all(np.abs(frame.positions()[inside, 0]) < g.half_width)
    sectors = pd.read_csv(folder / "results" / "wall_pressure_sectors.csv")
    assert set(sectors.sector) == {0, 1} and sectors.band.nunique() == case.sensors.bands
    static = json.loads((folder / "results" / "summary.json").read_text())["bands"]
    p = [b["static_pressure"] for b in static]
    h = summary["frame_analyses"]["settled_surface_height_m"]
    buried = [b for b in static if b["z_mid"] < h - 4 * 2 * case.particles.radius]
    assert len(buried) >= 2
    assert all(b["static_pressure"] > 0 for b in buried)
    assert p[0] > p[1]                                                  # pressure grows with depth
    # horizontal force balance of the resting bed: what pushes the left wall pushes the right
    # (and hopper) back; frictionless faces take no x force
    from siloflow.engine.tables import read_ave_time, wall_force_columns
    walls = RunFolder(folder).plan.walls
    forces = read_ave_time(folder / ENGINE_FILES["liggghts"].tables[1], wall_force_columns(walls))   # wall_forces.txt
    still = forces[(forces.step > record.stage_steps["static"]) & (forces.step <= record.stage_steps["open"])]
    fx = still[[c for c in still if c.endswith("_fx")]]
    load = fx.abs().sum(axis=1)                      # every wall's horizontal load, hopper and plate too
    assert np.all(np.abs(fx.sum(axis=1)) < 0.03 * load)   # a bed at rest (KE/PE < 1e-5): sampled 1-2 %
    faces = still[[f"{w.name}_fx" for w in walls if w.role == "face"]].abs().sum(axis=1)
    assert np.all(faces < 1e-3 * load)
    # grains left through the slot; Wr (surface speed) agrees with Wf (outlet count)
    assert summary["discharged_mass_kg"] > 0.3 * summary["initial_mass_kg"]
    assert summary["frame_analyses"]["flow_rate_surface_over_outlet"] == pytest.approx(1.0, abs=0.15)


@pytest.mark.engine
@pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS not installed (make install-engine); "
                    "CI installs it, so CI never skips this")
def test_slab_coarse_graining_gives_the_beds_own_solid_fraction(slab_run, tmp_path):
    """siloflow cg on a slab run: fields averaged through the thickness. In the flowing bed's
    middle the solid fraction is the bed's (the 3D kernel sampled at y = 0 gave about 0.3 of it)."""
    import xarray as xr
    from typer.testing import CliRunner

    from siloflow.cli import app
    case, folder, record, summary = slab_run
    out = tmp_path / "cg"
    result = CliRunner().invoke(app, ["cg", str(folder), "--grid", "cartesian", "--nr", "24", "--nz", "40",
                                      "--width", "2", "-o", str(out)])
    assert result.exit_code == 0, result.output
    fa = summary["frame_analyses"]
    with xr.open_dataset(out / "fields.nc") as ds:
        assert ds.attrs["slab_thickness_m"] == pytest.approx(case.geometry.thickness)
        assert ds.sizes["y"] == 1
        g = case.geometry
        mid = ds.solid_fraction.isel(y=0).sel(x=slice(-0.25 * g.half_width, 0.25 * g.half_width),
                                              z=slice(g.hopper_height + 0.01, g.hopper_height + 0.02)).mean()
        # settled 0.5-0.6; flowing somewhat looser
        assert 0.75 * fa["bulk_solid_fraction"] < float(mid) < 1.05 * fa["bulk_solid_fraction"]


@pytest.mark.parametrize("deck", ["slab", "cylinder"])
def test_central_fill_pours_from_a_narrow_region(deck, quick_dict):
    data = slab_dict() if deck == "slab" else quick_dict
    distributed = derive(case_from_dict(data))
    data["fill"]["pour_radius"] = 0.01
    central = derive(case_from_dict(data))
    r = central.fill.region
    assert (r.xhi if deck == "slab" else r.radius) == pytest.approx(0.01)
    assert central.fill.batch < distributed.fill.batch                 # same solid fraction per batch
    data["fill"]["pour_radius"] = 0.001                                 # narrower than two grains
    with pytest.raises(CaseError, match="fill.pour_radius"):
        case_from_dict(data)


def test_free_surface_of_a_slab_with_a_sloped_heap_tracks_its_volume():
    from test_post_analyses import frame_of

    from postprocess.flow_rate import FreeSurface

    rng = np.random.default_rng(11)
    a, t, r, n = 0.1, 0.003, 0.001, 30000
    # grains filling the slab up to h(x) = 0.08 + 0.04 |x| / a (a V-shaped crater), mean height 0.1
    x = rng.uniform(-a, a, n)
    z = rng.random(n) * (0.08 + 0.04 * np.abs(x) / a)
    frame = frame_of(np.column_stack([x, rng.uniform(-t / 2, t / 2, n), z]), np.full(n, r))
    fs = FreeSurface(radius=a, thickness=t, annuli=8)
    h = fs.run([frame]).table.surface_height.iloc[0]
    assert h == pytest.approx(0.1, abs=2 * r)
    assert fs.area == pytest.approx(2 * a * t)


def test_janssen_diameter_of_a_slab_counts_the_walls_with_friction():
    from postprocess.dump_results import janssen_diameter

    g = load_case(SLAB).geometry
    assert janssen_diameter(g) == pytest.approx(2 * g.width)           # side walls only: 4 W T / 2 T
    data = slab_dict()
    data["geometry"]["face_friction"] = 0.3
    g = case_from_dict(data).geometry
    assert janssen_diameter(g) == pytest.approx(4 * g.width * g.thickness / (2 * (g.width + g.thickness)))
