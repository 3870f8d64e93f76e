"""Wall meshes and the sector-force -> pressure conversion (why sector meshes measure pressure)."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from stl import mesh as stl_mesh

from postprocess.discharge import steady_flow_rate
from postprocess.wall_pressure import band_mean, band_pressures, sector_pressure
from siloflow.case_file import case_from_dict
from siloflow.derived import derive, wall_meshes
from siloflow.engine.tables import wall_force_columns
from siloflow.geometry import write_stl


def _plan(quick_dict):
    case = case_from_dict(quick_dict)
    return case, derive(case)


def _walls(quick_dict):
    """The case and its wall meshes (triangles), made for the plan's counting disc."""
    case, d = _plan(quick_dict)
    return case, wall_meshes(case, d, sensors=True)


def _vector_area(tris):
    """Sum of triangle normals times areas, oriented outwards from the axis."""
    n = 0.5 * np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    centre = tris.mean(axis=1)
    sign = np.sign((n[:, :2] * centre[:, :2]).sum(axis=1))
    return (n * sign[:, None]).sum(axis=0)


def test_sector_meshes_tile_the_wall(quick_dict):
    case, walls = _walls(quick_dict)
    bands = [w for w in walls if w.role == "band"]
    assert len(bands) == 6 * 4
    for w in bands:
        r = np.hypot(w.triangles[..., 0], w.triangles[..., 1])
        assert np.allclose(r, case.geometry.radius)
        assert w.triangles[..., 2].min() == pytest.approx(w.z0) and w.triangles[..., 2].max() == pytest.approx(w.z1)
    # the band heights cover the cylinder wall exactly once
    total = sum(w.z1 - w.z0 for w in bands) / 4
    assert total == pytest.approx(case.geometry.height)


def test_uniform_pressure_on_faceted_sector_is_recovered(quick_dict):
    """Integrate a uniform pressure (plus azimuthal and vertical friction) over the real facets
    of each sector mesh; the projected net force must give back the pressure exactly."""
    _, walls = _walls(quick_dict)
    p, tau_theta, tau_z = 1234.5, 300.0, 200.0
    for w in (w for w in walls if w.role == "band"):
        t = w.triangles
        normal_area = _vector_area(t)
        areas = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
        theta = np.arctan2(t[..., 1].mean(1), t[..., 0].mean(1))
        e_theta = np.stack([-np.sin(theta), np.cos(theta), 0 * theta], 1)
        force = p * normal_area + tau_theta * (areas[:, None] * e_theta).sum(0)
        force[2] -= tau_z * areas.sum()
        got = sector_pressure(force[0], force[1], w.radius, w.z1 - w.z0, w.theta0, w.theta1)
        assert got == pytest.approx(p, rel=1e-9)


def test_band_table_from_forces(quick_dict):
    _, d = _plan(quick_dict)
    walls = d.walls                       # the plan's Wall records
    cols = wall_force_columns(walls)
    forces = pd.DataFrame(np.zeros((2, len(cols))), columns=cols)
    forces["step"] = [100, 200]
    for w in walls:
        if w.role == "band":
            tc = 0.5 * (w.theta0 + w.theta1)
            area = 2 * w.radius * (w.z1 - w.z0) * math.sin(0.5 * (w.theta1 - w.theta0))
            forces[f"{w.name}_fx"] = 10.0 * (w.band + 1) * area * math.cos(tc)
            forces[f"{w.name}_fy"] = 10.0 * (w.band + 1) * area * math.sin(tc)
            forces[f"{w.name}_fz"] = -0.01
    bands = band_mean(band_pressures(forces, walls))
    assert np.allclose(bands.pressure, 10.0 * (bands.band + 1))
    assert np.allclose(bands.shear_force, 0.04)


def test_bottom_and_plate_cover_the_floor(quick_dict):
    case, walls = _walls(quick_dict)
    by = {w.role: w for w in walls}
    polygon = lambda r, k: 0.5 * k * r * r * math.sin(2 * math.pi / k)  # noqa: E731
    k = 4 * math.ceil(case.geometry.mesh_segments / 4)
    assert by["bottom"].area + by["plate"].area == pytest.approx(polygon(case.geometry.radius, k), rel=1e-9)
    assert by["outlet"].area > by["plate"].area  # the counting disc covers the orifice


def test_stl_round_trip(tmp_path, quick_dict):
    _, walls = _walls(quick_dict)
    w = walls[0]
    write_stl(w, tmp_path / "w.stl")
    assert (tmp_path / "w.stl").read_bytes().startswith(b"solid")
    back = stl_mesh.Mesh.from_file(str(tmp_path / "w.stl"))
    assert np.allclose(back.vectors, w.triangles, rtol=1e-6)


def test_steady_flow_rate_fit_recovers_rate():
    rng = np.random.default_rng(1)
    t = np.linspace(0, 3, 301)
    t_open = 1.0
    mass = np.where(t > t_open, 0.04 * (t - t_open), 0.0) + rng.normal(0, 1e-4, t.size)
    fit = steady_flow_rate(t, mass, t_open)
    assert abs(fit.rate - 0.04) < 4 * fit.stderr + 1e-12
    assert fit.t_start >= t_open and fit.r2 > 0.99
