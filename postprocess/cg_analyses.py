"""Paper B's analyses on axisymmetric coarse-grained fields (an xarray Dataset from
:class:`postprocess.coarse_grain.CoarseGraining` on an (r, z) grid).

* outlet profiles phi(r), v_z(r) at the outlet height, normalised by their centre values,
  against r/R, with the Janda et al. (2012) form v_z(r)/v_z(0) = sqrt(1 - (r/R)^2);
* v_z(0) against R across runs: a power-law fit (paper B: exponent 1/2);
* axial profiles (on the axis, r -> 0) of contact and kinetic pressure; the height h_c of the
  kinetic-pressure maximum above the outlet;
* kinetic pressure by particle size: partial kinetic pressures, their cumulative sum over sizes
  larger than r', and the partial kinetic pressure per partial solid fraction.

Their figures are drawn by the report layer (``postprocess.report.cg``).
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.optimize import curve_fit


def _axis_column(ds, var):
    """Values of ``var`` in the innermost radial column (r = dr/2), as a function of z."""
    return ds[var].isel(r=0)


def outlet_profiles(ds, z_outlet: float, outlet_radius: float) -> pd.DataFrame:
    """phi(r), v_z(r) at the grid row nearest ``z_outlet`` (m), for r < outlet radius R (m):
    columns r, r_over_R, solid_fraction, v_z, and both normalised by their value at r -> 0,
    plus the Janda form sqrt(1 - (r/R)^2)."""
    row = ds.sel(z=z_outlet, method="nearest")
    r = ds.r.values
    inside = r < outlet_radius
    phi = row.solid_fraction.values[inside] if "solid_fraction" in ds else row.rho.values[inside]
    vz = row.velocity.sel(component="z").values[inside]
    x = r[inside] / outlet_radius
    return pd.DataFrame({"z": float(row.z), "r": r[inside], "r_over_R": x, "solid_fraction": phi, "v_z": vz,
                         "phi_over_phi0": phi / phi[0], "vz_over_vz0": vz / vz[0],
                         "janda": np.sqrt(np.clip(1.0 - x * x, 0.0, None))})


def power_law_fit(x, y):
    """y = a x^b by least squares in log space: (a, b, b_stderr)."""
    lx, ly = np.log(np.asarray(x, float)), np.log(np.abs(np.asarray(y, float)))
    if len(lx) < 3:
        (b, la) = np.polyfit(lx, ly, 1)
        return float(np.exp(la)), float(b), float("nan")
    (b, la), cov = np.polyfit(lx, ly, 1, cov=True)
    return float(np.exp(la)), float(b), float(np.sqrt(cov[0, 0]))


def janda_fit(profile: pd.DataFrame) -> dict:
    """Fit v_z(r) = v0 (1 - (r/R)^2)^n to an outlet profile: n (Janda: 1/2) and the rms misfit
    of the n = 1/2 form."""
    x, v = profile.r_over_R.to_numpy(), profile.v_z.to_numpy()
    keep = x < 0.95

    def model(x, v0, n):
        return v0 * np.clip(1 - x * x, 1e-12, None) ** n

    (v0, n), cov = curve_fit(model, x[keep], v[keep], p0=[v[0], 0.5], maxfev=10000)
    rms = float(np.sqrt(np.mean((profile.vz_over_vz0.to_numpy()[keep] - profile.janda.to_numpy()[keep]) ** 2)))
    return {"v0": float(v0), "exponent": float(n), "exponent_stderr": float(np.sqrt(cov[1, 1])),
            "rms_misfit_of_sqrt_form": rms}


def axial_profiles(ds, z_outlet: float = 0.0) -> pd.DataFrame:
    """On the axis: z, height above the outlet, contact and kinetic pressure (Pa), solid fraction, v_z."""
    out = pd.DataFrame({"z": ds.z.values, "height": ds.z.values - z_outlet,
                        "kinetic_pressure": _axis_column(ds, "kinetic_pressure").values,
                        "v_z": ds.velocity.isel(r=0).sel(component="z").values})
    if "contact_pressure" in ds:
        out["contact_pressure"] = _axis_column(ds, "contact_pressure").values
    if "solid_fraction" in ds:
        out["solid_fraction"] = _axis_column(ds, "solid_fraction").values
    return out


def kinetic_peak_height(axial: pd.DataFrame, z_min: float | None = None) -> float:
    """h_c: height above the outlet (m) of the kinetic-pressure maximum on the axis, above ``z_min``."""
    sel = axial if z_min is None else axial[axial.z >= z_min]
    if sel.empty or not np.isfinite(sel.kinetic_pressure).any():
        return float("nan")
    return float(sel.height.iloc[int(np.nanargmax(sel.kinetic_pressure.to_numpy()))])


def species_kinetic_table(ds, z_outlet: float, height: float | None = None) -> pd.DataFrame:
    """Per size class on the axis at ``height`` above the outlet (default: where the total
    kinetic pressure peaks): partial kinetic pressure, partial solid fraction, their ratio
    normalised by the total's (p_a/phi_a)/(p/phi), and the cumulative kinetic pressure of all
    classes at least as large (sum over r >= r')."""
    if "kinetic_pressure_species" not in ds:
        raise ValueError("the fields have no species (coarse-grain with species='radius')")
    axial = axial_profiles(ds, z_outlet)
    h = kinetic_peak_height(axial, z_outlet) if height is None else height
    col = ds.isel(r=0).sel(z=z_outlet + h, method="nearest")
    sizes = np.asarray(ds.species.values, float)
    pk = col.kinetic_pressure_species.values
    phi_a = col.solid_fraction_species.values if "solid_fraction_species" in ds else col.rho_species.values
    phi = float(col.solid_fraction) if "solid_fraction" in ds else float(col.rho)
    order = np.argsort(sizes)[::-1]
    cumulative = np.empty_like(pk)
    cumulative[order] = np.cumsum(pk[order])
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = (pk / phi_a) / (float(col.kinetic_pressure) / phi)
    return pd.DataFrame({"radius": sizes, "height": h, "kinetic_pressure": pk, "solid_fraction": phi_a,
                         "cumulative_kinetic_pressure_larger_or_equal": cumulative,
                         "kinetic_per_solid_fraction_relative": ratio})
