"""Frame analyses on constructed data with known answers: lattices, cut spheres, Janssen
columns, flow-rate series, Beverloo data."""
from __future__ import annotations

import itertools
import math

import numpy as np
import pandas as pd
import pytest

from postprocess.coordination import Coordination, coordination, local_pairs, overlap_pairs
from postprocess.dumps import Frame
from postprocess.flow_rate import (FreeSurface, beverloo, fit_beverloo, rate_series, steady_window,
                                   surface_flow_rate)
from postprocess.force_chains import chain_segments
from postprocess.report.figures import force_chain_figure
from postprocess.janssen import compare_with_measurement, fit_janssen, pressure_error_w
from postprocess.overlap_volume import (circle_circle_overlap, sphere_cylinder_overlap, sphere_sphere_overlap,
                                        sphere_volume)
from postprocess.porosity import XI_A, MeasureRegion, Porosity, porosity_2d_to_3d, relative_density


def frame_of(positions, radii, **extra) -> Frame:
    n = len(positions)
    data = pd.DataFrame({"id": np.arange(1, n + 1), "type": np.ones(n, int), "x": positions[:, 0],
                         "y": positions[:, 1], "z": positions[:, 2], "radius": radii, **extra})
    lo, hi = positions.min(axis=0) - radii.max(), positions.max(axis=0) + radii.max()
    return Frame(0, np.column_stack([lo, hi]), data, source="constructed")


def lattice(kind: str, cells: int, a: float = 1.0):
    base = {"sc": [(0, 0, 0)], "fcc": [(0, 0, 0), (0.5, 0.5, 0), (0.5, 0, 0.5), (0, 0.5, 0.5)]}[kind]
    cell = np.array(list(itertools.product(range(cells), repeat=3)), float)
    pos = (cell[:, None, :] + np.array(base)[None, :, :]).reshape(-1, 3) * a
    r = {"sc": 0.5 * a, "fcc": a / (2 * math.sqrt(2))}[kind]
    return pos, np.full(len(pos), r)


# ---------------------------------------------------------------- overlap volumes

def monte_carlo_inside(rng, n, inside_fn, r=1.0):
    p = rng.uniform(-r, r, (n, 3))
    p = p[(p ** 2).sum(axis=1) < r * r]
    return inside_fn(p).mean() * sphere_volume(r), 1.0 / math.sqrt(max(inside_fn(p).sum(), 1))


@pytest.mark.parametrize("R,d", [(1.5, 1.0), (0.7, 0.9), (3.0, 2.5), (0.4, 0.2)])
def test_sphere_sphere_overlap_against_monte_carlo(R, d):
    rng = np.random.default_rng(5)
    mc, rel = monte_carlo_inside(rng, 2_000_000, lambda p: ((p - [d, 0, 0]) ** 2).sum(axis=1) < R * R)
    assert sphere_sphere_overlap(R, 1.0, d) == pytest.approx(mc, rel=4 * rel)


def test_overlap_limits():
    assert sphere_sphere_overlap(2.0, 1.0, 0.5) == pytest.approx(sphere_volume(1.0))   # inside
    assert sphere_sphere_overlap(1.0, 1.0, 2.0) == 0.0                                  # touching
    assert sphere_sphere_overlap(1.0, 1.0, 1e-12) == pytest.approx(sphere_volume(1.0))
    assert circle_circle_overlap(1.0, 1.0, 0.0) == pytest.approx(math.pi)
    assert circle_circle_overlap(1.0, 1.0, 1.0) == pytest.approx(2 * math.pi / 3 - math.sqrt(3) / 2)
    # a sphere half in a half-space (huge cylinder through its centre), or cut by a plane
    assert sphere_cylinder_overlap(3.0, 1.0, 0.0, -5.0, 0.0) == pytest.approx(0.5 * sphere_volume(1.0), rel=1e-12)
    assert sphere_cylinder_overlap(3.0, 1.0, 0.5, -5.0, 5.0) == pytest.approx(sphere_volume(1.0), rel=1e-12)


@pytest.mark.parametrize("Rc,d,t0,t1", [(1.2, 1.5, -0.3, 2.0), (0.5, 0.3, -2.0, 0.4), (0.9, 0.2, -0.5, 0.5)])
def test_sphere_cylinder_overlap_against_monte_carlo(Rc, d, t0, t1):
    rng = np.random.default_rng(6)
    mc, rel = monte_carlo_inside(
        rng, 3_000_000, lambda p: (np.hypot(p[:, 0] - d, p[:, 1]) < Rc) & (p[:, 2] > t0) & (p[:, 2] < t1))
    assert sphere_cylinder_overlap(Rc, 1.0, d, t0, t1) == pytest.approx(mc, rel=4 * rel)


# ---------------------------------------------------------------- porosity

@pytest.mark.parametrize("kind,expected", [("sc", 1 - math.pi / 6), ("fcc", 1 - math.pi / (3 * math.sqrt(2)))])
def test_lattice_porosity_in_sphere_and_cylinder(kind, expected):
    pos, r = lattice(kind, 14)
    c = (6.73, 7.11, 6.91)  # off the lattice symmetry: the boundary cuts grains
    regions = [MeasureRegion("s", "sphere", c, 4.3),
               MeasureRegion("c", "cylinder", c, 3.7, axis=2, t0=3.1, t1=10.4)]
    table = Porosity(regions).run([frame_of(pos, r)]).table.set_index("region")
    # measured: SC -8.3e-4 (sphere), -7.2e-4 (cylinder); FCC 1.1e-4, 5.8e-4 (grains cut by the boundary)
    assert table.loc["s", "porosity"] == pytest.approx(expected, abs=0.0015)
    assert table.loc["c", "porosity"] == pytest.approx(expected, abs=0.0015)


@pytest.mark.parametrize("kind,expected", [("sc", 0.476401), ("fcc", 0.259520)])
def test_lattice_porosity_averaged_over_random_spheres(kind, expected):
    """Exact porosities of the lattices, 1 - pi/6 = 0.476401 (simple cubic) and 1 - pi/(3 sqrt 2)
    = 0.259520 (FCC), from 40 measurement spheres (radius 4.3 a) at random centres: each sphere
    cuts grains at its boundary (measured over 3 seeds: spread 2.9-6.7e-4, worst 1.0e-3: bound
    1.5e-3), but without bias (mean within 1.0e-4: bound 3e-4, 3 standard errors)."""
    assert expected == pytest.approx({"sc": 1 - math.pi / 6, "fcc": 1 - math.pi / (3 * math.sqrt(2))}[kind], abs=1e-6)
    pos, r = lattice(kind, 14)
    rng = np.random.default_rng(1)
    regions = [MeasureRegion(f"s{k}", "sphere", tuple(rng.uniform(5.5, 8.5, 3)), 4.3) for k in range(40)]
    dev = Porosity(regions).run([frame_of(pos, r)]).table.porosity.to_numpy() - expected
    assert np.abs(dev).max() < 1.5e-3 and abs(dev.mean()) < 3e-4, (np.abs(dev).max(), dev.mean())


@pytest.mark.parametrize("offset", [0.0, 0.2, 0.35])
def test_circle_porosity_of_a_simple_cubic_section(offset):
    """A plane at height offset t above a layer of a simple cubic lattice (a = 1, r = 1/2) cuts
    each grain of that layer in a disc of radius sqrt(1/4 - t^2), one per unit area: area
    porosity 1 - pi (1/4 - t^2) (0.214602, 0.340266, 0.599447 for t = 0, 0.2, 0.35). 40 circles of
    radius 9 at random centres: measured spread 0.8-1.2e-3, worst 2.6e-3 (bound 3.5e-3), mean
    within 1.4e-4 (bound 6e-4, 3 standard errors)."""
    pos, r = lattice("sc", 24)
    expected = 1 - math.pi * (0.25 - offset ** 2)
    assert expected == pytest.approx({0.0: 0.214602, 0.2: 0.340266, 0.35: 0.599447}[offset], abs=1e-6)
    rng = np.random.default_rng(2)
    regions = [MeasureRegion(f"c{k}", "circle", (rng.uniform(10, 13), rng.uniform(10, 13), 0.0), 9.0, axis=2,
                             plane=12 + offset) for k in range(40)]
    dev = Porosity(regions).run([frame_of(pos, r)]).table.porosity.to_numpy() - expected
    assert np.abs(dev).max() < 3.5e-3 and abs(dev.mean()) < 6e-4, (np.abs(dev).max(), dev.mean())


def test_bulk_density_weighs_each_species_by_its_own_density():
    """Two species of different densities (dust scaled heavy): mass per volume, not rho_p phi."""
    rng = np.random.default_rng(4)
    pos, r = lattice("sc", 10)
    types = np.where(rng.random(len(pos)) < 0.3, 2, 1)
    r = np.where(types == 2, 0.1, r)                    # small, heavy "dust" on some sites
    frame = frame_of(pos, r)
    frame.data["type"] = types
    region = MeasureRegion("c", "cylinder", (4.6, 4.4, 0.0), 3.1, axis=2, t0=1.3, t1=8.2)
    dens = {1: 1000.0, 2: 4.0e5}
    row = Porosity([region], densities=dens).run([frame]).table.iloc[0]
    solid = {k: Porosity([region]).run([frame_of(pos[types == k], r[types == k])]).table.solid_fraction.iloc[0]
             for k in (1, 2)}
    assert row.bulk_density == pytest.approx(dens[1] * solid[1] + dens[2] * solid[2], rel=1e-12)
    assert row.bulk_density > 1.5 * dens[1] * row.solid_fraction         # the dust's mass counts
    with pytest.raises(ValueError, match="no particle density for atom type"):
        Porosity([region], densities={1: 1000.0}).run([frame])
    # a dump of any LIGGGHTS/LAMMPS run: the densities from its mass column
    frame.data["mass"] = np.where(types == 2, dens[2], dens[1]) * 4.0 / 3.0 * np.pi * r ** 3
    assert Porosity([region]).run([frame]).table.bulk_density.iloc[0] == pytest.approx(row.bulk_density, rel=1e-12)


def test_porosity_counts_the_part_of_a_cut_sphere_not_its_centre():
    # one sphere of radius 1 whose centre lies just outside the measurement sphere
    frame = frame_of(np.array([[2.2, 0.0, 0.0]]), np.array([1.0]))
    region = MeasureRegion("m", "sphere", (0.0, 0.0, 0.0), 2.0)
    phi = Porosity([region]).run([frame]).table.solid_fraction.iloc[0]
    assert phi * region.measure == pytest.approx(sphere_sphere_overlap(2.0, 1.0, 2.2))
    assert phi > 0


def test_circle_porosity_of_a_hexagonal_layer_and_its_3d_conversion():
    # a hexagonal layer of spheres (radius 1) cut through their centres: area fraction pi/(2 sqrt 3)
    rows = np.array([(2 * i + (j % 2), math.sqrt(3) * j, 0.0) for i in range(30) for j in range(30)], float)
    frame = frame_of(rows, np.ones(len(rows)))
    region = MeasureRegion("c", "circle", (30.3, 25.7, 0.0), 9.0, axis=2, plane=0.0)
    eps2 = Porosity([region]).run([frame]).table.porosity.iloc[0]
    assert eps2 == pytest.approx(1 - math.pi / (2 * math.sqrt(3)), abs=0.006)
    # the lattice-consistent reading maps hexagonal discs onto FCC spheres exactly
    assert porosity_2d_to_3d(1 - math.pi / (2 * math.sqrt(3)), 0.0, "hexagonal") == pytest.approx(
        1 - math.pi / (3 * math.sqrt(2)), rel=1e-12)


def test_2d_to_3d_as_printed_limits():
    assert porosity_2d_to_3d(0.2, 0.0) == pytest.approx(1 - XI_A * 0.8)
    assert porosity_2d_to_3d(1.0, 1.0) == 1.0                       # no solid stays no solid
    values = [porosity_2d_to_3d(0.3, dr) for dr in (0.0, 0.5, 1.0)]
    assert values[0] > values[1] > values[2]                        # denser (higher Dr) -> lower porosity
    with pytest.raises(ValueError, match="negative 3D porosity"):
        porosity_2d_to_3d(0.05, 1.0)                                # outside the printed formula's range
    with pytest.raises(ValueError, match="within"):
        porosity_2d_to_3d(0.2, 1.5)
    assert relative_density(0.6, 0.5, 0.9) == pytest.approx(0.75)


# ---------------------------------------------------------------- coordination

@pytest.mark.parametrize("kind,z", [("sc", 6), ("fcc", 12)])
def test_lattice_coordination(kind, z):
    pos, r = lattice(kind, 6)
    inner = np.all((pos > 1.0) & (pos < 4.0), axis=1)
    frame = frame_of(pos, r)
    table = Coordination(select=lambda f: inner, tolerance=1e-6).run([frame]).table
    row = table[table.species == "all"].iloc[0]
    assert row.z_mean == z and row.z_mech == z and row.rattlers_0 == 0
    assert row.source == "overlaps" and row.convention == "per_sphere"


def test_rattler_correction_and_clumps_counted_per_body():
    # chain 0-1-2-3-5 plus isolated 4: z = [1, 2, 2, 2, 0, 1]
    i, j = np.array([0, 1, 2, 3]), np.array([1, 2, 3, 5])
    res = coordination(6, i, j)
    assert res["z_mean"] == pytest.approx(8 / 6)
    assert (res["rattlers_0"], res["rattlers_1"]) == (1, 2)
    assert res["z_mech"] == pytest.approx((8 - 2) / (6 - 1 - 2))
    # two 3-sphere clumps (bodies 10 and 20) touching through two sub-sphere contacts, plus
    # contacts inside each clump: one body-body contact
    body = np.array([10, 10, 10, 20, 20, 20])
    i, j = np.array([0, 1, 0, 2, 3]), np.array([1, 2, 3, 4, 4])
    res = coordination(6, i, j, body=body)
    assert res["contacts"] == 1 and res["grains"] == 2 and res["z_mean"] == 1.0


def test_contacts_from_dump_local_match_overlaps():
    pos, r = lattice("sc", 4)
    frame = frame_of(pos, r)
    i, j = overlap_pairs(pos, r, 1e-6)
    ids = frame.column("id")
    contacts = Frame(0, frame.box, pd.DataFrame({"id1": ids[i], "id2": ids[j], "periodic": 0,
                                                  "fx": 0.0, "fy": 0.0, "fz": np.linspace(0.1, 1, len(i))}),
                     kind="entries")
    li, lj = local_pairs(frame, contacts)
    assert sorted(zip(li, lj)) == sorted(zip(i, j))
    table = Coordination().run([frame], [contacts]).table
    assert table.source.iloc[0] == "dump_local"
    assert table.contacts.iloc[0] == 3 * 4 * 4 * 3


def test_force_chain_segments_and_figure(tmp_path):
    pos, r = lattice("sc", 4)
    frame = frame_of(pos, r)
    i, j = overlap_pairs(pos, r, 1e-6)
    ids = frame.column("id")
    branch = pos[j] - pos[i]
    fn = np.arange(1, len(i) + 1, dtype=float)
    contacts = Frame(0, frame.box, pd.DataFrame({"id1": ids[i], "id2": ids[j], "periodic": 0,
                                                  "fx": branch[:, 0] * fn, "fy": branch[:, 1] * fn,
                                                  "fz": branch[:, 2] * fn}), kind="entries")
    seg, force, _ = chain_segments(frame, contacts, axis=1, center=1.0, thickness=0.5)
    assert len(seg) == 2 * 4 * 3              # the y = 1 layer: 4x4 grid, 24 in-plane bonds
    bonds = {(int(a), int(b)): f for a, b, f in zip(i, j, fn)}
    assert sorted(force) == sorted(f for (a, b), f in bonds.items() if pos[a, 1] == 1.0 and pos[b, 1] == 1.0)
    path = force_chain_figure(frame, contacts, tmp_path / "chains.png", axis=1, center=1.0, thickness=0.5)
    assert path.stat().st_size > 1000


# ---------------------------------------------------------------- wall pressure

def janssen_column(depth, rho_b, g, D, mu_w, K):
    """Horizontal wall pressure of a Janssen column, independently of postprocess.janssen: the
    slice balance dp_v/dz = rho_b g - (4 mu_w K / D) p_v (weight minus wall friction mu_w K p_v
    on the perimeter pi D over the area pi D^2 / 4), p_v(0) = 0, integrated numerically;
    p_h = K p_v."""
    from scipy.integrate import solve_ivp
    depth = np.asarray(depth, float)
    sol = solve_ivp(lambda z, p: [rho_b * g - 4.0 * mu_w * K / D * p[0]], (0.0, float(depth.max())), [0.0],
                    t_eval=depth, rtol=1e-12, atol=1e-9)
    return K * sol.y[0]


def test_janssen_fit_recovers_k_and_wall_friction_of_an_independent_column():
    """Exact data from the slice balance (not the module's janssen_pressure): K, mu_w, the decay
    length D / (4 mu_w K) and the asymptote rho_b g D / (4 mu_w) come back. By hand for
    rho_b = 1500, g = 9.81, D = 0.2 m, mu_w = 0.45, K = 0.55: length 0.2 / 0.99 = 0.202020 m,
    asymptote 1500 x 9.81 x 0.2 / 1.8 = 1635.0 Pa."""
    rho_b, g, D, mu_w, K = 1500.0, 9.81, 0.2, 0.45, 0.55
    depth = np.linspace(0.02, 0.6, 12)                # to three decay lengths
    p = janssen_column(depth, rho_b, g, D, mu_w, K)
    assert p[-1] == pytest.approx(1635.0 * (1 - math.exp(-0.6 / 0.20202)), rel=1e-4)
    fit = fit_janssen(depth, p, rho_b, D, g)
    assert fit.K == pytest.approx(K, rel=1e-5) and fit.mu_w == pytest.approx(mu_w, rel=1e-5)
    assert fit.length == pytest.approx(0.202020, rel=1e-5) and fit.asymptote == pytest.approx(1635.0, rel=1e-5)
    assert fit.saturated and fit.r2 == pytest.approx(1.0, abs=1e-9) and fit.n_points == 12
    # Eurocode EN 1991-4 wheat (unit weight 9 kN/m3, K 0.54, D3 wall mu 0.57) in a 4 m silo
    z = np.linspace(0.5, 20.0, 10)
    fit = fit_janssen(z, janssen_column(z, 9000 / 9.81, 9.81, 4.0, 0.57, 0.54), 9000 / 9.81, 4.0)
    assert fit.K == pytest.approx(0.54, rel=1e-5) and fit.mu_w == pytest.approx(0.57, rel=1e-5)
    # z_o = A / (K mu U) = D / (4 K mu) = 4 / 1.2312 = 3.24886 m, p_ho = gamma K z_o = 15789.5 Pa
    assert fit.length == pytest.approx(3.24886, rel=1e-5)
    assert fit.asymptote == pytest.approx(15789.5, rel=1e-5)


def test_janssen_fit_on_noisy_columns_scatters_as_its_standard_errors_say():
    """2 % multiplicative noise on 10 bands of the independent column (D = 0.05 m, mu_w 0.45,
    K 0.55), 200 realisations. Bounds from the spread measured over seeds 1, 2, 3, 7:
    * mean within 0.6 % of the truth (measured bias <= 0.37 %);
    * scatter of the fits 2.8-3.2 % (K) and 0.83-0.90 % (mu_w): bounds 4 % and 1.2 %;
    * the reported (linearised) standard errors, median over fits, are 1.14-1.28 (K) and
      0.82-0.91 (mu_w) times that scatter: bound 0.7-1.4;
    * every single fit within 15 % (K) and 4 % (mu_w) (measured worst 12.7 % and 2.8 %)."""
    rho_b, g, D, mu_w, K = 1500.0, 9.81, 0.05, 0.45, 0.55
    depth = np.linspace(0.01, 0.4, 10)
    p = janssen_column(depth, rho_b, g, D, mu_w, K)
    rng = np.random.default_rng(7)
    fits = [fit_janssen(depth, p * (1 + 0.02 * rng.standard_normal(len(p))), rho_b, D, g) for _ in range(200)]
    for name, true, spread, single in (("K", K, 0.04, 0.15), ("mu_w", mu_w, 0.012, 0.04)):
        values = np.array([getattr(f, name) for f in fits]) / true
        reported = np.array([getattr(f, f"{name}_stderr") for f in fits]) / true
        scatter = values.std(ddof=1)
        assert abs(values.mean() - 1) < 0.006, name
        assert scatter < spread, (name, scatter)
        assert 0.7 < np.median(reported) / scatter < 1.4, (name, np.median(reported), scatter)
        assert np.abs(values - 1).max() < single, name


def test_janssen_fit_of_a_hydrostatic_column_is_not_saturated():
    """A column without wall friction (p_h = K rho_b g z: a liquid-like bed, or friction not
    mobilised) fixes only K: the fit finds K, a decay length beyond the deepest band, and says
    it is not saturated; a linear profile that is not Janssen's at all is not forced into one."""
    rho_b, g, D = 1500.0, 9.81, 0.05
    depth = np.linspace(0.01, 0.4, 10)
    fit = fit_janssen(depth, 0.55 * rho_b * g * depth, rho_b, D, g)
    assert not fit.saturated and fit.K == pytest.approx(0.55, rel=0.05)
    assert fit.length > depth.max() and fit.r2 > 0.999
    # a column that saturates at 30 % of its Janssen asymptote (mu_w 0.45, K 0.55): the fit's
    # effective mu_w and K describe it, with the asymptote where the data levels off
    p = janssen_column(depth, rho_b, g, D, 0.45, 0.55)
    fit = fit_janssen(depth, 0.3 * p, rho_b, D, g)
    assert fit.asymptote == pytest.approx(0.3 * rho_b * g * D / (4 * 0.45), rel=1e-4)
    assert fit.mu_w == pytest.approx(0.45 / 0.3, rel=1e-4) and fit.K == pytest.approx(0.55 * 0.3, rel=1e-4)


def test_eq34_error_and_table3_comparison():
    t = np.linspace(0, 10, 101)
    measured = 1000 + 200 * np.sin(t)
    assert pressure_error_w(t, 1.1 * measured, t, measured) == pytest.approx(0.1)
    assert pressure_error_w(t, measured, t, measured) == 0.0
    t_open = 2.0
    bands = pd.DataFrame({"time": np.concatenate([t + t_open] * 2), "band": np.repeat([0, 1], len(t)),
                          "pressure": np.concatenate([1.2 * measured, 0.5 * measured])})
    table = compare_with_measurement(bands, pd.DataFrame({"time": t, "band_0": measured, "band_1": measured}),
                                     t_open).set_index("band")
    assert table.loc[0, "W"] == pytest.approx(0.2) and table.loc[1, "W"] == pytest.approx(0.5)
    assert table.loc[0, "relative_difference"] == pytest.approx(0.2)
    with pytest.raises(ValueError, match="band_<k>"):
        compare_with_measurement(bands, pd.DataFrame({"time": t, "point 1": measured}), t_open)


# ---------------------------------------------------------------- flow rates

def test_rate_series_and_steady_window():
    t = np.linspace(0, 10, 201)
    rate = np.where(t < 2, 0.5 * t, 1.0) * np.where(t > 8, 0.3, 1.0)
    mass = np.concatenate([[0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))])
    w = rate_series(t, mass, window=5)
    i0, i1 = steady_window(w, tolerance=0.05)
    assert t[i0] == pytest.approx(2.0, abs=0.2) and t[i1 - 1] == pytest.approx(8.0, abs=0.2)
    assert np.nanmedian(w[i0:i1]) == pytest.approx(1.0, rel=1e-6)


def test_free_surface_of_a_bed_with_a_crater_tracks_its_volume():
    rng = np.random.default_rng(8)
    R, r = 0.05, 0.002
    n = 40000
    # uniform random "grains" filling a cylinder up to h(rho) = 0.1 - 0.03 (1 - rho^2 / R^2) (a crater)
    rho = R * np.sqrt(rng.random(n))
    th = rng.uniform(0, 2 * np.pi, n)
    top = 0.1 - 0.03 * (1 - (rho / R) ** 2)
    z = rng.random(n) * top
    frame = frame_of(np.column_stack([rho * np.cos(th), rho * np.sin(th), z]), np.full(n, r))
    h = FreeSurface(radius=R, annuli=5).run([frame]).table.surface_height.iloc[0]
    mean_height = 0.1 - 0.03 * 0.5                                     # volume / area of the bed
    assert h == pytest.approx(mean_height, abs=2 * r)


def test_surface_flow_rate_sign_and_scale():
    t = np.linspace(0, 1, 11)
    fit = surface_flow_rate(t, 0.3 - 0.01 * t, area=0.02, bulk_density=2500 * 0.6)
    assert fit.rate == pytest.approx(0.01 * 0.02 * 2500 * 0.6)


def beverloo_by_hand(D0, d, C, k, rho_b, g=9.81):
    """Beverloo (1961), written out here, not postprocess.flow_rate.beverloo:
    W = C rho_b sqrt(g) (D0 - k d)^(5/2), kg/s."""
    return C * rho_b * math.sqrt(g) * (np.asarray(D0, float) - k * np.asarray(d, float)) ** 2.5


def test_beverloo_law_against_a_hand_worked_number():
    # D0 = 30 mm, d = 3 mm, C 0.58, k 1.5, rho_b 1500, g 9.81: D0 - k d = 0.0255 m,
    # 0.0255^2.5 = 6.5025e-4 x 0.159687 = 1.038366e-4; 0.58 x 1500 x 3.132092 = 2724.920 -> 0.282946 kg/s
    assert float(beverloo(0.03, 0.003, 0.58, 1.5, 1500.0)) == pytest.approx(0.282946, rel=1e-5)
    assert float(beverloo(0.03, 0.003, 0.58, 1.5, 1500.0, 10.0)) == pytest.approx(0.282946 * math.sqrt(10 / 9.81),
                                                                                 rel=1e-5)
    assert float(beverloo(0.004, 0.003, 0.58, 1.5, 1500.0)) == 0.0          # orifice below k d: no flow


def test_beverloo_fit_recovers_c_and_k():
    """Rates from the law written out in the test (1 % noise): C and k within 3 standard errors."""
    rng = np.random.default_rng(9)
    D0 = np.array([0.02, 0.03, 0.04, 0.05, 0.06, 0.03, 0.05])
    d = np.array([0.003, 0.003, 0.003, 0.004, 0.004, 0.002, 0.002])
    exact = beverloo_by_hand(D0, d, 0.58, 1.5, 1500.0)
    fit = fit_beverloo(D0, d, exact, 1500.0)
    assert fit.C == pytest.approx(0.58, rel=1e-6) and fit.k == pytest.approx(1.5, rel=1e-6)
    W = exact * (1 + 0.01 * rng.standard_normal(len(D0)))
    fit = fit_beverloo(D0, d, W, 1500.0)
    assert fit.C == pytest.approx(0.58, abs=3 * fit.C_stderr + 1e-3)
    assert fit.k == pytest.approx(1.5, abs=3 * fit.k_stderr + 1e-3)
    assert 0 < fit.C_stderr < 0.05 and fit.rms_relative_residual < 0.02
    with pytest.raises(ValueError, match="at least 3 runs"):
        fit_beverloo(D0[:2], d[:2], W[:2], 1500.0)


def test_beverloo_command_fits_across_run_folders(tmp_path, quick_dict):
    """Run folders (plan.json + results/summary.json) with flow rates from Beverloo's law."""
    import json

    from typer.testing import CliRunner

    from siloflow.case_file import case_from_dict
    from siloflow.cli import app
    from siloflow.derived import derive
    from siloflow.run_folder import RunFolder

    folders = []
    for k, (orifice, radius) in enumerate([(0.006, 0.001), (0.008, 0.001), (0.010, 0.001), (0.012, 0.0015),
                                           (0.009, 0.0008)]):
        case = dict(quick_dict, name=f"run{k}")
        case["geometry"] = dict(case["geometry"], orifice_radius=orifice)
        case["particles"] = dict(case["particles"], radius=radius)
        folder = tmp_path / f"run{k}"
        (folder / "results").mkdir(parents=True)
        plan = derive(case_from_dict(case))
        RunFolder(folder).write_plan(plan)
        assert plan.geometry.outlet_radius == orifice and plan.grains[0].radius == radius
        W = float(beverloo_by_hand(2 * orifice, 2 * radius, 0.6, 1.4, 1500.0, case.get("gravity", 9.81)))
        (folder / "results" / "summary.json").write_text(json.dumps(
            {"flow_rate": {"rate": W, "stderr": 0.01 * W}, "frame_analyses": {"bulk_density_kg_m3": 1500.0}}))
        folders.append(str(folder))
    out = tmp_path / "bev.csv"
    result = CliRunner().invoke(app, ["beverloo", *folders, "-o", str(out)])
    assert result.exit_code == 0, result.output
    fit = json.loads(out.with_suffix(".json").read_text())
    assert fit["C"] == pytest.approx(0.6, rel=1e-4) and fit["k"] == pytest.approx(1.4, rel=1e-3)
    import siloflow                                  # the same fit from Python
    table, api_fit = siloflow.beverloo(folders)
    assert len(table) == 5 and (api_fit.C, api_fit.k) == pytest.approx((fit["C"], fit["k"]), rel=1e-12)
    result = CliRunner().invoke(app, ["beverloo", folders[0], str(tmp_path)])
    assert result.exit_code == 1 and "summary.json" in result.output


def test_analyses_write_no_files(tmp_path, monkeypatch):
    """An analysis computes: run on a dump in a folder made read-only (and the working directory),
    its output is in ``results`` and no file appears anywhere under that folder (root ignores the
    mode, so the listing is compared too). Only the report layer writes."""
    import os

    from postprocess.any_dump import FrameSummary
    from postprocess.dumps import read_frames
    from postprocess.flow_rate import FreeSurface
    from test_dumps import dump_text, random_frame

    rng = np.random.default_rng(4)
    folder = tmp_path / "ro"
    folder.mkdir()
    dump = folder / "atoms.dump"
    dump.write_text(dump_text([(0, random_frame(rng, 400)), (100, random_frame(rng, 400))]))
    before = sorted(p.relative_to(folder) for p in folder.rglob("*"))
    folder.chmod(0o555)
    monkeypatch.chdir(folder)
    try:
        analyses = [FrameSummary(), Porosity([MeasureRegion("s", "sphere", (0.5, 0.5, 0.5), 0.3)]),
                    Coordination(), FreeSurface(radius=0.5, x0=0.5, y0=0.5)]
        for a in analyses:
            a.run(read_frames(dump))
            assert not a.results.table.empty and a.table is a.results.table
            assert not any(hasattr(a, attr) for attr in ("save", "plot", "products"))
        assert set(analyses[1].results.summary.columns) >= {"solid_fraction", "porosity"}
    finally:
        folder.chmod(0o755)
    assert sorted(p.relative_to(folder) for p in folder.rglob("*")) == before
    assert os.listdir(folder) == ["atoms.dump"]


def test_beverloo_d_of_several_sizes_is_their_mass_weighted_mean_diameter():
    """Paper B's seven sizes: d = sum(n_i r_i^3 2 r_i) / sum(n_i r_i^3) (one density), worked here
    from the case's radii and number fractions; one size is its diameter; a clump has none."""
    from pathlib import Path
    from postprocess.flow_rate import beverloo_diameter
    from siloflow.case_file import load_case
    from siloflow.derived import derive
    from siloflow.errors import ReadError
    root = Path(__file__).resolve().parents[1]
    plan = derive(load_case(root / "benchmarks" / "cases" / "accuracy_small.yaml"))
    r, n = np.array(plan.fill.radii), np.array(plan.fill.number_fractions)
    assert len(r) == 7
    d, density, what = beverloo_diameter(plan, "run")
    assert d == pytest.approx(np.sum(n * r ** 3 * 2 * r) / np.sum(n * r ** 3), rel=1e-12)
    assert 2 * r.min() < d < 2 * r.max() and "mass-weighted" in what
    assert density == pytest.approx(plan.grains[0].density, rel=1e-12)        # one density: the sum of w_i rho
    mono = derive(load_case(root / "decks" / "quick.yaml"))
    assert beverloo_diameter(mono, "run")[:2] == (2 * mono.grains[0].radius, mono.grains[0].density)
    with pytest.raises(ReadError, match="clump"):
        beverloo_diameter(derive(load_case(root / "decks" / "paper_a_clumps_quick.yaml")), "run")
