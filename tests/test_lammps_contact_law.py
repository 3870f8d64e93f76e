"""The plan's contact laws in LAMMPS (``siloflow.engine.lammps.contact_law``), measured.

Two-sphere head-on impacts and a sphere dropped on a wall run in LAMMPS (``pair_style granular``,
``fix wall/gran/region granular``) with the module's coefficients, for each law: hertz
(decks/quick.yaml), hooke (paper B, decks/paper_b_quick.yaml, a pair of unequal spheres) and
linear (paper A, decks/paper_a_spheres_quick.yaml). Measured restitution and contact time are
compared with the plan's restitution and contact time and with LIGGGHTS' law (its formulas, as
documented in the module) integrated independently here; a sphere sliding on the floor shows
the Coulomb limit and the wall force's sign; held spheres rolling show the rolling torque limit.
The text tests need no LAMMPS. Each LAMMPS run is a few hundred to two thousand steps of two
spheres (well under a second).
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from siloflow import contact_physics as cp
from siloflow.case_file import load_case
from siloflow.derived import derive
from siloflow.engine.lammps import contact_law as cl
from siloflow.engine.lammps.module import load_lammps

ROOT = Path(__file__).resolve().parents[1]
DECKS = {"hertz": "quick.yaml", "hooke": "paper_b_quick.yaml", "linear": "paper_a_spheres_quick.yaml"}
#: time steps per contact time in the measurements: the law is measured, not the step's error
STEPS_PER_CONTACT = 300


@pytest.fixture(scope="module")
def lmp():
    """The ``lammps`` module, loaded as the engine loads it (no LD_LIBRARY_PATH needed); a missing
    module is an error here, not a skip: ``make install`` installs it."""
    return load_lammps()


@pytest.fixture(scope="module")
def plans():
    return {law: derive(load_case(ROOT / "decks" / deck)) for law, deck in DECKS.items()}


def species(plan, name):
    return next(sp for sp in plan.species if sp.name == name)


class TwoBodies:
    """A LAMMPS run of one or two spheres (SI), with the plan's contact law between the species
    given (one atom type each) and, with ``wall``, a floor at z = 0 (a plane region)."""

    def __init__(self, lmp, plan, names, dt, pairs=None, wall=None, gravity=0.0):
        self.plan = plan
        self.types = {n: k + 1 for k, n in enumerate(names)}
        r = max(species(plan, n).radius for n in names)
        self.l = lmp.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
        self.l.commands_string(f"""
units           si
atom_style      sphere
atom_modify     map array sort 0 0.0
boundary        f f f
newton          off
comm_modify     vel yes
region          box block {-20 * r!r} {20 * r!r} {-20 * r!r} {20 * r!r} {-20 * r!r} {20 * r!r}
create_box      {len(names)} box
neighbor        {0.5 * r!r} bin
neigh_modify    delay 0 every 1 check yes
pair_style      granular
timestep        {dt!r}
""")
        pairs = dict(pairs or {})
        for i, a in enumerate(names):
            for b in names[i:]:
                pair = pairs.get((a, b)) or plan.pair(a, b)
                self.l.command(f"pair_coeff {self.types[a]} {self.types[b]} {cl.pair_coeff_args(plan, pair)}")
        if wall is not None:
            self.l.command("region floor plane 0 0 0 0 0 1 side in")
            self.l.command(f"fix wall all wall/gran/region granular {cl.wall_args(plan, wall)} region floor contacts")
        if gravity:
            self.l.command(f"fix gravity all gravity {gravity!r} vector 0 0 -1")
        self.n = 0

    def add(self, name, x, y=0.0, z=0.0, vx=0.0, vz=0.0):
        sp = species(self.plan, name)
        self.n += 1
        self.l.commands_string(f"""
create_atoms    {self.types[name]} single {x!r} {y!r} {z!r} units box
set             atom {self.n} diameter {2 * sp.radius!r} density {sp.density!r}
set             atom {self.n} vx {vx!r} vz {vz!r}
""")

    def start(self, setup=""):
        self.l.commands_string(setup + "fix nve all nve/sphere\nrun 0\n")

    def get(self, name):
        return np.array(self.l.numpy.extract_atom(name), copy=True)

    def run(self, steps, wall=False):
        """``steps`` single steps; per step x, v, omega (atom, 3) and, with ``wall``, the wall
        fix's per-atom contacts array (force on the particle in columns 1-3)."""
        out = {"x": [], "v": [], "omega": [], "contacts": []}
        for _ in range(steps):
            self.l.command("run 1 pre no post no")
            for key in ("x", "v", "omega"):
                out[key].append(self.get(key))
            if wall:
                out["contacts"].append(np.array(self.l.numpy.extract_fix("wall", 1, 2), copy=True))
        self.l.close()
        return {k: np.array(v) for k, v in out.items()}


def impact(table_gap, rel_velocity, dt):
    """(restitution, contact time s) from the per-step gap (< 0 in contact) and normal relative
    velocity (approach < 0)."""
    touching = np.flatnonzero(table_gap < 0)
    assert len(touching) > 50, "the contact is not resolved"
    first, last = touching[0], touching[-1]
    assert np.all(np.diff(touching) == 1), "more than one contact"
    assert last < len(table_gap) - 2, "the run ended during the contact"
    return -rel_velocity[last + 1] / rel_velocity[first - 1], (last - first + 1) * dt


def law_impact(force, m_eff, v, t_scale):
    """(restitution, contact time s) of a head-on impact at ``v`` under the normal force
    ``force(d, d')`` (overlap d m, its rate m/s), integrated with scipy until the overlap closes."""
    from scipy.integrate import solve_ivp
    parted = lambda t, s: s[0]              # noqa: E731
    parted.terminal, parted.direction = True, -1
    sol = solve_ivp(lambda t, s: [s[1], -force(max(s[0], 0.0), s[1]) / m_eff], [0, 10 * t_scale],
                    [1e-30, v], events=parted, rtol=1e-10, atol=1e-16, max_step=t_scale / 2000)
    return -sol.y_events[0][0][1] / v, sol.t_events[0][0]


def liggghts_force(plan, pair):
    """LIGGGHTS' normal force law of a pair, F(d, d') in N: hertz (no limitForce), or
    hooke/stiffness with limitForce on."""
    if plan.contact_model == "hertz":
        ln_e = math.log(pair.restitution)
        beta = ln_e / math.sqrt(ln_e ** 2 + math.pi ** 2)

        def hertz(d, dd):
            sn = 2 * pair.y_eff * math.sqrt(pair.r_eff * d)
            return 2 / 3 * sn * d - 2 * math.sqrt(5 / 6) * beta * math.sqrt(sn * pair.m_eff) * dd
        return hertz
    return lambda d, dd: max(0.0, pair.kn * d + pair.gamman * pair.m_eff * dd)


def expected_contact_time(plan, pair, v):
    """The plan's contact time at impact speed ``v``: Hertz's 2.87 formula (elastic) or the
    linear spring's pi sqrt(m*/kn) (undamped), both from siloflow.contact_physics."""
    if plan.contact_model == "hertz":
        return cp.hertz_contact_time(pair.m_eff, pair.r_eff, pair.y_eff, v)
    return pair.contact_time


# ------------------------------------------------------------------ text (no LAMMPS)

def test_hertz_numbers_are_liggghts_moduli_written_exactly(plans):
    plan = plans["hertz"]
    pair = plan.pair("grain", "grain")
    e, nu = plan.materials["particle"].youngs_modulus, plan.materials["particle"].poisson_ratio
    y_eff = e / (2 * (1 - nu ** 2))
    g_eff = e / (4 * (2 - nu) * (1 + nu))
    words = cl.pair_coeff_args(plan, pair).split()
    assert words[:5] == ["hertz", repr(4 / 3 * pair.y_eff), repr(pair.restitution), "damping", "coeff_restitution"]
    assert float(words[1]) == pytest.approx(4 / 3 * y_eff, rel=1e-14)
    assert words[5:7] == ["tangential", "mindlin"]
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


# ------------------------------------------------------------------ LAMMPS runs

HEAD_ON = {"hertz": ("grain", "grain"), "hooke": ("size1", "size7"), "linear": ("grain", "grain")}


@pytest.mark.engine
@pytest.mark.parametrize("law", ["hertz", "hooke", "linear"])
def test_head_on_impact_has_the_pair_restitution_and_contact_time(lmp, plans, law):
    """Sphere b hits sphere a (at rest) head-on at the plan's impact speed. Measured (dt = t_c /
    300, so t_c to 0.33 %): hertz (e = 0.5) e 0.4995, t_c 1.0933 x Hertz's elastic 2.87 time
    (LIGGGHTS' law integrated: 0.5000, 1.0927; LIGGGHTS itself, test_contact_law_engine: 0.4994,
    1.0922); with e = 1 t_c 1.0000 x the 2.87 time; hooke (size1-size7, e = 0.88) e 0.8825, t_c
    1.0033 x the plan's; linear (e = 0.855) e 0.8592, t_c 1.0000 x. The linear laws rebound a
    little above e, as LIGGGHTS' law does (0.8829, 0.8593): limitForce / limit_damping cut the
    attractive end of the damped contact."""
    plan = plans[law]
    a, b = HEAD_ON[law]
    pair = plan.pair(a, b)
    ra, rb = species(plan, a).radius, species(plan, b).radius
    v = plan.fill.impact_velocity
    cases = [pair] + ([pair.model_copy(update={"restitution": 1.0})] if law == "hertz" else [])
    for case in cases:
        tc = expected_contact_time(plan, case, v)
        dt = tc / STEPS_PER_CONTACT
        names = [a] if a == b else [a, b]
        sim = TwoBodies(lmp, plan, names, dt, pairs={(a, b): case})
        gap = 0.01 * (ra + rb)
        sim.add(a, 0.0)
        sim.add(b, ra + rb + gap, vx=-v)
        sim.start()
        t = sim.run(int((gap / v + 2 * tc) / dt))
        e, t_contact = impact(t["x"][:, 1, 0] - t["x"][:, 0, 0] - (ra + rb), t["v"][:, 1, 0] - t["v"][:, 0, 0], dt)
        e_law, tc_law = law_impact(liggghts_force(plan, case), case.m_eff, v, tc)
        assert e == pytest.approx(case.restitution, rel=0.02)
        assert e == pytest.approx(e_law, rel=0.005)                  # LIGGGHTS' law
        assert t_contact == pytest.approx(tc_law, rel=0.01)
        if law != "hertz" or case.restitution == 1.0:
            assert t_contact == pytest.approx(tc, rel=0.02)         # siloflow's contact time
        else:
            assert 1.05 * tc < t_contact < 1.15 * tc                 # damping lengthens Hertz' contact


WALL_GRAIN = {"hertz": "grain", "hooke": "size7", "linear": "grain"}


@pytest.mark.engine
@pytest.mark.parametrize("law", ["hertz", "hooke", "linear"])
def test_sphere_dropped_on_the_wall_rebounds_with_the_wall_restitution(lmp, plans, law):
    """A sphere falls (gravity on) onto the floor at the plan's impact speed: m* is its mass, R*
    its radius. Measured: hertz e 0.4996, t_c 1.0900 x the elastic 2.87 time of the wall pair
    (LIGGGHTS' law: 1.0927); hooke (size7, e = 0.88) e 0.8828, t_c 1.0000 x the plan's; linear
    (e = 0.855) e 0.8590, t_c 1.0033 x."""
    plan = plans[law]
    name = WALL_GRAIN[law]
    pair = plan.pair(name, "wall")
    r = species(plan, name).radius
    v = plan.fill.impact_velocity
    tc = expected_contact_time(plan, pair, v)
    dt = tc / STEPS_PER_CONTACT
    sim = TwoBodies(lmp, plan, [name], dt, wall=pair, gravity=plan.gravity)
    gap = 0.01 * r
    sim.add(name, 0.0, z=r + gap, vz=-v)
    sim.start()
    t = sim.run(int((gap / v + 2 * tc) / dt))
    e, t_contact = impact(t["x"][:, 0, 2] - r, t["v"][:, 0, 2], dt)
    e_law, tc_law = law_impact(liggghts_force(plan, pair), pair.m_eff, v, tc)
    assert e == pytest.approx(pair.restitution, rel=0.02)
    assert e == pytest.approx(e_law, rel=0.005)
    assert t_contact == pytest.approx(tc_law, rel=0.01)
    if law != "hertz":
        assert t_contact == pytest.approx(pair.contact_time, rel=0.02)


@pytest.mark.engine
@pytest.mark.parametrize("law", ["hertz", "hooke", "linear"])
def test_sphere_sliding_on_the_floor_feels_friction_times_its_weight(lmp, plans, law):
    """A sphere rests on the floor at its static overlap (m g / kn, or Hertz's): the wall pushes
    it up with m g. Set sliding at 0.1 m/s, the floor's force on it is -mu m g along x (Coulomb)
    and +m g along z until it rolls: it decelerates at mu g and spins up at 5/2 mu g / r (the
    friction's torque mu m g r). The wall fix's per-atom ``contacts`` columns hold the force on
    the particle (LAMMPS' documentation says: on the wall). Measured, on every sliding step:
    fx / fz = -mu to 5e-16, fz = m g to 2e-10, both rates to 6e-13 (size7 of paper B, the grain
    of the others). Once rolling, paper B's weakly damped tangential spring rings about the
    rolling speed (it would in LIGGGHTS too)."""
    plan = plans[law]
    name = WALL_GRAIN[law]
    pair = plan.pair(name, "wall")
    sp = species(plan, name)
    r, m, g, mu = sp.radius, sp.mass, plan.gravity, pair.friction
    weight = m * g
    if law == "hertz":
        overlap = (weight / (4 / 3 * pair.y_eff * math.sqrt(r))) ** (2 / 3)
        period = 2 * math.pi / math.sqrt(2 * pair.y_eff * math.sqrt(r * overlap) / m)   # small oscillation
    else:
        overlap = weight / pair.kn
        period = 2 * math.pi * math.sqrt(m / pair.kn)
    dt = period / 50
    v0 = 0.1
    slide_time = 2 * v0 / (7 * mu * g)
    sim = TwoBodies(lmp, plan, [name], dt, wall=pair, gravity=g)
    sim.add(name, 0.0, z=r - overlap)
    sim.start()
    rest = sim.run(int(5 * period / dt), wall=True)
    assert np.all(rest["contacts"][:, 0, 0] == 1.0)
    assert rest["contacts"][:, 0, 3] == pytest.approx(weight, rel=1e-6)      # up, on the particle
    assert r - rest["x"][:, 0, 2] == pytest.approx(overlap, rel=1e-6)

    sim = TwoBodies(lmp, plan, [name], dt, wall=pair, gravity=g)           # from rest, sliding
    sim.add(name, 0.0, z=r - overlap, vx=v0)
    sim.start()
    t = sim.run(int(1.2 * slide_time / dt), wall=True)
    vx, spin = t["v"][:, 0, 0], t["omega"][:, 0, 1]
    fx, fz = t["contacts"][:, 0, 1], t["contacts"][:, 0, 3]
    slip = vx - spin * r
    sliding = np.arange(np.argmax(slip < 0.05 * v0))          # until it (almost) rolls
    assert len(sliding) > 0.9 * slide_time / dt
    assert fx[sliding] / fz[sliding] == pytest.approx(np.full(len(sliding), -mu), rel=1e-9)
    assert fz[sliding] == pytest.approx(np.full(len(sliding), weight), rel=1e-9)
    time = np.arange(len(vx)) * dt
    assert np.polyfit(time[sliding], vx[sliding], 1)[0] == pytest.approx(-mu * g, rel=1e-6)
    assert np.polyfit(time[sliding], spin[sliding] * r, 1)[0] == pytest.approx(2.5 * mu * g, rel=1e-6)
    assert abs(slip[-1]) < 0.1 * v0                              # then rolls (no rolling friction)


@pytest.mark.engine
def test_rolling_torque_limit_is_liggghts_cdt_torque(lmp, plans):
    """Rolling friction 0.1 (CDT in LIGGGHTS, sds in LAMMPS): two spheres held at overlap d and
    counter-rotating (rolling, not sliding) slow down at mu_r F_n R* / I, with F_n = 4/3 Y*
    sqrt(R*) d^(3/2): the limiting torque of both. Measured: at the limit from the first step
    (at 20 rad/s the dashpot alone exceeds it), the deceleration within 3e-13 of it."""
    plan = plans["hertz"]
    pair = plan.pair("grain", "grain").model_copy(update={"rolling_friction": 0.1})
    sp = species(plan, "grain")
    r = sp.radius
    overlap = 1e-3 * r
    dt = pair.contact_time / 50
    sim = TwoBodies(lmp, plan, ["grain"], dt, pairs={("grain", "grain"): pair})
    sim.add("grain", 0.0)
    sim.add("grain", 2 * r - overlap)
    sim.start("set atom 1 omega 0.0 0.0 10.0\nset atom 2 omega 0.0 0.0 -10.0\nfix hold all setforce 0.0 0.0 0.0\n")
    t = sim.run(int(10 * pair.contact_time / dt))
    omega = t["omega"][:, :, 2]
    assert np.allclose(omega[:, 0], -omega[:, 1])
    fn = 4 / 3 * pair.y_eff * math.sqrt(pair.r_eff) * overlap ** 1.5
    inertia = 0.4 * sp.mass * r ** 2
    late = slice(len(omega) // 2, None)
    slope = np.polyfit(np.arange(len(omega))[late] * dt, omega[late, 0], 1)[0]
    assert -slope == pytest.approx(pair.rolling_friction * fn * pair.r_eff / inertia, rel=1e-6)
