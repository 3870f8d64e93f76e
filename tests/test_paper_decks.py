"""The papers' decks (decks/paper_*.yaml): valid, renderable, and carrying the papers' numbers
(REFERENCES.md); the quick versions scale what their comments say."""
from __future__ import annotations

import math

import pytest

from siloflow.case import paper_b_radii
from siloflow.case_file import load_case
from siloflow.derived import derive
from siloflow.engine.liggghts.deck import render_deck_text

from conftest import ROOT

DECKS = sorted((ROOT / "decks").glob("paper_*.yaml"))


def series(k1: float, k2: float) -> float:
    """PFC's contact stiffness of two entities' springs in series, N/m."""
    return k1 * k2 / (k1 + k2)


@pytest.mark.parametrize("path", DECKS, ids=[p.stem for p in DECKS])
def test_paper_deck_renders(path):
    case = load_case(path)
    d = derive(case)
    text = render_deck_text(d)
    assert "run" in text and d.fill.count == case.fill.count
    assert "scale" in path.read_text().splitlines()[0].lower()      # the scale is stated up front


@pytest.mark.parametrize("name", ["paper_a_spheres", "paper_a_spheres_quick", "paper_a_clumps", "paper_a_clumps_quick"])
def test_paper_a_decks_carry_tables_1_and_2(name):
    case = load_case(ROOT / "decks" / f"{name}.yaml")
    g, m = case.geometry, case.materials
    assert g.kind == "planar" and g.half_angle_deg == 60.0
    assert len(case.sensors.heights) - 1 == 10                      # ten sections on each side
    assert case.fill.frictionless
    ball, wall = (3.2e5, 1.6e5), (3.2e6, 1.6e6)
    pp, pw = m.particle_particle, m.particle_wall
    assert (pp.kn, pp.kt) == pytest.approx((series(ball[0], ball[0]), series(ball[1], ball[1])))
    assert (pw.kn, pw.kt) == pytest.approx((series(ball[0], wall[0]), series(ball[1], wall[1])), rel=1e-3)
    assert pw.friction == 0.62 and m.particle.density == 1000.0
    zeta = 0.05
    assert pp.restitution == pytest.approx(math.exp(-math.pi * zeta / math.sqrt(1 - zeta ** 2)), abs=1e-3)
    quick = name.endswith("quick")
    full = load_case(ROOT / "decks" / f"{name.removesuffix('_quick')}.yaml")
    if quick:       # lengths x 1/4, counts x 1/16 (the clump model: 800 grains, a shallower bed)
        assert g.width == pytest.approx(full.geometry.width / 4)
        want = 800 if "clumps" in name else full.fill.count / 16
        assert case.fill.count == pytest.approx(want, rel=0.01)
    if "spheres" in name:
        assert case.particles.radius == 0.0025 and pp.friction == 0.43
        assert full.fill.count == 23000
        return
    p = case.particles
    assert (p.length, p.width) == (0.006, 0.004) and pp.friction == 0.3
    dust = p.dust
    assert (dust.radius, dust.density, dust.number_ratio) == (0.00025, 2000.0, 0.1)
    assert (dust.dust_dust.kn, dust.dust_wall.kn) == pytest.approx((series(wall[0], wall[0]),) * 2)
    assert dust.dust_particle.kn == pytest.approx(series(ball[0], wall[0]), rel=1e-3)
    assert full.fill.count == 24676 and full.particles.dust.density_scale == 1.0
    d = derive(case)
    if quick:       # the dust remedy: the dust's cost falls from 67x to about 3x, at 8 % of the mass
        assert d.timestep.without_dust / d.dt < 4
        dust_mass = d.fill.dust_count * d.dust.mass
        assert dust_mass < 0.1 * d.total_mass
    else:
        assert d.timestep.without_dust / d.dt > 50


@pytest.mark.parametrize("name", ["paper_b", "paper_b_quick"])
def test_paper_b_decks_carry_its_numbers(name):
    case = load_case(ROOT / "decks" / f"{name}.yaml")
    m, p = case.materials, case.particles
    assert case.gravity == 10.0 and m.model == "hooke"
    assert (m.particle.density, m.particle_particle.friction, m.particle_particle.restitution) == (7520.0, 0.5, 0.88)
    assert m.tangential_stiffness_ratio == pytest.approx(2 / 7) and m.tangential_damping_ratio == 0.1
    assert p.radii == pytest.approx(paper_b_radii(1 / 64)) and p.protocol == "shrink_after_settling"
    assert p.number_fractions == pytest.approx([1 / 7] * 7)
    assert case.engine.timestep_fraction == pytest.approx(1 / 50)
    if name == "paper_b":
        assert case.fill.count == 393216 and m.particle.youngs_modulus == 1.2e11
        assert case.geometry.orifice_radius == pytest.approx(12 / 64)
        d = derive(case)
        text = render_deck_text(d)
        assert "hard_particles   yes" in text
