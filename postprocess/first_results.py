"""First results of a run folder: discharge curve and flow rate, band pressures (static and
dynamic), force balance of the settled bed, EN 1991-4 beside the bands, and the frame analyses
of its dumps (``dump_results``). :func:`analyse_run` computes them into a
:class:`postprocess.run_results.RunResults` (data only: it writes nothing and draws nothing); the
report layer (``postprocess.report.write_run``, or ``postprocess.report.post_process`` for both
steps) writes results/.

Reads only what the run left, through ``siloflow.run_folder.RunFolder`` (its plan, record and
the engine-neutral flow and wall-force tables), so it runs on any finished siloflow run folder,
whichever engine wrote it.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from siloflow.design_loads import bulk_solid, design_loads
from siloflow.errors import ReadError
from siloflow.run_folder import RESULT_TABLES, RunFolder
from siloflow.silos.registry import silo_kind

from .batch_means import batch_means_stderr
from .discharge import clog, discharge_table, steady_flow_rate
from .dump_results import MIN_STEADY_SAMPLES, analyse_dumps, steady_resolution
from .en_verdicts import band_verdicts, bed_state, compare_with_dem
from .flow_rate import beverloo_prediction, rate_series, steady_window
from .janssen import compare_with_measurement
from .run_results import RunResults
from .wall_pressure import band_mean, band_pressures, vertical_load, wide_forces


class RunOutputs:
    """The tables of one run folder, with the stage boundaries in time (s)."""

    def __init__(self, folder):
        self.run = folder if isinstance(folder, RunFolder) else RunFolder(folder)
        self.folder = self.run.path
        self.plan = self.run.plan
        self.record = self.run.record
        self.dt = self.plan.dt
        self.walls = self.plan.walls
        self.flow = self.run.flow()
        self.forces = None                  # no result asked for the walls' forces: none sampled
        if self.plan.outputs.wall_forces:
            try:
                self.forces = wide_forces(self.run.wall_forces(), self.walls)
            except ValueError as exc:
                raise ReadError(f"{self.folder}: {exc}") from None
        self.has_bands = self.forces is not None and any(w.role == "band" for w in self.walls)
        steps = self.record.stage_steps
        missing = [s for s in ("static", "open", "discharge") if s not in steps]
        if missing:
            raise ReadError(f"{folder}: the run never reached stage(s) {', '.join(missing)}")
        self.stage_steps = {k: int(v) for k, v in steps.items()}
        self.sample_steps = self.plan.outputs.sample_steps

    def stage_time(self, stage: str) -> float:
        return self.stage_steps[stage] * self.dt


def static_window(forces: pd.DataFrame, run: RunOutputs) -> pd.Series:
    """Samples averaged wholly inside the static stage (the first step of a run doubles mesh forces)."""
    lo = run.stage_steps["static"] + run.sample_steps
    hi = run.stage_steps["open"]
    return (forces.step > lo) & (forces.step <= hi)


def discharge_window(forces: pd.DataFrame, run: RunOutputs) -> pd.Series:
    """Samples averaged wholly after the opening: the whole discharge, over which a band's maximum
    dynamic pressure is taken."""
    return forces.step > run.stage_steps["open"] + run.sample_steps


def dynamic_window(forces: pd.DataFrame, run: RunOutputs, window: dict | None) -> pd.Series:
    """Samples averaged wholly after the opening and inside the discharge ``window`` ({t_start,
    t_end}, s: :func:`pressure_window`); none without a window."""
    after = forces.step > run.stage_steps["open"] + run.sample_steps
    if not window:
        return after & False
    t = forces.step * run.dt
    return after & (t >= window["t_start"]) & (t <= window["t_end"])


def pressure_window(steady: dict | None, rate) -> dict | None:
    """The discharge window of the pressure statistics: the detected steady window when it is
    resolved, else the flow-rate fit's window; None if neither exists. {source, t_start, t_end} (s)."""
    if steady and steady.get("resolved", True):
        return {"source": "steady window detected", "t_start": steady["t_start"], "t_end": steady["t_end"]}
    if np.isfinite(rate.t_start) and np.isfinite(rate.t_end) and rate.t_end > rate.t_start:
        return {"source": "flow-rate fit window", "t_start": float(rate.t_start), "t_end": float(rate.t_end)}
    return None


#: the pressure-statistics columns of bands.csv, after the first six
BAND_STATISTICS = ["static_pressure_stderr", "static_pressure_batch_stderr", "static_pressure_sector_stderr",
                   "static_samples", "static_batches", "static_sectors", "dynamic_mean_pressure",
                   "dynamic_std_pressure", "dynamic_p95_pressure", "dynamic_max_pressure", "dynamic_samples"]


def static_stderr(batch: float, sector: float) -> float:
    """The headline standard error of a band's static pressure (Pa) from its two parts: the
    window's time series (``batch``, batch means) and the band's sectors (``sector``, their spread
    around the wall over the square root of their number), added in quadrature; NaN when either
    part is unknown (a window too short for batches, a band of one sector), so that no error that
    leaves out the bed's packing is stated. ``benchmarks/results/coverage`` measures it against the
    spread of seeds."""
    return float(math.hypot(batch, sector)) if np.isfinite(batch) and np.isfinite(sector) else float("nan")


def band_statistics(bands: pd.DataFrame, dynamic_mask, static_mask, sector_means=None) -> pd.DataFrame:
    """Per band (index ``band``) of a tidy band table (step, band, pressure Pa): the static
    window's sample count and the batch-means standard error of its mean pressure
    (:func:`batch_means_stderr`); from ``sector_means`` (the static window's mean pressure per
    band and sector, Pa, a Series indexed by (band, sector)) the sectors' standard error,
    sd(sectors, ddof 1) / sqrt(sectors); their sum in quadrature (:func:`static_stderr`); and
    over the dynamic window the mean, standard deviation (ddof 1), 95th percentile (linear
    interpolation, numpy's default), maximum and count of the pressure (Pa): the columns
    :data:`BAND_STATISTICS`."""
    def aligned(mask):
        return pd.Series(np.broadcast_to(np.asarray(mask, bool), (len(bands),)), index=bands.index)

    static_mask, dynamic_mask = aligned(static_mask), aligned(dynamic_mask)
    rows = {}
    nan = float("nan")
    for band, grp in bands.groupby("band"):
        st = grp[static_mask[grp.index]].sort_values("step").pressure.to_numpy(float)
        dy = grp[dynamic_mask[grp.index]].pressure.to_numpy(float)
        se, nb = batch_means_stderr(st)
        per_sector = np.asarray(sector_means.loc[band], float) if sector_means is not None and \
            band in sector_means.index.get_level_values(0) else np.array([])
        sector_se = float(per_sector.std(ddof=1) / math.sqrt(len(per_sector))) if len(per_sector) > 1 else nan
        rows[band] = {"static_pressure_stderr": static_stderr(se, sector_se), "static_pressure_batch_stderr": se,
                      "static_pressure_sector_stderr": sector_se, "static_samples": len(st), "static_batches": nb,
                      "static_sectors": len(per_sector),
                      "dynamic_mean_pressure": float(dy.mean()) if len(dy) else nan,
                      "dynamic_std_pressure": float(dy.std(ddof=1)) if len(dy) > 1 else nan,
                      "dynamic_p95_pressure": float(np.percentile(dy, 95)) if len(dy) else nan,
                      "dynamic_max_pressure": float(dy.max()) if len(dy) else nan, "dynamic_samples": len(dy)}
    return pd.DataFrame.from_dict(rows, orient="index", columns=BAND_STATISTICS).rename_axis("band")


def sector_statistics(sectors: pd.DataFrame, walls, static_mask, dynamic_mask, discharge_mask=None) -> pd.DataFrame:
    """Per (band, sector) of a tidy sector table (step, band, sector, z_mid, pressure Pa): the
    sector's height range z0..z1 (m), azimuth (deg, the middle of its arc; a slab's or box's side
    wall: the direction of its normal, a slab's at 180 and 0) and arc (deg; NaN for a flat wall), the mean pressure (Pa) over the static
    window and over the dynamic window, each with its batch-means standard error
    (:func:`batch_means_stderr`: the samples are autocorrelated) and sample count, and the largest
    sample over ``discharge_mask`` (the whole discharge, as a band's max dynamic pressure; NaN
    without a mask). ``walls``: the plan's walls (their theta0..theta1, or their normal)."""
    azimuth, heights, arcs = {}, {}, {}
    nan = float("nan")
    for w in walls:
        if w.role == "band":
            tc = 0.5 * (w.theta0 + w.theta1) if w.theta0 is not None else math.atan2(w.normal[1], w.normal[0])
            azimuth[(w.band, w.sector)] = math.degrees(tc) % 360.0
            heights[(w.band, w.sector)] = (w.z0, w.z1)
            arcs[(w.band, w.sector)] = math.degrees(w.theta1 - w.theta0) if w.theta0 is not None else nan
    rows = []
    for (band, sector), grp in sectors.groupby(["band", "sector"]):
        z0, z1 = heights.get((band, sector), (nan, nan))
        row = {"band": band, "sector": sector, "z_mid": float(grp.z_mid.iloc[0]),
               "z0": nan if z0 is None else float(z0), "z1": nan if z1 is None else float(z1),
               "azimuth_deg": azimuth.get((band, sector), nan), "arc_deg": arcs.get((band, sector), nan)}
        for name, mask in (("static", static_mask), ("dynamic", dynamic_mask)):
            x = grp[np.asarray(mask, bool)[grp.index]].sort_values("step").pressure.to_numpy(float)
            se, _ = batch_means_stderr(x)
            row.update({f"{name}_mean_pressure": float(x.mean()) if len(x) else nan,
                        f"{name}_mean_stderr": se, f"{name}_samples": len(x)})
        during = grp[np.asarray(discharge_mask, bool)[grp.index]].pressure if discharge_mask is not None else ()
        row["discharge_max_pressure"] = float(np.max(during)) if len(during) else nan
        rows.append(row)
    return pd.DataFrame(rows)


def eccentric_discharge(table: pd.DataFrame, sectors: int, offset: float, kind: str = "cylinder",
                        offset_y: float = 0.0) -> dict:
    """An eccentric outlet's wall: per band, the dynamic mean pressure of the sector facing the
    outlet (a cylinder's sector 0, centred on +x; a slab's side wall on the slot's side; a box's
    wall on the side the outlet is farther off the middle, x or y) and of the wall opposite
    (sector ``sectors / 2``; for an odd count, the mean of the two sectors either side of 180 deg;
    a slab's or box's opposite wall), their difference near - far (Pa) and the ratio near / far.

    The difference's error holds two parts in quadrature: each sector's time series (batch means)
    and the packing against the wall, which differs from sector to sector in one fill and which
    a time average never removes. The packing part, a fraction of the pressure, is measured on the
    mirror pairs (sectors s and ``sectors`` - s, at -+ the same azimuth from the outlet, equal by
    symmetry): over every loaded band and pair, its relative variance is max(0, sum(d^2 - e^2) /
    sum(m^2)) / 2, d a pair's difference, e its time-series error and m its mean pressure (the
    loaded bands weigh most).
    ``table``: :func:`sector_statistics`."""
    near, far, pairs = silo_kind(kind).eccentric_sectors(sectors, offset, offset_y)
    excess = []
    by_band = {band: grp.set_index("sector") for band, grp in table.groupby("band")}
    for by in by_band.values():
        for a, b in pairs:
            if a in by.index and b in by.index and by.loc[a].dynamic_samples and by.loc[a].dynamic_mean_pressure:
                d = by.loc[a].dynamic_mean_pressure - by.loc[b].dynamic_mean_pressure
                e = math.hypot(by.loc[a].dynamic_mean_stderr, by.loc[b].dynamic_mean_stderr)
                m = 0.5 * (by.loc[a].dynamic_mean_pressure + by.loc[b].dynamic_mean_pressure)
                if np.isfinite(d) and np.isfinite(e) and m > 0:
                    excess.append((d * d - e * e, m * m))
    packing = math.sqrt(max(0.0, sum(x for x, _ in excess) / sum(w for _, w in excess)) / 2.0) \
        if excess else float("nan")
    out = []
    for band, by in by_band.items():
        if near not in by.index or any(k not in by.index for k in far):
            continue
        a = by.loc[near]
        p_far = float(np.mean([by.loc[k].dynamic_mean_pressure for k in far]))
        se_far = math.hypot(*[by.loc[k].dynamic_mean_stderr for k in far]) / len(far)
        time_se = math.hypot(a.dynamic_mean_stderr, se_far)
        pack_se = packing * math.hypot(a.dynamic_mean_pressure, p_far / math.sqrt(len(far))) \
            if np.isfinite(packing) else 0.0
        out.append({"band": int(band), "z_mid": float(a.z_mid), "near_pressure": float(a.dynamic_mean_pressure),
                    "far_pressure": p_far, "difference": float(a.dynamic_mean_pressure - p_far),
                    "difference_stderr": float(math.hypot(time_se, pack_se)), "time_stderr": float(time_se),
                    "ratio": float(a.dynamic_mean_pressure / p_far) if p_far else float("nan")})
    return {"outlet_offset_m": offset, **({"outlet_offset_y_m": offset_y} if offset_y else {}),
            "near_sector": near, "far_sectors": far,
            "packing_relative_sd": packing, "mirror_pairs": len(excess),
            "what": "dynamic mean pressure over the steady discharge on the wall sector facing the outlet "
                    "(near) and opposite it (far); error: each sector's batch means and the packing against the "
                    "wall in quadrature (" + (f"{packing:.1%} of a sector's pressure" if packing > 0 else
                                              "no spread beyond the time series'" if packing == 0 else
                                              "not measured: no mirror pair of sectors, the time series' error only")
                    + (f", from {len(excess)} mirror-pair differences)" if excess else ")"),
            "bands": out}


def analyse_run(folder, measured_pressure=None) -> RunResults:
    """Compute the results of a run folder: its summary, tables and what its figures show
    (:class:`RunResults`); nothing is written. The report layer
    (:func:`postprocess.report.write_run`) writes them to results/ with the figures and reports.

    ``measured_pressure``: optional CSV (``time`` s since opening, ``band_<k>`` Pa) compared
    band by band with the run (paper A's Table 3 and Eq. 34), as pressure_comparison.csv.
    """
    run = RunOutputs(folder)
    g = run.plan.gravity
    t_open = run.stage_time("open")

    # discharge
    dis = discharge_table(run.flow, run.dt, t_open)
    initial_mass = float(dis.loc[dis.step <= run.stage_steps["open"], "mass_total"].iloc[-1])
    after = dis[dis.step >= run.stage_steps["open"]]
    rate = steady_flow_rate(after.time, after.outlet_mass, t_open,
                            mass_in_silo=after.mass_in_silo, initial_mass=initial_mass)
    clogged = clog(after.time_since_open, after.outlet_mass, after.mass_in_silo, initial_mass)
    # steady state detected from the rate itself (smoothed over a tenth of the discharge)
    w = rate_series(after.time, after.outlet_mass, window=max(5, len(after) // 10))
    i0, i1 = steady_window(w, tolerance=0.2)
    steady = {"t_start": float(after.time.iloc[i0]), "t_end": float(after.time.iloc[i1 - 1]),
              "median_rate": float(np.nanmedian(w[i0:i1])), "tolerance": 0.2, "n_samples": int(i1 - i0),
              **steady_resolution(int(i1 - i0))} if i1 > i0 else None

    # wall pressure
    bands, table = None, pd.DataFrame(columns=["band", "z_mid", "static_pressure", "static_shear",
                                               "max_dynamic_pressure", "discharge_factor", *BAND_STATISTICS])
    pressure_stats, sector_table = None, None
    if run.has_bands:
        sectors = band_pressures(run.forces, run.walls)
        bands = band_mean(sectors)
        bands.insert(1, "time", bands.step * run.dt)
        static_mask = static_window(bands, run)
        if not static_mask.any():
            raise ReadError(f"{folder}: no wall-force sample inside the static window; "
                            "make fill.settle.static_window longer than outputs.sample_interval")
        static = bands[static_mask].groupby("band").agg(z_mid=("z_mid", "first"), static_pressure=("pressure", "mean"),
                                                        static_shear=("shear_force", "mean"))
        dynamic = bands[discharge_window(bands, run)].groupby("band").agg(max_dynamic_pressure=("pressure", "max"))
        table = static.join(dynamic)
        with np.errstate(divide="ignore", invalid="ignore"):
            table["discharge_factor"] = table.max_dynamic_pressure / table.static_pressure
        # designer's statistics: dynamic pressure over the steady discharge, static mean's error
        window = pressure_window(steady, rate)
        dyn_mask = dynamic_window(bands, run, window)
        sector_static = static_window(sectors, run)
        sector_means = sectors[sector_static].groupby(["band", "sector"]).pressure.mean()
        sector_table = sector_statistics(sectors, run.walls, sector_static, dynamic_window(sectors, run, window),
                                         discharge_window(sectors, run))
        table = table.join(band_statistics(bands, dyn_mask, static_mask, sector_means)).reset_index()
        n_dyn = int(table.dynamic_samples.min()) if len(table) else 0
        pressure_stats = {
            "dynamic_window": {**(window or {"source": "none: no steady or flow-rate window"}),
                               "n_samples": n_dyn, **steady_resolution(n_dyn, what="the pressure window")},
            "static_window": {"t_start": float(bands.time[static_mask].min()),
                              "t_end": float(bands.time[static_mask].max()),
                              "n_samples": int(table.static_samples.min()) if len(table) else 0},
            "static_stderr": "the window's batch means (contiguous batches, 10 from 40 samples, 5 from 10: "
                             "SE = sd(batch means) / sqrt(batches); the samples are autocorrelated) and the "
                             "band's sectors (sd / sqrt(sectors): the packing around the wall) in quadrature"}

    # force balance of the settled bed
    balance = None
    if run.forces is not None:
        load = vertical_load(run.forces, run.walls)
        fmask = static_window(run.forces, run)
        fstatic = run.flow[(run.flow.step > run.stage_steps["static"]) & (run.flow.step <= run.stage_steps["open"])]
        weight = float(fstatic.mass_total.mean()) * g
        wall_load = float(load[fmask].mean())
        band_cols = [w.name for w in run.walls if w.role in ("band", "wall")]
        wall_shear = float(sum(-run.forces.loc[fmask, f"{n}_fz"].mean() for n in band_cols))
        balance = {"weight_N": weight, "wall_and_bottom_load_N": wall_load,
                   "ratio": wall_load / weight if weight > 0 else float("nan"),
                   "wall_friction_share": wall_shear / weight if weight > 0 else float("nan")}

    summary = {
        "particles_inserted": run.record.inserted,
        "fill_losses": run.record.fill_losses,
        "initial_mass_kg": initial_mass,
        "settled_ke_pe": run.record.settled_ke_pe,
        "time_open_s": t_open,
        "force_balance": balance,
        "results_asked": run.plan.outputs.results,
        "flow_rate": rate.record(),
        "clogged": clogged,
        "steady_window_detected": steady,
        "discharged_mass_kg": float(dis.outlet_mass.iloc[-1]),
        "mass_in_silo_end_kg": float(dis.mass_in_silo.iloc[-1]),
        "bands": table.to_dict(orient="records"),
        "pressure_statistics": pressure_stats,
        "engine": {"name": run.record.engine, "ranks": run.plan.engine.ranks},
        "engine_wall_time_s": run.record.wall_time,
        "numerical_profile": _profile_record(run.plan),
        **({"discharge_stop": run.record.discharge_stop} if run.record.discharge_stop else {}),
        **({"fill_cache": run.record.fill_cache} if run.record.fill_cache else {}),
        "engine_warnings": run.record.warnings,
        "guard": {"stopped": run.record.guard, "peaks": run.record.guard_peaks,
                  "smallest_radius_m": min(sp.radius for sp in run.plan.species)},
        "planned_bed": {"grains": run.plan.fill.count, "mass_kg": run.plan.expected_mass},
    }
    # the tables, and what the figures show, for the report layer to write
    results = RunResults(run.folder, run.run.results, summary, {RESULT_TABLES["flow"]: dis},
                         discharge=dis, bands=bands, band_table=table, t_open=t_open)
    if bands is not None:
        results.tables.update({RESULT_TABLES["wall_pressure"]: bands,
                               RESULT_TABLES["wall_pressure_sectors"]: sectors.assign(time=sectors.step * run.dt),
                               RESULT_TABLES["bands"]: table, "wall_pressure_sectors.parquet": sectors,
                               RESULT_TABLES["sectors"]: sector_table})
        geo = run.plan.geometry
        offset, offset_y = getattr(geo, "outlet_offset", 0.0), getattr(geo, "outlet_offset_y", 0.0)
        if offset or offset_y:
            summary["eccentric_discharge"] = eccentric_discharge(sector_table, run.plan.sensors.sectors, offset,
                                                                 geo.kind, offset_y)
    summary["frame_analyses"] = analyse_dumps(run, table, dis, rate, results)
    summary["beverloo_prediction"] = beverloo_prediction(run.plan, summary, folder)
    summary["design_loads"] = en1991_comparison(run, table, summary, results)
    if measured_pressure is not None:
        summary["pressure_comparison"] = measured_comparison(folder, measured_pressure, bands, t_open, results)
    return results


def measured_comparison(folder, measured_pressure, bands: pd.DataFrame | None, t_open: float,
                        results: RunResults) -> list[dict]:
    """The run's band pressures against measured ones (``measured_pressure``, a CSV): the
    summary's records; the table added to ``results`` (pressure_comparison.csv)."""
    if bands is None:
        raise ReadError(f"{folder} has no wall-pressure sensors to compare with {measured_pressure} "
                        "(its outputs.results does not ask for wall_pressure)")
    try:
        measured = pd.read_csv(measured_pressure)
    except (OSError, ValueError) as exc:
        raise ReadError(f"cannot read measured pressures {measured_pressure}: {exc}") from None
    try:
        comparison = compare_with_measurement(bands, measured, t_open)
    except ValueError as exc:
        raise ReadError(f"{measured_pressure}: {exc}") from None
    results.tables["pressure_comparison.csv"] = comparison
    return comparison.to_dict(orient="records")


def en1991_comparison(run: RunOutputs, table: pd.DataFrame, summary: dict, results: RunResults) -> dict:
    """EN 1991-4's filling and discharge wall pressures for the run's silo beside its bands: the
    summary's ``design_loads``; ``design_vs_dem.csv`` and the loads (``results.design``, the
    figure design_loads.png) added to ``results`` when computed. The solid is the case's ``design`` section, or else the simulated one: unit weight from the bed's measured bulk density (the case's packing
    fraction without dumps), K = 1.1 (1 - sin phi) with tan phi the grains' friction (the
    standard's K_m from phi_im), mu the grains' wall friction, phi_r = phi. Fill height: the
    settled surface if measured, else the plan's estimate."""
    plan = run.plan
    if table.empty:
        return {"computed": False, "reason": "no wall-pressure sensors (outputs.results lacks wall_pressure)"}
    fa = summary.get("frame_analyses", {})
    surface = fa.get("settled_surface_height_m") or plan.fill.bed_height_estimate
    s = plan.design
    try:
        if s is not None:
            solid = bulk_solid(s.material, unit_weight=s.unit_weight, K=s.K, mu=s.mu, phi_r=s.phi_r_deg, C_op=s.C_op)
            wall_type, aac, ecc, what = s.wall_type, s.action_assessment_class, s.eccentricity, s.material or "explicit"
        else:
            rho_b = fa.get("cross_section_bulk_density_kg_m3") or plan.fill.packing_fraction * plan.grains[0].density
            phi = math.atan(plan.pairs["particle_particle"].friction)
            solid = bulk_solid(unit_weight=rho_b * plan.gravity, K=1.1 * (1 - math.sin(phi)),
                               mu=plan.pairs["particle_wall"].friction, phi_r=math.degrees(phi))
            wall_type, aac, ecc, what = "D2", 2, 0.0, "the simulated grains"
        loads = design_loads(plan.geometry, solid, surface, wall_type, aac, ecc)
    except ValueError as exc:
        return {"computed": False, "reason": str(exc)}
    compared = compare_with_dem(loads, table)
    state, verdicts = en_band_verdicts(plan, loads, compared, table, summary, surface)
    compared = compared.assign(static_verdict=[v["static_verdict"] for v in verdicts],
                               static_causes=["; ".join(v["static_causes"]) for v in verdicts],
                               dynamic_verdict=[v["dynamic_verdict"] for v in verdicts])
    results.tables["design_vs_dem.csv"] = compared
    results.design = loads
    return {"computed": True, "solid": what, "classification": loads.classification, "C_h": loads.C_h,
            "C_w": loads.C_w, "fill_height_m": surface, "notes": list(loads.notes), "bed_state": state,
            "bands": compared.to_dict(orient="records")}


def en_band_verdicts(plan, loads, compared, table, summary: dict, surface: float):
    """The settled bed's state (``en_verdicts.bed_state``, with the grains' wall friction mu_w) and
    a verdict per band of ``compared``."""
    g = plan.geometry
    diameter = 2.0 * g.half_width
    protocol = "mobilised (fill.mobilise)" if plan.fill.mobilise is not None else (
        f"{plan.fill.protocol}" + (", poured frictionless" if plan.fill.frictionless else ""))
    max_case = loads.values["max_horizontal"]
    fa = summary.get("frame_analyses", {})
    flat_cylinder = silo_kind(g.kind).wall_force_balance and g.hopper_height == 0
    state = bed_state(summary.get("force_balance") if flat_cylinder else None, wall_normal_force(plan, table),
                      fa.get("janssen_static"), surface, diameter, max_case.mu, max_case.K, protocol,
                      mu_w=plan.pairs["particle_wall"].friction)
    grains_across = diameter / (2.0 * max(gr.radius for gr in plan.grains))
    se = table.set_index("band").reindex(compared.band).static_pressure_stderr.to_numpy(float)
    return state, band_verdicts(compared, se, state, diameter, loads.material.gamma, grains_across)


def wall_normal_force(plan, table) -> float | None:
    """The settled bed's normal force on a cylinder's vertical wall (N): each band's static
    pressure over its area 2 pi R (z1 - z0); None for another silo or without bands."""
    g = plan.geometry
    if not silo_kind(g.kind).wall_force_balance or table.empty:
        return None
    spans = {w.band: (w.z0, w.z1) for w in plan.walls if w.role == "band"}
    pressure = table.set_index("band").static_pressure
    return float(sum(pressure[b] * 2.0 * math.pi * g.half_width * (z1 - z0) for b, (z0, z1) in spans.items()
                     if b in pressure.index and np.isfinite(pressure[b])))


def _profile_record(plan) -> dict | None:
    """The plan's numerical profile as a dict (None for a plan written before profiles existed)."""
    profile = getattr(plan, "profile", None)
    return profile.model_dump(mode="json") if profile is not None else None
