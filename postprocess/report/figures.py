"""Figures (matplotlib, Agg backend) drawn from analyses' results: the ``*_plot`` functions draw
and return a ``matplotlib.figure.Figure``, the ``*_figure`` ones write it atomically
(:func:`save_figure`). :func:`analysis_figure` is a frame analysis' figure; the first-results
panels, the force chains and EN 1991-4's loads beside the DEM's bands are a run's."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.collections import LineCollection, PatchCollection  # noqa: E402
from matplotlib.colors import TwoSlopeNorm  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from siloflow.atomic_files import atomic_path  # noqa: E402

from ..any_dump import FrameSummary  # noqa: E402
from ..coordination import Coordination  # noqa: E402
from ..flow_rate import FreeSurface  # noqa: E402
from ..force_chains import ForceChains, force_chains  # noqa: E402
from ..porosity import Porosity  # noqa: E402


def save_figure(fig, path, dpi: int = 130) -> None:
    """Write ``fig`` to ``path`` (format from the suffix) atomically (``siloflow.atomic_files.atomic_path``)
    and close it."""
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=path.suffix[1:].lower() or "png", dpi=dpi)
    finally:
        plt.close(fig)


def first_results_plot(bands, discharge, band_table, t_open: float):
    """Pressure per band vs time (left), static/max-dynamic profile (middle), discharged mass (right);
    a run without wall-pressure sensors (``bands`` None) gets the discharge only. Returns the Figure."""
    if bands is None:
        fig, ax3 = plt.subplots(figsize=(6, 4.5))
        _discharge_panel(ax3, discharge, t_open)
        fig.tight_layout()
        return fig
    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(15, 4.5))
    cmap = plt.get_cmap("viridis")
    nb = max(1, bands.band.nunique())
    for b, grp in bands.groupby("band"):
        ax1.plot(grp.time, grp.pressure, lw=0.9, color=cmap(b / max(1, nb - 1)),
                 label=f"band {b} (z = {grp.z_mid.iloc[0] * 100:.1f} cm)")
    ax1.axvline(t_open, color="k", ls="--", lw=0.8)
    ax1.set(xlabel="time (s)", ylabel="normal wall pressure (Pa)", title="wall pressure per band")
    ax1.legend(fontsize=7)
    ax2.plot(band_table.static_pressure, band_table.z_mid * 100, "o-", label="static (settled)")
    ax2.plot(band_table.max_dynamic_pressure, band_table.z_mid * 100, "s--", label="max during discharge")
    ax2.set(xlabel="normal wall pressure (Pa)", ylabel="height of band centre (cm)", title="pressure profile")
    ax2.legend(fontsize=8)
    _discharge_panel(ax3, discharge, t_open)
    fig.tight_layout()
    return fig


def _discharge_panel(ax, discharge, t_open: float) -> None:
    """Mass through the outlet and in the silo (g) against time (s)."""
    ax.plot(discharge.time, discharge.outlet_mass * 1000, label="through the outlet")
    ax.plot(discharge.time, discharge.mass_in_silo * 1000, label="in the silo")
    ax.axvline(t_open, color="k", ls="--", lw=0.8)
    ax.set(xlabel="time (s)", ylabel="mass (g)", title="discharge")
    ax.legend(fontsize=8)


def line_plot(table, x: str, y, hue: str | None = None, xlabel: str = "", ylabel: str = "",
              title: str = "", logy: bool = False):
    """One line per ``hue`` group (or per column when ``y`` is a list); returns the Figure."""
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    if hue is not None:
        for key, grp in table.groupby(hue):
            ax.plot(grp[x], grp[y], marker=".", lw=1, label=str(key))
    else:
        for col in ([y] if isinstance(y, str) else y):
            ax.plot(table[x], table[col], marker=".", lw=1, label=col)
    if logy:
        ax.set_yscale("log")
    ax.set(xlabel=xlabel or x, ylabel=ylabel or str(y), title=title)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def sector_plot(sectors: pd.DataFrame):
    """Each band's dynamic mean wall pressure (Pa, with its batch-means error) against the sensor's
    azimuth (deg; a box's walls at 180, 0, 270, 90): the circumferential variation an eccentric
    outlet makes. ``sectors``: sectors.csv. Returns the Figure."""
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for band, grp in sectors.groupby("band"):
        if not (grp.dynamic_mean_pressure > 0).any():
            continue
        grp = grp.sort_values("azimuth_deg")
        ax.errorbar(grp.azimuth_deg, grp.dynamic_mean_pressure, yerr=grp.dynamic_mean_stderr, marker="o", ms=3,
                    lw=1, capsize=2, label=f"band {band} (z = {grp.z_mid.iloc[0]:.3g} m)")
    ax.set(xlabel="sensor azimuth (deg; the outlet's side at 0 on a cylinder)",
           ylabel="dynamic mean wall pressure (Pa)", title="Wall pressure around the silo during discharge")
    ax.set_xticks(range(0, 361, 45))
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


#: a flat wall's name by the direction of its normal (deg): the side of the silo it closes
FACE_NAMES = {0: "+x wall", 90: "+y wall", 180: "-x wall", 270: "-y wall"}


def _wall_cells(sectors: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, list, str]:
    """Each sector's cell on the unrolled wall: x0..x1 (a cylinder's arc in degrees; a flat wall one unit
    wide, in the order of its normal's azimuth), the x tick positions and labels, and the x axis' label."""
    if sectors.arc_deg.notna().all():
        x0 = (sectors.azimuth_deg - sectors.arc_deg / 2).to_numpy(float)
        x1 = (sectors.azimuth_deg + sectors.arc_deg / 2).to_numpy(float)
        ticks = np.arange(0, 361, 45)
        return x0, x1, [ticks, [f"{t:.0f}" for t in ticks]], "azimuth (deg; +x at 0, +y at 90)"
    faces = sorted(sectors.azimuth_deg.round(6).unique())
    index = sectors.azimuth_deg.round(6).map({a: k for k, a in enumerate(faces)}).to_numpy(float)
    labels = [FACE_NAMES.get(int(round(a)) % 360, f"wall at {a:.0f} deg") for a in faces]
    return index, index + 1, [np.arange(len(faces)) + 0.5, labels], "side wall (by the direction it faces out)"


def wall_map_plot(sectors: pd.DataFrame, en_bands: list | None = None):
    """The wall unrolled: height (m) against the azimuth (a cylinder's or hopper's sectors) or the side
    (a box's or slab's flat walls), each sensor sector a cell coloured by its pressure: the settled bed's
    static mean, the steady discharge's mean, the discharge's largest sample (Pa, one colour scale), and,
    with EN 1991-4's loads per band (``en_bands``: the summary's design_loads bands), static / p_hf and
    largest dynamic / p_he (1 = EN's load). ``sectors``: sectors.csv. Returns the Figure."""
    sectors = sectors.reset_index(drop=True)
    x0, x1, (tick_at, tick_labels), xlabel = _wall_cells(sectors)
    z0, z1 = sectors.z0.to_numpy(float), sectors.z1.to_numpy(float)
    en = {int(b["band"]): b for b in (en_bands or [])}
    p_hf = sectors.band.map(lambda k: en.get(int(k), {}).get("en_p_hf", np.nan)).to_numpy(float)
    p_he = sectors.band.map(lambda k: en.get(int(k), {}).get("en_p_he", np.nan)).to_numpy(float)
    panels = [("static (settled bed)", sectors.static_mean_pressure.to_numpy(float), "Pa"),
              ("discharge: steady mean", sectors.dynamic_mean_pressure.to_numpy(float), "Pa"),
              ("discharge: largest sample", sectors.discharge_max_pressure.to_numpy(float), "Pa")]
    if np.isfinite(p_hf).any():
        with np.errstate(divide="ignore", invalid="ignore"):
            panels += [("static / EN p_hf", panels[0][1] / p_hf, "ratio"),
                       ("largest dynamic / EN p_he", panels[2][1] / p_he, "ratio")]
    pa_max = max([np.nanmax(v) for _, v, u in panels if u == "Pa" and np.isfinite(v).any()] or [1.0])
    ratios = np.concatenate([v[np.isfinite(v)] for _, v, u in panels if u == "ratio"] or [np.array([1.0])])
    r_hi = max(2.0, float(ratios.max()) if len(ratios) else 2.0)
    fig, axes = plt.subplots(1, len(panels), figsize=(3.3 * len(panels) + 1.2, 4.6), sharey=True, squeeze=False)
    for ax, (title, values, unit) in zip(axes[0], panels):
        cells = [Rectangle((a, b), c - a, d - b) for a, b, c, d in zip(x0, z0, x1, z1)]
        cmap = plt.get_cmap("viridis" if unit == "Pa" else "RdBu_r").with_extremes(bad="#dddddd")
        coll = PatchCollection(cells, cmap=cmap, edgecolor="white", linewidth=0.5)
        coll.set_array(np.ma.masked_invalid(values))
        if unit == "Pa":
            coll.set_clim(0.0, pa_max)
        else:
            coll.set_norm(TwoSlopeNorm(vcenter=1.0, vmin=0.0, vmax=r_hi))
        ax.add_collection(coll)
        ax.set_xlim(np.nanmin(x0), np.nanmax(x1))
        ax.set_ylim(np.nanmin(z0), np.nanmax(z1))
        ax.set_xticks(tick_at, tick_labels, fontsize=7, rotation=0 if len(tick_labels) > 4 or len(tick_labels) < 3 else 20)
        ax.set(title=title, xlabel=xlabel if ax is axes[0][0] else "")
        fig.colorbar(coll, ax=ax, label="pressure (Pa)" if unit == "Pa" else "DEM / EN (1 = EN's load)",
                     shrink=0.85)
    axes[0][0].set_ylabel("height of the wall (m)")
    fig.suptitle("The wall unrolled: each sensor sector's pressure (grey: no data)", fontsize=10)
    fig.tight_layout()
    return fig


def line_figure(table, x: str, y, path, hue: str | None = None, xlabel: str = "", ylabel: str = "",
                title: str = "", logy: bool = False):
    """:func:`line_plot` written to ``path``; returns the path."""
    save_figure(line_plot(table, x, y, hue, xlabel, ylabel, title, logy), path)
    return Path(path)


def analysis_figure(analysis):
    """A frame analysis' figure from its ``results.table`` (free surface, porosity, coordination
    number, per-frame counts); None for an analysis without one or with an empty table."""
    t = analysis.results.table
    if t.empty:
        return None
    if isinstance(analysis, FreeSurface):
        return line_plot(t, x="time", y="surface_height", xlabel="time (s)", ylabel="free-surface height (m)")
    if isinstance(analysis, Porosity):
        return line_plot(t, x="step", y="porosity", hue="region", xlabel="timestep", ylabel="porosity")
    if isinstance(analysis, Coordination):
        return line_plot(t[t.species == "all"], x="step", y=["z_mean", "z_mech"],
                         xlabel="timestep", ylabel="coordination number")
    if isinstance(analysis, FrameSummary):
        return line_plot(t, x="step", y="particles", xlabel="timestep", ylabel="particles")
    return None


def force_chain_plot(chains: ForceChains, max_width: float = 3.0):
    """The contact network of a slice (``force_chains.ForceChains``), line width =
    max_width * Fn / max Fn; returns the Figure."""
    seg, fn, axis, center, thickness = chains.segments, chains.forces, chains.axis, chains.center, chains.thickness
    fig, ax = plt.subplots(figsize=(5.5, 8))
    if len(fn):
        widths = max_width * fn / max(float(fn.max()), 1e-300)
        lines = LineCollection(seg * 1000, linewidths=widths, colors="k", capstyle="round")
        ax.add_collection(lines)
        ax.autoscale()
    names = "xyz"
    plane = [names[k] for k in range(3) if k != axis]
    ax.set_aspect("equal")
    ax.set(xlabel=f"{plane[0]} (mm)", ylabel=f"{plane[1]} (mm)",
           title=f"force chains, step {chains.step}: {len(fn)} contacts in |{names[axis]} - "
                 f"{center * 1000:.1f} mm| <= {thickness * 500:.1f} mm\nline width ~ normal force "
                 f"(max {fn.max() if len(fn) else 0:.3g} N)")
    ax.title.set_fontsize(8)
    fig.tight_layout()
    return fig


def force_chain_figure(atoms, contacts, path, axis: int = 1, center: float | None = None,
                       thickness: float | None = None, max_width: float = 3.0) -> Path:
    """The force chains of ``atoms``' frame (``force_chains.force_chains``) drawn
    (:func:`force_chain_plot`) and written to ``path`` (PNG); returns the path."""
    save_figure(force_chain_plot(force_chains(atoms, contacts, axis, center, thickness), max_width), path)
    return Path(path)


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
