"""Janssen fit of a static wall-pressure profile, discharge factors and the comparison with a
measured pressure time series (paper A's Table 3 and Eq. 34).

Janssen, cylinder of diameter D (m), depth z (m) below the free surface:
    p_h(z) = rho_b g D / (4 mu_w) * (1 - exp(-4 mu_w K z / D))        (Pa)
Fitting p_h(z) to band pressures gives the wall friction mu_w from the asymptote and the
lateral pressure ratio K from the length scale D / (4 mu_w K). A profile that has not
saturated (depth << D / (4 mu_w K)) only fixes the product K near the surface
(p_h ~ K rho_b g z): ``saturated`` says which case a fit is in.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.optimize import curve_fit


def janssen_pressure(depth, rho_b: float, g: float, D: float, mu_w: float, K: float):
    """Horizontal wall pressure (Pa) at ``depth`` (m) below the surface."""
    depth = np.maximum(np.asarray(depth, float), 0.0)
    return rho_b * g * D / (4.0 * mu_w) * (1.0 - np.exp(-4.0 * mu_w * K * depth / D))


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
    """Least-squares fit of :func:`janssen_pressure` to band pressures (Pa) at depths (m)."""
    depth = np.asarray(depth, float)
    pressure = np.asarray(pressure, float)
    ok = np.isfinite(depth) & np.isfinite(pressure) & (depth > 0)
    depth, pressure = depth[ok], pressure[ok]
    if len(depth) < 3:
        raise ValueError("a Janssen fit needs at least 3 bands below the free surface")
    slope = float((depth * pressure).sum() / (depth * depth).sum())  # p ~ K rho_b g z near the top
    k0 = max(slope / (rho_b * g), 0.05)

    def model(z, K, mu_w):
        return janssen_pressure(z, rho_b, g, D, mu_w, K)

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
