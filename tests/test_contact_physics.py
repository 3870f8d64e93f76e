"""Derived physics against independent numerical integration and known formulas."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from siloflow import contact_physics as cp
from siloflow.case_file import case_from_dict
from siloflow.fill_placement import class_counts
from siloflow.derived import bed_height, bed_volume, derive
from siloflow.engine.liggghts.encoding import encode, is_prime


def _impact(force, m, v0):
    """Integrate a head-on impact m x'' = -force(x, v) from x = 0, v = v0 until separation.
    Returns (contact time, rebound speed)."""
    def rhs(t, y):
        return [y[1], -force(max(y[0], 0.0), y[1]) / m]

    def out(t, y):
        return y[0]
    out.terminal, out.direction = True, -1
    sol = solve_ivp(rhs, (0, 1.0), [0.0, v0], events=out, rtol=1e-10, atol=1e-14, max_step=1e-6)
    return sol.t_events[0][0], -sol.y_events[0][0][1]


@pytest.mark.parametrize("e", [0.3, 0.5, 0.88, 1.0])
def test_linear_spring_dashpot_restitution_and_contact_time(e):
    kn, m = 3.2e5, 1e-4
    gamma = cp.linear_gamma(kn, m, e)            # LIGGGHTS: damping force gamma_n * m_eff * v
    t_c, v_out = _impact(lambda x, v: kn * x + gamma * m * v, m, 1.0)
    assert v_out == pytest.approx(e, rel=1e-4)
    assert t_c == pytest.approx(cp.linear_contact_time(kn, m, e), rel=1e-4)


def test_hertz_contact_time_formula():
    m, r, y, v = 1e-4, 1e-3, 3e6, 1.0
    t_c, v_out = _impact(lambda x, vel: 4.0 / 3.0 * y * math.sqrt(r) * x ** 1.5, m, v)
    assert v_out == pytest.approx(v, rel=1e-4)
    assert cp.hertz_contact_time(m, r, y, v) == pytest.approx(t_c, rel=0.01)


def test_restitution_round_trip_and_limits():
    assert cp.damping_ratio_from_restitution(1.0) == 0.0
    for e in (0.1, 0.5, 0.9):
        assert cp.restitution_from_damping_ratio(cp.damping_ratio_from_restitution(e)) == pytest.approx(e)
    with pytest.raises(ValueError):
        cp.damping_ratio_from_restitution(0.0)


def rayleigh_root(nu: float) -> float:
    """c_R / c_s from the Rayleigh equation (2 - x^2)^2 = 4 sqrt(1 - x^2) sqrt(1 - k x^2),
    k = c_s^2 / c_p^2 = (1 - 2 nu) / (2 (1 - nu)), solved numerically (its root in (0, 1))."""
    k = (1 - 2 * nu) / (2 * (1 - nu))
    return brentq(lambda x: (2 - x * x) ** 2 - 4 * math.sqrt(1 - x * x) * math.sqrt(1 - k * x * x),
                  0.5, 1 - 1e-12, xtol=1e-15)


def test_rayleigh_root_solver_gives_the_classical_poisson_solid_value():
    # Rayleigh (1885), nu = 1/4: x^2 = 2 - 2/sqrt(3), c_R = 0.9194 c_s
    assert rayleigh_root(0.25) == pytest.approx(math.sqrt(2 - 2 / math.sqrt(3)), rel=1e-12)
    assert rayleigh_root(0.25) == pytest.approx(0.91940, abs=1e-5)


@pytest.mark.parametrize("nu", [0.0, 0.1, 0.25, 0.3, 0.4, 0.49])
@pytest.mark.parametrize("radius,density,youngs", [(1.5e-3, 2500.0, 5e6), (1 / 64, 7520.0, 1.2e11)])
def test_rayleigh_time_is_the_rayleigh_wave_crossing_a_grain(radius, density, youngs, nu):
    """dt_R = pi r / c_R: a Rayleigh wave (speed from the root of the Rayleigh equation, not
    from the 0.1631 nu + 0.8766 fit) crossing half a grain's circumference. The fit LIGGGHTS
    uses deviates from the root by at most 0.30 % over 0 <= nu <= 0.5 (0.29 % at nu = 0,
    0.20 % at 0.3): tolerance 0.35 %."""
    c_s = math.sqrt(youngs / (2 * (1 + nu)) / density)        # shear wave speed sqrt(G / rho)
    expected = math.pi * radius / (rayleigh_root(nu) * c_s)
    assert cp.rayleigh_time(radius, density, youngs, nu) == pytest.approx(expected, rel=3.5e-3)


def test_masses_and_moduli():
    assert cp.sphere_mass(0.5, 1000) == pytest.approx(1000 * 4 / 3 * math.pi / 8)
    assert cp.effective_modulus(5e6, 0.3, 5e6, 0.3) == pytest.approx(5e6 / (2 * 0.91))
    assert cp.reduced(2.0, 2.0) == 1.0 and cp.reduced(2.0, None) == 2.0


def test_derived_timestep_is_fraction_of_smallest_time(quick_dict):
    case = case_from_dict(quick_dict)
    d = derive(case)
    enc = encode(d)
    times = [p.contact_time for p in d.pairs.values()] + [d.timestep.rayleigh_time]
    assert d.timestep.critical_time == min(times)
    assert d.dt == pytest.approx(case.engine.timestep_fraction * min(times))
    assert d.particle_mass * d.fill.count == pytest.approx(d.total_mass)
    seeds = [s for v in enc.seeds.values() for s in (v if isinstance(v, list) else [v])]
    assert all(is_prime(s) and s > 10000 for s in seeds) and len(set(seeds)) == len(seeds)
    assert d.outputs.sample_steps % enc.sample_every == 0
    # the insertion region sits above the expected bed
    assert d.fill.region.z_min > d.fill.bed_height_estimate


def test_linear_model_derivation(quick_dict):
    quick_dict["materials"] = {
        "model": "linear", "particle": {"density": 1000.0}, "wall": {},
        "particle_particle": {"friction": 0.43, "kn": 3.2e5, "kt": 1.6e5, "restitution": 0.5},
        "particle_wall": {"friction": 0.62, "kn": 3.2e6, "kt": 1.6e6, "restitution": 0.5}}
    d = derive(case_from_dict(quick_dict))
    pw = d.pairs["particle_wall"]
    assert pw.contact_time == pytest.approx(math.pi * math.sqrt(d.particle_mass / 3.2e6))
    assert d.timestep.critical_time == pw.contact_time          # the stiff wall limits the step
    assert pw.gammat == pytest.approx(0.1 * pw.gamman)


def test_fill_height_converts_to_count(quick_dict):
    quick_dict["fill"].pop("count")
    quick_dict["fill"]["height"] = 0.1
    case = case_from_dict(quick_dict)
    d = derive(case)
    expected = 0.6 * math.pi * 0.015 ** 2 * 0.1 / d.particle_volume
    assert abs(d.fill.count - expected) <= 1
    assert d.fill.bed_height_estimate == pytest.approx(0.1, rel=1e-3)


def test_hopper_volume_is_cone_plus_cylinder(quick_dict):
    quick_dict["geometry"] = {"kind": "hopper", "radius": 0.015, "height": 0.3,
                              "half_angle_deg": 45.0, "outlet_radius": 0.008}
    case = case_from_dict(quick_dict)
    hh = case.geometry.hopper_height
    assert hh == pytest.approx(0.007)
    cone = math.pi * hh / 3 * (0.008 ** 2 + 0.008 * 0.015 + 0.015 ** 2)
    assert bed_volume(case, hh + 0.05) == pytest.approx(cone + math.pi * 0.015 ** 2 * 0.05)
    assert bed_height(case, bed_volume(case, 0.04)) == pytest.approx(0.04, rel=1e-6)


def test_polydisperse_number_and_mass_fractions_and_time_step(quick_dict):
    from siloflow.case import paper_b_radii
    from siloflow.engine.liggghts.deck import render_deck_text
    quick_dict["particles"] = {"kind": "polydisperse_spheres", "radii": [0.0015, 0.001, 0.00075],
                               "fractions": [0.2, 0.3, 0.5], "basis": "number"}
    case = case_from_dict(quick_dict)
    mono = dict(quick_dict, particles={"kind": "spheres", "radius": 0.00075})
    d, d_small = derive(case), derive(case_from_dict(mono))
    w = [0.2 * 1.5 ** 3, 0.3 * 1.0, 0.5 * 0.75 ** 3]
    assert d.fill.mass_fractions == pytest.approx([v / sum(w) for v in w])
    # the smallest grains set the contact times and the time step
    assert d.dt == pytest.approx(d_small.dt)
    assert d.particle_radius == 0.0015
    assert d.particle_volume == pytest.approx(sum(n * 4 / 3 * math.pi * r ** 3 for n, r in zip([0.2, 0.3, 0.5],
                                                                                              [0.0015, 0.001, 0.00075])))
    # the fill holds the number fractions' counts (siloflow.fill_placement), each size its own type and density
    assert class_counts(d) == {0: 0.2 * d.fill.count, 1: 0.3 * d.fill.count, 2: 0.5 * d.fill.count}
    deck = render_deck_text(d)
    assert "particletemplate" not in deck and "read_dump" in deck
    assert [ln.split()[2] for ln in deck.splitlines() if ln.startswith("set ")][:3] == ["1", "2", "3"]
    # the same distribution given by mass converts back to the number fractions
    by_mass = dict(quick_dict, particles=dict(quick_dict["particles"], fractions=d.fill.mass_fractions, basis="mass"))
    assert case_from_dict(by_mass).particles.number_fractions == pytest.approx([0.2, 0.3, 0.5])
    assert paper_b_radii(1 / 64) == pytest.approx([(16 - k) / 16 / 64 for k in range(7)])


@pytest.mark.parametrize("particles,words", [
    ({"radii": [0.001, 0.002], "fractions": [0.5, 0.6]}, "sum to 1"),
    ({"radii": [0.001, 0.002], "fractions": [1.0]}, "fractions"),
    ({"radii": [0.001, 0.001], "fractions": [0.5, 0.5]}, "distinct"),
    ({"radii": [0.001, 0.009], "fractions": [0.5, 0.5]}, "smaller than the outlet"),
])
def test_bad_size_distributions_are_refused(quick_dict, particles, words):
    from siloflow.errors import CaseError
    quick_dict["particles"] = {"kind": "polydisperse_spheres", "basis": "number", **particles}
    with pytest.raises(CaseError, match=words) as info:
        case_from_dict(quick_dict)
    assert any(path.startswith("particles") or "particles.radii" in msg for path, msg in info.value.problems)


def test_hooke_model_per_size_pair(quick_dict):
    """Paper B's contact law: kn from Young's modulus and a characteristic velocity (Eq. 10, LIGGGHTS'
    hooke), kt = 2/7 kn, gamma_t = 0.1 gamma_n, computed for every pair of size classes."""
    from siloflow.contact_physics import effective_modulus, hooke_kn, reduced, sphere_mass
    from conftest import hooke_materials
    from siloflow.engine.liggghts.deck import _properties
    quick_dict["materials"] = hooke_materials(7520.0, 1.2e11, 0.88, characteristic_velocity=1.37)
    quick_dict["particles"] = {"kind": "polydisperse_spheres", "radii": [0.0015, 0.001], "fractions": [0.5, 0.5],
                               "basis": "number"}
    case = case_from_dict(quick_dict)
    d = derive(case)
    enc = encode(d)
    y = effective_modulus(1.2e11, 0.3, 1.2e11, 0.3)
    m1, m2 = sphere_mass(0.0015, 7520.0), sphere_mass(0.001, 7520.0)
    p12 = enc.type_pairs[(1, 2)]
    # Eq. 10 by hand: the linear spring with Hertz's maximum overlap at speed V
    r, m = reduced(0.0015, 0.001), reduced(m1, m2)
    v = 1.37                 # not 1: at V = 1 a V^2 -> V slip in Eq. 10 would be invisible
    assert p12.kn == pytest.approx(16 / 15 * math.sqrt(r) * y * (15 * m * v ** 2 / (16 * math.sqrt(r) * y)) ** 0.2)
    assert p12.kn == pytest.approx(hooke_kn(m, r, y, v))
    # and its meaning: Hertz's largest overlap at V (integrated), independent of the algebra
    assert p12.kn == pytest.approx(m * v * v / hertz_max_overlap(m, r, y, v) ** 2, rel=1e-6)
    assert p12.kt == pytest.approx(2 / 7 * p12.kn) and p12.gammat == pytest.approx(0.1 * p12.gamman)
    # the smallest pair has the shortest contact, and sets the time step
    times = {k: v.contact_time for k, v in enc.type_pairs.items()}
    assert min(times, key=times.get) in ((2, 2), (2, 3))
    assert d.timestep.critical_time == pytest.approx(min(times.values()))
    kn = next(p for p in _properties(d, enc) if p["name"] == "kn")["numbers"]
    matrix = np.array(kn).reshape(3, 3)
    assert np.allclose(matrix, matrix.T) and matrix[0, 1] == pytest.approx(p12.kn)
    assert matrix[1, 2] == pytest.approx(enc.type_pairs[(2, 3)].kn)      # size class 2 with the wall


# Paper B's largest pair (rb = 1/64 m, rho 7520 kg/m3, Y 120 GPa, nu 0.3), worked by hand:
#   m  = 7520 x 4/3 pi (1/64)^3 = 7520 x 1.59790e-5 m3 = 0.1201618 kg;  m* = m/2 = 0.0600809 kg
#   R* = rb/2 = 1/128 m = 0.0078125 m;  sqrt(R*) = 0.0883883
#   Y* = 1 / (2 (1 - 0.3^2) / 1.2e11) = 1.2e11 / 1.82 = 6.59341e10 Pa
#   Eq. 10: kn = 16/15 sqrt(R*) Y* (15 m* V^2 / (16 sqrt(R*) Y*))^(1/5)
#           = 16/15 x 0.0883883 x 6.59341e10 x (0.901214 V^2 / 9.32449e10)^(1/5)
#           = 6.21632e9 x (9.66502e-12 V^2)^(1/5)
#   V = 1.37 m/s (paper_b.yaml):       (1.81403e-11)^(1/5) = 7.10770e-3 -> kn = 4.41837e7 N/m
#   V = 0.88 m/s (paper_b_quick.yaml): (7.48459e-12)^(1/5) = 5.95434e-3 -> kn = 3.70141e7 N/m
#   (paper_b_quick's Y is 1.2e8: kn scales as Y*^(4/5), 1000^(-4/5) = 3.98107e-3 -> 1.47356e5 N/m)
PAPER_B_LARGEST = dict(m_eff=0.0600809, r_eff=1 / 128, y_eff=1.2e11 / 1.82)
HOOKE_KN_BY_HAND = {1.37: 4.41837e7, 0.88: 3.70141e7}


def hertz_max_overlap(m, r, y, v):
    """Largest overlap of an elastic Hertz impact m x'' = -4/3 Y* sqrt(R*) x^(3/2) at speed v,
    by numerical integration (turning point: x' = 0)."""
    def rhs(t, q):
        return [q[1], -4.0 / 3.0 * y * math.sqrt(r) * max(q[0], 0.0) ** 1.5 / m]

    def turn(t, q):
        return q[1]
    turn.terminal, turn.direction = True, -1
    t_scale = (m / (y * math.sqrt(r) * (m * v * v / (y * math.sqrt(r))) ** 0.2)) ** 0.5
    sol = solve_ivp(rhs, (0, 100 * t_scale), [0.0, v], events=turn, rtol=1e-11, atol=1e-18,
                    max_step=0.01 * t_scale)
    return sol.y_events[0][0][0]


@pytest.mark.parametrize("v", [1.37, 0.88, 3.0])
def test_hooke_kn_gives_hertz_maximum_overlap_at_the_characteristic_velocity(v):
    """Eq. 10's meaning, checked without its algebra: the linear spring kn stops a grain arriving
    at V within the same overlap as the Hertz contact does, V sqrt(m*/kn) = delta_max (Hertz,
    integrated numerically)."""
    m, r, y = PAPER_B_LARGEST.values()
    delta = hertz_max_overlap(m, r, y, v)
    assert cp.hooke_kn(m, r, y, v) == pytest.approx(m * v * v / delta ** 2, rel=1e-6)
    if v in HOOKE_KN_BY_HAND:                   # and the worked numbers above
        assert cp.hooke_kn(m, r, y, v) == pytest.approx(HOOKE_KN_BY_HAND[v], rel=2e-5)


@pytest.mark.parametrize("deck,v,young", [("paper_b.yaml", 1.37, 1.2e11), ("paper_b_quick.yaml", 0.88, 1.2e8)])
def test_paper_b_decks_hooke_kn_of_the_largest_pair_by_hand(deck, v, young):
    """derive() on the paper decks themselves (their V is not 1): the largest pair's kn is the
    hand-worked Eq. 10 value above (Y 1.2e8 in the quick deck scales it by 1000^(-4/5))."""
    from conftest import ROOT
    from siloflow.case_file import load_case
    case = load_case(ROOT / "decks" / deck)
    assert case.materials.characteristic_velocity == v
    pair = encode(derive(case)).type_pairs[(1, 1)]
    assert pair.r_eff == pytest.approx(1 / 128) and pair.m_eff == pytest.approx(0.0600809, rel=1e-6)
    expected = HOOKE_KN_BY_HAND[v] * (young / 1.2e11) ** 0.8
    assert pair.kn == pytest.approx(expected, rel=2e-5)
    if deck == "paper_b_quick.yaml":
        assert pair.kn == pytest.approx(1.47356e5, rel=2e-5)


def test_hooke_needs_its_velocity_and_no_springs(quick_dict):
    from siloflow.errors import CaseError
    quick_dict["materials"]["model"] = "hooke"
    with pytest.raises(CaseError, match="characteristic_velocity is required"):
        case_from_dict(quick_dict)
    quick_dict["materials"]["characteristic_velocity"] = 1.0
    quick_dict["materials"]["particle_particle"]["kn"] = 1e5
    with pytest.raises(CaseError, match="computed by model 'hooke'"):
        case_from_dict(quick_dict)


def test_is_prime_agrees_with_a_sieve_and_with_known_primes_and_pseudoprimes():
    """The Miller-Rabin primality test that picks LIGGGHTS' seeds: every n below 2e5 against a
    sieve of Eratosthenes; strong pseudoprimes to small bases and Carmichael numbers are composite;
    primes near the seeds' top (5e7) and Mersenne 2^31 - 1 are prime."""
    n = 200_000
    sieve = np.ones(n, bool)
    sieve[:2] = False
    for k in range(2, int(n ** 0.5) + 1):
        if sieve[k]:
            sieve[k * k::k] = False
    assert [k for k in range(n) if is_prime(k)] == list(np.flatnonzero(sieve))
    for composite in (2047, 1373653, 25326001, 3215031751, 2152302898747, 3474749660383, 561, 41041, 825265):
        assert not is_prime(composite), composite
    for prime in (50_000_017, 2_147_483_647, 10_007, 999_999_937):
        assert is_prime(prime), prime
