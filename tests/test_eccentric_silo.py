"""Eccentric outlets (``geometry.outlet_offset``): the walls they make (a floor with an off-centre
orifice, an oblique cone), their refusals, the per-azimuth pressures and the EN 1991-4 eccentricity;
and a small eccentric discharge on both engines (force balance, mass counted, a steady flow, the
flow channel against the outlet's wall)."""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
import yaml
from conftest import ROOT, engine_run

from postprocess.dumps import read_frames
from postprocess.first_results import eccentric_discharge
from siloflow.case_file import case_from_dict
from siloflow.derived import derive
from siloflow.design_loads import bulk_solid, design_loads
from siloflow.engine import get_engine
from siloflow.engine.lammps.deck import walls as lammps_walls
from siloflow.errors import CaseError
from siloflow.fill_cache import fill_key_inputs

ECCENTRIC = ROOT / "tests" / "data" / "eccentric_silo.yaml"
R, R_OUT, E = 0.0125, 0.0065, 0.004


def case_data(**geometry) -> dict:
    data = yaml.safe_load(ECCENTRIC.read_text())
    data["geometry"] = {**data["geometry"], **geometry}
    return data


def hopper(**changes) -> dict:
    return case_data(**{"kind": "hopper", "half_angle_deg": 30.0, "outlet_radius": R_OUT, "orifice_radius": None,
                        "outlet_offset": 0.0, **changes})


def plan_of(data: dict):
    data = {**data, "geometry": {k: v for k, v in data["geometry"].items() if v is not None}}
    return derive(case_from_dict(data))


def meshes(plan) -> dict:
    return {m.name: m for m in plan.meshes}


def edges(triangles, boundary_only=True) -> set:
    """The (rounded) edges of a triangle set; with ``boundary_only`` those of one triangle only."""
    count: dict = {}
    for t in np.round(np.asarray(triangles, float), 9):
        for a, b in ((0, 1), (1, 2), (2, 0)):
            key = tuple(sorted((tuple(t[a]), tuple(t[b]))))
            count[key] = count.get(key, 0) + 1
    return {k for k, n in count.items() if n == 1 or not boundary_only}


def test_eccentric_floor_keeps_its_area_faces_up_and_closes_on_the_wall_and_the_plate():
    centred, eccentric = meshes(plan_of(case_data(outlet_offset=0.0))), meshes(plan_of(case_data()))
    floor = eccentric["bottom"]
    # the annulus is mapped inside its plane: the same area as the centred one's, every facet facing up
    assert floor.area == pytest.approx(centred["bottom"].area, rel=1e-9)
    t = np.asarray(floor.triangles)
    assert np.allclose(t[..., 2], 0.0)
    assert (np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])[:, 2] > 0).all()
    # its edges are the wall's lowest ring and the plate's rim: no gap a grain could fall through
    plate = eccentric["plate"]
    wall_ring = {e for name, m in eccentric.items() if m.role == "band" and m.band == 0
                 for e in edges(m.triangles) if e[0][2] == 0.0 and e[1][2] == 0.0}
    assert edges(floor.triangles) == wall_ring | edges(plate.triangles)
    # the plate is the orifice at x = e, the counting disc under it
    p = np.asarray(plate.triangles).reshape(-1, 3)
    assert np.hypot(p[:, 0] - E, p[:, 1]).max() == pytest.approx(R_OUT, rel=1e-9)
    assert np.asarray(eccentric["outlet"].triangles)[..., 0].mean() == pytest.approx(E, abs=1e-4)


def test_eccentric_sectors_are_centred_on_the_outlet_and_opposite_it():
    plan = plan_of(case_data())
    bands = [w for w in plan.walls if w.role == "band" and w.band == 0]
    centres = {w.sector: math.degrees(0.5 * (w.theta0 + w.theta1)) % 360 for w in bands}
    assert centres == pytest.approx({0: 0.0, 1: 90.0, 2: 180.0, 3: 270.0}, abs=1e-9)
    assert bands[0].normal == pytest.approx((1.0, 0.0))
    # the sector's own facets lie about its centre: its mean point is on the outlet's side
    m = meshes(plan)[bands[0].name]
    t = np.asarray(m.triangles)
    assert t[..., 0].mean() > 0.85 * R and abs(t[..., 1].mean()) < 1e-9


def test_oblique_cone_runs_from_the_offset_outlet_to_the_cylinder():
    plan = plan_of(hopper(outlet_offset=0.004))
    cone = np.asarray(meshes(plan)["cone"].triangles)
    pts = cone.reshape(-1, 3)
    hh = plan.geometry.hopper_height
    low, high = pts[np.isclose(pts[:, 2], 0.0)], pts[np.isclose(pts[:, 2], hh)]
    assert np.hypot(low[:, 0] - 0.004, low[:, 1]).max() == pytest.approx(R_OUT, rel=1e-9)
    assert np.hypot(high[:, 0], high[:, 1]).max() == pytest.approx(R, rel=1e-9)
    # every facet faces into the silo (up) and the near side is steeper than the far side
    normals = np.cross(cone[:, 1] - cone[:, 0], cone[:, 2] - cone[:, 0])
    assert (normals[:, 2] > 0).all()
    near, far = math.degrees(math.atan((R - R_OUT - 0.004) / hh)), math.degrees(math.atan((R - R_OUT + 0.004) / hh))
    assert near < 30.0 < far
    # an oblique frustum holds what the right one holds (Cavalieri): the fill estimate does not move
    assert plan.fill.bed_height_estimate == pytest.approx(plan_of(hopper()).fill.bed_height_estimate, rel=1e-12)


@pytest.mark.parametrize("geometry,field", [
    ({"outlet_offset": R - R_OUT}, "geometry.outlet_offset"),
    ({"outlet_offset": -0.001}, "geometry.outlet_offset"),
    ({"outlet_offset": float("nan")}, "geometry.outlet_offset"),
    ({"outlet_offset": R - R_OUT - 1e-4}, "geometry.outlet_offset"),      # the floor's gap cannot be meshed
])
def test_outlet_offset_outside_what_fits_is_refused_naming_the_field(geometry, field):
    with pytest.raises(CaseError) as info:
        plan_of(case_data(**geometry))
    assert info.value.problems[0][0] == field


def test_lammps_refuses_an_oblique_hopper_and_moves_the_floors_hole_for_a_cylinder():
    data = hopper(outlet_offset=0.003)
    data["engine"] = {**data["engine"], "name": "lammps"}
    data["geometry"] = {k: v for k, v in data["geometry"].items() if v is not None}
    problems = get_engine("lammps").check(case_from_dict(data))
    assert [p[0] for p in problems] == ["geometry.outlet_offset"]
    regions = {rid: (style, args) for w in lammps_walls(plan_of(case_data())) for rid, style, args in w.regions}
    for rid in ("bottom_hole", "plate", "rim"):
        style, args = regions[rid]
        x = float(args[0] if style == "sphere" else args[1])
        assert x == E, rid
    assert float(regions["side"][1][1]) == 0.0          # the silo stays on the axis


def test_design_loads_take_the_outlets_eccentricity():
    plan = plan_of(case_data())
    solid = bulk_solid("wheat")
    loads = design_loads(plan.geometry, solid, 0.07, "D2", 1, 0.0)
    centred = design_loads(plan_of(case_data(outlet_offset=0.0)).geometry, solid, 0.07, "D2", 1, 0.0)
    assert loads.eccentricity == E and centred.eccentricity == 0.0
    # AAC 1, slender: (5.21) C_w = 1.4 (1 + 0.4 e / d_c)
    assert loads.C_w == pytest.approx(1.4 * (1 + 0.4 * E / (2 * R))) and centred.C_w == pytest.approx(1.4)
    assert any("e_o" in n for n in loads.notes)


def test_fill_key_ignores_a_flat_floors_offset_but_not_a_hoppers():
    """Eccentric cylinders share a fill whatever their offset (the plate closes the floor); not with
    the centred one, whose sensor sectors are turned by half a sector (another partition of the wall
    is another bed in LIGGGHTS)."""
    lig = get_engine("liggghts")
    key = lambda data: json.dumps(fill_key_inputs(plan_of(data), lig), sort_keys=True)  # noqa: E731
    assert key(case_data()) == key(case_data(outlet_offset=0.002))
    assert key(case_data()) != key(case_data(outlet_offset=0.0))
    assert key(hopper(outlet_offset=0.003)) != key(hopper())
    assert "outlet_offset" not in fill_key_inputs(plan_of(hopper()), lig)["geometry"]


def test_near_and_far_pressures_carry_the_mirror_pairs_packing_spread():
    """Mirror sectors 1 and 3 differ by exactly the packing's spread (their time series having no
    error): the difference near - far gets it, on top of the time series' error."""
    rows = []
    for band, (p1, p3) in enumerate([(110.0, 90.0), (90.0, 110.0)]):
        for sector, p in enumerate([150.0, p1, 100.0, p3]):
            rows.append({"band": band, "sector": sector, "z_mid": 0.01 * band, "dynamic_mean_pressure": p,
                         "dynamic_mean_stderr": 3.0 if sector in (0, 2) else 0.0, "dynamic_samples": 100})
    out = eccentric_discharge(pd.DataFrame(rows), 4, 0.01)
    # d = 20 Pa on a mean of 100 Pa in each pair: relative variance 0.04 / 2
    assert out["packing_relative_sd"] == pytest.approx(math.sqrt(0.02))
    b = out["bands"][0]
    assert b["difference"] == pytest.approx(50.0)
    assert b["difference_stderr"] == pytest.approx(math.hypot(math.hypot(3, 3), math.sqrt(0.02) * math.hypot(150, 100)))
    assert out["far_sectors"] == [2]
    # five sectors: no sector is opposite the outlet, the two either side of 180 deg are
    assert eccentric_discharge(pd.DataFrame(rows), 5, 0.01)["far_sectors"] == [2, 3]


# ---------------------------------------------------------------- a small eccentric discharge, both engines

def discharge_of(tmp_path_factory, engine: str, name: str, geometry: dict | None = None):
    """One run of the eccentric case (its geometry changed by ``geometry``) on ``engine``:
    (engine, folder, summary)."""
    data = yaml.safe_load(ECCENTRIC.read_text())
    if geometry:
        data["geometry"] = geometry
    run = engine_run(tmp_path_factory, data, f"eccentric_{name}", engine)
    return name, run.folder, run.summary


@pytest.fixture(scope="module", params=["liggghts", "lammps"])
def eccentric_run(request, tmp_path_factory):
    """The eccentric cylinder on each engine."""
    return discharge_of(tmp_path_factory, request.param, request.param)


@pytest.fixture(scope="module")
def oblique_run(tmp_path_factory):
    """An oblique hopper (outlet 3 mm off the axis, a 30 deg cone) on LIGGGHTS (LAMMPS refuses it:
    its cone region is a right cone)."""
    return discharge_of(tmp_path_factory, "liggghts", "liggghts-hopper", {
        "kind": "hopper", "radius": R, "height": 0.16, "half_angle_deg": 30.0, "outlet_radius": R_OUT,
        "outlet_offset": 0.003, "mesh_segments": 32})


def balances_counts_and_flows(engine, folder, summary):
    """Force balance within 2 %, every grain that left counted, a steady flow."""
    assert summary["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.02), engine
    dis = pd.read_csv(folder / "results" / "discharge.csv")
    end = dis.iloc[-1]
    m_p = summary["initial_mass_kg"] / 2500
    # nothing lost: every grain that left the box (deleted below the outlet) was counted there first; a
    # counted grain not yet deleted is still below the orifice
    deleted = summary["initial_mass_kg"] - end.mass_total
    in_transit = end.mass_total - end.mass_in_silo
    assert -0.5 * m_p <= end.outlet_mass - deleted <= in_transit + 0.5 * m_p, engine
    assert dis.mass_total.max() == pytest.approx(summary["initial_mass_kg"], rel=1e-9)
    # what left the silo was counted, but for grains between the orifice and the counting disc
    left = summary["initial_mass_kg"] - end.mass_in_silo
    assert -0.5 * m_p <= left - end.outlet_mass <= end.mass_total - end.mass_in_silo + 0.5 * m_p
    fr = summary["flow_rate"]
    assert fr["r2"] > 0.98 and fr["stderr"] < 0.1 * fr["rate"], engine
    assert end.outlet_mass > 100 * m_p


@pytest.mark.engine
def test_eccentric_discharge_balances_counts_and_flows_steadily(eccentric_run):
    balances_counts_and_flows(*eccentric_run)


@pytest.mark.engine
def test_oblique_hopper_balances_counts_and_flows_steadily(oblique_run):
    balances_counts_and_flows(*oblique_run)


@pytest.mark.engine
def test_eccentric_flow_runs_down_the_wall_facing_the_outlet(eccentric_run):
    """The flow channel meets the wall on the outlet's side: the grains against that wall, in the
    lower half of the bed, go down faster than those against the opposite wall (measured: 2.8x on
    both engines), and the report gives every band's near and far pressure."""
    engine, folder, summary = eccentric_run
    from siloflow.run_folder import RunFolder
    run = RunFolder(folder)
    dt, fr = run.plan.dt, summary["flow_rate"]
    d = 2 * run.plan.particle_radius
    near, far = [], []
    for frame in read_frames(run.dump_files("particles")):
        if not fr["t_start"] <= frame.timestep * dt <= fr["t_end"]:
            continue
        p, v = frame.positions(), frame.velocities()
        azimuth = np.degrees(np.arctan2(p[:, 1], p[:, 0]))
        against = (np.hypot(p[:, 0], p[:, 1]) > R - 2 * d) & (p[:, 2] > 0) & (p[:, 2] < 0.04)
        near.append(v[against & (np.abs(azimuth) < 45), 2].mean())
        far.append(v[against & (np.abs(azimuth) > 135), 2].mean())
    assert len(near) >= 10
    assert np.mean(near) < 1.5 * np.mean(far) < 0, engine
    ecc = summary["eccentric_discharge"]
    assert ecc["outlet_offset_m"] == E and len(ecc["bands"]) == 7
    sectors = pd.read_csv(folder / "results" / "sectors.csv")
    assert sorted(sectors.azimuth_deg.round(6).unique()) == [0.0, 90.0, 180.0, 270.0]
    assert "Eccentric outlet" in (folder / "results" / "report.md").read_text()
