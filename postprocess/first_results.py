"""First results of a run folder: discharge curve and flow rate, band pressures (static and
dynamic), force balance of the settled bed; written as CSV/Parquet tables, summary.json
and one figure.

Reads only what the run left, through ``siloflow.run_folder.RunFolder`` (its plan, record and
the engine-neutral flow and wall-force tables), so it runs on any finished siloflow run folder,
whichever engine wrote it.
"""
from __future__ import annotations

import math

from dataclasses import asdict

import numpy as np
import pandas as pd

from siloflow.atomic_files import atomic_path, write_json, write_text
from siloflow.errors import ReadError
from siloflow.run_folder import RESULT_TABLES, SUMMARY_NAME, RunFolder

from .batch_means import batch_means_stderr
from .discharge import discharge_table, steady_flow_rate
from .dump_results import MIN_STEADY_SAMPLES, analyse_dumps, steady_resolution
from .flow_rate import rate_series, steady_window
from .janssen import compare_with_measurement
from .numbers import mass_rate, pressure
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


def analyse(folder, measured_pressure=None) -> dict:
    """Compute the results of a run folder; return the summary (also written to results/).

    ``measured_pressure``: optional CSV (``time`` s since opening, ``band_<k>`` Pa) compared
    band by band with the run (paper A's Table 3 and Eq. 34), written to pressure_comparison.csv.
    """
    run = RunOutputs(folder)
    out = run.run.results
    out.mkdir(exist_ok=True)
    g = run.plan.gravity
    t_open = run.stage_time("open")

    # discharge
    dis = discharge_table(run.flow, run.dt, t_open)
    initial_mass = float(dis.loc[dis.step <= run.stage_steps["open"], "mass_total"].iloc[-1])
    after = dis[dis.step >= run.stage_steps["open"]]
    rate = steady_flow_rate(after.time, after.outlet_mass, t_open,
                            mass_in_silo=after.mass_in_silo, initial_mass=initial_mass)
    # steady state detected from the rate itself (smoothed over a tenth of the discharge)
    w = rate_series(after.time, after.outlet_mass, window=max(5, len(after) // 10))
    i0, i1 = steady_window(w, tolerance=0.2)
    steady = {"t_start": float(after.time.iloc[i0]), "t_end": float(after.time.iloc[i1 - 1]),
              "median_rate": float(np.nanmedian(w[i0:i1])), "tolerance": 0.2, "n_samples": int(i1 - i0),
              **steady_resolution(int(i1 - i0))} if i1 > i0 else None

    # wall pressure
    bands, table = None, pd.DataFrame(columns=["band", "z_mid", "static_pressure", "static_shear",
                                               "max_dynamic_pressure", "discharge_factor", *BAND_STATISTICS])
    pressure_stats = None
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
        dynamic = bands[bands.step > run.stage_steps["open"] + run.sample_steps].groupby("band").agg(
            max_dynamic_pressure=("pressure", "max"))
        table = static.join(dynamic)
        with np.errstate(divide="ignore", invalid="ignore"):
            table["discharge_factor"] = table.max_dynamic_pressure / table.static_pressure
        # designer's statistics: dynamic pressure over the steady discharge, static mean's error
        window = pressure_window(steady, rate)
        dyn_mask = bands.step > run.stage_steps["open"] + run.sample_steps
        dyn_mask &= (bands.time >= window["t_start"]) & (bands.time <= window["t_end"]) if window else False
        sector_means = sectors[static_window(sectors, run)].groupby(["band", "sector"]).pressure.mean()
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

    # tables
    write_text(out / RESULT_TABLES["flow"], dis.to_csv(index=False))
    if bands is not None:
        write_text(out / RESULT_TABLES["wall_pressure"], bands.to_csv(index=False))
        write_text(out / RESULT_TABLES["wall_pressure_sectors"],
                   sectors.assign(time=sectors.step * run.dt).to_csv(index=False))
        write_text(out / RESULT_TABLES["bands"], table.to_csv(index=False))
        try:
            with atomic_path(out / "wall_pressure_sectors.parquet") as tmp:
                sectors.to_parquet(tmp, index=False)
        except ImportError:  # pyarrow is a dependency; a missing one only loses the Parquet copy
            pass

    summary = {
        "particles_inserted": run.record.inserted,
        "fill_losses": run.record.fill_losses,
        "initial_mass_kg": initial_mass,
        "settled_ke_pe": run.record.settled_ke_pe,
        "time_open_s": t_open,
        "force_balance": balance,
        "results_asked": run.plan.outputs.results,
        "flow_rate": asdict(rate),
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
    }
    summary["frame_analyses"] = analyse_dumps(run, out, table, dis, rate)
    summary["design_loads"] = en1991_comparison(run, table, summary, out)
    if measured_pressure is not None:
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
        write_text(out / "pressure_comparison.csv", comparison.to_csv(index=False))
        summary["pressure_comparison"] = comparison.to_dict(orient="records")
    write_json(out / SUMMARY_NAME, summary)
    write_text(out / "report.md", report_text(summary, run))
    from .figures import first_results_figure  # matplotlib only when figures are drawn
    first_results_figure(bands, dis, table, t_open, out / "first_results.png")
    return summary


def en1991_comparison(run: RunOutputs, table: pd.DataFrame, summary: dict, out) -> dict:
    """EN 1991-4's filling and discharge wall pressures for the run's silo beside its bands
    (``design_vs_dem.csv``, ``design_loads.png``). The solid is the case's ``design`` section, or
    else the simulated one: unit weight from the bed's measured bulk density (the case's packing
    fraction without dumps), K = 1.1 (1 - sin phi) with tan phi the grains' friction (the
    standard's K_m from phi_im), mu the grains' wall friction, phi_r = phi. Fill height: the
    settled surface if measured, else the plan's estimate."""
    import math
    from siloflow.design_loads import bulk_solid, design_loads
    from .design_figure import compare_with_dem, design_figure
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
    write_text(out / "design_vs_dem.csv", compared.to_csv(index=False))
    design_figure(loads, out / "design_loads.png", table)
    return {"computed": True, "solid": what, "classification": loads.classification, "C_h": loads.C_h,
            "C_w": loads.C_w, "fill_height_m": surface, "notes": list(loads.notes), "bed_state": state,
            "bands": compared.to_dict(orient="records")}


def en_band_verdicts(plan, loads, compared, table, summary: dict, surface: float):
    """The settled bed's state (``en_verdicts.bed_state``) and a verdict per band of ``compared``."""
    from .en_verdicts import band_verdicts, bed_state
    g = plan.geometry
    diameter = 2.0 * g.half_width
    protocol = "mobilised (fill.mobilise)" if plan.fill.mobilise is not None else (
        f"{plan.fill.protocol}" + (", poured frictionless" if plan.fill.frictionless else ""))
    max_case = loads.values["max_horizontal"]
    fa = summary.get("frame_analyses", {})
    flat_cylinder = g.kind == "cylinder" and g.hopper_height == 0
    state = bed_state(summary.get("force_balance") if flat_cylinder else None, wall_normal_force(plan, table),
                      fa.get("janssen_static"), surface, diameter, max_case.mu, max_case.K, protocol)
    grains_across = diameter / (2.0 * max(gr.radius for gr in plan.grains))
    se = table.set_index("band").reindex(compared.band).static_pressure_stderr.to_numpy(float)
    return state, band_verdicts(compared, se, state, diameter, loads.material.gamma, grains_across)


def wall_normal_force(plan, table) -> float | None:
    """The settled bed's normal force on a cylinder's vertical wall (N): each band's static
    pressure over its area 2 pi R (z1 - z0); None for another silo or without bands."""
    g = plan.geometry
    if g.kind != "cylinder" or table.empty:
        return None
    spans = {w.band: (w.z0, w.z1) for w in plan.walls if w.role == "band"}
    pressure = table.set_index("band").static_pressure
    return float(sum(pressure[b] * 2.0 * math.pi * g.half_width * (z1 - z0) for b, (z0, z1) in spans.items()
                     if b in pressure.index and np.isfinite(pressure[b])))


def _fmt(value, spec: str = ".4g") -> str:
    try:
        return format(float(value), spec)
    except (TypeError, ValueError):
        return "n/a"


def _ci(ci, spec: str = ".3g") -> str:
    return f"[{_fmt(ci[0], spec)}, {_fmt(ci[1], spec)}]" if ci else "[n/a]"


def _ranges(numbers) -> str:
    """1, 2, 3, 5 -> '1-3, 5'."""
    out, run = [], []
    for k in sorted(numbers):
        if run and k != run[-1] + 1:
            out.append(f"{run[0]}-{run[-1]}" if len(run) > 1 else f"{run[0]}")
            run = []
        run.append(k)
    if run:
        out.append(f"{run[0]}-{run[-1]}" if len(run) > 1 else f"{run[0]}")
    return ", ".join(out)


def janssen_lines(j: dict) -> list[str]:
    """The report's lines on the band-true Janssen fit (summary's ``janssen_static``)."""
    if not j:
        return []
    if "K" not in j:
        return [f"- Janssen fit of the settled profile: not fitted: {j.get('error', 'no fit')}"]
    how = (f"band-averaged below the free surface, {j['n_bands_used']} band(s) {_ranges(j['bands_used'])}"
           + ("; corner band excluded" if j.get("exclude_corner") else "; corner band included") + ")")
    values = (f"K = {_fmt(j['K'], '.3f')} {_ci(j['K_ci'])}, mu_eff = {_fmt(j['mu_eff'], '.3f')} {_ci(j['mu_eff_ci'])}, "
              f"mobilisation mu_eff / mu_w = {_fmt(j['mobilisation'], '.2f')} {_ci(j['mobilisation_ci'], '.2f')} "
              f"of mu_w = {_fmt(j['mu_w'], '.3g')}, r2 {_fmt(j['r2'], '.3f')}")
    hyd = (f"  - hydrostatic comparison p = K rho_b g d: K = {_fmt(j['hydrostatic_K'], '.3f')} "
           f"{_ci(j['hydrostatic_K_ci'])}, r2 {_fmt(j['hydrostatic_r2'], '.3f')}")
    if j["resolved"]:
        return [f"- Janssen fit of the settled profile ({how}: {values} (95 % intervals)", hyd]
    return [f"- Janssen fit of the settled profile ({how}: not resolved: {j['reason']}",
            f"  - fitted values, not to be used as material data: {values}", hyd]


def _profile_record(plan) -> dict | None:
    """The plan's numerical profile as a dict (None for a plan written before profiles existed)."""
    profile = getattr(plan, "profile", None)
    return profile.model_dump(mode="json") if profile is not None else None


def profile_line(p: dict | None) -> str:
    """The report's line on the numerical profile (engine.profile) and the error bounds it carries."""
    if not p:
        return "- numerical profile: not recorded (rendered by an older siloflow)"
    line = (f"- numerical profile {p['name']}: time step {_fmt(p['timestep_fraction'], 'g')} of the critical time, "
            f"stiffness x {_fmt(p['stiffness_scale'], 'g')}")
    if p["name"] == "fast":
        bounds = ", ".join(f"{q} {b:.1%}" for q, b in (p.get("error_bounds") or {}).items())
        line += (f"; 95 % error bounds against the papers' settings: {bounds}, measured on the benchmark's case "
                 f"(siloflow bench, {p.get('benchmark')}); another case's own error is not measured" if bounds
                 else "; its error bounds are not measured yet")
    return line


def flow_rate_line(fr: dict) -> str:
    """The report's flow-rate line: the one steady rate, its batch-means error, its window."""
    line = (f"- steady flow rate Wf = {mass_rate(fr['rate'], fr.get('stderr'))} (t = {_fmt(fr['t_start'], '.3g')}-"
            f"{_fmt(fr['t_end'], '.3g')} s, {fr.get('n_samples')} samples, r2 {_fmt(fr['r2'], '.4f')}")
    if fr.get("batches"):
        line += (f"; standard error by batch means of {fr['batches']} batches, the error that matches the spread "
                 f"of seeds (the straight line's own, {mass_rate(fr.get('fit_stderr'), float('nan')).split(' (')[0]},"
                 " takes the samples as independent)")
    elif "batches" in fr:
        line += "; its error is not resolved: the window holds too few samples for batch means"
    return line + ")"


def steady_window_line(steady: dict, fr: dict) -> str:
    """The detected steady window, the dynamic pressures' window; not a second flow rate: its
    median sample rate is compared with Wf in units of Wf's error."""
    line = (f"- steady discharge detected (the window of the dynamic pressures): t = {_fmt(steady['t_start'], '.3g')}-"
            f"{_fmt(steady['t_end'], '.3g')} s")
    if not steady.get("resolved", True):
        return line + f": not resolved: {steady['reason']}"
    line += f" ({steady['n_samples']} samples)"
    diff = steady["median_rate"] - fr["rate"]
    se = fr.get("stderr")
    if se is not None and math.isfinite(se) and se > 0 and abs(diff) > 2 * se:
        line += (f"; its median sample rate {mass_rate(steady['median_rate'], float('nan')).split(' (')[0]} differs "
                 f"from Wf by {diff / se:+.1f} standard errors: the rate drifts over Wf's window (the silo empties "
                 "or the flow is still starting), so Wf is an average over that window")
    return line


def static_cell(b: dict) -> str:
    """A band's static pressure with its error, or why its error is not resolved."""
    value, se = b.get("static_pressure"), b.get("static_pressure_stderr")
    if se is not None and math.isfinite(se):
        return pressure(value, se)
    why = []
    if b.get("static_batches") == 0:
        why.append(f"the static window holds {b.get('static_samples')} samples (batch means need 10)")
    if b.get("static_sectors", 2) < 2:
        why.append("a band of one sector shows no spread around the wall")
    return f"{_fmt(value, '.1f')} Pa (error not resolved: {'; '.join(why) or 'see bands.csv'})"


def en_verdict_lines(en: dict) -> list[str]:
    """The report's bed state and per-band verdicts of the EN comparison (no ratio without one)."""
    state, lines = en.get("bed_state") or {}, []
    if state:
        line = f"The settled bed ({state['protocol']} fill)"
        if state.get("mu_eff") is not None:
            line += (f": the wall carries {state['wall_friction_share']:.2f} of its weight by friction (Janssen with "
                     f"EN's mu = {state['mu_en']:.3g} and K = {state['K_en']:.3g}: {state['janssen_share_en']:.2f}); "
                     f"its friction over its normal force, the mobilised mu_eff, is {state['mu_eff']:.2g} "
                     f"({state['mu_eff'] / state['mu_en']:.2f} of EN's mu), and Janssen's law carries that share with "
                     f"K_eff = {_fmt(state.get('K_eff'), '.2g')}")
        else:
            line += ": its wall friction's mobilisation is not measured (needs the force balance of a flat-bottomed cylinder)"
        if state.get("K_bed") is not None:
            line += f"; its own K = {state['K_bed']:.3g}"
        lines += ["", line + "."]
    verdicts = [b for b in en.get("bands", []) if b.get("static_verdict")]
    if verdicts:
        lines += ["", "Verdicts per band:"]
        for b in verdicts:
            causes = f"; cause: {b['static_causes']}" if b.get("static_causes") else ""
            lines.append(f"- band {b['band']}: static {b['static_verdict']}{causes}; maximum dynamic "
                         f"{b['dynamic_verdict']}")
    return lines


def report_text(summary: dict, run: RunOutputs) -> str:
    """A short human-readable report of a run's results (Markdown)."""
    fb, fr = summary["force_balance"], summary["flow_rate"]
    lines = [f"# Run report: {run.folder.name}", "",
             f"- particles inserted: {summary['particles_inserted']}, mass {_fmt(summary['initial_mass_kg'] * 1000)} g"
             + (f" ({summary['fill_losses']} atoms left the box while pouring; the bed settled without them)"
                if summary.get("fill_losses") else ""),
             f"- settled at KE/PE = {_fmt(summary['settled_ke_pe'], '.2e')}; outlet opened at t = "
             f"{_fmt(summary['time_open_s'])} s",
             (f"- force balance of the settled bed: walls + bottom carry {_fmt(fb['ratio'], '.4f')} x the weight "
              f"({_fmt(fb['wall_friction_share'], '.2f')} of it by wall friction)" if fb else
              "- force balance: not measured (outputs.results asks for neither force_balance nor wall_pressure)"),
             flow_rate_line(fr),
             f"- discharged {_fmt(summary['discharged_mass_kg'] * 1000)} g; {_fmt(summary['mass_in_silo_end_kg'] * 1000)} g left"]
    engine = summary.get("engine")
    if engine:
        lines += [f"- engine: {engine['name']} on {engine['ranks']} MPI rank(s), {_fmt(summary['engine_wall_time_s'], '.3g')} s"]
    lines += [profile_line(summary.get("numerical_profile"))]
    steady = summary.get("steady_window_detected")
    if steady:
        lines += [steady_window_line(steady, fr)]
    fa = summary.get("frame_analyses", {})
    if "bulk_solid_fraction" in fa:
        if "cross_section_solid_fraction" in fa:
            lines += [f"- settled bed: bulk solid fraction {_fmt(fa['bulk_solid_fraction'], '.3f')} (core), "
                      f"{_fmt(fa['cross_section_solid_fraction'], '.3f')} (whole cross-section); bulk density "
                      f"{_fmt(fa['bulk_density_kg_m3'], '.4g')} kg/m3 (core); free surface at "
                      f"{_fmt(fa['settled_surface_height_m'] * 1000)} mm"]
        else:
            lines += [f"- settled bed: free surface at {_fmt(fa['settled_surface_height_m'] * 1000)} mm; "
                      f"no bulk solid fraction: {fa['bulk_solid_fraction']['error']}"]
        if "coordination_settled" in fa:
            c = fa["coordination_settled"]
            lines += [f"- coordination number (core, {fa['coordination_convention']}): {_fmt(c['z_mean'], '.2f')}, "
                      f"mechanical {_fmt(c['z_mech'], '.2f')}"]
        if "flow_rate_surface" in fa:
            wr = fa["flow_rate_surface"]
            if wr.get("resolved", True):
                lines += [f"- free-surface flow rate Wr = {_fmt(wr['rate'] * 1000)} g/s = "
                          f"{_fmt(fa['flow_rate_surface_over_outlet'], '.3f')} +/- "
                          f"{_fmt(fa.get('flow_rate_surface_over_outlet_stderr'), '.2g')} x Wf (the surface descended "
                          f"{_fmt(wr.get('surface_descent_grain_diameters'), '.3g')} grain diameters)"]
            else:
                lines += [f"- free-surface flow rate Wr: not resolved: {wr['reason']}"]
        lines += janssen_lines(fa.get("janssen_static", {}))
    else:
        lines += [f"- frame analyses: {fa.get('dumps', 'none')}"]
    if summary["bands"]:
        ps = summary.get("pressure_statistics") or {}
        win = ps.get("dynamic_window") or {}
        if win.get("t_start") is not None:
            lines += ["", f"Band pressures (Pa). Static: mean over t = {_fmt(ps['static_window']['t_start'], '.3g')}-"
                      f"{_fmt(ps['static_window']['t_end'], '.3g')} s +/- its batch-means standard error. Dynamic: "
                      f"over the {win['source']} t = {_fmt(win['t_start'], '.3g')}-{_fmt(win['t_end'], '.3g')} s "
                      f"({win['n_samples']} samples"
                      + (")" if win.get("resolved", True) else f"; not resolved: {win['reason']})")
                      + "; max dynamic and C_h = max dynamic / static over the whole discharge."]
        lines += ["", "| band | z (m) | static p | dynamic mean +/- sd | p95 | max (window) | max dynamic | C_h |",
                  "|---|---|---|---|---|---|---|---|"]
        for b in summary["bands"]:
            lines.append(f"| {b['band']} | {_fmt(b['z_mid'], '.3f')} | {static_cell(b)} | "
                         f"{_fmt(b.get('dynamic_mean_pressure'), '.1f')} "
                         f"+/- {_fmt(b.get('dynamic_std_pressure'), '.2g')} | {_fmt(b.get('dynamic_p95_pressure'), '.1f')} | "
                         f"{_fmt(b.get('dynamic_max_pressure'), '.1f')} | {_fmt(b['max_dynamic_pressure'], '.1f')} | "
                         f"{_fmt(b['discharge_factor'], '.2f')} |")
    en = summary.get("design_loads") or {}
    if en.get("computed"):
        lines += ["", f"EN 1991-4 beside the DEM ({en['classification']} silo, solid: {en['solid']}; "
                  f"C_h = {_fmt(en['C_h'], '.3g')}): design_vs_dem.csv, design_loads.png", "",
                  "| band | EN p_hf (Pa) | DEM static / p_hf | EN p_he (Pa) | DEM max dynamic / p_he | DEM C_h |",
                  "|---|---|---|---|---|---|"]
        for b in en["bands"]:
            lines.append(f"| {b['band']} | {_fmt(b['en_p_hf'], '.1f')} | {_fmt(b['static_over_p_hf'], '.2f')} | "
                         f"{_fmt(b['en_p_he'], '.1f')} | {_fmt(b['max_dynamic_over_p_he'], '.2f')} | "
                         f"{_fmt(b['dem_discharge_factor'], '.2f')} |")
        lines += en_verdict_lines(en)
    elif en:
        lines += ["", f"EN 1991-4 loads: not computed ({en.get('reason')})"]
    if "pressure_comparison" in summary:
        lines += ["", "| band | max measured (Pa) | max simulated (Pa) | difference | W (Eq. 34) |", "|---|---|---|---|---|"]
        for r in summary["pressure_comparison"]:
            lines.append(f"| {r['band']} | {_fmt(r['max_measured_Pa'], '.1f')} | {_fmt(r['max_simulated_Pa'], '.1f')} | "
                         f"{_fmt(r['relative_difference'], '+.1%')} | {_fmt(r['W'], '.1%')} |")
    warnings = summary.get("engine_warnings") or []
    if warnings:
        lines += ["", f"Engine warnings ({len(warnings)}): see {SUMMARY_NAME}"]
    return "\n".join(lines) + "\n"
