"""Frame analyses of a siloflow run folder's dumps: bulk solid fraction, coordination number,
force chains, free surface and Wr vs Wf, and the band-true Janssen fit of the settled
wall-pressure profile. Called by :func:`postprocess.first_results.analyse` when the run wrote dumps;
its tables and what its figures show are added to the run's ``run_results.RunResults`` (data
only), which the report layer writes.

Every derived number that can be unresolved carries ``resolved`` and ``reason`` beside it: Wr
(the surface must descend :data:`MIN_SURFACE_DESCENT` grain diameters over its fit window), a
steady window (:data:`MIN_STEADY_SAMPLES` samples), the Janssen fit (its ``flags``).

Everything is read from the folder (its run plan and dumps, through ``RunFolder``); the geometry only
places the measurement regions (the bulk core: two grain diameters from the wall, three
from the bottom and the free surface).
"""
from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pandas as pd

from siloflow.errors import ReadError
from siloflow.silos.registry import silo_kind

from .coordination import Coordination
from .dumps import Frame, read_frames
from .discharge import FlowRate
from .flow_rate import FreeSurface, rate_series, surface_flow_rate
from .force_chains import force_chains
from .janssen import fit_janssen_bands
from .porosity import MeasureRegion, Porosity
from .run_results import RunResults


#: Wr is resolved when the free surface descends at least this many grain diameters over its fit window
MIN_SURFACE_DESCENT = 3.0
#: a steady window is resolved with at least this many samples
MIN_STEADY_SAMPLES = 10


def surface_rate_resolution(wr: FlowRate, area: float, bulk_density: float, d: float,
                            min_diameters: float = MIN_SURFACE_DESCENT) -> dict:
    """Whether Wr (``wr``, kg/s, from ``flow_rate.surface_flow_rate``) is resolved: the free
    surface must descend at least ``min_diameters`` grain diameters ``d`` (m) over the fit window.
    The descent is the fitted speed times the window, Wr / (``area`` m2 x ``bulk_density``
    kg/m3) x (t_end - t_start). Returns resolved, reason ('' when resolved),
    surface_descent_m, surface_descent_grain_diameters, min_descent_grain_diameters."""
    out = {"surface_descent_m": float("nan"), "surface_descent_grain_diameters": float("nan"),
           "min_descent_grain_diameters": float(min_diameters)}
    if wr.n_samples < 3 or not np.isfinite(wr.rate):
        return {"resolved": False, "reason": f"only {wr.n_samples} free-surface sample(s) in the Wr window "
                f"(needs 3)", **out}
    duration = wr.t_end - wr.t_start
    descent = wr.rate / (area * bulk_density) * duration
    out.update(surface_descent_m=float(descent), surface_descent_grain_diameters=float(descent / d))
    if descent < min_diameters * d:
        return {"resolved": False, "reason": (
            f"the free surface descended {descent * 1000:.3g} mm = {descent / d:.2g} grain diameters over "
            f"t = {wr.t_start:.3g}-{wr.t_end:.3g} s; Wr needs at least {min_diameters:g} "
            f"({min_diameters * d * 1000:.3g} mm)"), **out}
    return {"resolved": True, "reason": "", **out}


def steady_resolution(n_samples: int, min_samples: int = MIN_STEADY_SAMPLES, what: str = "the steady window") -> dict:
    """Whether a window (``what``) of ``n_samples`` samples is resolved: resolved, reason."""
    if n_samples < min_samples:
        return {"resolved": False, "reason": f"{what} holds {n_samples} samples (needs {min_samples})"}
    return {"resolved": True, "reason": ""}


def band_extents(walls) -> dict[int, tuple[float, float]]:
    """Each sensor band's height range (z0, z1), m, from the plan's walls of role ``band``."""
    out: dict[int, tuple[float, float]] = {}
    for w in walls:
        if w.role == "band":
            lo, hi = out.get(w.band, (w.z0, w.z1))
            out[w.band] = (min(lo, w.z0), max(hi, w.z1))
    return out


def bed_regions(g, surface: float, d: float) -> list[MeasureRegion]:
    """Measurement cylinders about the silo axis in the settled bed, three grain diameters
    from the bottom and the free surface: ``bulk_core`` (two diameters from the wall: the
    bulk solid fraction) and ``cross_section`` (the whole radius, wall layers included: the
    solid fraction that converts a free-surface speed into a mass flow rate). A slab silo
    gets discs through its thickness at mid-bed, the cross-section one reaching the side
    walls only when the bed is at least as deep as the silo is wide. ``g``: the plan's geometry
    (``siloflow.plan.Silo``)."""
    z0 = g.hopper_height + 3.0 * d
    z1 = surface - 3.0 * d
    if z1 - z0 < 2.0 * d:
        raise ReadError(f"the settled bed ({surface:.4g} m) is too shallow for a bulk measurement region")
    return [MeasureRegion(name, "cylinder", centre, radius, axis=axis, t0=t0, t1=t1)
            for name, centre, radius, axis, t0, t1 in silo_kind(g.kind).bed_discs(g, z0, z1, d)]


def janssen_diameter(g) -> float:
    """The D of Janssen's p = rho g D / (4 mu K) (1 - exp(-4 mu K z / D)), m: the diameter of a
    cylinder; for a slab 4 A / P with P the perimeter that carries wall friction (the side
    walls, and the faces only when they have friction); for a box 4 A / P of its four walls; for a
    silo from STL 4 A / P of its vertical walls' section half way up."""
    return silo_kind(g.kind).janssen_diameter(g)


def case_regions(analysis) -> list[MeasureRegion]:
    """The case's own measurement regions (``analysis.porosity_regions`` of the plan)."""
    axes = {"x": 0, "y": 1, "z": 2}
    return [MeasureRegion(r.name, r.shape, tuple(r.center), r.radius, axes[r.axis], r.t0, r.t1, r.plane)
            for r in analysis.porosity_regions]


def periodic_length(g) -> float | None:
    """A slab's periodic length along y (m), None for a walled silo (``g``: the plan's geometry)."""
    return g.thickness if getattr(g, "periodic_depth", False) else None


def case_regions_porosity(analysis, atoms_files, settled: Frame, results: RunResults,
                          period_y: float | None = None) -> dict:
    """Porosity in the case's regions over all frames (porosity_regions.csv and its figure, added to
    ``results``); the settled values. ``period_y``: a periodic slab's length along y, m."""
    a = analysis
    conversion = None
    if a.relative_density is not None:
        conversion = {"relative_density": a.relative_density, "reading": a.porosity_conversion}
    analysis = Porosity(case_regions(a), conversion, period_y=period_y)
    analysis.name = "porosity_regions"
    analysis.run(read_frames(atoms_files))
    results.add_analysis(analysis)
    at = analysis.table[analysis.table.step == settled.timestep].set_index("region")
    cols = [c for c in ("porosity", "porosity_3d") if c in at]
    return {name: {c: float(at.loc[name, c]) for c in cols} for name in at.index}


def analyse_dumps(run, bands_table: pd.DataFrame, discharge: pd.DataFrame, flow_rate, results: RunResults) -> dict:
    """Run the frame analyses of a run folder; add their tables, and what their figures show, to
    ``results``; return their summary."""
    atoms_files = run.run.dump_files("particles")
    contact_files = run.run.dump_files("contacts")
    if atoms_files is None:
        return {"dumps": "none written (outputs.dump_interval unset): frame analyses skipped"}
    plan = run.plan
    dt = run.dt
    open_step = run.stage_steps["open"]
    columns = run.run.dump_layout.contact_columns or None
    has_contacts = bool(contact_files) and bool(columns)

    def contact_frames(wanted=None):
        """Contact frames streamed from disk (a long run's do not fit in memory together)."""
        return read_frames(contact_files, columns=columns, steps=wanted)

    g = plan.geometry
    R = g.half_width
    kind = silo_kind(g.kind)

    # free surface over all frames (a box: strips across its width, its whole depth); its table also
    # says which frames exist
    surface = FreeSurface(radius=R, z_min=g.hopper_height, timestep=dt,
                          thickness=kind.surface_thickness(g)).run(read_frames(atoms_files))
    results.add_analysis(surface)
    steps = surface.table.step
    if not (steps <= open_step).any():
        raise ReadError(f"{run.folder}: no particle dump at or before the outlet opened (step {open_step})")
    settled = next(read_frames(atoms_files, steps=[int(steps[steps <= open_step].max())]))
    d = 2.0 * float(np.mean(settled.radii()))
    summary: dict = {"dump_frames": len(atoms_files), "grain_diameter_m": d}
    h_settled = float(surface.table.loc[surface.table.step == settled.timestep, "surface_height"].iloc[0])

    # bulk solid fraction of the settled bed
    rho_p = plan.grains[0].density
    summary["settled_surface_height_m"] = h_settled
    try:
        regions = bed_regions(g, h_settled, d)
    except ReadError as exc:     # a shallow bed: say so and skip what needs its solid fraction
        regions = None
        summary["bulk_solid_fraction"] = {"error": str(exc)}
    if regions is not None:
        try:
            por = Porosity(regions, densities=run.run.species_densities(), period_y=periodic_length(g)).run([settled])
        except ValueError as exc:      # a type the run's species do not list: the grain density only
            summary["bulk_density_note"] = f"{exc}; bulk density = particle density x solid fraction"
            por = Porosity(regions, period_y=periodic_length(g)).run([settled])
        results.add_analysis(por, figure=False)
        at = por.table.set_index("region")
        phi_bulk, phi_section = (float(at.loc[k, "solid_fraction"]) for k in ("bulk_core", "cross_section"))
        if "bulk_density" in at:      # species of different densities (dust): measured mass per volume
            rho_bulk, rho_section = (float(at.loc[k, "bulk_density"]) for k in ("bulk_core", "cross_section"))
        else:
            rho_bulk, rho_section = phi_bulk * rho_p, phi_section * rho_p
        summary["bulk_solid_fraction"] = phi_bulk
        summary["bulk_density_kg_m3"] = rho_bulk
        summary["cross_section_solid_fraction"] = phi_section
        summary["cross_section_bulk_density_kg_m3"] = rho_section
    if plan.analysis.porosity_regions:
        summary["porosity_regions"] = case_regions_porosity(plan.analysis, atoms_files, settled, results,
                                                            periodic_length(g))

    # coordination number in the core, every contact frame
    def core(frame: Frame) -> np.ndarray:
        p = frame.positions()
        top = float(p[:, 2].max()) if frame.n else 0.0
        return ((kind.across(g, p) < R - 2 * d) & (p[:, 2] > g.hopper_height + 2 * d)
                & (p[:, 2] < top - 2 * d))

    def settled_coordination(coord) -> None:
        results.add_analysis(coord)
        row = coord.table[(coord.table.step == settled.timestep) & (coord.table.species == "all")]
        if not row.empty:
            summary["coordination_settled"] = {k: float(row[k].iloc[0]) for k in ("z_mean", "z_mech")}
            summary["coordination_convention"] = str(row.convention.iloc[0])
            summary["coordination_source"] = str(row.source.iloc[0])

    if not has_contacts:
        # no contact dump (a LAMMPS run, or contacts not asked for): the settled bed's contacts are
        # its overlapping spheres (a clump's own spheres excepted: counted per body)
        settled_coordination(Coordination(select=core).run(read_frames(atoms_files, steps=[settled.timestep])))
    if has_contacts:
        coord = Coordination(select=core).run(read_frames(atoms_files), contact_frames())
        settled_coordination(coord)
        with_contacts = set(int(k) for k in coord.table.step.unique())
        after = [int(k) for k in steps if k > open_step and k in with_contacts]
        last = next(read_frames(atoms_files, steps=[max(after)])) if after else None
        figs = [(f, name) for f, name in [(settled, "force_chains_settled.png"), (last, "force_chains_discharge.png")]
                if f is not None and f.timestep in with_contacts]
        chains = {c.timestep: c for c in contact_frames([f.timestep for f, _ in figs])} if figs else {}
        for frame, name in figs:
            results.force_chains[name] = force_chains(frame, chains[frame.timestep], axis=1, center=0.0, thickness=d)

    if regions is None:
        return summary

    # Wr (free-surface speed) against Wf (outlet count) in Wf's steady window
    area = kind.bed_area(g, surface.area)     # the bed's whole cross-section
    st = surface.table
    in_window = (st.time >= flow_rate.t_start) & (st.time <= flow_rate.t_end) & (st.surface_height > g.hopper_height + 3 * d)
    wr = surface_flow_rate(st.time[in_window], st.surface_height[in_window], area, rho_section)
    summary["flow_rate_surface"] = {**wr.record(), **surface_rate_resolution(wr, area, rho_section, d)}
    ratio = wr.rate / flow_rate.rate if flow_rate.rate else float("nan")
    summary["flow_rate_surface_over_outlet"] = ratio     # resolved as flow_rate_surface is
    summary["flow_rate_surface_over_outlet_stderr"] = abs(ratio) * float(np.hypot(
        wr.stderr / wr.rate, flow_rate.stderr / flow_rate.rate)) if wr.rate and flow_rate.rate else float("nan")
    wf_t = rate_series(discharge.time, discharge.outlet_mass)
    flows = pd.DataFrame({"time": discharge.time, "Wf_kg_s": wf_t})
    wr_t = -rate_series(st.time, st.surface_height) * area * rho_section
    flows = pd.merge_asof(flows.sort_values("time"), pd.DataFrame({"time": st.time, "Wr_kg_s": wr_t}).sort_values("time"),
                          on="time", direction="nearest", tolerance=0.5 * dt * run.sample_steps)
    results.tables["flow_rates.csv"] = flows

    summary["janssen_static"] = janssen_static(plan, bands_table, h_settled, rho_section)
    return summary


def janssen_static(plan, bands_table: pd.DataFrame, surface: float, bulk_density: float,
                   exclude_corner: bool = True) -> dict:
    """The band-true Janssen fit (``janssen.fit_janssen_bands``) of a run's static band pressures
    (``bands_table``: band, static_pressure), as summary.json's ``janssen_static``: each band
    averaged over its height (the plan's walls) below the settled ``surface`` (m), the corner
    band excluded by default, ``bulk_density`` (kg/m3) the cross-section's, D from
    :func:`janssen_diameter`, mu_w the plan's particle-wall friction. Without sensors or with a
    bad band: {error, resolved False, reason}."""
    if bands_table.empty:
        why = "no wall-pressure sensors (outputs.results lacks wall_pressure)"
        return {"error": why, "resolved": False, "reason": why}
    extents = band_extents(plan.walls)
    static = bands_table[bands_table.band.isin(list(extents))]
    try:
        fit = fit_janssen_bands([extents[b][0] for b in static.band], [extents[b][1] for b in static.band],
                                static.static_pressure, surface, bulk_density, janssen_diameter(plan.geometry),
                                plan.pairs["particle_wall"].friction, plan.gravity, floor=plan.geometry.hopper_height,
                                exclude_corner=exclude_corner, bands=static.band.to_numpy())
    except ValueError as exc:
        return {"error": str(exc), "resolved": False, "reason": str(exc)}
    return asdict(fit)
