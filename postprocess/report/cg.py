"""The files of a coarse-graining (``siloflow cg``): fields.nc (NetCDF), paper B's profiles as
CSV, cg_summary.json and the figures (maps of solid fraction and v_z, outlet profiles, axial
pressures, kinetic pressure by size), written from ``postprocess.cg_run.CgResults``."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from siloflow.atomic_files import write_json
from siloflow.run_folder import CG_SUMMARY_NAME

from ..cg_analyses import axial_profiles, outlet_profiles, species_kinetic_table
from ..cg_run import CgResults, CgSetup, analyse_cg
from .figures import plt, save_figure
from .files import write_netcdf, write_tables


def write_cg(results: CgResults, out) -> dict:
    """Write a coarse-graining's results into ``out``: fields.nc, its tables, its figures (an
    (r, z) grid's, :func:`cg_figures`, listed in the summary) and cg_summary.json; returns the summary."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_netcdf(results.dataset, out / "fields.nc")
    write_tables(results.tables, out)
    summary = dict(results.summary)
    if results.figures:
        summary["figures"] = [p.name for p in cg_figures(results.dataset, out, results.z_outlet, results.outlet_radius)]
    write_json(out / CG_SUMMARY_NAME, summary)
    return summary


def run_cg(setup: CgSetup, out: Path, *args, **kwargs) -> dict:
    """Coarse-grain (``cg_run.analyse_cg``: the arguments after ``out`` are its) and write the
    results to ``out`` (made first; :func:`write_cg`); returns the summary."""
    out.mkdir(parents=True, exist_ok=True)
    return write_cg(analyse_cg(setup, *args, **kwargs), out)


def cg_figures(ds, folder, z_outlet: float, outlet_radius: float) -> list[Path]:
    """Maps of solid fraction and v_z (paper B Figs. 3-4), outlet profiles (Figs. 5-6), axial
    pressure profiles (Figs. 8-10) and kinetic pressure by size (Figs. 11-12)."""
    folder = Path(folder)
    written = []
    r, z = ds.r.values, ds.z.values
    fig, axes = plt.subplots(1, 2, figsize=(9, 6), sharey=True)
    field = ds.solid_fraction if "solid_fraction" in ds else ds.rho
    for ax, data, title in ((axes[0], field.values, field.name), (axes[1], ds.velocity.sel(component="z").values, "v_z (m/s)")):
        extent = [-r[-1], r[-1], z[0], z[-1]]
        full = np.concatenate([data[:, ::-1], data], axis=1)
        im = ax.imshow(full, origin="lower", extent=extent, aspect="equal", cmap="viridis")
        fig.colorbar(im, ax=ax, shrink=0.8)
        ax.set(title=title, xlabel="r (m)")
    axes[0].set_ylabel("z (m)")
    fig.tight_layout()
    save_figure(fig, folder / "cg_maps.png")
    written.append(folder / "cg_maps.png")

    prof = outlet_profiles(ds, z_outlet, outlet_radius)
    fig, ax = plt.subplots(figsize=(6, 4.2))
    ax.plot(prof.r_over_R, prof.phi_over_phi0, "o-", label="phi / phi(0)")
    ax.plot(prof.r_over_R, prof.vz_over_vz0, "s-", label="v_z / v_z(0)")
    ax.plot(prof.r_over_R, prof.janda, "k--", label="sqrt(1 - (r/R)^2)")
    ax.set(xlabel="r / R", ylabel="normalised", title=f"outlet profiles at z = {prof.z.iloc[0]:.4g} m")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, folder / "cg_outlet_profiles.png")
    written.append(folder / "cg_outlet_profiles.png")

    axial = axial_profiles(ds, z_outlet)
    fig, ax = plt.subplots(figsize=(6, 4.2))
    if "contact_pressure" in axial:
        ax.plot(axial.height / outlet_radius, axial.contact_pressure, label="contact pressure")
    ax.plot(axial.height / outlet_radius, axial.kinetic_pressure, label="kinetic pressure")
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.set(xlabel="z / R (above the outlet)", ylabel="pressure on the axis (Pa)", title="axial pressure profiles")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, folder / "cg_axial_pressure.png")
    written.append(folder / "cg_axial_pressure.png")

    if "kinetic_pressure_species" in ds:
        table = species_kinetic_table(ds, z_outlet)
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
        a1.plot(table.radius * 1000, table.cumulative_kinetic_pressure_larger_or_equal, "o-")
        a1.set(xlabel="particle radius r' (mm)", ylabel="sum of p_k over r >= r' (Pa)",
               title=f"cumulative kinetic pressure at h_c = {table.height.iloc[0]:.3g} m")
        a2.plot(table.radius * 1000, table.kinetic_per_solid_fraction_relative, "s-")
        a2.axhline(1.0, color="k", lw=0.8)
        a2.set(xlabel="particle radius (mm)", ylabel="(p_k^a / phi^a) / (p_k / phi)",
               title="kinetic pressure per solid fraction, by size")
        fig.tight_layout()
        save_figure(fig, folder / "cg_kinetic_by_size.png")
        written.append(folder / "cg_kinetic_by_size.png")
    return written
