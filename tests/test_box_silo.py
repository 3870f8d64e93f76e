"""Rectangular silos (``geometry.kind: box``): flat floors around a rectangle, slot or circle,
pyramidal and wedge hoppers, offset outlets; their walls on both engines, their refusals, the
frustum's volume, Beverloo's rectangular law; and small discharges on both engines (force balance
in x, y and z, mass counted, a steady flow, four sensed walls)."""
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

BOX = ROOT / "tests" / "data" / "box_silo.yaml"
A, B = 0.025, 0.015                       # half width and half depth, m

VARIANTS = {
    "rectangle": {},
    "pyramid": {"half_angle_deg": 35.0, "outlet_offset": 0.008, "outlet_offset_y": 0.004},
    "wedge": {"half_angle_deg": 35.0, "outlet": "slot", "outlet_length": None, "outlet_width": 0.01},
    "slot": {"outlet": "slot", "outlet_length": None, "outlet_width": 0.01},
    "circle": {"outlet": "circle", "outlet_width": None, "outlet_length": None, "outlet_radius": 0.0065,
               "outlet_offset": -0.01},
}


def data_of(**geometry) -> dict:
    data = yaml.safe_load(BOX.read_text())
    data["geometry"] = {k: v for k, v in {**data["geometry"], **geometry}.items() if v is not None}
    return data


def plan_of(variant: str):
    return derive(case_from_dict(data_of(**VARIANTS[variant])))


def points(m) -> np.ndarray:
    return np.asarray(m.triangles).reshape(-1, 3)


@pytest.mark.parametrize("variant", ["rectangle", "slot", "circle"])
def test_flat_floor_and_plate_cover_the_box_exactly(variant):
    plan = plan_of(variant)
    floor = [m for m in plan.meshes if m.role in ("bottom", "plate")]
    assert sum(m.area for m in floor) == pytest.approx(4 * A * B, rel=1e-9)
    for m in floor:
        p = points(m)
        assert np.allclose(p[:, 2], 0.0) and (np.abs(p[:, 0]) <= A * (1 + 1e-12)).all()
        assert (np.abs(p[:, 1]) <= B * (1 + 1e-12)).all()
    if variant == "circle":                 # the rings reach every corner of the floor
        p = points(next(m for m in floor if m.role == "bottom"))
        for cx, cy in ((A, B), (-A, B), (-A, -B), (A, -B)):
            assert np.hypot(p[:, 0] - cx, p[:, 1] - cy).min() < 1e-12
    plate = points(next(m for m in floor if m.role == "plate"))
    g = plan.geometry
    assert 0.5 * (plate[:, 0].min() + plate[:, 0].max()) == pytest.approx(g.outlet_offset, abs=1e-12)


@pytest.mark.parametrize("variant", ["pyramid", "wedge"])
def test_hopper_faces_run_from_the_outlet_to_the_walls_feet(variant):
    plan = plan_of(variant)
    g = plan.geometry
    hh = g.hopper_height
    assert hh == pytest.approx((A - g.outlet_radius) / math.tan(math.radians(35.0)))
    faces = [m for m in plan.meshes if m.role == "hopper" and not m.name.startswith("slot_end")]
    assert len(faces) == 4
    x0, x1 = g.outlet_offset - g.outlet_radius, g.outlet_offset + g.outlet_radius
    y0, y1 = g.outlet_offset_y - g.outlet_half_y, g.outlet_offset_y + g.outlet_half_y
    top = np.concatenate([points(m)[np.isclose(points(m)[:, 2], hh)] for m in faces])
    low = np.concatenate([points(m)[np.isclose(points(m)[:, 2], 0.0)] for m in faces])
    # the top edges are the box's perimeter, the low edges the outlet's
    assert np.all(np.isclose(np.abs(top[:, 0]), A) | np.isclose(np.abs(top[:, 1]), B))
    on_outlet = (np.isclose(low[:, 0], x0) | np.isclose(low[:, 0], x1) | np.isclose(low[:, 1], y0)
                 | np.isclose(low[:, 1], y1))
    assert on_outlet.all()
    # the four faces and the outlet close the frustum: its volume is bed_volume's
    case = case_from_dict(data_of(**VARIANTS[variant]))
    z = np.linspace(0.0, hh, 2001)
    wx = 2 * g.outlet_radius + (2 * A - 2 * g.outlet_radius) * z / hh
    wy = 2 * g.outlet_half_y + (2 * B - 2 * g.outlet_half_y) * z / hh
    assert bed_volume(case, hh) == pytest.approx(np.trapezoid(wx * wy, z), rel=1e-6)


def test_four_walls_are_sensed_with_their_own_normals():
    plan = plan_of("rectangle")
    bands = {w.sector: w for w in plan.walls if w.role == "band" and w.band == 0}
    assert {k: w.normal for k, w in bands.items()} == {0: (-1.0, 0.0), 1: (1.0, 0.0), 2: (0.0, -1.0), 3: (0.0, 1.0)}
    assert bands[0].projected_area == pytest.approx(2 * B * 0.01) and bands[2].projected_area == pytest.approx(2 * A * 0.01)
    assert plan.sensors.sectors == 4


@pytest.mark.parametrize("changes,message", [
    ({"half_angle_deg": 40.0, **VARIANTS["circle"]}, "circular outlet sits in a flat floor"),
    ({"outlet_length": None}, "missing outlet_length"),
    ({"outlet_radius": 0.005}, "outlet_radius does not apply"),
    ({"outlet_offset": 0.02}, "must lie inside the floor"),
    ({"outlet_length": 0.03}, "must lie inside the floor"),
    ({**VARIANTS["slot"], "outlet_offset_y": 0.002}, "outlet_offset_y must be 0"),
])
def test_box_outlet_that_cannot_be_is_refused(changes, message):
    with pytest.raises(CaseError, match=message) as info:
        case_from_dict(data_of(**changes))
    assert info.value.problems[0][0] == "geometry"


def test_box_wall_mesh_refusal_names_the_boxs_own_fields():
    """Issue 55.10a: a circular outlet a hair from the wall leaves a sliver of floor that cannot be
    meshed; the refusal named a cylinder's fields (orifice_radius, radius, mesh_segments), which a
    box lacks, instead of the box's own."""
    with pytest.raises(CaseError) as info:
        derive(case_from_dict(data_of(**{**VARIANTS["circle"], "outlet_offset": A - 0.0065 - 1e-7})))
    [(field, message)] = info.value.problems
    assert field == "geometry.outlet_offset" and "'bottom'" in message
    assert message.endswith("change geometry.outlet_offset or geometry.outlet_radius or geometry.width or "
                            "geometry.depth"), message
    for foreign in ("orifice_radius", "geometry.radius", "mesh_segments"):
        assert foreign not in message


def test_box_hopper_too_fine_to_mesh_is_refused_before_it_fills_memory():
    """Found by the fuzz test of the examples' extremes: a 100 m deep hopper 5 cm wide needed a
    hopper face of 64 million triangles (MemoryError); its trapezoids are now held to the walls'
    triangle budget before any is made, and the refusal names the box's fields."""
    from test_case_loading import memory_cap
    with pytest.raises(CaseError) as info, memory_cap(2 ** 30):
        derive(case_from_dict(data_of(depth=100.0, half_angle_deg=35.0)))
    [(field, message)] = info.value.problems
    assert field == "geometry.half_angle_deg" and "more than siloflow writes for one wall" in message
    assert "geometry.depth" in message


def test_box_refuses_clumps_naming_the_kind():
    data = data_of()
    data["particles"] = {"kind": "clumps", "shape": "wheat", "length": 0.005, "width": 0.0025}
    with pytest.raises(CaseError, match="geometry.kind box: a rectangular silo takes spheres"):
        case_from_dict(data)


def test_lammps_box_walls():
    regions = {v: {rid: (style, args) for w in lammps_walls(plan_of(v)) for rid, style, args in w.regions}
               for v in VARIANTS}
    assert {"floor_xlo", "floor_xhi", "floor_ylo", "floor_yhi", "plate", "side"} <= set(regions["rectangle"])
    assert "floor_ylo" not in regions["slot"] and "slot_ends" in regions["slot"] and "slot_ends" in regions["wedge"]
    style, args = regions["circle"]["bottom_hole"]
    assert style == "sphere" and (float(args[0]), float(args[1])) == (-0.01, 0.0)
    assert sorted(r for r in regions["pyramid"] if r.endswith("_plane")) == [
        "hopper_xhi_plane", "hopper_xlo_plane", "hopper_yhi_plane", "hopper_ylo_plane"]
    # a face's plane passes through its outlet edge and the wall's foot
    plan = plan_of("pyramid")
    g = plan.geometry
    px, _, _, nx, _, nz = (float(v) for v in regions["pyramid"]["hopper_xlo_plane"][1])
    assert px == pytest.approx(g.outlet_offset - g.outlet_radius)
    assert nx * (-A - px) + nz * g.hopper_height == pytest.approx(0.0, abs=1e-15)


def test_beverloo_of_a_rectangle_takes_both_sides_less_k_d():
    from postprocess.flow_rate import beverloo
    W = float(beverloo(0.012, 0.0025, 0.6, 1.5, 1500.0, 9.81, slot_length=0.01, slot_ends=True))
    assert W == pytest.approx(0.6 * 1500.0 * math.sqrt(9.81) * (0.01 - 1.5 * 0.0025) * (0.012 - 1.5 * 0.0025) ** 1.5)


# ---------------------------------------------------------------- small discharges

ENGINE_RUNS = [("rectangle", "liggghts"), ("rectangle", "lammps"), ("pyramid", "lammps"), ("circle", "liggghts"),
               ("wedge", "liggghts")]


@pytest.fixture(scope="module", params=ENGINE_RUNS, ids=[f"{v}-{e}" for v, e in ENGINE_RUNS])
def box_run(request, tmp_path_factory):
    variant, engine = request.param
    data = data_of(**VARIANTS[variant])
    if variant != "rectangle":
        data["discharge"] = {"duration": 0.3}
    run = engine_run(tmp_path_factory, data, f"box_{variant}_{engine}", engine)
    return variant, engine, run.folder, run.summary


@pytest.mark.engine
def test_box_balances_in_x_y_z_counts_and_flows(box_run):
    variant, engine, folder, summary = box_run
    what = f"{variant} on {engine}"
    assert summary["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.02), what
    out = RunOutputs(folder)
    still = out.forces[static_window(out.forces, out)]
    for axis in ("_fx", "_fy"):                   # a bed at rest pushes its walls with no net horizontal force
        f = still[[c for c in still if c.endswith(axis)]]
        assert np.all(np.abs(f.sum(axis=1)) < 0.03 * f.abs().sum(axis=1)), (what, axis)
    dis = pd.read_csv(folder / "results" / "discharge.csv")
    end, m0 = dis.iloc[-1], summary["initial_mass_kg"]
    m_p = m0 / out.plan.fill.count
    deleted, in_transit = m0 - end.mass_total, end.mass_total - end.mass_in_silo
    assert -0.5 * m_p <= end.outlet_mass - deleted <= in_transit + 0.5 * m_p, what
    assert end.outlet_mass > 100 * m_p, what
    fr = summary["flow_rate"]
    assert fr["r2"] > 0.98 and fr["stderr"] < 0.1 * fr["rate"], what
    sectors = pd.read_csv(folder / "results" / "sectors.csv")
    assert sorted(sectors.azimuth_deg.round(6).unique()) == [0.0, 90.0, 180.0, 270.0]
    loaded = sectors[(sectors.band == 0)]
    assert (loaded.static_mean_pressure > 0).all(), what          # the bed presses all four walls
    if out.plan.geometry.outlet_offset or out.plan.geometry.outlet_offset_y:
        assert summary["eccentric_discharge"]["near_sector"] == (1 if out.plan.geometry.outlet_offset > 0 else 0)
