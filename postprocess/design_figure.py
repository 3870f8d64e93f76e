"""EN 1991-4 design loads beside the DEM's band pressures: the figure and the comparison table.

``loads`` is a :class:`siloflow.design_loads.DesignLoads`; ``bands`` the run's ``bands.csv``
(columns z_mid (m above the outlet), static_pressure and max_dynamic_pressure, Pa).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from .figures import plt, save_figure

#: the columns of :func:`compare_with_dem`
COMPARISON_COLUMNS = ("band", "z_mid", "depth", "en_p_hf", "en_p_he", "dem_static", "dem_max_dynamic",
                      "static_over_p_hf", "max_dynamic_over_p_he", "dem_discharge_factor", "en_C_h")


def compare_with_dem(loads, bands: pd.DataFrame) -> pd.DataFrame:
    """Per band: EN p_hf and p_he at the band centre z_mid (Pa), the DEM's static and maximum
    dynamic pressure, their ratios (DEM static / p_hf, DEM max dynamic / p_he; NaN where EN gives
    no pressure, above the fill or below the wall's foot), and the DEM's discharge factor (max
    dynamic / static) next to EN's C_h."""
    z = np.asarray(bands["z_mid"], float)
    static = np.asarray(bands["static_pressure"], float)
    dynamic = np.asarray(bands["max_dynamic_pressure"], float)
    p_hf, p_he = loads.at("p_hf", z), loads.at("p_he", z)
    outside = (z < loads.transition) | (z > loads.surface)
    p_hf, p_he = np.where(outside, np.nan, p_hf), np.where(outside, np.nan, p_he)

    def ratio(a, b):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(np.isfinite(b) & (b > 0), a / b, np.nan)

    band = bands["band"].to_numpy() if "band" in bands else np.arange(len(z))
    return pd.DataFrame({"band": band, "z_mid": z, "depth": loads.surface - z, "en_p_hf": p_hf, "en_p_he": p_he,
                         "dem_static": static, "dem_max_dynamic": dynamic,
                         "static_over_p_hf": ratio(static, p_hf), "max_dynamic_over_p_he": ratio(dynamic, p_he),
                         "dem_discharge_factor": ratio(dynamic, static), "en_C_h": loads.C_h},
                        columns=list(COMPARISON_COLUMNS))


def design_plot(loads, dem_bands: pd.DataFrame | None = None):
    """Pressures (Pa) against height (m above the outlet): EN filling and discharge normal
    pressure, discharge plus patch, wall friction and mean vertical stress on the vertical wall,
    the hopper's normal pressures, and (``dem_bands``) the DEM's static and maximum dynamic band
    pressures as points. Returns the Figure."""
    fig, ax = plt.subplots(figsize=(6.4, 5.2))
    z = loads.z
    ax.plot(loads.p_hf, z, color="C0", label="EN p_hf (filling)")
    ax.plot(loads.p_he, z, color="C1", label=f"EN p_he = {loads.C_h:.3g} p_hf (discharge)")
    if np.nanmax(np.nan_to_num(loads.p_patch)) > 0:
        ax.plot(loads.p_he + loads.p_patch, z, color="C1", ls="--", lw=0.9,
                label=f"EN p_he + p_pe (patch, C_pe {loads.C_pe:.3g})")
    ax.plot(loads.p_wf, z, color="C2", lw=0.9, label="EN p_wf (wall friction)")
    ax.plot(loads.p_vf, z, color="0.5", ls=":", label="EN p_vf (vertical)")
    if loads.hopper is not None:
        ax.plot(loads.p_nf, z, color="C4", label="EN hopper p_nf (filling)")
        ax.plot(loads.p_ne, z, color="C4", ls="--", label="EN hopper p_ne (discharge)")
        ax.axhline(loads.transition, color="k", lw=0.6, ls="-.")
    if dem_bands is not None and len(dem_bands):
        ax.plot(dem_bands.static_pressure, dem_bands.z_mid, "o", color="C0", mfc="none", label="DEM static")
        ax.plot(dem_bands.max_dynamic_pressure, dem_bands.z_mid, "s", color="C1", mfc="none",
                label="DEM max during discharge")
    ax.axhline(loads.surface, color="k", lw=0.6, ls=":")
    ax.set(xlabel="pressure (Pa)", ylabel="height above the outlet (m)", ylim=(0, loads.surface * 1.05),
           title=f"EN 1991-4: {loads.material.name}, {loads.wall_type}, AAC {loads.aac}, "
                 f"{loads.classification} (h_c/d_c {loads.aspect_ratio:.2f})")
    ax.title.set_fontsize(9)
    ax.set_xlim(left=0)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def design_figure(loads, path, dem_bands: pd.DataFrame | None = None):
    """:func:`design_plot` written to ``path``; returns the path."""
    save_figure(design_plot(loads, dem_bands), path)
    return path
