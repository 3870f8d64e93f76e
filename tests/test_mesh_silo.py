"""The user's own silo from STL (``geometry.kind: mesh``): the container checks (each bad mesh refused
naming the triangle), the cuts into sensor bands and sectors, the volume, and the same silo as a
``kind: cylinder`` exported to STL giving the same plan and, on LIGGGHTS, the same answers."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from conftest import SMALL, needs_liggghts
from stl import mesh as stl_mesh

from siloflow.case_file import load_case
from siloflow.derived import derive
from siloflow.errors import CaseError
from siloflow.geometry.container import split
from siloflow.geometry.quality import min_angles

DATA = Path(__file__).parent / "data"
MM = 1000.0          # the exported files are in mm (scale 0.001), as CAD files often are


def export_walls(plan, path: Path, roles=("band", "wall", "bottom", "cone", "hopper"), factor: float = MM,
                 edit=None) -> Path:
    """Write the walls of ``plan`` of ``roles`` (not the plate or the counting disc) as one binary
    STL, times ``factor``; ``edit(triangles)`` may change them first."""
    tris = np.concatenate([m.triangles for m in plan._meshes if m.role in roles]) * factor
    if edit is not None:
        tris = edit(tris)
    m = stl_mesh.Mesh(np.zeros(len(tris), dtype=stl_mesh.Mesh.dtype))
    m.vectors[:] = tris
    m.save(str(path))
    return path


def mesh_case(source: Path, folder: Path, outlet: dict, edit=None, name: str = "mesh_silo", **changes) -> Path:
    """A case file in ``folder``: ``source``'s case with its silo exported to ``walls.stl`` (mm) as a
    ``kind: mesh`` with ``outlet`` (mm)."""
    data = yaml.safe_load(source.read_text())
    export_walls(derive(load_case(source)), folder / "walls.stl", edit=edit)
    data.update(name=name, geometry={"kind": "mesh", "files": ["walls.stl"], "scale": 1.0 / MM, "outlet": outlet},
                **changes)
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


SMALL_OUTLET = {"z": 0.0, "center": [0.0, 0.0], "radius": 5.5}


@pytest.fixture(scope="module")
def cylinder_pair(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mesh_silo")
    return derive(load_case(SMALL)), derive(load_case(mesh_case(SMALL, folder, SMALL_OUTLET)))


def test_cylinder_as_mesh_gives_the_cylinders_sensors(cylinder_pair):
    """Every band sector cut from the exported walls has the cylinder's projected area and
    normal (float32 rounding aside), and the same heights and azimuths."""
    cyl, mesh = cylinder_pair
    a = {w.name: w for w in cyl.walls if w.role == "band"}
    b = {w.name: w for w in mesh.walls if w.role == "band"}
    assert sorted(a) == sorted(b) and len(a) == 7 * 4
    for name, w in a.items():
        v = b[name]
        assert v.projected_area == pytest.approx(w.projected_area, rel=1e-6)
        assert v.normal == pytest.approx(w.normal, abs=1e-7)
        assert (v.z0, v.z1, v.band, v.sector) == pytest.approx((w.z0, w.z1, w.band, w.sector), abs=1e-7)
        assert (v.theta0, v.theta1) == pytest.approx((w.theta0, w.theta1))
        assert v.area == pytest.approx(w.area, rel=1e-6)


def test_cylinder_as_mesh_keeps_the_cylinders_triangles(cylinder_pair):
    """Every wall cut from the exported file is the cylinder's own wall: the same triangles (float32
    rounding aside), facing the grains as siloflow's walls do, whatever way the file faced."""
    cyl, mesh = cylinder_pair
    a = {m.name: m.triangles for m in cyl.meshes}
    for m in mesh.meshes:
        if m.role in ("plate", "outlet"):             # made anew: a fan and a disc
            continue
        mine, theirs = (np.round(t.reshape(-1, 9), 7) + 0.0 for t in (m.triangles, a[m.name]))   # 0.1 um keys
        np.testing.assert_allclose(mine[np.lexsort(mine.T[::-1])], theirs[np.lexsort(theirs.T[::-1])], atol=1e-7)


def test_cylinder_as_mesh_measures_like_the_cylinder(cylinder_pair):
    """Height, floor, radii and the fill: the polygon's inscribed circle (the apothem) for the
    insertion, the circumscribed one for the box; the bed height from the polygon's volume."""
    cyl, mesh = cylinder_pair
    g, n = mesh.geometry, 32
    R = cyl.geometry.radius
    assert g.kind == "mesh" and g.hopper_height == 0.0
    assert g.height == pytest.approx(0.16, rel=1e-6)
    assert g.radius == pytest.approx(R * math.cos(math.pi / n), rel=1e-6)
    assert g.outer_radius == pytest.approx(R, rel=1e-6)
    assert g.hydraulic_diameter == pytest.approx(2 * R * math.cos(math.pi / n), rel=1e-6)   # a regular polygon's
    assert mesh.fill.count == cyl.fill.count
    polygon = 0.5 * n * R ** 2 * math.sin(2 * math.pi / n)
    circle = math.pi * R ** 2
    assert mesh.fill.bed_height_estimate == pytest.approx(cyl.fill.bed_height_estimate * circle / polygon, rel=1e-5)
    assert mesh.outlet.radius == pytest.approx(cyl.outlet.radius)
    roles = sorted(w.role for w in mesh.walls)
    assert roles.count("bottom") == 1 and roles.count("plate") == 1 and roles.count("outlet") == 1


def test_volume_and_section_of_a_hopper(tmp_path):
    """A cone hopper exported: its floor is the cone (role hopper, up to its height), and the
    volume below any height is the polygonal frustum's plus the prism above."""
    data = yaml.safe_load(SMALL.read_text())
    data["geometry"] = {"kind": "hopper", "radius": 0.0125, "height": 0.1, "half_angle_deg": 30.0,
                        "outlet_radius": 0.0055, "mesh_segments": 32}
    data["sensors"] = {"bands": 4, "sectors": 4}
    src = tmp_path / "hopper.yaml"
    src.write_text(yaml.safe_dump(data))
    hopper = derive(load_case(src))
    mesh = derive(load_case(mesh_case(src, tmp_path, SMALL_OUTLET)))
    hh = hopper.geometry.hopper_height
    assert mesh.geometry.hopper_height == pytest.approx(hh, rel=1e-6)
    assert [w.role for w in mesh.walls].count("hopper") == 1
    n, r0, R = 32, 0.0055, 0.0125
    k = 0.5 * n * math.sin(2 * math.pi / n)                 # a regular n-gon's area over r^2
    case = load_case(tmp_path / "mesh_silo.yaml")
    from siloflow.derived import bed_volume, measured
    case = measured(case)
    for h in (0.5 * hh, hh, hh + 0.05):
        hc = min(h, hh)
        r1 = r0 + (R - r0) * hc / hh
        expected = k * hc / 3 * (r0 ** 2 + r0 * r1 + r1 ** 2) + k * R ** 2 * max(0.0, h - hh)
        assert bed_volume(case, h) == pytest.approx(expected, rel=1e-5)
    a = {w.name: w.projected_area for w in hopper.walls if w.role == "band"}
    assert {w.name: w.projected_area for w in mesh.walls if w.role == "band"} == pytest.approx(a, rel=1e-6)


def test_eccentric_outlet_turns_the_sectors_like_the_cylinders(tmp_path):
    """An off-axis outlet (sectors about the cylinder's axis): sector 0 is centred on the outlet's
    azimuth, as on an eccentric cylinder, and the outlet is placed off the axis."""
    src = DATA / "eccentric_silo.yaml"
    cyl = derive(load_case(src))
    e = cyl.geometry.outlet_offset
    r = cyl.geometry.outlet_radius
    mesh = derive(load_case(mesh_case_with_axis(src, tmp_path, e, r)))
    assert mesh.geometry.outlet_offset == pytest.approx(e)
    a = {w.name: w for w in cyl.walls if w.role == "band"}
    for w in mesh.walls:
        if w.role == "band":
            assert w.normal == pytest.approx(a[w.name].normal, abs=1e-6)
            assert w.projected_area == pytest.approx(a[w.name].projected_area, rel=1e-5)
    plate = next(m for m in mesh._meshes if m.role == "plate").triangles
    assert plate[..., 0].mean() == pytest.approx(e, rel=1e-3)


def mesh_case_with_axis(src: Path, folder: Path, e: float, r: float) -> Path:
    """``src``'s eccentric cylinder exported, its outlet at x = e (m) and the axis at the origin."""
    path = mesh_case(src, folder, {"z": 0.0, "center": [e * MM, 0.0], "radius": r * MM})
    data = yaml.safe_load(path.read_text())
    data["geometry"]["axis"] = [0.0, 0.0]
    path.write_text(yaml.safe_dump(data))
    return path


def bin_walls(width: float, depth: float, height: float, hx: float, hy: float) -> np.ndarray:
    """A rectangular bin as a CAD model exports it (mm): four walls and a flat floor around a
    centred hx x hy (half sizes) rectangular hole, watertight and every normal facing out."""
    a, b = 0.5 * width, 0.5 * depth
    outer = [(-a, -b), (a, -b), (a, b), (-a, b)]             # counter-clockwise from above
    inner = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
    tris = []
    for k in range(4):
        (x0, y0), (x1, y1) = outer[k], outer[(k + 1) % 4]
        (u0, v0), (u1, v1) = inner[k], inner[(k + 1) % 4]
        # wall: outward normal on the right of the bottom edge's direction, seen from outside
        tris += [[(x0, y0, 0), (x1, y1, 0), (x1, y1, height)], [(x0, y0, 0), (x1, y1, height), (x0, y0, height)]]
        # floor between the outer and inner edges, facing down
        tris += [[(x0, y0, 0), (u1, v1, 0), (x1, y1, 0)], [(x0, y0, 0), (u0, v0, 0), (u1, v1, 0)]]
    return np.array(tris, float)


def test_polygon_outlet_of_a_bin(tmp_path):
    """A rectangular bin from CAD with a rectangular hole: the polygon outlet (given clockwise:
    siloflow orders it), its hydraulic half width as the outlet radius, the bin's volume and
    section, and the bands' vector areas cancelling around the axis."""
    data = yaml.safe_load(SMALL.read_text())
    width, depth, height, hx, hy = 40.0, 30.0, 100.0, 6.0, 4.0
    m = stl_mesh.Mesh(np.zeros(16, dtype=stl_mesh.Mesh.dtype))
    m.vectors[:] = bin_walls(width, depth, height, hx, hy)
    m.save(str(tmp_path / "bin.stl"), mode=stl_mesh.stl.Mode.ASCII)
    data.update(geometry={"kind": "mesh", "files": ["bin.stl"], "scale": 1e-3,
                          "outlet": {"z": 0.0, "polygon": [[-hx, -hy], [-hx, hy], [hx, hy], [hx, -hy]]}},
                sensors={"bands": 5, "sectors": 4}, name="bin")
    path = tmp_path / "bin.yaml"
    path.write_text(yaml.safe_dump(data))
    case = load_case(path)
    assert case.geometry.outlet_radius == pytest.approx(2 * (0.012 * 0.008) / (2 * 0.02))
    plan = derive(case)
    from siloflow.derived import bed_volume, measured
    g = measured(case).geometry
    assert bed_volume(measured(case), 0.05) == pytest.approx(0.04 * 0.03 * 0.05, rel=1e-6)
    assert g.section == pytest.approx((0.04 * 0.03, 0.14), rel=1e-6)
    assert plan.geometry.radius == pytest.approx(0.015, rel=1e-6)
    assert plan.geometry.outer_radius == pytest.approx(math.hypot(0.02, 0.015), rel=1e-6)
    bands = [w for w in plan.walls if w.role == "band"]
    assert len(bands) == 5 * 4
    total = sum(np.asarray(w.normal) * w.projected_area for w in bands)
    assert np.abs(total).max() < 1e-6 * sum(w.projected_area for w in bands)
    # sector 0 (0 to 90 deg) holds half the +x wall and half the +y wall
    s0 = next(w for w in bands if w.band == 0 and w.sector == 0)
    assert s0.projected_area == pytest.approx(math.hypot(0.015, 0.02) * 0.02, rel=1e-6)


# --------------------------------------------------------------------------- bad meshes


def _refused(tmp_path, edit=None, outlet=SMALL_OUTLET) -> str:
    path = mesh_case(SMALL, tmp_path, outlet, edit=edit)
    with pytest.raises(CaseError) as err:
        derive(load_case(path))
    text = str(err.value)
    assert "geometry.files" in text
    return text


def test_open_wall_is_refused_naming_the_triangle(tmp_path):
    """A wall triangle missing half way up: an open edge, with the triangle beside the gap named."""
    def drop(tris):
        mid = np.flatnonzero((tris[:, :, 2].min(axis=1) > 50) & (tris[:, :, 2].max(axis=1) < 140))[0]
        return np.delete(tris, mid, axis=0)
    text = _refused(tmp_path, drop)
    assert "open edge" in text and "triangle " in text and "walls.stl" in text


def test_flipped_normals_are_refused_naming_the_triangle(tmp_path):
    def flip(tris):
        tris = tris.copy()
        tris[7] = tris[7, ::-1]
        return tris
    text = _refused(tmp_path, flip)
    assert "triangle 7 of" in text and "flipped normals" in text


def test_outlet_outside_the_opening_is_refused(tmp_path):
    text = _refused(tmp_path, outlet={"z": 0.0, "center": [4.0, 0.0], "radius": 5.5})
    assert "does not follow geometry.outlet" in text
    text = _refused(tmp_path, outlet={"z": 30.0, "center": [0.0, 0.0], "radius": 5.5})
    assert "below the outlet plane" in text or "no opening" in text


def test_nan_vertex_is_refused_naming_the_triangle(tmp_path):
    def poison(tris):
        tris = tris.copy()
        tris[12, 1, 0] = np.nan
        return tris
    text = _refused(tmp_path, poison)
    assert "non-finite" in text and "triangle 12" in text


def test_duplicate_triangle_is_refused(tmp_path):
    text = _refused(tmp_path, lambda t: np.concatenate([t, t[3:4]]))
    assert "duplicate" in text and "triangle 3 of" in text


def test_axis_outside_the_walls_is_refused(tmp_path):
    path = mesh_case(SMALL, tmp_path, SMALL_OUTLET)
    data = yaml.safe_load(path.read_text())
    data["geometry"]["axis"] = [40.0, 0.0]
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(CaseError, match="axis") as err:
        derive(load_case(path))
    assert "lies outside the vertical walls' cross-section" in str(err.value)


def ring_cylinder(path: Path, radius: float = 12.5, hole: float = 5.5, rows=(0.0, 40.0, 80.0, 120.0, 160.0),
                  n: int = 32) -> Path:
    """A closed polygonal cylinder (mm) built by hand as CAD exports one: a floor annulus round the
    outlet hole at z = 0 and the side split into rows at the heights ``rows``, so that a ring of
    vertices lies exactly half way up the vertical wall (80 mm); normals out."""
    th = 2 * math.pi * np.arange(n) / n
    ring = lambda r, z: np.stack([r * np.cos(th), r * np.sin(th), np.full(n, z)], axis=1)   # noqa: E731
    tris = []
    for lo, hi in zip(rows, rows[1:]):
        a, b = ring(radius, lo), ring(radius, hi)
        for i in range(n):
            j = (i + 1) % n
            tris += [[a[i], a[j], b[j]], [a[i], b[j], b[i]]]
    inner, outer = ring(hole, 0.0), ring(radius, 0.0)
    for i in range(n):
        j = (i + 1) % n
        tris += [[inner[i], outer[j], outer[i]], [inner[i], inner[j], outer[j]]]
    tris = np.array(tris)
    m = stl_mesh.Mesh(np.zeros(len(tris), dtype=stl_mesh.Mesh.dtype))
    m.vectors[:] = tris
    m.save(str(path))
    return path


def test_vertex_ring_half_way_up_is_a_valid_silo(tmp_path):
    """A ring of vertices exactly half way up the vertical wall (where the section is measured)
    is a valid silo: its section is the 32-gon's, not an empty cut refused as an axis outside."""
    ring_cylinder(tmp_path / "walls.stl")
    data = yaml.safe_load(SMALL.read_text())
    data.update(name="ring_silo", geometry={"kind": "mesh", "files": ["walls.stl"], "scale": 1.0 / MM,
                                            "outlet": {"z": 0.0, "center": [0.0, 0.0], "radius": 5.5}})
    path = tmp_path / "ring_silo.yaml"
    path.write_text(yaml.safe_dump(data))
    plan = derive(load_case(path))
    g, R, n = plan.geometry, 0.0125, 32
    assert g.kind == "mesh" and g.height == pytest.approx(0.16, rel=1e-6)
    assert g.section_area == pytest.approx(0.5 * n * R ** 2 * math.sin(2 * math.pi / n), rel=1e-6)
    assert g.section_perimeter == pytest.approx(2 * n * R * math.sin(math.pi / n), rel=1e-6)
    assert len([w for w in plan.walls if w.role == "band"]) == 7 * 4


def test_inward_normals_are_turned_out(tmp_path, cylinder_pair):
    """Every normal facing into the silo is one consistent surface: siloflow turns them all and
    plans exactly what the outward file gives."""
    path = mesh_case(SMALL, tmp_path, SMALL_OUTLET, edit=lambda t: t[:, ::-1])
    plan = derive(load_case(path))
    mine = {w.name: (w.projected_area, w.normal) for w in plan.walls if w.role == "band"}
    theirs = {w.name: (w.projected_area, w.normal) for w in cylinder_pair[1].walls if w.role == "band"}
    assert mine.keys() == theirs.keys()
    for name, (area, normal) in mine.items():
        assert area == pytest.approx(theirs[name][0], rel=1e-9) and normal == pytest.approx(theirs[name][1])


def test_lammps_refuses_a_mesh_silo(tmp_path):
    from siloflow.engine import get_engine
    case = load_case(mesh_case(SMALL, tmp_path, SMALL_OUTLET))
    problems = get_engine("lammps").check(case)
    assert any(field == "geometry.kind" and "STL" in text for field, text in problems)


def test_schema_refuses_half_outlets():
    from pydantic import ValidationError

    from siloflow.case import MeshOutlet
    with pytest.raises(ValidationError, match="either radius"):
        MeshOutlet(z=0.0, center=(0.0, 0.0))
    with pytest.raises(ValidationError, match="needs its center"):
        MeshOutlet(z=0.0, radius=1.0)
    with pytest.raises(ValidationError, match="convex"):
        MeshOutlet(z=0.0, polygon=[(0, 0), (2, 0), (1, 0.2), (2, 2), (0, 2)])
    star = [(math.cos(4 * math.pi * k / 5), math.sin(4 * math.pi * k / 5)) for k in range(5)]
    with pytest.raises(ValidationError, match="convex"):
        MeshOutlet(z=0.0, polygon=star)
    clockwise = MeshOutlet(z=0.0, polygon=[(0, 0), (0, 1), (1, 1), (1, 0)])
    assert clockwise.scaled_polygon(2.0) == [(2, 0), (2, 2), (0, 2), (0, 0)]          # counter-clockwise


# --------------------------------------------------------------------------- cutting


def test_split_keeps_area_and_sides():
    """Random triangles cut by random planes: the pieces cover the triangles' area exactly, each on
    its side of the plane (within the snap), and no cut leaves an angle below LIGGGHTS' limit."""
    rng = np.random.default_rng(7)
    tris = rng.uniform(-1, 1, (400, 3, 3))
    tris = tris[min_angles(tris) > 5.0]
    for _ in range(20):
        n, c = rng.normal(size=3), rng.uniform(-0.5, 0.5)
        n /= np.linalg.norm(n)
        s = tris @ n - c
        low, high = split(tris, s)

        def area(t):
            return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
        assert area(low) + area(high) == pytest.approx(area(tris), rel=1e-12)
        size = np.linalg.norm(tris - np.roll(tris, -1, axis=1), axis=2).max()
        assert (low @ n - c).max() <= 0.01 * size + 1e-12
        assert (high @ n - c).min() >= -0.01 * size - 1e-12
        assert min_angles(np.concatenate([low, high])).min() > 0.256


def test_run_folder_holds_the_walls_and_renders_again(tmp_path):
    """The run folder keeps a copy of the walls (in m) and a case naming it, so that the folder
    renders the same deck without the user's files; the user's file is untouched."""
    from conftest import render

    from siloflow.deck import verify_deck
    from siloflow.engine import get_engine
    case_file = mesh_case(SMALL, tmp_path, SMALL_OUTLET)
    before = (tmp_path / "walls.stl").read_bytes()
    folder = render(load_case(case_file), tmp_path / "run")
    stored = yaml.safe_load((folder / "case.yaml").read_text())["geometry"]
    assert stored["files"] == ["meshes/container.stl"] and stored["scale"] == 1.0
    assert stored["outlet"]["radius"] == pytest.approx(0.0055)
    shutil.move(tmp_path / "walls.stl", tmp_path / "elsewhere.stl")
    verify_deck(folder, get_engine)                   # renders the folder's own case anew: same bytes
    assert (tmp_path / "elsewhere.stl").read_bytes() == before
    plan = json.loads((folder / "plan.json").read_text())
    assert plan["geometry"]["kind"] == "mesh"


# --------------------------------------------------------------------------- engine


@needs_liggghts
def test_cylinder_as_mesh_runs_like_the_cylinder(small_run, tmp_path):
    """tests/data/small_silo.yaml's walls exported to STL (mm) and run as ``kind: mesh``, against the
    same case as ``kind: cylinder`` (the ``small_run`` fixture; the same seed): the settled bed's
    weight carried within 2 %, the outlet-counted mass what left, each band's static pressure within three times
    the two runs' errors (the spread over the band's sectors: the packing, which differs from
    fill to fill), and the steady flow rate within 5 % plus three of the runs' errors."""
    import siloflow
    cyl = small_run[3]
    run = siloflow.run(mesh_case(SMALL, tmp_path, SMALL_OUTLET), tmp_path / "run")
    mesh = run.summary
    assert abs(mesh["force_balance"]["ratio"] - 1.0) < 0.02
    # the mass counted at the outlet is what left the box, give or take the grains still falling
    dis = pd.read_csv(run.folder / "results" / "discharge.csv")
    end, m0 = dis.iloc[-1], mesh["initial_mass_kg"]
    m_p = m0 / 2500
    assert -0.5 * m_p <= end.outlet_mass - (m0 - end.mass_total) <= end.mass_total - end.mass_in_silo + 0.5 * m_p
    assert end.outlet_mass > 100 * m_p
    a = {b["band"]: b for b in cyl["bands"]}
    for b in mesh["bands"]:
        c = a[b["band"]]
        if c["static_pressure"] < 20.0:          # the band above the bed
            continue
        err = math.hypot(b["static_pressure_sector_stderr"], c["static_pressure_sector_stderr"])
        assert abs(b["static_pressure"] - c["static_pressure"]) < 3 * err, b["band"]
    wa, wb = mesh["flow_rate"], cyl["flow_rate"]
    assert abs(wa["rate"] - wb["rate"]) < 0.05 * wb["rate"] + 3 * math.hypot(wa["stderr"], wb["stderr"])


def hexagonal_silo(across: float, height: float, outlet_across: float, half_angle_deg: float) -> np.ndarray:
    """The walls of decks/mesh_quick.stl (mm): a hexagonal prism ``across`` flats wide and ``height``
    high on a hexagonal pyramid frustum whose faces stand ``half_angle_deg`` from the vertical, down
    to a hexagonal outlet ``outlet_across`` flats wide at z = 0; watertight, normals out."""
    def ring(flats, z):
        r = flats / math.sqrt(3.0)               # corner radius of a hexagon across flats
        return [(r * math.cos(math.pi / 3 * k), r * math.sin(math.pi / 3 * k), z) for k in range(6)]
    hh = 0.5 * (across - outlet_across) / math.tan(math.radians(half_angle_deg))
    low, mid, top = ring(outlet_across, 0.0), ring(across, hh), ring(across, hh + height)
    tris = []
    for k in range(6):
        j = (k + 1) % 6
        for a, b in ((low, mid), (mid, top)):     # a band of quads, counter-clockwise seen from outside
            tris += [[a[k], a[j], b[j]], [a[k], b[j], b[k]]]
    return np.array(tris, float)


def test_the_mesh_example_is_its_generator_and_plans():
    """decks/mesh_quick.stl is what :func:`hexagonal_silo` writes (its comment's numbers), and the
    example plans: a hexagonal outlet of 15 mm across flats (hydraulic diameter 15 mm), the hopper
    17.3 mm high, sensors on the six-sided walls."""
    deck = Path(__file__).parents[1] / "decks"
    written = np.array(stl_mesh.Mesh.from_file(str(deck / "mesh_quick.stl")).vectors, float)
    assert written == pytest.approx(hexagonal_silo(50.0, 150.0, 15.0, 45.0), abs=1e-4)
    case = load_case(deck / "mesh_quick.yaml")
    assert case.geometry.outlet_radius == pytest.approx(0.0075)
    plan = derive(case)
    assert plan.geometry.hopper_height == pytest.approx(0.0175, rel=1e-6)
    assert plan.geometry.radius == pytest.approx(0.025, rel=1e-6)
    assert plan.geometry.hydraulic_diameter == pytest.approx(0.05, rel=1e-6)
    assert len([w for w in plan.walls if w.role == "band"]) == plan.sensors.bands * 6


def test_example_copies_the_walls_beside_the_case(tmp_path):
    """``siloflow example mesh_quick`` writes the case and its STL beside it, so the copy runs as it
    is; an existing STL of the user's is never replaced without --force."""
    from typer.testing import CliRunner

    from siloflow.cli import app
    runner = CliRunner()
    (tmp_path / "mesh_quick.stl").write_text("mine")
    refused = runner.invoke(app, ["example", "mesh_quick", "-o", str(tmp_path / "case.yaml")])
    assert refused.exit_code == 1 and "mesh_quick.stl exists" in " ".join(refused.output.split())
    assert (tmp_path / "mesh_quick.stl").read_text() == "mine" and not (tmp_path / "case.yaml").exists()
    (tmp_path / "mesh_quick.stl").unlink()
    done = runner.invoke(app, ["example", "mesh_quick", "-o", str(tmp_path / "case.yaml")])
    assert done.exit_code == 0, done.output
    assert derive(load_case(tmp_path / "case.yaml")).geometry.kind == "mesh"
