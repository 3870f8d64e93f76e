"""Slabs on a flat floor (``half_angle_deg: 90``), with an offset slot (``outlet_offset``) and
periodic in depth (``periodic_depth``): their walls on both engines, their refusals, the periodic
fill, and a small discharge of each on each engine (force balance in z and x, mass counted, a
steady flow; the periodic slab's grains fill its depth evenly)."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import yaml
from conftest import ROOT, engine_run

from postprocess.first_results import RunOutputs, static_window
from siloflow.case_file import case_from_dict
from siloflow.derived import bed_volume, derive
from siloflow.engine.lammps.deck import walls as lammps_walls
from siloflow.errors import CaseError

FLAT = ROOT / "tests" / "data" / "slab_flat.yaml"
SLAB = ROOT / "tests" / "data" / "slab_silo.yaml"
PERIODIC = ROOT / "tests" / "data" / "slab_periodic.yaml"


def data_of(path=FLAT, **geometry) -> dict:
    data = yaml.safe_load(path.read_text())
    data["geometry"] = {**data["geometry"], **geometry}
    return data


def plan_of(data):
    return derive(case_from_dict(data))


def test_flat_floor_has_no_hopper_and_closes_the_slot_where_the_offset_puts_it():
    plan = plan_of(data_of())
    g = plan.geometry
    assert g.hopper_height == 0.0 and g.outlet_offset == 0.01
    walls = {m.name: m for m in plan.meshes}
    assert {"bottom_s00", "bottom_s01", "plate"} <= set(walls) and not any(m.role == "hopper" for m in walls.values())
    x = {n: np.asarray(walls[n].triangles)[..., 0] for n in ("bottom_s00", "bottom_s01", "plate")}
    z = np.concatenate([np.asarray(walls[n].triangles)[..., 2].ravel() for n in x])
    assert np.allclose(z, 0.0)
    # left floor, slot (plate), right floor: the floor's width without gap or overlap
    assert x["bottom_s00"].min() == pytest.approx(-0.03) and x["bottom_s00"].max() == pytest.approx(0.001)
    assert x["plate"].min() == pytest.approx(0.001) and x["plate"].max() == pytest.approx(0.019)
    assert x["bottom_s01"].min() == pytest.approx(0.019) and x["bottom_s01"].max() == pytest.approx(0.03)
    areas = sum(walls[n].area for n in x)
    assert areas == pytest.approx(0.06 * 0.00275, rel=1e-12)
    # the faces are the whole rectangle; the bed's volume is the rectangle's
    faces = [m for m in plan.meshes if m.role == "face"]
    assert all(m.area == pytest.approx(0.06 * 0.09, rel=1e-12) for m in faces)
    case = case_from_dict(data_of())
    assert bed_volume(case, 0.05) == pytest.approx(0.06 * 0.05 * 0.00275, rel=1e-12)


def test_offset_wedge_is_the_centred_wedge_sheared():
    centred, offset = plan_of(data_of(SLAB)), plan_of(data_of(SLAB, outlet_offset=-0.008))
    c, o = ({m.name: m for m in p.meshes} for p in (centred, offset))
    assert o["face_s00"].area == pytest.approx(c["face_s00"].area, rel=1e-12)
    # the slot's edges moved by the offset, the hopper's tops stayed at the side walls' feet
    for name, edge in (("hopper_s00", -0.009 - 0.008), ("hopper_s01", 0.009 - 0.008)):
        pts = np.asarray(o[name].triangles).reshape(-1, 3)
        assert pts[pts[:, 2] == 0.0, 0] == pytest.approx(edge)
        assert np.abs(pts[np.isclose(pts[:, 2], offset.geometry.hopper_height), 0]) == pytest.approx(0.03)
    assert offset.fill.bed_height_estimate == pytest.approx(centred.fill.bed_height_estimate, rel=1e-12)
    # the centred slab's meshes are those it always had (byte-identical goldens): offset 0 changes nothing
    assert all(np.array_equal(m.triangles, plan_of(data_of(SLAB, outlet_offset=0.0)).meshes[k].triangles)
               for k, m in enumerate(centred.meshes))


@pytest.mark.parametrize("geometry", [{"outlet_offset": 0.021}, {"outlet_offset": -0.021}, {"half_angle_deg": 90.5},
                                      {"outlet_offset": float("inf")}])
def test_slot_outside_the_slab_is_refused_naming_the_field(geometry):
    with pytest.raises(CaseError) as info:
        case_from_dict(data_of(**geometry))
    assert info.value.problems[0][0] == f"geometry.{next(iter(geometry))}"


def test_lammps_flat_floor_is_two_blocks_beside_the_slot():
    regions = {rid: (style, args) for w in lammps_walls(plan_of(data_of())) for rid, style, args in w.regions}
    assert "rim" not in regions and not any(r.startswith("hopper") for r in regions)
    (_, left), (_, right), (_, plate) = regions["floor_left"], regions["floor_right"], regions["plate"]
    assert float(left[1]) == pytest.approx(0.001) and float(right[0]) == pytest.approx(0.019)
    assert (float(plate[0]), float(plate[1])) == pytest.approx((0.001, 0.019))
    assert left[-2:] == ["side", "out"] and float(left[5]) == 0.0          # the floor's top at z = 0
    # an offset wedge: each plane through its own edge of the slot
    sheared = {rid: args for w in lammps_walls(plan_of(data_of(SLAB, outlet_offset=-0.008)))
               for rid, style, args in w.regions}
    assert float(sheared["hopper_left_plane"][0]) == pytest.approx(-0.017)
    assert float(sheared["hopper_right_plane"][0]) == pytest.approx(0.001)


def test_periodic_slab_has_no_faces_and_a_periodic_box_on_both_engines(tmp_path):
    from siloflow.engine.lammps.deck import box as lammps_box
    from siloflow.engine.lammps.deck import render_deck_text as lammps_deck
    from siloflow.engine.liggghts.deck import render_deck_text as liggghts_deck
    from siloflow.engine.liggghts.encoding import encode
    plan = plan_of(data_of(PERIODIC))
    assert plan.geometry.periodic_depth and not any(m.role == "face" for m in plan.meshes)
    b = 0.005
    for m in plan.meshes:                                 # every wall spans the periodic length exactly
        y = np.asarray(m.triangles)[..., 1]
        assert (y.min(), y.max()) == pytest.approx((-b, b), abs=1e-15), m.name
    assert (encode(plan).box["ylo"], encode(plan).box["yhi"]) == (-b, b)
    assert (lammps_box(plan, 10)["ylo"], lammps_box(plan, 10)["yhi"]) == (-b, b)
    assert "boundary        f p f" in liggghts_deck(plan)
    lmp = lammps_deck(plan)
    assert "boundary        f p f" in lmp and "region          faces" not in lmp
    walled = data_of(PERIODIC, periodic_depth=False, thickness=0.00275)
    walled["fill"]["count"] = 400
    walled = plan_of(walled)
    assert "boundary        f f f" in lammps_deck(walled) and "region          faces" in lammps_deck(walled)


def test_periodic_fill_places_no_grain_on_its_image():
    from scipy.spatial import cKDTree

    from siloflow.fill_placement import fill_batches
    plan = plan_of(data_of(PERIODIC))
    L = plan.geometry.thickness
    first = fill_batches(plan)[0]
    c, r = first.centres, plan.particle_radius
    assert len(c) > 100 and (np.abs(c[:, 1]) <= 0.5 * L).all()
    # through the periodic boundary too: no two centres closer than a diameter
    q = c - c.min(axis=0)
    q[:, 1] = np.mod(c[:, 1] + 0.5 * L, L)
    size = np.array([q[:, 0].max() + 1, L, q[:, 2].max() + 1])
    pairs = cKDTree(q, boxsize=size).query_pairs(2 * r * (1 - 1e-9))
    assert not pairs
    # and grains were placed across the boundary: some within a radius of it on each side
    assert (c[:, 1] > 0.5 * L - r).any() and (c[:, 1] < -0.5 * L + r).any()


@pytest.mark.parametrize("changes,field", [
    ({"periodic_depth": True, "face_friction": 0.3}, "geometry.periodic_depth"),
    ({"periodic_depth": 1}, "geometry.periodic_depth"),
])
def test_periodic_slab_refuses_face_friction_naming_the_field(changes, field):
    with pytest.raises(CaseError) as info:
        case_from_dict(data_of(PERIODIC, **changes))
    assert info.value.problems[0][0] == field


def test_periodic_slab_refuses_a_depth_of_fewer_than_three_grains_and_clumps():
    with pytest.raises(CaseError, match="geometry.thickness .* must hold at least 3 grain diameters"):
        case_from_dict(data_of(PERIODIC, thickness=0.007))
    data = data_of(PERIODIC)
    data["particles"] = {"kind": "clumps", "shape": "wheat", "length": 0.005, "width": 0.0025}
    with pytest.raises(CaseError, match="periodic_depth: a periodic slab takes spheres"):
        case_from_dict(data)


@pytest.fixture(scope="module", params=[(FLAT, "liggghts"), (FLAT, "lammps"), (PERIODIC, "liggghts"),
                                        (PERIODIC, "lammps")], ids=lambda p: f"{p[0].stem}-{p[1]}")
def slab_run(request, tmp_path_factory):
    path, engine = request.param
    run = engine_run(tmp_path_factory, data_of(path), f"{path.stem}_{engine}", engine)
    return engine, run.folder, run.summary


@pytest.mark.engine
def test_slab_balances_in_z_and_x_counts_and_flows(slab_run):
    engine, folder, summary = slab_run
    from siloflow.run_folder import RunFolder
    run = RunFolder(folder)
    assert summary["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.02), engine
    # x: the settled bed at rest pushes its walls, floor and plate with no net horizontal force
    out = RunOutputs(folder)
    still = out.forces[static_window(out.forces, out)]
    fx = still[[c for c in still if c.endswith("_fx")]]
    load = fx.abs().sum(axis=1)                          # every wall's horizontal load
    assert (load > 0).all()
    assert np.all(np.abs(fx.sum(axis=1)) < 0.03 * load), engine      # a bed at rest (KE/PE < 1e-5): sampled
    dis = pd.read_csv(folder / "results" / "discharge.csv")
    end, m0 = dis.iloc[-1], summary["initial_mass_kg"]
    m_p = m0 / run.plan.fill.count
    # nothing lost: every grain that left the box (deleted below the outlet) was counted there first; a
    # counted grain not yet deleted is still below the orifice
    deleted = summary["initial_mass_kg"] - end.mass_total
    in_transit = end.mass_total - end.mass_in_silo
    assert -0.5 * m_p <= end.outlet_mass - deleted <= in_transit + 0.5 * m_p, engine
    assert -0.5 * m_p <= (m0 - end.mass_in_silo) - end.outlet_mass <= end.mass_total - end.mass_in_silo + 0.5 * m_p
    fr = summary["flow_rate"]
    assert fr["r2"] > 0.98 and fr["stderr"] < 0.1 * fr["rate"], engine
    assert end.outlet_mass > 50 * m_p
    if run.plan.geometry.outlet_offset:
        assert summary["eccentric_discharge"]["near_sector"] == 1


@pytest.mark.engine
def test_slab_holds_its_count_within_its_depth(slab_run):
    """Every grain asked for is in, and the settled grains keep to the depth: between a walled slab's
    faces; evenly through a periodic slab's depth (it has no faces to layer against), so the count
    per unit depth is the case's."""
    engine, folder, summary = slab_run
    from postprocess.dumps import read_frames
    from siloflow.run_folder import RunFolder
    run = RunFolder(folder)
    g = run.plan.geometry
    assert run.record.inserted == run.plan.fill.count
    open_step = run.record.stage_steps["open"]
    settled = [f for f in read_frames(run.dump_files("particles")) if f.timestep <= open_step][-1]
    y, r = settled.wrapped_positions()[:, 1], settled.radii()    # a periodic depth: wrapped as the engine will
    assert len(y) == run.plan.fill.count
    if not g.periodic_depth:                        # one layer between the faces
        assert np.all(np.abs(y) + r <= 0.5 * g.thickness + 0.05 * r), engine
        return
    assert (np.abs(y) <= 0.5 * g.thickness * (1 + 1e-9)).all()
    counts, _ = np.histogram(y, bins=4, range=(-0.5 * g.thickness, 0.5 * g.thickness))
    expected = len(y) / 4
    assert np.all(np.abs(counts - expected) < 4 * np.sqrt(expected)), (engine, counts)


@pytest.mark.parametrize("shift", [0.0, 0.3, 0.5])
def test_porosity_of_a_periodic_slab_counts_the_volume_grains_carry_across_its_ends(shift):
    """A simple cubic packing (solid fraction pi/6) in a slab periodic over 4 diameters, placed so
    that grains straddle y = -+ L/2: a cylinder through the depth measures pi/6 only with the
    grains' periodic images (without them, the straddling grains' far halves are lost)."""
    from test_post_analyses import frame_of

    from postprocess.porosity import MeasureRegion, Porosity
    d, L = 1.0, 4.0
    grid = np.arange(-10, 11) * d
    ys = (np.arange(4) + shift) * d - 0.5 * L
    ys = np.mod(ys + 0.5 * L, L) - 0.5 * L                       # wrapped into [-L/2, L/2)
    pos = np.array([(x, y, z) for x in grid for y in ys for z in grid], float)
    frame = frame_of(pos, np.full(len(pos), 0.5 * d))
    region = MeasureRegion("through", "cylinder", (0.0, 0.0, 0.0), 6.0 * d, axis=1, t0=-0.5 * L, t1=0.5 * L)
    periodic = Porosity([region], period_y=L).run([frame]).table.solid_fraction.iloc[0]
    walled = Porosity([region]).run([frame]).table.solid_fraction.iloc[0]
    assert periodic == pytest.approx(math.pi / 6, rel=0.02)
    # without the images each layer loses the cap beyond the end: pi h^2 (3 r - h) / 3, h its height
    r = 0.5 * d
    caps = [math.pi * h * h * (3 * r - h) / 3 for h in np.maximum(0.0, np.abs(ys) + r - 0.5 * L)]
    assert walled == pytest.approx(periodic * (1 - sum(caps) / (len(ys) * 4 / 3 * math.pi * r ** 3)), rel=1e-3)


def test_beverloo_of_slots_is_the_two_dimensional_law_and_its_fit_recovers_c_and_k():
    from postprocess.flow_rate import beverloo, fit_beverloo
    # W = C rho_b sqrt(g) L (W0 - k d)^(3/2)
    assert float(beverloo(0.03, 0.003, 0.6, 1.4, 1500.0, 9.81, slot_length=0.01)) == pytest.approx(
        0.6 * 1500.0 * math.sqrt(9.81) * 0.01 * (0.03 - 1.4 * 0.003) ** 1.5, rel=1e-12)
    W0 = np.array([0.012, 0.015, 0.02, 0.025])
    L = np.array([0.01, 0.01, 0.02, 0.02])
    W = beverloo(W0, 0.0025, 0.65, 1.3, 1500.0, slot_length=L)
    fit = fit_beverloo(W0, 0.0025, W, 1500.0, slot_length=L)
    assert (fit.C, fit.k) == pytest.approx((0.65, 1.3), rel=1e-6)
    # the round-orifice law on the same numbers is another fit: the slot's must be asked for
    assert fit_beverloo(W0, 0.0025, W, 1500.0).k != pytest.approx(1.3, rel=1e-3)
