"""The plan's contact laws as LAMMPS coefficients (``siloflow.engine.lammps.contact_law``), as text.

For each law, hertz (decks/quick.yaml), hooke (paper B, decks/paper_b_quick.yaml) and linear (paper
A, decks/paper_a_spheres_quick.yaml), the coefficients are LIGGGHTS' numbers written exactly. No
LAMMPS is needed: the laws are run, in LAMMPS and in LIGGGHTS, by tests/test_contact_laws.py.
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from siloflow.case_file import load_case
from siloflow.derived import derive
from siloflow.engine.lammps import contact_law as cl

ROOT = Path(__file__).resolve().parents[1]
DECKS = {"hertz": "quick.yaml", "hooke": "paper_b_quick.yaml", "linear": "paper_a_spheres_quick.yaml"}


@pytest.fixture(scope="module")
def plans():
    return {law: derive(load_case(ROOT / "decks" / deck)) for law, deck in DECKS.items()}


def test_hertz_numbers_are_liggghts_moduli_written_exactly(plans):
    plan = plans["hertz"]
    pair = plan.pair("grain", "grain")
    e, nu = plan.materials["particle"].youngs_modulus, plan.materials["particle"].poisson_ratio
    y_eff = e / (2 * (1 - nu ** 2))
    g_eff = e / (4 * (2 - nu) * (1 + nu))
    words = cl.pair_coeff_args(plan, pair).split()
    assert words[:5] == ["hertz", repr(4 / 3 * pair.y_eff), repr(pair.restitution), "damping", "coeff_restitution"]
    assert float(words[1]) == pytest.approx(4 / 3 * y_eff, rel=1e-14)
    assert words[5:7] == ["tangential", "mindlin_rescale/force"]
    assert float(words[7]) == pytest.approx(8 * g_eff, rel=1e-14)
    assert float(words[8]) == pytest.approx(2 * math.sqrt(g_eff / y_eff), rel=1e-14)   # gamma_t / gamma_n
    assert words[9] == repr(pair.friction) and len(words) == 10        # no limit_damping, no rolling


@pytest.mark.parametrize("law", ["hooke", "linear"])
def test_linear_laws_carry_liggghts_numbers(plans, law):
    plan = plans[law]
    for pair in plan.contacts:
        text = cl.wall_args(plan, pair) if pair.b in cl.WALL_SIDES else cl.pair_coeff_args(plan, pair)
        assert text == (f"hooke {pair.kn!r} {pair.gamman!r} damping mass_velocity tangential linear_history "
                        f"{pair.kt!r} {pair.gammat / pair.gamman!r} {pair.friction!r} limit_damping")


def test_frictionless_changes_only_the_friction_and_walls_are_told_apart(plans):
    for plan in plans.values():
        grain = plan.grains[0].name
        pair, wall = plan.pair(grain, grain), plan.pair(grain, "wall")
        full, bare = cl.pair_coeff_args(plan, pair).split(), cl.pair_coeff_args(plan, pair, frictionless=True).split()
        changed = [k for k, (a, b) in enumerate(zip(full, bare)) if a != b]
        assert len(full) == len(bare) and len(changed) == 1
        assert full[changed[0]] == repr(pair.friction) and bare[changed[0]] == "0.0"
        with pytest.raises(ValueError):
            cl.pair_coeff_args(plan, wall)
        with pytest.raises(ValueError):
            cl.wall_args(plan, pair)


def test_rolling_friction_is_written_only_where_set(plans):
    plan = plans["hertz"]
    pair = plan.pair("grain", "grain")
    assert "rolling" not in cl.pair_coeff_args(plan, pair)
    rolling = pair.model_copy(update={"rolling_friction": 0.1})
    k, gamma, mu = cl.rolling_coefficients(plan, rolling)
    assert f"rolling sds {k!r} {gamma!r} {mu!r}" in cl.pair_coeff_args(plan, rolling) and mu == 0.1
    m_roll = cl.rolling_mass(plan, rolling)     # equal spheres: I / (2 R*^2) = 0.8 m
    assert m_roll == pytest.approx(0.8 * plan.grains[0].mass, rel=1e-12)
    assert math.pi * math.sqrt(m_roll / k) == pytest.approx(pair.contact_time, rel=1e-12)
