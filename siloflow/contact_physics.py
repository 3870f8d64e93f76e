"""Contact mechanics of spheres: masses, stiffness, damping, contact and critical times.

Pure functions in SI units; the deck only places the numbers computed here.
"""
from __future__ import annotations

import math


def sphere_volume(radius: float) -> float:
    """Volume of a sphere, m3."""
    return 4.0 / 3.0 * math.pi * radius ** 3


def sphere_mass(radius: float, density: float) -> float:
    """Mass of a sphere, kg."""
    return density * sphere_volume(radius)


def reduced(a: float, b: float | None) -> float:
    """Reduced quantity a*b/(a+b); ``b=None`` stands for an infinite partner (a wall)."""
    if b is None:
        return a
    return a * b / (a + b)


def effective_modulus(e1: float, nu1: float, e2: float, nu2: float) -> float:
    """Hertz effective modulus Y* with 1/Y* = (1-nu1^2)/E1 + (1-nu2^2)/E2, Pa (as in LIGGGHTS)."""
    return 1.0 / ((1.0 - nu1 ** 2) / e1 + (1.0 - nu2 ** 2) / e2)


def shear_modulus(youngs_modulus: float, poisson_ratio: float) -> float:
    """G = E / (2 (1 + nu)), Pa."""
    return youngs_modulus / (2.0 * (1.0 + poisson_ratio))


def rayleigh_time(radius: float, density: float, youngs_modulus: float, poisson_ratio: float) -> float:
    """Rayleigh time pi r sqrt(rho/G) / (0.1631 nu + 0.8766), s (as LIGGGHTS' check/timestep/gran)."""
    g = shear_modulus(youngs_modulus, poisson_ratio)
    return math.pi * radius * math.sqrt(density / g) / (0.1631 * poisson_ratio + 0.8766)


def hertz_contact_time(m_eff: float, r_eff: float, y_eff: float, impact_velocity: float) -> float:
    """Duration of an elastic Hertz impact 2.87 (m*^2 / (r* Y*^2 v))^(1/5), s."""
    return 2.87 * (m_eff ** 2 / (r_eff * y_eff ** 2 * impact_velocity)) ** 0.2


def damping_ratio_from_restitution(restitution: float) -> float:
    """Damping ratio zeta of a linear spring-dashpot that gives restitution e:
    zeta = -ln e / sqrt(pi^2 + ln^2 e) (0 for e = 1)."""
    if not 0.0 < restitution <= 1.0:
        raise ValueError("restitution must be in (0, 1]")
    ln_e = math.log(restitution)
    return -ln_e / math.sqrt(math.pi ** 2 + ln_e ** 2)


def restitution_from_damping_ratio(zeta: float) -> float:
    """Inverse of :func:`damping_ratio_from_restitution` (zeta < 1): e = exp(-pi zeta / sqrt(1 - zeta^2))."""
    return math.exp(-math.pi * zeta / math.sqrt(1.0 - zeta ** 2))


def linear_gamma(kn: float, m_eff: float, restitution: float) -> float:
    """Normal damping of LIGGGHTS' hooke/stiffness (absolute_damping off), 1/s.

    The damping force there is gamma_n * m_eff * v_n, so critical damping 2 sqrt(kn m_eff)
    times zeta gives gamma_n = 2 zeta sqrt(kn / m_eff).
    """
    return 2.0 * damping_ratio_from_restitution(restitution) * math.sqrt(kn / m_eff)


def hooke_kn(m_eff: float, r_eff: float, y_eff: float, characteristic_velocity: float) -> float:
    """Normal stiffness (N/m) of LIGGGHTS' ``hooke`` model (paper B, Eq. 10):
    kn = 16/15 sqrt(R*) Y* (15 m* V^2 / (16 sqrt(R*) Y*))^(1/5): the linear spring whose
    maximum overlap at impact speed V equals Hertz's. (Paper B prints sqrt(R* Y) in the bracket,
    which is not dimensionally consistent; this is LIGGGHTS' form.)"""
    root = math.sqrt(r_eff)
    return 16.0 / 15.0 * root * y_eff * (15.0 * m_eff * characteristic_velocity ** 2 / (16.0 * root * y_eff)) ** 0.2


def linear_contact_time(kn: float, m_eff: float, restitution: float = 1.0) -> float:
    """Duration of a linear spring-dashpot contact pi / sqrt(kn/m - (gamma/2)^2), s.

    With restitution 1 this is the undamped t_c = pi sqrt(m_eff / kn).
    """
    omega0 = math.sqrt(kn / m_eff)
    zeta = damping_ratio_from_restitution(restitution)
    return math.pi / (omega0 * math.sqrt(1.0 - zeta ** 2))


def free_fall_speed(height: float, gravity: float, initial_speed: float = 0.0) -> float:
    """Speed after falling ``height`` from ``initial_speed``, m/s."""
    return math.sqrt(initial_speed ** 2 + 2.0 * gravity * max(height, 0.0))
