"""Silo design loads after EN 1991-4:2006 (Eurocode 1, Part 4: silos) for a case's geometry.

Pure functions, SI units throughout (Pa, m, N/m3); no printing. The entry point is
:func:`design_loads`, which returns a :class:`DesignLoads` of pressures per height ``z`` in the
case's frame (m above the outlet; the vertical wall starts at ``hopper_height``).

What is implemented (clause and equation numbers as the author knows them; **check them, and
every number of the material table, against the standard before relying on them**):

- §4.2.3 / Table 3.1: characteristic values from a mean and a conversion factor (K_u = a_K K_m,
  K_l = K_m / a_K, mu and phi_i likewise), and which bound each load case takes; the upper unit
  weight gamma_u for every load.
- §5.1 / §1.5: classification by the aspect ratio h_c/d_c: slender >= 2, intermediate 1-2,
  squat 0.4 < . <= 1, retaining <= 0.4 (flat bottom only; a hopper silo that low is squat, §5.1(3)).
- §5.2.1.1 (5.1)-(5.7): slender silos, Janssen filling pressures p_hf, p_wf, p_vf and the wall's
  vertical force per unit perimeter n_zSk.
- §5.3.1.1: squat and intermediate silos, the modified depth function Y_R(z) and the vertical
  stress through z_V (derived below; the equation numbers are not recalled with certainty).
- §5.2.2.2 (5.16)-(5.22), §5.3.2.2: discharge factors C_h, C_w (slender: 1.15 and 1.10; AAC 1:
  the enlarged factors that replace the patch; intermediate: through C_S = h_c/d_c - 1; squat:
  discharge = filling).
- §5.2.1.2 (5.8)-(5.12), §5.2.2.3: patch reference pressures p_pf = C_pf p_hf, p_pe = C_pe p_he,
  over a zone of height s = pi d_c / 16.
- §6.1 (6.1): steep / shallow hopper; §6.3 (6.2)-(6.6) mean vertical stress in a hopper;
  §6.3.2 filling F_f (b = 0.2); §6.3.3 (6.22)-(6.23) discharge F_e; §6.4 shallow hoppers with the
  mobilised friction mu_heff; §6.1/§6.2 p_vft = C_b p_vf(h_c) at the transition (and on a flat
  bottom).

Not implemented (named in :attr:`DesignLoads.notes` where it matters): §5.4 retaining silos'
own rules (the squat procedure is used), the substitute uniform pressure increase (§5.2.1.3,
§5.2.2.4), eccentric discharge with large eccentricities (§5.2.4), the flat-bottom increment of
squat silos (§6.2.3), the hopper discharge switch pressure, rectangular silos, thermal and
other loads.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np

from .silos.registry import SILO_KINDS

#: wall surface categories of Annex E's wall friction columns (D1 low friction / polished,
#: D2 moderate / smooth steel, D3 high friction / rough: concrete, rusted steel)
WALL_TYPES = ("D1", "D2", "D3")
#: the three wall-load cases of Table 3.1 and the bounds (K, mu, phi_i) each takes
LOAD_CASES = {
    "max_horizontal": ("upper", "lower", "lower"),   # max normal pressure on the vertical wall
    "max_friction": ("upper", "upper", "lower"),     # max frictional traction on the vertical wall
    "max_vertical": ("lower", "lower", "upper"),     # max vertical load on the hopper or bottom
}
#: empirical coefficient of the hopper filling pressure ratio (§6.3.2)
HOPPER_B = 0.2
#: discharge factors of slender silos in AAC 2 and 3 (§5.2.2.2)
SLENDER_C_H, SLENDER_C_W = 1.15, 1.10


@dataclass(frozen=True)
class BulkSolid:
    """A stored solid's properties (EN 1991-4 Annex E, Table E.1, or given by hand).

    Unit weights gamma in N/m3; angles in degrees; ``mu_m`` the mean wall friction coefficient
    for wall types D1, D2, D3; ``a_*`` the conversion factors to characteristic values."""

    name: str
    gamma_l: float
    gamma_u: float
    phi_r: Optional[float]       # angle of repose (needed by squat and intermediate silos)
    phi_im: float                # angle of internal friction, mean
    a_phi: float
    K_m: float                   # lateral pressure ratio, mean
    a_K: float
    mu_m: tuple[float, float, float]
    a_mu: float
    C_op: float                  # patch load solid reference factor
    explicit: tuple[str, ...] = ()   # which values were given by hand (no spread applied)

    def K(self, bound: str) -> float:
        """K_u = a_K K_m or K_l = K_m / a_K (§4.2.3)."""
        return self.K_m * self.a_K if bound == "upper" else self.K_m / self.a_K

    def mu(self, bound: str, wall_type: str) -> float:
        """mu_u = a_mu mu_m or mu_l = mu_m / a_mu for the wall type (§4.2.3)."""
        m = self.mu_m[_wall_index(wall_type)]
        return m * self.a_mu if bound == "upper" else m / self.a_mu

    def phi_i(self, bound: str) -> float:
        """phi_i,u = a_phi phi_im or phi_i,l = phi_im / a_phi, degrees (§4.2.3)."""
        return self.phi_im * self.a_phi if bound == "upper" else self.phi_im / self.a_phi

    @property
    def gamma(self) -> float:
        """The unit weight every load uses: the upper characteristic value gamma_u, N/m3."""
        return self.gamma_u


def _row(name, gl, gu, phi_r, phi_im, a_phi, K_m, a_K, d1, d2, d3, a_mu, C_op) -> BulkSolid:
    return BulkSolid(name, gl * 1e3, gu * 1e3, phi_r, phi_im, a_phi, K_m, a_K, (d1, d2, d3), a_mu, C_op)


#: EN 1991-4:2006 Annex E, Table E.1, as recalled by the author: **every value must be checked
#: against the standard before it is used for design.** Columns: gamma_l, gamma_u (kN/m3), phi_r,
#: phi_im (deg), a_phi, K_m, a_K, mu_m for D1, D2, D3, a_mu, C_op. The wheat row agrees with
#: ../shared/REFERENCES.md; every row satisfies the standard's estimate K_m ~ 1.1 (1 - sin phi_im)
#: to within 0.04 (tests/test_design_loads.py checks it), a check of the transcription only.
MATERIALS: dict[str, BulkSolid] = {r.name: r for r in (
    _row("default", 6.0, 22.0, 40, 35, 1.3, 0.50, 1.5, 0.32, 0.39, 0.50, 1.40, 1.0),
    _row("aggregate", 17.0, 18.0, 36, 31, 1.16, 0.52, 1.15, 0.39, 0.49, 0.59, 1.12, 0.4),
    _row("alumina", 10.0, 12.0, 36, 30, 1.22, 0.54, 1.20, 0.41, 0.46, 0.51, 1.07, 0.5),
    _row("barley", 7.0, 8.0, 31, 28, 1.14, 0.59, 1.11, 0.24, 0.33, 0.48, 1.16, 0.5),
    _row("cement", 13.0, 16.0, 36, 30, 1.22, 0.54, 1.20, 0.41, 0.46, 0.51, 1.07, 0.5),
    _row("cement_clinker", 15.0, 18.0, 47, 40, 1.20, 0.38, 1.31, 0.46, 0.56, 0.62, 1.07, 0.7),
    _row("coal", 7.0, 10.0, 36, 31, 1.16, 0.52, 1.15, 0.44, 0.49, 0.59, 1.12, 0.6),
    _row("fly_ash", 8.0, 15.0, 41, 35, 1.16, 0.46, 1.20, 0.51, 0.62, 0.72, 1.07, 0.5),
    _row("flour", 6.5, 7.0, 45, 42, 1.06, 0.36, 1.11, 0.24, 0.33, 0.48, 1.16, 0.6),
    _row("lime_hydrated", 6.0, 8.0, 34, 27, 1.26, 0.58, 1.20, 0.36, 0.41, 0.51, 1.07, 0.6),
    _row("limestone_powder", 11.0, 13.0, 36, 30, 1.22, 0.54, 1.20, 0.41, 0.51, 0.56, 1.07, 0.5),
    _row("maize", 7.0, 8.0, 35, 31, 1.14, 0.53, 1.14, 0.22, 0.36, 0.53, 1.24, 0.9),
    _row("sand", 14.0, 16.0, 39, 36, 1.09, 0.45, 1.11, 0.38, 0.48, 0.57, 1.16, 0.4),
    _row("soya_beans", 7.0, 8.0, 29, 25, 1.16, 0.63, 1.11, 0.24, 0.38, 0.48, 1.16, 0.5),
    _row("sugar", 8.0, 9.5, 38, 32, 1.19, 0.50, 1.20, 0.46, 0.51, 0.56, 1.07, 0.4),
    _row("wheat", 7.5, 9.0, 34, 30, 1.12, 0.54, 1.11, 0.24, 0.38, 0.57, 1.16, 0.5),
)}
MATERIAL_NAMES = tuple(MATERIALS)
#: the case fields (dotted paths) the design loads and a run's band pressures beside them depend on:
#: a run compared with a case's loads must agree with it in these (``siloflow design --run``)
CASE_FIELDS = ("gravity", "geometry", "materials", "particles", "fill.count", "fill.height",
               "fill.packing_fraction")
#: physical ranges [lo, hi] of explicit values (unit weight N/m3), as the case schema's
#: ``siloflow.case.DESIGN_RANGES`` (why each bound: there); K mu is the divisor of z_o
EXPLICIT_RANGES = {"unit_weight": (100.0, 1e5), "K": (0.1, 1.0), "mu": (0.05, 1.5), "phi_r": (5.0, 70.0)}


def _wall_index(wall_type: str) -> int:
    if wall_type not in WALL_TYPES:
        raise ValueError(f"wall_type {wall_type!r} is not one of {', '.join(WALL_TYPES)}")
    return WALL_TYPES.index(wall_type)


def bulk_solid(name: Optional[str] = None, *, unit_weight: Optional[float] = None, K: Optional[float] = None,
               mu: Optional[float] = None, phi_r: Optional[float] = None,
               C_op: Optional[float] = None) -> BulkSolid:
    """The solid: a row of :data:`MATERIALS` (``name``), with any explicit value replacing the
    table's, or (``name`` None) explicit values only.

    An explicit ``K`` or ``mu`` is used for every load case (its conversion factor is 1; ``mu``
    for every wall type); an explicit ``unit_weight`` (N/m3) is gamma_l = gamma_u. Without a
    table row, ``unit_weight``, ``K`` and ``mu`` are required; phi_im is estimated from K with
    the standard's K_m = 1.1 (1 - sin phi_im) (used only by the hopper discharge factor F_e),
    and C_op defaults to the table's default material (1.0).

    Raises
    ------
    ValueError
        for an unknown name, a missing explicit value or one out of range.
    """
    given = {k: v for k, v in dict(unit_weight=unit_weight, K=K, mu=mu, phi_r=phi_r, C_op=C_op).items()
             if v is not None}
    for key, (lo, hi) in EXPLICIT_RANGES.items():
        if key in given and not (lo <= given[key] <= hi and math.isfinite(given[key])):
            raise ValueError(f"{key} = {given[key]} is outside [{lo:g}, {hi:g}]")
    for key, lo, hi in (("C_op", -1e-12, 10.0),):
        if key in given and not (lo < given[key] <= hi and math.isfinite(given[key])):
            raise ValueError(f"{key} = {given[key]} is outside ({lo:g}, {hi:g}]")
    if name is None:
        missing = [k for k in ("unit_weight", "K", "mu") if k not in given]
        if missing:
            raise ValueError(f"without a material name, give {', '.join(missing)} (explicit values)")
        phi_im = math.degrees(math.asin(min(1.0, max(0.0, 1.0 - K / 1.1))))
        solid = BulkSolid("explicit", unit_weight, unit_weight, phi_r, phi_im, 1.0, K, 1.0, (mu,) * 3, 1.0,
                          MATERIALS["default"].C_op if C_op is None else C_op)
        return replace(solid, explicit=tuple(given))
    if name not in MATERIALS:
        raise ValueError(f"material {name!r} is not in the EN 1991-4 Annex E table; one of: "
                         + ", ".join(MATERIAL_NAMES))
    solid = MATERIALS[name]
    changes: dict = {}
    if "unit_weight" in given:
        changes.update(gamma_l=unit_weight, gamma_u=unit_weight)
    if "K" in given:
        changes.update(K_m=K, a_K=1.0)
    if "mu" in given:
        changes.update(mu_m=(mu,) * 3, a_mu=1.0)
    if "phi_r" in given:
        changes.update(phi_r=phi_r)
    if "C_op" in given:
        changes.update(C_op=C_op)
    return replace(solid, explicit=tuple(given), **changes) if changes else solid


# --------------------------------------------------------------------------- characteristic values
@dataclass(frozen=True)
class LoadCaseValues:
    """K, mu and phi_i (deg) of one load case (Table 3.1), with z_o = A / (K mu U) (m)."""

    K: float
    mu: float
    phi_i: float
    z_o: float


def characteristic_values(solid: BulkSolid, wall_type: str, a_over_u: float) -> dict[str, LoadCaseValues]:
    """K, mu, phi_i and z_o per load case of :data:`LOAD_CASES` (EN 1991-4 Table 3.1):
    maximum horizontal pressure K upper, mu lower; maximum wall friction K upper, mu upper;
    maximum vertical load K lower, mu lower. ``a_over_u`` is A/U (m; d_c/4 for a circle)."""
    out = {}
    for case, (kb, mb, pb) in LOAD_CASES.items():
        K, mu = solid.K(kb), solid.mu(mb, wall_type)
        out[case] = LoadCaseValues(K, mu, solid.phi_i(pb), a_over_u / (K * mu))
    return out


def classify(aspect_ratio: float, flat_bottom: bool = True) -> str:
    """Silo class by h_c/d_c (§5.1(2)-(3), §1.5): ``slender`` (>= 2), ``intermediate`` (1 < . < 2),
    ``squat`` (0.4 < . <= 1) or ``retaining`` (<= 0.4, a flat bottom; with a hopper: squat)."""
    if aspect_ratio >= 2.0:
        return "slender"
    if aspect_ratio > 1.0:
        return "intermediate"
    if aspect_ratio > 0.4 or not flat_bottom:
        return "squat"
    return "retaining"


# --------------------------------------------------------------------------- vertical walls
def _janssen_terms(depth, gamma: float, K: float, mu: float, a_over_u: float):
    """Janssen's law's parts at ``depth`` (m, clipped at 0): (z, z_o, p_ho, Y_J) with
    z_o = A/(K mu U) (5.5), p_ho = gamma K z_o (5.4), Y_J = 1 - exp(-z/z_o) (5.6)."""
    z = np.maximum(np.asarray(depth, float), 0.0)
    z_o = a_over_u / (K * mu)
    return z, z_o, gamma * K * z_o, -np.expm1(-z / z_o)


def janssen_pressure(depth, gamma: float, K: float, mu: float, a_over_u: float):
    """Janssen's horizontal wall pressure (Pa) at ``depth`` (m) below the surface, 0 above it:
    p_ho Y_J = gamma K z_o (1 - exp(-z/z_o)), z_o = A/(K mu U) (EN 1991-4 (5.1), (5.4)-(5.6)),
    with ``gamma`` the unit weight (N/m3), K the lateral pressure ratio, ``mu`` the wall friction
    and ``a_over_u`` = A/U (m; D/4 for a cylinder of diameter D). It levels off at gamma A/(mu U).
    The one statement of the law: EN's filling pressure and postprocess' fits use it."""
    _, _, p_ho, y = _janssen_terms(depth, gamma, K, mu, a_over_u)
    return p_ho * y


def janssen_filling(depth, gamma: float, K: float, mu: float, a_over_u: float):
    """Slender silo filling (§5.2.1.1, (5.1)-(5.7)) at ``depth`` below the equivalent surface:
    p_hf = p_ho Y_J (5.1, :func:`janssen_pressure`), p_wf = mu p_ho Y_J (5.2), p_vf = p_ho Y_J / K (5.3),
    n_zSk = mu p_ho (z - z_o Y_J) (5.7, N/m). Returns (p_hf, p_wf, p_vf, n_zSk)."""
    z, z_o, p_ho, y = _janssen_terms(depth, gamma, K, mu, a_over_u)
    return p_ho * y, mu * p_ho * y, p_ho * y / K, mu * p_ho * (z - z_o * y)


def squat_exponent(z_o: float, h_o: float, phi_r: float) -> float:
    """n = -(1 + tan phi_r)(1 - h_o/z_o) of Y_R (§5.3.1.1); ``phi_r`` in degrees."""
    return -(1.0 + math.tan(math.radians(phi_r))) * (1.0 - h_o / z_o)


def squat_filling(depth, gamma: float, K: float, mu: float, a_over_u: float, phi_r: float, h_o: float):
    """Squat and intermediate silo filling (§5.3.1.1) at ``depth`` (m below the equivalent
    surface; ``h_o`` the depth of the highest wall contact, zero pressure above it):

        Y_R(z) = 1 - ((z - h_o)/(z_o - h_o) + 1)^n,   n = -(1 + tan phi_r)(1 - h_o/z_o),
        p_hf = p_ho Y_R,  p_wf = mu p_ho Y_R,  p_vf = gamma z_V,  n_zSk = mu p_ho (z - z_V),
        z_V = h_o - (z_o - h_o - (z + z_o - 2 h_o)^(n+1) / (z_o - h_o)^n) / (n + 1),

    evaluated as z_V = h_o + (z_o - h_o) (X^(n+1) - 1) / (n + 1), X = (z - h_o)/(z_o - h_o) + 1 (no
    power of z_o - h_o alone, which overflows at a steep phi_r, and the limit (z_o - h_o) ln X at
    n = -1, where the standard's form divides 0 by 0).

    z_V is the standard's form as recalled and re-derived here: vertical equilibrium of a slice,
    dp_v/dz = gamma - (U/A) mu p_hf = gamma (1 - Y_R) because (U/A) mu p_ho = gamma, integrated
    from p_v(h_o) = gamma h_o (the heap above the wall contact, whose volume is A h_o).
    Returns (p_hf, p_wf, p_vf, n_zSk); p_vf is NaN above the wall contact (inside the heap)."""
    z = np.asarray(depth, float)
    z_o = a_over_u / (K * mu)
    if not z_o > h_o:
        raise ValueError(f"the highest wall contact h_o ({h_o:.4g} m) lies below z_o ({z_o:.4g} m): "
                         "Y_R is not defined")
    p_ho = gamma * K * z_o
    n = squat_exponent(z_o, h_o, phi_r)
    below = z >= h_o - 1e-12               # m: round-off of a height given at the contact
    zz = np.where(below, np.maximum(z, h_o), h_o)
    x = (zz - h_o) / (z_o - h_o) + 1.0
    y = np.where(below, 1.0 - x ** n, 0.0)
    log_x, m = np.log(x), n + 1.0
    # (X^m - 1) / m, its series where m is too near 0 to divide by
    growth = log_x * (1.0 + 0.5 * m * log_x) if abs(m) < 1e-9 else np.expm1(m * log_x) / m
    z_v = h_o + (z_o - h_o) * growth
    p_vf = np.where(below, gamma * z_v, np.where(z < 0, 0.0, np.nan))
    return p_ho * y, mu * p_ho * y, p_vf, np.where(below, mu * p_ho * (zz - z_v), 0.0)


def discharge_factors(classification: str, aspect_ratio: float, aac: int, eccentricity_ratio: float,
                      C_op: float) -> tuple[float, float]:
    """C_h, C_w (§5.2.2.2, §5.3.2.2), with e/d_c = ``eccentricity_ratio``:

    - slender, AAC 2 and 3: C_h = 1.15 (5.18), C_w = 1.10 (5.19);
    - slender, AAC 1 (the patch is then omitted): C_h = 1.15 + 1.5 (1 + 0.4 e/d_c) C_op (5.20),
      C_w = 1.4 (1 + 0.4 e/d_c) (5.21), e = max(e_f, e_o) (5.22);
    - intermediate, with C_S = h_c/d_c - 1: AAC 2, 3: C_h = 1 + 0.15 C_S, C_w = 1 + 0.1 C_S;
      AAC 1: C_h = 1 + (0.15 + 1.5 (1 + 0.4 e/d_c) C_op) C_S, C_w = 1 + 0.4 (1 + 1.4 e/d_c) C_S
      (both continuous with the slender values at h_c/d_c = 2);
    - squat and retaining: discharge = filling, C_h = C_w = 1."""
    e = eccentricity_ratio
    if classification == "slender":
        if aac == 1:
            return 1.15 + 1.5 * (1.0 + 0.4 * e) * C_op, 1.4 * (1.0 + 0.4 * e)
        return SLENDER_C_H, SLENDER_C_W
    if classification == "intermediate":
        c_s = aspect_ratio - 1.0
        if aac == 1:
            return 1.0 + (0.15 + 1.5 * (1.0 + 0.4 * e) * C_op) * c_s, 1.0 + 0.4 * (1.0 + 1.4 * e) * c_s
        return 1.0 + 0.15 * c_s, 1.0 + 0.1 * c_s
    return 1.0, 1.0


def patch_factors(aspect_ratio: float, C_op: float, E: float, aac: int) -> tuple[float, float]:
    """C_pf, C_pe of the patch reference pressures p_pf = C_pf p_hf and p_pe = C_pe p_he, with
    E = 2 e/d_c (§5.2.1.2 (5.9)-(5.11), §5.2.2.3):

        C_pf = 0.21 C_op (1 + 2 E^2)(1 - exp(-1.5 (h_c/d_c - 1))),  >= 0;
        C_pe = 0.42 C_op (1 + 2 E^2)(1 - exp(-1.5 (h_c/d_c - 1)))   for h_c/d_c > 1.2,
        C_pe = 0.272 C_op (h_c/d_c - 1 + E)                          for h_c/d_c <= 1.2,  >= 0.

    AAC 1: no patch (0, 0); its discharge factors carry the allowance instead."""
    if aac == 1:
        return 0.0, 0.0
    growth = 1.0 - math.exp(-1.5 * (aspect_ratio - 1.0))
    c_pf = max(0.0, 0.21 * C_op * (1.0 + 2.0 * E ** 2) * growth)
    if aspect_ratio > 1.2:
        c_pe = 0.42 * C_op * (1.0 + 2.0 * E ** 2) * growth
    else:
        c_pe = 0.272 * C_op * (aspect_ratio - 1.0 + E)
    return c_pf, max(0.0, c_pe)


def bottom_load_magnifier(aac: int, dynamic: bool = False) -> float:
    """C_b of p_vft = C_b p_vf (§6.1(?), §6.2.2): 1.3 for AAC 1 and 1.0 for AAC 2 and 3; where
    the solid may load the bottom dynamically (collapsing arches), 1.6 and 1.2."""
    if dynamic:
        return 1.6 if aac == 1 else 1.2
    return 1.3 if aac == 1 else 1.0


# --------------------------------------------------------------------------- hoppers
def hopper_is_steep(beta_deg: float, K_l: float, mu_h: float) -> bool:
    """Steep hopper (§6.1 (6.1)): tan beta < (1 - K) / (2 mu_h), K the lower characteristic K of
    the vertical wall, mu_h the lower wall friction in the hopper, beta the half angle from the
    vertical; otherwise shallow."""
    return math.tan(math.radians(beta_deg)) < (1.0 - K_l) / (2.0 * mu_h)


def hopper_filling_ratio(beta_deg: float, mu_h: float, b: float = HOPPER_B) -> float:
    """F_f = 1 - b / (1 + tan beta / mu_h) (§6.3.2; shallow hoppers with mu_heff)."""
    return 1.0 - b / (1.0 + math.tan(math.radians(beta_deg)) / mu_h)


def hopper_discharge_ratio(beta_deg: float, mu_h: float, phi_i_deg: float) -> float:
    """F_e = (1 + sin phi_i cos eps) / (1 - sin phi_i cos(2 beta + eps)) (§6.3.3 (6.22)),
    eps = phi_wh + asin(sin phi_wh / sin phi_i), phi_wh = atan mu_h (6.23). A wall friction
    angle above phi_i (sliding within the solid) is limited to phi_i."""
    s = math.sin(math.radians(phi_i_deg))
    phi_wh = min(math.atan(mu_h), math.radians(phi_i_deg))
    eps = phi_wh + math.asin(min(1.0, math.sin(phi_wh) / s))
    return (1.0 + s * math.cos(eps)) / (1.0 - s * math.cos(2.0 * math.radians(beta_deg) + eps))


def hopper_exponent(F: float, mu_h: float, beta_deg: float, S: float = 2.0) -> float:
    """n = S (F mu_h cot beta + F) - 2 (§6.3 (6.3)); S = 2 for a conical hopper, 1 for a wedge.
    With F = F_f this is S (1 - b) mu_h cot beta + S - 2."""
    return S * (F * mu_h / math.tan(math.radians(beta_deg)) + F) - 2.0


def hopper_vertical_stress(x, h_h: float, gamma: float, n: float, p_vft: float):
    """Mean vertical stress in a hopper (§6.3 (6.2)) at ``x`` (m above the apex), h_h (m) apex to
    transition: p_v = gamma h_h / (n - 1) (x/h_h - (x/h_h)^n) + p_vft (x/h_h)^n; at n = 1 the
    limit gamma x ln(h_h/x) + p_vft x/h_h. It solves dp_v/dx = n p_v / x - gamma, the vertical
    equilibrium of a slice when p_n = F p_v and p_t = mu_h F p_v."""
    s = np.clip(np.asarray(x, float) / h_h, 1e-300, None)
    if abs(n - 1.0) < 1e-9:
        return gamma * h_h * s * np.log(1.0 / s) + p_vft * s
    return gamma * h_h / (n - 1.0) * (s - s ** n) + p_vft * s ** n


@dataclass(frozen=True)
class HopperLoads:
    """Scalars of a conical hopper's loads: half angle beta (deg), apex-to-transition height h_h
    and the outlet's height above the apex x_outlet (m), steep or shallow, the friction used
    (mu_h; shallow: mu_heff), F and n of filling and discharge, p_vft (Pa) and C_b."""

    beta: float
    h_h: float
    x_outlet: float
    steep: bool
    mu_h: float
    F_f: float
    n_f: float
    F_e: float
    n_e: float
    p_vft: float
    C_b: float


def hopper_loads(beta_deg: float, h_h: float, x_outlet: float, K_l: float, mu_l: float,
                 phi_i_u: float, p_vft: float, C_b: float) -> HopperLoads:
    """The hopper's F and n (§6.3, §6.4): steep hoppers F_f (filling) and F_e (discharge) with
    mu_h = mu_l; shallow ones the mobilised mu_heff = (1 - K)/(2 tan beta) (§6.4.1) in F_f, and
    discharge = filling (§6.4.3). Values for maximum hopper loads (Table 3.1): K and mu lower,
    phi_i upper."""
    steep = hopper_is_steep(beta_deg, K_l, mu_l)
    mu_h = mu_l if steep else (1.0 - K_l) / (2.0 * math.tan(math.radians(beta_deg)))
    F_f = hopper_filling_ratio(beta_deg, mu_h)
    n_f = hopper_exponent(F_f, mu_h, beta_deg)
    F_e = hopper_discharge_ratio(beta_deg, mu_h, phi_i_u) if steep else F_f
    n_e = hopper_exponent(F_e, mu_h, beta_deg) if steep else n_f
    return HopperLoads(beta_deg, h_h, x_outlet, steep, mu_h, F_f, n_f, F_e, n_e, p_vft, C_b)


# --------------------------------------------------------------------------- the loads of a case
@dataclass(frozen=True)
class DesignLoads:
    """EN 1991-4 loads of one silo, per height ``z`` (m above the outlet, the case's frame).

    Arrays (Pa, one value per ``z``): on the vertical wall (NaN below the transition, 0 above
    the highest wall contact) ``p_hf``, ``p_wf`` filling normal and friction pressure, ``p_he``,
    ``p_we`` discharge, ``p_pf``, ``p_pe`` the filling and discharge patch reference pressures
    (to be added over a zone of height ``patch_height``, centred anywhere), ``p_patch`` = p_pe
    (the larger; 0 for AAC 1), ``n_zSk`` the wall's vertical force per unit perimeter (N/m,
    filling, max-friction case); in the solid ``p_vf`` the mean vertical stress (max-vertical
    case; NaN inside a heap); in the hopper (NaN above the transition) ``p_v_hopper``, ``p_nf``,
    ``p_tf``, ``p_ne``, ``p_te``. ``depth`` is the depth below the equivalent surface (m).

    Which K and mu each array uses (Table 3.1): p_hf, p_he, patch ``K["max_horizontal"]`` etc.;
    p_wf, p_we, n_zSk the max-friction case; p_vf and the hopper the max-vertical case."""

    z: np.ndarray
    depth: np.ndarray
    p_hf: np.ndarray
    p_wf: np.ndarray
    p_vf: np.ndarray
    p_he: np.ndarray
    p_we: np.ndarray
    p_pf: np.ndarray
    p_pe: np.ndarray
    p_patch: np.ndarray
    n_zSk: np.ndarray
    p_v_hopper: np.ndarray
    p_nf: np.ndarray
    p_tf: np.ndarray
    p_ne: np.ndarray
    p_te: np.ndarray
    classification: str
    aspect_ratio: float          # h_c / d_c
    d_c: float                   # m
    h_c: float                   # m, transition to equivalent surface
    surface: float               # m above the outlet: the equivalent surface
    transition: float            # m above the outlet: the vertical wall's foot
    h_o: float                   # m, depth of the highest wall contact below the surface
    top: str                     # "flat" or "heap"
    values: dict                 # load case -> LoadCaseValues
    C_h: float
    C_w: float
    C_pf: float
    C_pe: float
    patch_height: float          # m, s = pi d_c / 16
    C_b: float
    p_vft: float                 # Pa, C_b p_vf at the transition (hopper top or flat bottom)
    hopper: Optional[HopperLoads]
    material: BulkSolid
    wall_type: str
    aac: int
    eccentricity: float          # m
    notes: tuple[str, ...] = field(default=())

    @property
    def K(self) -> dict[str, float]:
        return {k: v.K for k, v in self.values.items()}

    @property
    def mu(self) -> dict[str, float]:
        return {k: v.mu for k, v in self.values.items()}

    @property
    def z_o(self) -> dict[str, float]:
        return {k: v.z_o for k, v in self.values.items()}

    @property
    def C_p(self) -> float:
        """The patch factor of ``p_patch`` (the discharge one, C_pe)."""
        return self.C_pe

    COLUMNS = ("z", "depth", "p_hf", "p_wf", "p_vf", "p_he", "p_we", "p_pf", "p_pe", "p_patch", "n_zSk",
               "p_v_hopper", "p_nf", "p_tf", "p_ne", "p_te")

    def table(self):
        """The arrays as a pandas DataFrame, one row per height."""
        import pandas as pd
        return pd.DataFrame({c: getattr(self, c) for c in self.COLUMNS})

    def at(self, name: str, z):
        """Array ``name`` linearly interpolated at heights ``z`` (m above the outlet)."""
        order = np.argsort(self.z)
        return np.interp(np.asarray(z, float), self.z[order], np.asarray(getattr(self, name))[order])


def _default_heights(transition: float, top: float, contact: float) -> np.ndarray:
    """161 heights up the filled wall (and the highest wall contact), 41 in a hopper."""
    parts = [np.linspace(transition, top, 161), [contact]]
    if transition > 0:
        parts.append(np.linspace(0.0, transition, 41))
    return np.unique(np.concatenate(parts))


def design_loads(geometry, material, fill_height: float, wall_type: str = "D2", aac: int = 2,
                 eccentricity: float = 0.0, heights=None, top: str = "flat",
                 dynamic_bottom: bool = False) -> DesignLoads:
    """EN 1991-4 design loads of a circular silo filled to ``fill_height``.

    Parameters
    ----------
    geometry : siloflow.plan.Silo
        ``kind`` cylinder (flat bottom at z = 0) or hopper (a cone from the outlet at z = 0 up to
        ``hopper_height``); the vertical wall has radius ``radius`` (or ``half_width``).
    material : BulkSolid or str
        a solid from :func:`bulk_solid`, or a name of :data:`MATERIALS`.
    fill_height : float
        the equivalent surface, m above the outlet: the level of a flat surface holding the
        bed's volume (``plan.fill.bed_height_estimate`` is exactly that). h_c = fill_height -
        hopper_height.
    wall_type : str
        D1, D2 or D3 (Annex E's wall friction columns).
    aac : int
        action assessment class 1, 2 or 3 (§2.5); AAC 3 is computed as AAC 2.
    eccentricity : float
        e, m: the filling and outlet eccentricity (e = max(e_f, e_o)); E = 2 e / d_c. A geometry with an
        ``outlet_offset`` larger than it uses that (e_o).
    heights : array, optional
        z values, m above the outlet (default: 161 up the wall, 41 in a hopper).
    top : str
        ``flat``: the free surface is level, the highest wall contact is the equivalent surface
        (h_o = 0), as in siloflow's distributed fills; ``heap``: the standard's symmetrical fill,
        a cone at the angle of repose, h_o = (r/3) tan phi_r below the equivalent surface.
    dynamic_bottom : bool
        use C_b for a solid that may load the bottom dynamically.

    Raises
    ------
    ValueError
        for a planar (slab) geometry, a fill not above the hopper or above the wall, an
        eccentricity not inside the silo, an unknown wall type or class, a missing phi_r.
    """
    solid = bulk_solid(material) if isinstance(material, str) else material
    kind = getattr(geometry, "kind", None)
    standard = SILO_KINDS[kind].en1991 if kind in SILO_KINDS else None
    if standard is None:
        covered = " or ".join(k for k, v in SILO_KINDS.items() if v.en1991)
        raise ValueError(SILO_KINDS[kind].design_refusal(covered) if kind in SILO_KINDS else
                         f"geometry.kind {kind!r}: design loads need kind {covered}")
    _wall_index(wall_type)
    if aac not in (1, 2, 3):
        raise ValueError(f"action assessment class {aac!r} is not 1, 2 or 3")
    if top not in ("flat", "heap"):
        raise ValueError(f"top {top!r} is not 'flat' or 'heap'")
    r = float(geometry.radius if getattr(geometry, "radius", None) is not None else geometry.half_width)
    d_c, transition = 2.0 * r, float(geometry.hopper_height)
    wall_top = transition + float(geometry.height)
    if not fill_height > transition:
        raise ValueError(f"the fill ({fill_height:.4g} m) does not reach above the hopper ({transition:.4g} m): "
                         "the standard's wall loads need a filled vertical wall")
    if fill_height > wall_top * (1 + 1e-9):
        raise ValueError(f"the fill ({fill_height:.4g} m) is above the silo's wall ({wall_top:.4g} m)")
    if not 0.0 <= eccentricity < r:
        raise ValueError(f"eccentricity ({eccentricity} m) must be within the silo (0 <= e < r = {r:.4g} m)")

    notes = []
    e_o = float(getattr(geometry, "outlet_offset", 0.0) or 0.0)
    if e_o > eccentricity:             # (5.22) e = max(e_f, e_o): the silo's own outlet eccentricity
        notes.append(f"e = the outlet's eccentricity e_o = {e_o:.4g} m (geometry.outlet_offset), larger than the "
                     f"given {eccentricity:.4g} m (5.22)")
        eccentricity = e_o
    a_over_u = d_c / 4.0
    h_c = fill_height - transition
    ratio = h_c / d_c
    cls = classify(ratio, flat_bottom=standard == "flat")
    values = characteristic_values(solid, wall_type, a_over_u)
    gamma = solid.gamma
    h_o = 0.0
    if top == "heap":
        if solid.phi_r is None:
            raise ValueError("top 'heap' needs the angle of repose phi_r (give phi_r)")
        h_o = r / 3.0 * math.tan(math.radians(solid.phi_r))
        if h_o >= fill_height - transition:
            raise ValueError(f"a heap at the angle of repose (h_o {h_o:.4g} m) does not fit on a fill of "
                             f"{fill_height - transition:.4g} m above the transition; use top 'flat'")

    z = _default_heights(transition, fill_height, fill_height - h_o) if heights is None else np.asarray(heights, float)
    depth = fill_height - z
    on_wall = z >= transition - 1e-12

    def wall(case):
        v = values[case]
        if cls == "slender":
            out = janssen_filling(depth, gamma, v.K, v.mu, a_over_u)
            contact = depth >= h_o - 1e-12
            out = tuple(np.where(contact, a, 0.0) for a in out[:2]) + (
                np.where(contact, out[2], np.where(depth < 0, 0.0, np.nan)), np.where(contact, out[3], 0.0))
        else:
            if solid.phi_r is None:
                raise ValueError(f"a {cls} silo (h_c/d_c = {ratio:.3g}) needs the angle of repose phi_r "
                                 "(give phi_r)")
            out = squat_filling(depth, gamma, v.K, v.mu, a_over_u, solid.phi_r, h_o)
        return tuple(np.where(on_wall, a, np.nan) for a in out)

    p_hf = wall("max_horizontal")[0]
    _, p_wf, _, n_zsk = wall("max_friction")
    p_vf = wall("max_vertical")[2]
    if cls == "retaining":
        notes.append("retaining silo (h_c/d_c <= 0.4): the squat procedure (§5.3) is used; §5.4's own rules are "
                     "not implemented")
    e_ratio = eccentricity / d_c
    if eccentricity > 0.25 * d_c:
        notes.append("eccentricity above 0.25 d_c: the standard's large-eccentricity discharge (§5.2.4) is "
                     "not implemented")
    C_h, C_w = discharge_factors(cls, ratio, aac, e_ratio, solid.C_op)
    C_pf, C_pe = patch_factors(ratio, solid.C_op, 2.0 * e_ratio, aac)
    if aac == 1:
        notes.append("AAC 1: no patch load; the discharge factors (5.20), (5.21) carry its allowance")
    if aac == 3:
        notes.append("AAC 3 is computed as AAC 2 (its further analyses are not implemented)")
    p_he, p_we = C_h * p_hf, C_w * p_wf
    p_pf, p_pe = C_pf * p_hf, C_pe * p_he

    # the transition: the bottom of the vertical wall (max vertical load case)
    vv = values["max_vertical"]
    C_b = bottom_load_magnifier(aac, dynamic_bottom)
    p_v_transition = wall_vertical_stress(cls, h_c, gamma, vv, a_over_u, solid.phi_r, h_o)
    p_vft = C_b * p_v_transition
    nan = np.full_like(z, np.nan)
    hopper = None
    p_v_hopper, p_nf, p_tf, p_ne, p_te = nan, nan, nan, nan, nan
    if standard == "hopper":
        beta = math.degrees(math.atan((r - geometry.outlet_radius) / transition))
        x_outlet = geometry.outlet_radius / math.tan(math.radians(beta))
        h_h = transition + x_outlet
        hopper = hopper_loads(beta, h_h, x_outlet, vv.K, vv.mu, vv.phi_i, p_vft, C_b)
        inside = (z >= -1e-12) & (z <= transition + 1e-12)
        x = z + x_outlet
        pv_f = hopper_vertical_stress(x, h_h, gamma, hopper.n_f, p_vft)
        pv_e = hopper_vertical_stress(x, h_h, gamma, hopper.n_e, p_vft)
        p_v_hopper = np.where(inside, pv_f, np.nan)
        p_nf = np.where(inside, hopper.F_f * pv_f, np.nan)
        p_tf = hopper.mu_h * p_nf
        p_ne = np.where(inside, hopper.F_e * pv_e, np.nan)
        p_te = hopper.mu_h * p_ne
        if not hopper.steep:
            notes.append(f"shallow hopper (beta {beta:.1f} deg): mobilised friction mu_heff = {hopper.mu_h:.3f}, "
                         "discharge = filling (§6.4)")
    else:
        notes.append(f"flat bottom: p_vsq = C_b p_vf(h_c) = {p_vft:.4g} Pa" + (
            "" if cls == "slender" else " (the squat-silo increment of §6.2.3 is not implemented)"))
    if solid.explicit:
        notes.append("given by hand: " + ", ".join(solid.explicit) + " (used for every load case)")
    return DesignLoads(z=z, depth=depth, p_hf=p_hf, p_wf=p_wf, p_vf=p_vf, p_he=p_he, p_we=p_we, p_pf=p_pf,
                       p_pe=p_pe, p_patch=p_pe, n_zSk=n_zsk, p_v_hopper=p_v_hopper, p_nf=p_nf, p_tf=p_tf,
                       p_ne=p_ne, p_te=p_te, classification=cls, aspect_ratio=ratio, d_c=d_c, h_c=h_c,
                       surface=fill_height, transition=transition, h_o=h_o, top=top, values=values, C_h=C_h,
                       C_w=C_w, C_pf=C_pf, C_pe=C_pe, patch_height=math.pi * d_c / 16.0, C_b=C_b, p_vft=p_vft,
                       hopper=hopper, material=solid, wall_type=wall_type, aac=aac, eccentricity=eccentricity,
                       notes=tuple(notes))


def wall_vertical_stress(classification: str, depth: float, gamma: float, v: LoadCaseValues, a_over_u: float,
                         phi_r: Optional[float], h_o: float) -> float:
    """p_vf (Pa) at ``depth`` below the equivalent surface: (5.3) for slender silos, gamma z_V
    (§5.3.1.1) otherwise."""
    if classification == "slender":
        return float(janssen_filling(depth, gamma, v.K, v.mu, a_over_u)[2])
    return float(squat_filling(depth, gamma, v.K, v.mu, a_over_u, phi_r, h_o)[2])
