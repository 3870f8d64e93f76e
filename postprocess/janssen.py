"""Janssen fits of a static wall-pressure profile, discharge factors and the comparison with a
measured pressure time series (paper A's Table 3 and Eq. 34).

Janssen, cylinder of diameter D (m) (a slab: D = 4 A / P, ``dump_results.janssen_diameter``),
depth d (m) below the free surface:
    p(d) = rho_b g D / (4 mu) * (1 - exp(-d / L)),   L = D / (4 mu K)        (Pa)
with K the lateral pressure ratio and mu the wall friction the bed actually mobilises (mu_eff:
a poured bed need not mobilise the wall's Coulomb friction mu_w, Landry et al. PRE 67, 041303).

**Band-true fit** (:func:`fit_janssen_bands`, what ``siloflow post`` reports). A pressure band
is a sensor over heights z0..z1 (m) that reads its force over its whole area, so the model value
of a band, with the free surface at h, is the model averaged over the band's whole height with
zero pressure above the surface:

    p_band = 1 / (z1 - z0) * integral_{z0}^{min(z1, h)} p(h - z) dz
           = 1 / (z1 - z0) * integral_{a}^{b} p(d) dd,   a = max(h - z1, 0), b = max(h - z0, 0)

(a band wholly above the surface reads 0 and is not used). For Janssen, with
F(x) = x - (1 - exp(-x)) = integral_0^x (1 - e^-s) ds,

    integral_a^b p(d) dd = rho_b g D / (4 mu) * L * (F(b / L) - F(a / L))

and for the hydrostatic comparison p = K rho_b g d: K rho_b g (b^2 - a^2) / 2. F is evaluated
by its series below x = 1e-3, so the hydrostatic limit mu -> 0 stays exact. K and mu_eff are
fitted by least squares (bounds K in (0, 3], mu_eff in (0, 2]); their 95 % intervals are
t(0.975, n - 2) times the standard errors of the linearised covariance. The corner band (the
one whose bottom z0 is the floor, the hopper's top: the floor's corner stresses are not
Janssen's) is left out by default. A fit says whether it is ``resolved`` and, if not, why
(``flags``): K outside 0.2-1.0 beyond its interval, a mobilisation mu_eff / mu_w above 1 beyond its interval,
fewer than 3 loaded bands, an interval half-width above 50 % of its value, a parameter on its
bound.

:func:`fit_janssen` is the older fit of the model at each band's centre (kept for existing
callers and comparisons; it mis-models bands cut by the surface and the corner band).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import stats
from scipy.optimize import curve_fit, least_squares

from siloflow.design_loads import janssen_pressure

#: bounds of the band-true fit's parameters (lower ends: open, approximated by LOWER)
K_MAX, MU_MAX, LOWER = 3.0, 2.0, 1e-6
#: K of a poured granular bed lies in this range; outside it a fit is flagged
K_PLAUSIBLE = (0.2, 1.0)
#: a fit needs at least this many loaded bands (two parameters, and one degree of freedom left)
MIN_BANDS = 3
#: a parameter whose 95 % interval's half-width exceeds this fraction of its value is not resolved
MAX_RELATIVE_HALF_WIDTH = 0.5


def _ramp(x):
    """F(x) = x - (1 - exp(-x)) = integral_0^x (1 - e^-s) ds, to round-off also for small x
    (series x^2/2 - x^3/6 + x^4/24 - x^5/120 below 1e-3: truncation < 1e-15 relative)."""
    x = np.asarray(x, float)
    series = x * x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x / 120.0)))
    return np.where(x < 1e-3, series, x + np.expm1(-np.where(x < 1e-3, 1.0, x)))


def janssen_depth_integral(a, b, rho_b: float, g: float, D: float, mu: float, K: float):
    """integral_a^b p(d) dd of Janssen's pressure over depths a..b (m, 0 <= a <= b): Pa m.

    rho_b g D / (4 mu) * L * (F(b / L) - F(a / L)), L = D / (4 mu K), F(x) = x - 1 + exp(-x)."""
    a = np.maximum(np.asarray(a, float), 0.0)
    b = np.maximum(np.asarray(b, float), 0.0)
    L = D / (4.0 * mu * K)
    return rho_b * g * D / (4.0 * mu) * L * (_ramp(b / L) - _ramp(a / L))


def _loaded_depths(z0, z1, surface: float):
    """The depth range a..b (m) of each band's part below the surface h, and 1 / (z1 - z0)."""
    z0, z1 = np.asarray(z0, float), np.asarray(z1, float)
    return np.maximum(surface - z1, 0.0), np.maximum(surface - z0, 0.0), 1.0 / (z1 - z0)


def band_janssen_pressure(z0, z1, surface: float, rho_b: float, g: float, D: float, mu: float, K: float):
    """Janssen's pressure (Pa) as bands z0..z1 (m) read it with the free surface at ``surface``
    (m): the average over the band's whole height, zero above the surface (module docstring)."""
    a, b, inv = _loaded_depths(z0, z1, surface)
    return inv * janssen_depth_integral(a, b, rho_b, g, D, mu, K)


def _band_janssen_jacobian(z0, z1, surface: float, rho_b: float, g: float, D: float, mu: float, K: float):
    """d p_band / d K and d p_band / d mu (columns), from the closed form: with C = rho_b g D^2 / 16,
    A L = C / (mu^2 K), x = d / L = 4 mu K d / D, F'(x) = 1 - e^-x and G(x) = x F'(x):
    d/dK = A L / K (dG - dF), d/dmu = A L / mu (dG - 2 dF), dF = F(x_b) - F(x_a), likewise dG."""
    a, b, inv = _loaded_depths(z0, z1, surface)
    L = D / (4.0 * mu * K)
    xa, xb = a / L, b / L
    dF = _ramp(xb) - _ramp(xa)
    dG = -xb * np.expm1(-xb) + xa * np.expm1(-xa)
    AL = rho_b * g * D * D / (16.0 * mu * mu * K)
    return np.column_stack([inv * AL / K * (dG - dF), inv * AL / mu * (dG - 2.0 * dF)])


def band_hydrostatic_pressure(z0, z1, surface: float, rho_b: float, g: float, K: float):
    """The hydrostatic p = K rho_b g d (Pa) averaged over bands the same way: K rho_b g (b^2 - a^2) / 2 / (z1 - z0)."""
    a, b, inv = _loaded_depths(z0, z1, surface)
    return inv * K * rho_b * g * 0.5 * (b * b - a * a)


@dataclass
class JanssenBandFit:
    """The band-true Janssen fit of a static profile (:func:`fit_janssen_bands`).

    K: lateral pressure ratio; mu_eff: the wall friction the profile mobilises; ``*_stderr``
    their standard errors and ``*_ci`` their 95 % intervals [low, high] (t-distribution, n - 2
    degrees of freedom, low end clipped at 0; NaN without one); mu_w: the wall's Coulomb friction (the case's
    particle-wall friction); mobilisation = mu_eff / mu_w with its interval; length =
    D / (4 mu_eff K) (m) and asymptote = rho_b g D / (4 mu_eff) (Pa); r2 of the band values;
    depth_over_length: the deepest loaded depth over ``length`` (below ~1 the profile has not
    levelled off and mu_eff is weakly fixed); hydrostatic_*: p = K rho_b g d fitted the same
    way; surface_height (m), diameter D (m), exclude_corner; bands_used, bands_excluded (band,
    reason); resolved, and the reasons it is not (flags; reason: them joined).
    """

    K: float
    K_stderr: float
    K_ci: list
    mu_eff: float
    mu_eff_stderr: float
    mu_eff_ci: list
    mu_w: float
    mobilisation: float
    mobilisation_ci: list
    length: float
    asymptote: float
    r2: float
    depth_over_length: float
    hydrostatic_K: float
    hydrostatic_K_ci: list
    hydrostatic_r2: float
    n_bands_used: int
    bands_used: list
    bands_excluded: list
    surface_height: float
    diameter: float
    exclude_corner: bool
    resolved: bool
    flags: list = field(default_factory=list)
    reason: str = ""
    model: str = "band-averaged Janssen, cut at the free surface"


def _r2(residual, values) -> float:
    ss_tot = float(((values - values.mean()) ** 2).sum()) if len(values) else 0.0
    return 1.0 - float((residual ** 2).sum()) / ss_tot if ss_tot > 0 else float("nan")


def _interval(value: float, stderr: float, dof: int) -> list:
    """value -/+ t(0.975, dof) stderr, the low end clipped at 0 (every parameter here is > 0)."""
    if dof < 1 or not np.isfinite(stderr):
        return [float("nan"), float("nan")]
    half = float(stats.t.ppf(0.975, dof)) * stderr
    return [max(float(value - half), 0.0), float(value + half)]


def fit_janssen_bands(z0, z1, pressure, surface: float, rho_b: float, D: float, mu_w: float,
                      g: float = 9.81, floor: float | None = None, exclude_corner: bool = True,
                      bands=None) -> JanssenBandFit:
    """Fit K and mu_eff of Janssen's profile, averaged over each band as a sensor reads it.

    Parameters
    ----------
    z0, z1 : bottom and top of each band (m).
    pressure : each band's static pressure (Pa, its force over its whole area).
    surface : the measured free-surface height h (m); depth is h - z.
    rho_b : bulk density (kg/m3); D : Janssen's diameter (m; 4 A / P for a slab).
    mu_w : the wall's Coulomb friction, for the mobilisation mu_eff / mu_w.
    g : gravity (m/s2).
    floor : height (m) of the floor the bands stand on (the hopper's top); with
        ``exclude_corner`` the band whose bottom is there is left out.
    bands : the bands' numbers (default 0, 1, ...), for ``bands_used`` and ``bands_excluded``.

    Returns
    -------
    JanssenBandFit. A profile that cannot be fitted (fewer than 2 usable bands) is returned with
    NaN parameters, ``resolved`` False and the reason in ``flags``; nothing is raised for it.

    Raises
    ------
    ValueError : the arrays differ in length, or a band has z1 <= z0.
    """
    z0, z1, p = (np.atleast_1d(np.asarray(x, float)) for x in (z0, z1, pressure))
    ids = np.arange(len(p)) if bands is None else np.asarray(bands)
    if not (len(z0) == len(z1) == len(p) == len(ids)):
        raise ValueError("z0, z1, pressure and bands must have one entry per band")
    if np.any(~(z1 > z0)):
        raise ValueError("every band needs z1 > z0")
    nan = float("nan")
    excluded, use = [], np.zeros(len(p), bool)
    for k in range(len(p)):
        tol = 1e-9 + 1e-6 * (z1[k] - z0[k])
        if not z0[k] < surface:
            why = f"above the free surface (z0 = {z0[k]:.4g} m >= h = {surface:.4g} m)"
        elif not np.isfinite(p[k]):
            why = "no pressure measured"
        elif exclude_corner and floor is not None and abs(z0[k] - floor) <= tol:
            why = f"corner band (its bottom is the floor, z = {floor:.4g} m)"
        else:
            use[k] = True
            continue
        excluded.append({"band": int(ids[k]), "reason": why})
    zu0, zu1, pu = z0[use], z1[use], p[use]
    n = int(use.sum())
    flags: list[str] = []
    if n < MIN_BANDS:
        flags.append(f"only {n} loaded band(s) used, fewer than {MIN_BANDS}"
                     + (" (the corner band is excluded)" if exclude_corner and any(
                         e["reason"].startswith("corner") for e in excluded) else ""))

    # hydrostatic comparison: linear in K
    q = band_hydrostatic_pressure(zu0, zu1, surface, rho_b, g, 1.0)
    if n >= 1 and float(q @ q) > 0:
        k_h = float(q @ pu / (q @ q))
        res_h = pu - k_h * q
        se_h = float(np.sqrt((res_h @ res_h) / (n - 1) / (q @ q))) if n > 1 else nan
        hyd = (k_h, _interval(k_h, se_h, n - 1), _r2(res_h, pu))
    else:
        hyd = (nan, [nan, nan], nan)

    common = dict(mu_w=float(mu_w), hydrostatic_K=hyd[0], hydrostatic_K_ci=hyd[1], hydrostatic_r2=hyd[2],
                  n_bands_used=n, bands_used=[int(b) for b in ids[use]], bands_excluded=excluded,
                  surface_height=float(surface), diameter=float(D), exclude_corner=bool(exclude_corner))
    if n < 2:
        flags.append("too few bands to fit two parameters")
        return JanssenBandFit(nan, nan, [nan, nan], nan, nan, [nan, nan], mobilisation=nan,
                              mobilisation_ci=[nan, nan], length=nan, asymptote=nan, r2=nan,
                              depth_over_length=nan, resolved=False, flags=flags, reason="; ".join(flags), **common)

    def residual(x):
        return band_janssen_pressure(zu0, zu1, surface, rho_b, g, D, x[1], x[0]) - pu

    def jacobian(x):
        return _band_janssen_jacobian(zu0, zu1, surface, rho_b, g, D, x[1], x[0])

    k_start = float(np.clip(hyd[0], 0.05, K_MAX * 0.9)) if np.isfinite(hyd[0]) else 0.5
    best = None
    for K0 in sorted({k_start, 0.4, 1.5}):
        for mu0 in (0.03, 0.3, 1.2):
            r = least_squares(residual, [K0, mu0], jac=jacobian, bounds=([LOWER, LOWER], [K_MAX, MU_MAX]),
                              x_scale=[0.5, 0.3], xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=500)
            if best is None or r.cost < best.cost:
                best = r
    K, mu = (float(v) for v in best.x)
    res = best.fun
    dof = n - 2
    err = [nan, nan]
    if dof >= 1:
        J = best.jac
        try:
            cov = np.linalg.inv(J.T @ J) * float(res @ res) / dof
            err = [float(np.sqrt(c)) if c >= 0 else nan for c in np.diag(cov)]
        except np.linalg.LinAlgError:
            pass
    K_ci, mu_ci = _interval(K, err[0], dof), _interval(mu, err[1], dof)
    mob, mob_ci = (mu / mu_w, [c / mu_w for c in mu_ci]) if mu_w > 0 else (nan, [nan, nan])
    length = D / (4.0 * mu * K)
    deepest = float(np.max(np.maximum(surface - zu0, 0.0)))

    # what makes the fit not usable, each with its numbers
    at_bound = set()
    for name, value, hi in (("K", K, K_MAX), ("mu_eff", mu, MU_MAX)):
        if value >= hi * (1 - 1e-4):
            at_bound.add(name)
            flags.append(f"{name} = {value:.3g} is at the fit's upper bound {hi:g}")
        elif value <= LOWER * 10:
            at_bound.add(name)
            flags.append(f"{name} fell to the fit's lower bound (0)" + (
                f": the profile is hydrostatic, no wall friction is measurable (hydrostatic K = {hyd[0]:.3g}, "
                f"r2 {hyd[2]:.3f})" if name == "mu_eff" else ""))
    # like the mobilisation below: implausible when the whole 95 % interval is outside the range
    # (a K of 1.0 [0.7, 1.3] is a bed at the top of the range, not an implausible one)
    k_lo, k_hi = (K_ci[0], K_ci[1]) if all(np.isfinite(K_ci)) else (K, K)
    if k_hi < K_PLAUSIBLE[0] or k_lo > K_PLAUSIBLE[1]:
        flags.append(f"K = {K:.3g} (95 % CI {k_lo:.3g}-{k_hi:.3g}) is outside the physical range "
                     f"{K_PLAUSIBLE[0]:g}-{K_PLAUSIBLE[1]:g} of a granular bed")
    mob_low = mob_ci[0] if np.isfinite(mob_ci[0]) else mob
    if mob_low > 1.0:
        flags.append(f"mobilisation mu_eff / mu_w = {mob:.3g} (95 % CI {mob_ci[0]:.3g}-{mob_ci[1]:.3g}) "
                     f"exceeds 1: the wall (mu_w = {mu_w:g}) cannot carry that much friction")
    if dof < 1:
        flags.append("no confidence interval: as many parameters as bands")
    else:
        for name, value, ci in (("K", K, K_ci), ("mu_eff", mu, mu_ci)):
            half = ci[1] - value          # the interval's upper half: its low end may be clipped at 0
            if name in at_bound:
                continue
            if not np.isfinite(half):
                flags.append(f"{name} is not identified by the profile (singular covariance)")
            elif half > MAX_RELATIVE_HALF_WIDTH * abs(value):
                flags.append(f"{name} not resolved: 95 % CI +/- {half:.3g} is {half / abs(value):.0%} of "
                             f"{value:.3g} (more than {MAX_RELATIVE_HALF_WIDTH:.0%})")
    return JanssenBandFit(K, err[0], K_ci, mu, err[1], mu_ci, mobilisation=mob, mobilisation_ci=mob_ci,
                          length=float(length), asymptote=float(rho_b * g * D / (4.0 * mu)), r2=_r2(res, pu),
                          depth_over_length=deepest / length, resolved=not flags, flags=flags,
                          reason="; ".join(flags), **common)


@dataclass
class JanssenFit:
    """K and mu_w with standard errors; ``length`` = D/(4 mu_w K) (m); ``asymptote`` (Pa);
    ``saturated``: the deepest point lies beyond one decay length."""

    K: float
    K_stderr: float
    mu_w: float
    mu_w_stderr: float
    length: float
    asymptote: float
    r2: float
    saturated: bool
    n_points: int


def fit_janssen(depth, pressure, rho_b: float, D: float, g: float = 9.81) -> JanssenFit:
    """Least-squares fit of Janssen's law (``siloflow.design_loads.janssen_pressure``, gamma =
    rho_b g, A/U = D/4) to pressures (Pa) at points ``depth`` (m).

    The older point fit: a band is taken as a point at its centre, so a band cut by the free
    surface or the floor corner distorts it. Use :func:`fit_janssen_bands` for sensor bands."""
    depth = np.asarray(depth, float)
    pressure = np.asarray(pressure, float)
    ok = np.isfinite(depth) & np.isfinite(pressure) & (depth > 0)
    depth, pressure = depth[ok], pressure[ok]
    if len(depth) < 3:
        raise ValueError("a Janssen fit needs at least 3 bands below the free surface")
    slope = float((depth * pressure).sum() / (depth * depth).sum())  # p ~ K rho_b g z near the top
    k0 = max(slope / (rho_b * g), 0.05)

    def model(z, K, mu_w):
        return janssen_pressure(z, rho_b * g, K, mu_w, D / 4.0)

    best = None
    for mu0 in (0.1, 0.3, 0.6, 1.0):
        try:
            popt, pcov = curve_fit(model, depth, pressure, p0=[k0, mu0], bounds=([1e-3, 1e-3], [20.0, 20.0]),
                                   maxfev=20000)
        except RuntimeError:
            continue
        cost = float(((model(depth, *popt) - pressure) ** 2).sum())
        if best is None or cost < best[0]:
            best = (cost, popt, pcov)
    if best is None:
        raise ValueError("the Janssen fit did not converge")
    cost, (K, mu_w), pcov = best
    err = np.sqrt(np.clip(np.diag(pcov), 0, None)) if np.all(np.isfinite(pcov)) else [np.nan, np.nan]
    ss_tot = float(((pressure - pressure.mean()) ** 2).sum())
    length = D / (4.0 * mu_w * K)
    return JanssenFit(float(K), float(err[0]), float(mu_w), float(err[1]), float(length),
                      float(rho_b * g * D / (4.0 * mu_w)), 1.0 - cost / ss_tot if ss_tot > 0 else float("nan"),
                      bool(depth.max() > length), int(len(depth)))


def pressure_error_w(sim_time, sim_pressure, meas_time, meas_pressure) -> float:
    """Paper A's Eq. 34: W = (1/n) sum |p_A - p_B| / |p_B| over the n measured samples, the
    simulated series p_A linearly interpolated to the measured times t_B; samples with p_B = 0
    or outside the simulated time range are left out."""
    st = np.asarray(sim_time, float)
    sp = np.asarray(sim_pressure, float)
    mt = np.asarray(meas_time, float)
    mp = np.asarray(meas_pressure, float)
    order = np.argsort(st)
    st, sp = st[order], sp[order]
    keep = (mt >= st[0]) & (mt <= st[-1]) & (mp != 0) & np.isfinite(mp)
    if not keep.any():
        raise ValueError("the measured and simulated pressure series do not overlap in time")
    pa = np.interp(mt[keep], st, sp)
    return float(np.mean(np.abs(pa - mp[keep]) / np.abs(mp[keep])))


def compare_with_measurement(bands: pd.DataFrame, measured: pd.DataFrame, t_open: float) -> pd.DataFrame:
    """Table 3 style comparison per band: measured and simulated maximum dynamic pressure (Pa),
    their relative difference, and W (Eq. 34).

    ``bands``: tidy band pressures (columns time, band, pressure) of a run. ``measured``: a
    table with a ``time`` column (s since the outlet opened) and one column ``band_<k>`` (Pa)
    per monitored band.
    """
    if "time" not in measured:
        raise ValueError("the measured pressure table needs a 'time' column (s since opening)")
    rows = []
    for col in measured.columns:
        if col == "time":
            continue
        if not col.startswith("band_") or not col[5:].isdigit():
            raise ValueError(f"measured column {col!r}: name columns band_<k> after the run's bands")
        band = int(col[5:])
        sim = bands[(bands.band == band) & (bands.time >= t_open)]
        if sim.empty:
            raise ValueError(f"measured column {col!r}: the run has no band {band}")
        sim_max = float(sim.pressure.max())
        meas_max = float(measured[col].max())
        rows.append({"band": band, "max_measured_Pa": meas_max, "max_simulated_Pa": sim_max,
                     "relative_difference": (sim_max - meas_max) / meas_max,
                     "W": pressure_error_w(sim.time - t_open, sim.pressure, measured.time, measured[col])})
    return pd.DataFrame(rows)
