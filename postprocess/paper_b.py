"""Paper B's claims (Rubio-Largo et al. 2016, issue 38) from runs of the polydisperse silo at
several apertures: what was measured, with honest errors, and a computed verdict per claim.

Two steps, so that the report can be made again without the runs:

1. :func:`extract` reads the run folders (results/, dumps) and returns small tables
   (:data:`TABLES`): every quantity measured per **batch**, the steady window of each run cut
   into ``batches`` equal, contiguous time windows. Each batch's coarse-grained fields come
   from its own frames (:func:`postprocess.cg_run.analyse_cg` on the window), its flow rates from
   its own samples. The error of every number is then the batch means' (the spread of the batch
   values / sqrt(batches), Student's t with batches - 1 dof): the frames of a flow are
   autocorrelated, so per-frame errors would understate it, and one fill gives no seed spread.
2. :func:`analyse` computes every claim from those tables: :class:`PaperBAnalysis`, the claim
   rows (``postprocess.claims.ClaimRow``, verdicts by ``postprocess.claims``) and the curves the
   report's figures draw. The report layer (``postprocess.report.claims_report``) writes.

Lengths are in metres in the tables; R is the outlet radius, r_b the largest grain radius,
z the height above the outlet plane, t_d = sqrt(2 r_b / g) paper B's time unit.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from siloflow.errors import ReadError
from siloflow.run_folder import RunFolder

from .claims import (
    FAILS,
    HOLDS,
    NOT_RESOLVED,
    SHOWN,
    ClaimRow,
    Estimate,
    all_of,
    bonferroni,
    collapse,
    follows,
    greater,
    monotonic,
    pooled_mean,
    power_law_exponent,
    within,
)
from .discharge import straight_line_fit
from .numbers import with_error

_STEP = re.compile(r"\.(\d+)\.[A-Za-z]+$")
#: the tables :func:`extract` returns and :func:`analyse` reads (CSV file names), and the study's record
RUNS, BATCHES, FLOW, OUTLET, AXIAL, SPECIES, MAPS, STUDY = (
    "runs.csv", "batches.csv", "flow_series.csv", "outlet_profiles.csv", "axial_profiles.csv",
    "species_axial.csv", "maps.csv", "study.json")
TABLES = (RUNS, BATCHES, FLOW, OUTLET, AXIAL, SPECIES, MAPS)

#: the tolerances that turn paper B's words into testable claims (each said in its row's note)
TOL = {
    "wr_over_wf": 0.10,          # "excellent agreement" of Wr and Wf: their ratio is 1 within 10 %
    "steady_drift": 0.10,        # "a constant flow rate": it drifts less than 10 % over the steady window
    "flow_collapse": 0.10,       # the rescaled flow rates agree within 10 % of their mean
    "profile_collapse": 0.10,    # outlet profiles phi/phi0, v/v0 agree within 0.1 (absolute) at every r/R
    "sqrt_form": 0.10,           # v/v0 within 0.1 of sqrt(1 - (r/R)^2)
    "vz_exponent": 0.15,         # v_z(0) ~ R^b, b = 1/2 within 0.15
    "hc_exponent": 0.25,         # h_c ~ R^b, b = 1 within 0.25
    "kinetic_collapse": 0.15,    # axial p_k / its peak, against z/R: within 0.15 at every point
    "contact_collapse": 0.15,    # axial contact pressure within 15 % of its largest value at every height
    "steepest_share": 0.5,       # no discontinuity: no single kernel width holds half the contact-pressure drop
    "kinetic_over_contact": 0.01,  # "orders of magnitude smaller": p_k / p_c below 1/100 at h_c
    "phi_bulk": 0.02,            # paper: 0.60 +/- 0.02
}
PHI_BULK_PAPER = 0.60
#: points of the outlet profiles' collapse (r/R) and of the kinetic profiles' collapse (z/R)
OUTLET_X = np.round(np.arange(0.1, 0.81, 0.1), 10)
KINETIC_X = np.round(np.arange(0.25, 3.01, 0.25), 10)
#: the (r, z) sums of the batches' coarse-graining: the lattice method, many times faster than exact and
#: within 0.4 % of each field's maximum (docs/coarse_graining.md), far below the batch-to-batch spread
CG_METHOD = "lattice"
#: the contact pressure is tested from the outlet up to this many R
CONTACT_SPAN_R = 3.0
#: the axial tables keep heights up to this many of the largest R
AXIAL_SPAN_R = 8.0


# ------------------------------------------------------------------ extraction (run folders -> tables)

def batch_edges(t_start: float, t_end: float, batches: int) -> np.ndarray:
    """``batches`` + 1 equally spaced times from ``t_start`` to ``t_end`` (s)."""
    if not (t_end > t_start and batches >= 2):
        raise ValueError(f"a window {t_start}-{t_end} s cut into {batches} batches")
    return np.linspace(t_start, t_end, batches + 1)


def slope_in(time, values, t0: float, t1: float) -> float:
    """Least-squares slope of ``values`` against ``time`` over t0 <= time <= t1 (NaN below 3 samples)."""
    t, v = np.asarray(time, float), np.asarray(values, float)
    m = (t >= t0) & (t <= t1) & np.isfinite(v)
    return straight_line_fit(t[m], v[m]).slope if m.sum() >= 3 else float("nan")


def slab_solid_fraction(positions, radii, surface: float, spread: float, d: float, radius: float) -> float:
    """Solid fraction of the slab touching the free surface (paper B's phi_bulk): 3 grain diameters
    ``d`` deep, its top one diameter below the lowest point of the surface (mean height ``surface``
    minus its ring-to-ring ``spread``), over the whole cross-section of ``radius`` (m)."""
    from .overlap_volume import solid_volume_in_cylinder

    top = surface - max(spread, 0.0) - d
    bottom = top - 3 * d
    solid = solid_volume_in_cylinder((0.0, 0.0, 0.0), radius, 2, bottom, top, np.asarray(positions, float),
                                     np.asarray(radii, float))
    return solid / (math.pi * radius ** 2 * (top - bottom))


def peak_height(height, values) -> float:
    """Height of the maximum of ``values`` (the axial kinetic pressure: h_c), refined between grid
    points by the parabola through the largest value and its two neighbours (so that batches differ
    by less than a cell: the error of h_c is not the grid's quantum)."""
    h, v = np.asarray(height, float), np.asarray(values, float)
    ok = np.isfinite(v)
    if not ok.any():
        return float("nan")
    h, v = h[ok], v[ok]
    k = int(np.argmax(v))
    if 0 < k < len(v) - 1:
        denom = v[k - 1] - 2 * v[k] + v[k + 1]
        if denom < 0:
            shift = 0.5 * (v[k - 1] - v[k + 1]) / denom
            return float(h[k] + shift * 0.5 * (h[k + 1] - h[k - 1]))
    return float(h[k])


def files_in(files, lo: int, hi: int):
    """Of a run's per-frame dump files (``<kind>.<step>.<ext>``), those of steps lo..hi, so that a
    batch reads its own frames only; a list whose names carry no step is returned whole."""
    if not files:
        return files
    out = []
    for f in files:
        m = _STEP.search(Path(f).name)
        if m is None:
            return files
        if lo <= int(m.group(1)) <= hi:
            out.append(f)
    return out


def _cells(extent: float, width: float) -> int:
    """Grid cells over ``extent`` (m): three per kernel width ``width``."""
    return max(10, int(math.ceil(extent / (width / 3.0))))


def extract_run(folder, batches: int, width_flow_rb: float, width_stress_rb: float) -> dict:
    """One run's rows of every table (:data:`TABLES`, as lists of dicts / DataFrames)."""
    from .cg_analyses import axial_profiles, outlet_profiles
    from .cg_run import analyse_cg, setup_from_run
    from .dumps import read_frames

    run = RunFolder(folder)
    plan, summary = run.plan, run.read_summary()
    if summary.get("clogged"):
        raise ReadError(f"{folder}: the discharge clogged ({summary['clogged']}); widen the outlet")
    rb = float(max(plan.fill.radii))
    R, Rc = float(plan.geometry.outlet_radius), float(plan.geometry.half_width)
    key = round(R / rb, 6)
    rate = summary["flow_rate"]
    edges = batch_edges(rate["t_start"], rate["t_end"], batches)
    dt = plan.dt
    dis = pd.read_csv(run.results / "discharge.csv")
    surf = pd.read_csv(run.results / "free_surface.csv")
    flows = pd.read_csv(run.results / "flow_rates.csv")
    rho_p = float(plan.grains[0].density)
    fa = summary.get("frame_analyses", summary)

    # phi_bulk of the slab under the free surface, every frame of the steady window
    surf_at = surf.set_index("step")
    wanted = [int(s) for s in surf.step if edges[0] <= s * dt <= edges[-1]]
    phi_frames = []
    in_window = files_in(run.dump_files("particles"), min(wanted, default=0), max(wanted, default=-1))
    for frame in read_frames(in_window, steps=wanted):
        row = surf_at.loc[frame.timestep]
        rad = frame.radii()
        d = 2.0 * float(np.mean(rad))
        spread = float(row.get("surface_spread", 0.0))
        phi_frames.append((frame.timestep * dt, slab_solid_fraction(
            frame.positions(), rad, float(row.surface_height), spread if math.isfinite(spread) else 0.0, d, Rc)))
    phi_t = np.array(phi_frames) if phi_frames else np.empty((0, 2))

    setup = setup_from_run(run)
    w_flow, w_stress = width_flow_rb * rb, width_stress_rb * rb
    nr, nz = _cells(setup.r_max, min(w_flow, w_stress)), _cells(setup.z_hi - setup.z_lo, min(w_flow, w_stress))
    z_keep = AXIAL_SPAN_R * R
    batch_rows, outlet_rows, axial_rows, species_rows = [], [], [], []
    maps = None
    for b in range(batches):
        t0, t1 = float(edges[b]), float(edges[b + 1])
        lo = int(math.ceil(t0 / dt))
        hi = int(math.floor(t1 / dt)) if b == batches - 1 else int(math.ceil(t1 / dt)) - 1
        window = replace(setup, step_lo=lo, step_hi=hi, atoms=files_in(setup.atoms, lo, hi),
                         contacts=files_in(setup.contacts, lo, hi), wall_contacts=files_in(setup.wall_contacts, lo, hi),
                         primitive_walls=[(w, files_in(f, lo, hi)) for w, f in setup.primitive_walls])
        flow = analyse_cg(window, "gaussian", w_flow, "m", nr, nz, species="radius", method=CG_METHOD).dataset
        stress = flow if w_stress == w_flow else analyse_cg(window, "gaussian", w_stress, "m", nr, nz, method=CG_METHOD,
                                                             species="radius").dataset
        prof = outlet_profiles(flow, setup.z_outlet, R)
        axial = axial_profiles(stress, setup.z_outlet)
        above = axial.height >= 0          # the grid reaches below the outlet plane, where grains fall free
        h_c = peak_height(axial.height[above].to_numpy(), axial.kinetic_pressure[above].to_numpy())
        in_b = (phi_t[:, 0] >= t0) & (phi_t[:, 0] <= t1) if len(phi_t) else np.zeros(0, bool)
        phi_slab = float(np.nanmean(phi_t[in_b, 1])) if in_b.any() else float("nan")
        wf = slope_in(dis.time, dis.outlet_mass, t0, t1)
        s_in = (surf.step * dt >= t0) & (surf.step * dt <= t1)
        v_s = -slope_in(surf.step[s_in] * dt, surf.surface_height[s_in], t0, t1)
        wr = v_s * math.pi * Rc ** 2 * rho_p * float(phi_slab)
        batch_rows.append({"R_over_rb": key, "batch": b, "t0": t0, "t1": t1, "frames": int(flow.attrs["frames"]),
                           "Wf": wf, "Wr": wr, "surface_speed": v_s, "phi_bulk": float(phi_slab),
                           "phi_c": float(prof.solid_fraction.iloc[0]), "v_c": float(-prof.v_z.iloc[0]),
                           "h_c": h_c})
        for r in prof.itertuples():
            outlet_rows.append({"R_over_rb": key, "batch": b, "r": r.r, "r_over_R": r.r_over_R,
                                "solid_fraction": r.solid_fraction, "v_z": r.v_z})
        keep = axial.height <= z_keep
        for r in axial[keep].itertuples():
            axial_rows.append({"R_over_rb": key, "batch": b, "height": r.height,
                               "contact_pressure": getattr(r, "contact_pressure", np.nan),
                               "kinetic_pressure": r.kinetic_pressure, "solid_fraction": r.solid_fraction,
                               "v_z": r.v_z})
        col = stress.isel(r=0)
        heights = stress.z.values - setup.z_outlet
        partial = col.solid_fraction_species if "solid_fraction_species" in col else col.rho_species / rho_p
        for k, radius in enumerate(np.asarray(stress.species.values, float)):
            pk = col.kinetic_pressure_species.isel(species=k).values
            ph = partial.isel(species=k).values
            for h, p, f in zip(heights, pk, ph):
                if h <= z_keep:
                    species_rows.append({"R_over_rb": key, "batch": b, "radius": radius, "height": h,
                                         "kinetic_pressure": p, "solid_fraction": f})
        fields = {"contact_pressure": stress.contact_pressure.values, "kinetic_pressure": stress.kinetic_pressure.values,
                  "solid_fraction": flow.solid_fraction.values, "v_z": flow.velocity.sel(component="z").values}
        maps = fields if maps is None else {k: maps[k] + v for k, v in fields.items()}
    zz, rr = np.meshgrid(flow.z.values - setup.z_outlet, flow.r.values, indexing="ij")
    map_table = pd.DataFrame({"R_over_rb": key, "height": zz.ravel(), "r": rr.ravel(),
                              **{k: (v / batches).ravel() for k, v in maps.items()}})
    record = run.record
    run_row = {"R_over_rb": key, "R": R, "rb": rb, "Rc": Rc, "rho_p": rho_p, "g": float(plan.gravity),
               "dt": dt, "t_open": summary["time_open_s"], "t_start": float(edges[0]), "t_end": float(edges[-1]),
               "batches": batches, "width_flow": w_flow, "width_stress": w_stress, "nr": nr, "nz": nz,
               "particles": summary.get("particles_inserted"), "initial_mass": summary.get("initial_mass_kg"),
               "discharged_mass": summary.get("discharged_mass_kg"),
               "run_flow_rate": rate["rate"], "run_flow_rate_stderr": rate.get("stderr"),
               "settled_bulk_solid_fraction": fa.get("bulk_solid_fraction") if isinstance(
                   fa.get("bulk_solid_fraction"), float) else np.nan,
               "engine_wall_s": float(record.wall_time)}
    flow_series = flows.assign(R_over_rb=key)[["R_over_rb", "time", "Wf_kg_s", "Wr_kg_s"]]
    return {RUNS: [run_row], BATCHES: batch_rows, FLOW: flow_series, OUTLET: outlet_rows, AXIAL: axial_rows,
            SPECIES: species_rows, MAPS: map_table}


def significant(table: pd.DataFrame, digits: int = 6) -> pd.DataFrame:
    """``table`` with every float rounded to ``digits`` significant digits (small CSV files)."""
    out = table.copy()
    for c in out.columns:
        if out[c].dtype.kind == "f":
            v = out[c].to_numpy()
            with np.errstate(divide="ignore", invalid="ignore"):
                mag = np.where(np.isfinite(v) & (v != 0), np.floor(np.log10(np.abs(v))), 0)
                scale = 10.0 ** (digits - 1 - mag)
                out[c] = np.where(np.isfinite(v), np.round(v * scale) / scale, v)
    return out


def extract(folders, batches: int, width_flow_rb: float, width_stress_rb: float) -> dict:
    """Every table (:data:`TABLES`: name -> DataFrame) of the runs in ``folders`` (one per aperture),
    floats to 6 significant digits (5 for the maps)."""
    parts = [extract_run(f, batches, width_flow_rb, width_stress_rb) for f in folders]
    out = {}
    for name in TABLES:
        frames = [p[name] if isinstance(p[name], pd.DataFrame) else pd.DataFrame(p[name]) for p in parts]
        table = pd.concat(frames, ignore_index=True).sort_values(["R_over_rb"], kind="stable").reset_index(drop=True)
        out[name] = significant(table, 5 if name == MAPS else 6)
    return out


def read_tables(folder) -> dict:
    """The tables :func:`extract` returned, as written (CSV) in ``folder``."""
    folder = Path(folder)
    missing = [n for n in TABLES if not (folder / n).is_file()]
    if missing:
        raise ReadError(f"{folder}: missing {', '.join(missing)}")
    return {n: pd.read_csv(folder / n) for n in TABLES}


# ------------------------------------------------------------------ analysis (tables -> claims)

def batch_estimate(values) -> Estimate:
    """The mean of a run's batch values and its batch-means error (batches - 1 dof)."""
    return Estimate.of_samples(np.asarray(values, float))


def _fmt(e: Estimate, unit: str = "", scale: float = 1.0) -> str:
    return with_error(e.value * scale, e.stderr * scale, unit)


def _ci(e: Estimate, scale: float = 1.0, spec: str = ".3g") -> str:
    lo, hi = e.interval()
    dof = "inf" if math.isinf(e.dof) else f"{e.dof:.3g}"
    return f"95 % [{lo * scale:{spec}}, {hi * scale:{spec}}], {dof} dof"


def _per_aperture(keys, ests, unit: str = "", scale: float = 1.0) -> tuple[str, str]:
    """'R = 4.5 r_b: 1.02 +/- 0.03; ...' and the standard errors' column for the same."""
    ours = "; ".join(f"{k:g} r_b: {_fmt(e, unit, scale)}" for k, e in zip(keys, ests))
    unc = "; ".join(f"{k:g} r_b: {_ci(e, scale)}" for k, e in zip(keys, ests))
    return ours, unc


def _profile_estimates(table: pd.DataFrame, x: str, y: str, grid: np.ndarray) -> list[Estimate] | None:
    """One Estimate per grid point: the batch means of ``y`` interpolated at ``grid`` (in ``x``)."""
    rows = []
    for _, g in table.groupby("batch"):
        g = g.sort_values(x)
        if g[x].min() > grid.min() or g[x].max() < grid.max():
            return None
        rows.append(np.interp(grid, g[x].to_numpy(), g[y].to_numpy()))
    a = np.array(rows)
    if len(a) < 2 or not np.isfinite(a).all():
        return None
    return [Estimate.of_samples(a[:, k]) for k in range(a.shape[1])]


@dataclass
class PaperBAnalysis:
    """Paper B's claims computed: ``rows`` (the claims table, in the paper's order), ``curves``
    (name -> DataFrame: what the figures draw, each with its batch-means error), ``numbers``
    (name -> value: the study's numbers the report states)."""

    rows: list
    curves: dict = field(default_factory=dict)
    numbers: dict = field(default_factory=dict)


def analyse(tables: dict, study: dict | None = None) -> PaperBAnalysis:
    """Every claim of paper B from the tables of :func:`extract` (or :func:`read_tables`)."""
    runs = tables[RUNS].sort_values("R_over_rb").reset_index(drop=True)
    bat = tables[BATCHES]
    keys = list(runs.R_over_rb)
    n_ap = len(keys)
    if n_ap < 2:
        raise ReadError("paper B's claims need runs at two apertures at least")
    R = dict(zip(keys, runs.R))
    rb = float(runs.rb.iloc[0])
    g = float(runs.g.iloc[0])
    rho_p = float(runs.rho_p.iloc[0])
    t_d = math.sqrt(2 * rb / g)
    w_stress = float(runs.width_stress.iloc[0])
    by = {k: bat[bat.R_over_rb == k].sort_values("batch") for k in keys}
    rows: list[ClaimRow] = []
    curves: dict = {}
    numbers: dict = {"t_d": t_d, "rb": rb, "apertures_rb": keys, "R": [R[k] for k in keys],
                     "batches": int(runs.batches.iloc[0]), "width_flow": float(runs.width_flow.iloc[0]),
                     "width_stress": w_stress, "rho_p": rho_p}
    level = bonferroni(n_ap)

    # -- flow rates: Wf(t), Wr(t) and their steady means
    wf = [batch_estimate(by[k].Wf) for k in keys]
    wr_over = [batch_estimate(by[k].Wr / by[k].Wf) for k in keys]
    ours, unc = _per_aperture(keys, wf, "kg/s")
    rows.append(ClaimRow("Wf(t): steady mass flow rate through the outlet", "Fig. 2a (R = 12 r_b and others)",
                         ours, unc, SHOWN, "mean of the batch slopes of the discharged mass; figure flow_rates.png"))
    ours, unc = _per_aperture(keys, wr_over)
    rows.append(ClaimRow(
        "Wr(t) = v_s pi Rc^2 rho_p phi_bulk agrees with Wf(t) (weak segregation)", "\"excellent agreement\" (Fig. 2a)",
        ours, unc, all_of([within(e, 1.0, TOL["wr_over_wf"], confidence=level) for e in wr_over]),
        f"Wr/Wf per batch (v_s: the free surface's speed, phi_bulk: the slab under it); holds if 1 within "
        f"{TOL['wr_over_wf']:.0%} at every aperture (Bonferroni over {n_ap})"))
    drifts = []
    for k in keys:
        b = by[k]
        mid = 0.5 * (b.t0 + b.t1).to_numpy()
        fit = straight_line_fit(mid, b.Wf.to_numpy())
        span = float(b.t1.max() - b.t0.min())
        mean = float(b.Wf.mean())
        dof = max(len(b) - 2, 1)
        drifts.append(Estimate(fit.slope * span / mean, (fit.stderr if math.isfinite(fit.stderr) else 0.0)
                               * span / mean, dof))
    onset = [(float(runs.t_start[runs.R_over_rb == k].iloc[0]) - float(runs.t_open[runs.R_over_rb == k].iloc[0])) / t_d
             for k in keys]
    numbers["steady_onset_td"] = onset
    ours, unc = _per_aperture(keys, drifts, scale=100.0)
    rows.append(ClaimRow(
        "The flow quickly reaches a steady state of constant flow rate", "\"quickly evolves to a steady state\"",
        ours.replace(" r_b:", " r_b: drift") + " % over the window",
        unc, all_of([within(e, 0.0, TOL["steady_drift"], confidence=level) for e in drifts]),
        "steady window from " + ", ".join(f"{o:.1f}" for o in onset) + " t_d after opening; drift = the "
        f"batch rates' straight-line change over the window / their mean; holds if within "
        f"+/-{TOL['steady_drift']:.0%} at every aperture"))

    # -- the flow-rate collapse W / (rho_p phi_c v_c pi R^2)
    resc = [batch_estimate(by[k].Wf / (rho_p * by[k].phi_c * by[k].v_c * math.pi * R[k] ** 2)) for k in keys]
    mean_resc = float(np.mean([e.value for e in resc]))
    ours, unc = _per_aperture(keys, resc)
    rows.append(ClaimRow(
        "Flow rate collapses when divided by rho_p phi_c v_c pi R^2", "Fig. 2b: the curves collapse",
        ours, unc, collapse([[e] for e in resc], TOL["flow_collapse"] * mean_resc),
        f"phi_c, v_c: solid fraction and v_z at the outlet's centre (coarse-grained, w = "
        f"{numbers['width_flow'] / rb:g} r_b), per batch; holds if every pair agrees within "
        f"{TOL['flow_collapse']:.0%} of the mean ({mean_resc:.3g})"))

    # -- outlet profiles
    out = tables[OUTLET]
    prof_curves, phi_c, v_c = {}, {}, {}
    for k in keys:
        o = out[out.R_over_rb == k].copy()
        first = o.groupby("batch").r.transform("min")
        centre = o[o.r == first].set_index("batch")
        o["phi_n"] = o.solid_fraction / o.batch.map(centre.solid_fraction)
        o["v_n"] = o.v_z / o.batch.map(centre.v_z)
        phi_c[k] = _profile_estimates(o, "r_over_R", "phi_n", OUTLET_X)
        v_c[k] = _profile_estimates(o, "r_over_R", "v_n", OUTLET_X)
        mean = o.groupby("r_over_R")[["phi_n", "v_n"]].agg(["mean", "std", "count"])
        prof_curves[k] = pd.DataFrame({"r_over_R": mean.index, "phi_n": mean["phi_n"]["mean"].to_numpy(),
                                       "phi_n_se": (mean["phi_n"]["std"] / np.sqrt(mean["phi_n"]["count"])).to_numpy(),
                                       "v_n": mean["v_n"]["mean"].to_numpy(),
                                       "v_n_se": (mean["v_n"]["std"] / np.sqrt(mean["v_n"]["count"])).to_numpy()})
    curves["outlet"] = prof_curves
    grid_txt = f"r/R = {OUTLET_X[0]:g}-{OUTLET_X[-1]:g} step 0.1"
    for name, ests, what in (("phi_n", phi_c, "phi(r)/phi(0)"), ("v_n", v_c, "v_z(r)/v_z(0)")):
        ok = all(ests[k] is not None for k in keys)
        spread = max(abs(ests[i][j].value - ests[m][j].value) for i in keys for m in keys
                     for j in range(len(OUTLET_X))) if ok else float("nan")
        rows.append(ClaimRow(
            f"{what} at the outlet collapses against r/R", "Figs. 4b, 5b: the data collapse",
            f"largest difference between apertures {spread:.3f}" if ok else "n/a",
            "batch-means error per point" if ok else "profile does not span the grid",
            collapse([ests[k] for k in keys], TOL["profile_collapse"]) if ok else NOT_RESOLVED,
            f"{grid_txt}, each aperture's batches interpolated there; holds if every pair agrees within "
            f"{TOL['profile_collapse']:g} at every point (Bonferroni over pairs and points)"))
    model = np.sqrt(1 - OUTLET_X ** 2)
    ok = all(v_c[k] is not None for k in keys)
    dev = [max(abs(e.value - m) for e, m in zip(v_c[k], model)) for k in keys] if ok else []
    rows.append(ClaimRow(
        "v_z(r)/v_z(0) = sqrt(1 - (r/R)^2) at the outlet", "Fig. 5b's line",
        "; ".join(f"{k:g} r_b: largest deviation {d:.3f}" for k, d in zip(keys, dev)) if ok else "n/a",
        "batch-means error per point",
        all_of([follows(v_c[k], model, TOL["sqrt_form"], confidence=level) for k in keys]) if ok else NOT_RESOLVED,
        f"{grid_txt}; holds if every point is within {TOL['sqrt_form']:g} of the form at every aperture"))

    # -- v_z(0) ~ sqrt(R), h_c ~ R
    vz0 = [batch_estimate(by[k].v_c) for k in keys]
    b_v = power_law_exponent([R[k] for k in keys], vz0)
    ours, _ = _per_aperture(keys, vz0, "m/s")
    rows.append(ClaimRow("v_z(0) ~ sqrt(R)", "exponent 1/2", f"exponent {_fmt(b_v)} (v_z(0): {ours})", _ci(b_v),
                         within(b_v, 0.5, TOL["vz_exponent"]),
                         f"weighted fit of log v_z(0) on log R (Birge-scaled error); holds if 0.5 within "
                         f"{TOL['vz_exponent']:g}"))
    hc = [batch_estimate(by[k].h_c) for k in keys]
    numbers["h_c"] = hc
    try:
        b_h = power_law_exponent([R[k] for k in keys], hc)
        hc_verdict, hc_txt, hc_ci = within(b_h, 1.0, TOL["hc_exponent"]), f"exponent {_fmt(b_h)}", _ci(b_h)
    except ValueError as exc:
        hc_verdict, hc_txt, hc_ci = NOT_RESOLVED, f"no fit ({exc})", "n/a"
    rows.append(ClaimRow(
        "The kinetic-pressure peak height h_c scales with R", "h_c(R) depends on R; profiles collapse against z/R",
        f"{hc_txt}; h_c/R: " + "; ".join(f"{k:g} r_b: {_fmt(e, scale=1 / R[k])}" for k, e in zip(keys, hc)),
        hc_ci, hc_verdict, f"h_c: the height of the largest axial kinetic pressure, per batch (w = "
        f"{w_stress / rb:g} r_b); holds if the exponent is 1 within {TOL['hc_exponent']:g}"))

    # -- axial pressure profiles
    ax = tables[AXIAL]
    axial_curves = {}
    for k in keys:
        a = ax[ax.R_over_rb == k]
        m = a.groupby("height")[["contact_pressure", "kinetic_pressure", "solid_fraction", "v_z"]].agg(["mean", "std", "count"])
        axial_curves[k] = pd.DataFrame({"height": m.index, **{
            f"{c}{s}": (m[c]["mean"] if s == "" else m[c]["std"] / np.sqrt(m[c]["count"])).to_numpy()
            for c in ("contact_pressure", "kinetic_pressure", "solid_fraction", "v_z") for s in ("", "_se")}})
    curves["axial"] = axial_curves

    def at_heights(k, col, heights):
        return _profile_estimates(ax[ax.R_over_rb == k], "height", col, np.asarray(heights, float))

    # contact pressure: monotonic towards the outlet, no discontinuity, independent of R
    mono, steep, steep_v = [], [], []
    for k in keys:
        hs = np.arange(0.0, CONTACT_SPAN_R * R[k] + 1e-12, w_stress)      # from the outlet plane up
        pc = at_heights(k, "contact_pressure", hs)
        mono.append(monotonic(pc, increasing=True, confidence=level) if pc else NOT_RESOLVED)
        a = ax[ax.R_over_rb == k]
        shares = []
        for _, gb in a.groupby("batch"):
            p = np.interp(hs, gb.height, gb.contact_pressure)
            total = p[-1] - p[0]
            shares.append(np.max(np.diff(p)) / total if total > 0 else np.nan)
        e = batch_estimate(shares) if np.isfinite(shares).all() else None
        steep_v.append(e)
        steep.append(greater(Estimate(TOL["steepest_share"]), e, confidence=level) if e else NOT_RESOLVED)
    rows.append(ClaimRow(
        "Contact pressure decreases monotonically towards the outlet", "Fig. 6; \"monotonically decreases\"",
        "; ".join(f"{k:g} r_b: {v}" for k, v in zip(keys, mono)), "batch-means error per point",
        all_of(mono), f"on the axis from the outlet to {CONTACT_SPAN_R:g} R, points one kernel width "
        f"({w_stress / rb:g} r_b) apart; holds if the rise is resolved and no step is resolved against it"))
    ok = all(e is not None for e in steep_v)
    ours, unc = _per_aperture(keys, steep_v) if ok else ("n/a", "n/a")
    rows.append(ClaimRow(
        "No discontinuity in the contact stress (no free-fall arch)", "\"discontinuities in the stress field are not found\"",
        ours, unc, all_of(steep) if ok else NOT_RESOLVED,
        f"the largest rise of the axial contact pressure over one kernel width, as a share of its rise "
        f"from the outlet to {CONTACT_SPAN_R:g} R; holds if below {TOL['steepest_share']:g} at every aperture"))
    h_common = np.arange(w_stress, CONTACT_SPAN_R * min(R.values()) + 1e-12, w_stress)
    pcs = [at_heights(k, "contact_pressure", h_common) for k in keys]
    if all(pcs):
        scale = max(e.value for p in pcs for e in p)
        spread = max(abs(pcs[i][j].value - pcs[m][j].value) for i in range(n_ap) for m in range(n_ap)
                     for j in range(len(h_common))) / scale
        v = collapse(pcs, TOL["contact_collapse"] * scale)
    else:
        spread, v = float("nan"), NOT_RESOLVED
    rows.append(ClaimRow(
        "Contact pressure nearly independent of the outlet size", "\"nearly independent of the outlet size\"",
        f"largest difference between apertures {spread:.1%} of the largest pressure", "batch-means error per point",
        v, f"on the axis at the same heights z = {h_common[0] * 100:.2g}-{h_common[-1] * 100:.2g} cm; holds if "
        f"every pair agrees within {TOL['contact_collapse']:.0%} of the largest pressure"))

    # kinetic pressure: peak (transition) and its collapse against z/R
    peaks, ratio_kc, ratio_local, kin_n = [], [], [], {}
    for k in keys:
        h = hc[keys.index(k)].value
        pts = at_heights(k, "kinetic_pressure", [0.0, h, min(3 * h, AXIAL_SPAN_R * R[k])])
        if pts:
            peaks += [greater(pts[1], pts[0], confidence=bonferroni(2 * n_ap)),
                      greater(pts[1], pts[2], confidence=bonferroni(2 * n_ap))]
        else:
            peaks.append(NOT_RESOLVED)
        a = ax[ax.R_over_rb == k].copy()
        rk, local = [], []
        for _, gb in a.groupby("batch"):
            rk.append(float(gb.kinetic_pressure.max() / gb.contact_pressure.max()))
            local.append(float(np.interp(h, gb.height, gb.kinetic_pressure) / np.interp(h, gb.height, gb.contact_pressure)))
        ratio_kc.append(batch_estimate(rk))
        ratio_local.append(float(np.mean(local)))
        a["x"] = a.height / R[k]
        a["pk_n"] = a.kinetic_pressure / a.groupby("batch").kinetic_pressure.transform("max")
        kin_n[k] = _profile_estimates(a, "x", "pk_n", KINETIC_X)
    rows.append(ClaimRow(
        "Kinetic pressure peaks at a transition height h_c above the outlet", "Figs. 7-8: a well-defined maximum",
        "h_c/R: " + "; ".join(f"{k:g} r_b: {_fmt(e, scale=1 / R[k])}" for k, e in zip(keys, hc)),
        "; ".join(f"{k:g} r_b: h_c {_fmt(e, 'cm', 100)}" for k, e in zip(keys, hc)),
        all_of(peaks), "holds if, on the axis, p_k(h_c) exceeds both p_k at the outlet and p_k at 3 h_c "
        "(resolved, Bonferroni over the 2 tests x apertures)"))
    ok = all(kin_n[k] is not None for k in keys)
    if ok:
        spread = max(abs(kin_n[i][j].value - kin_n[m][j].value) for i in keys for m in keys for j in range(len(KINETIC_X)))
    rows.append(ClaimRow(
        "Axial kinetic-pressure profiles collapse against z/R", "Fig. 8a: the data collapse",
        f"largest difference {spread:.3f} (of the peak)" if ok else "n/a", "batch-means error per point",
        collapse([kin_n[k] for k in keys], TOL["kinetic_collapse"]) if ok else NOT_RESOLVED,
        f"p_k / its batch's peak on the axis at z/R = {KINETIC_X[0]:g}-{KINETIC_X[-1]:g} step 0.25; holds if "
        f"every pair agrees within {TOL['kinetic_collapse']:g}"))
    curves["kinetic_collapsed"] = kin_n
    ours, unc = _per_aperture(keys, ratio_kc)
    rows.append(ClaimRow(
        "Kinetic pressure is orders of magnitude below the contact pressure", "\"several orders of magnitude smaller\"",
        ours, unc, all_of([greater(Estimate(TOL["kinetic_over_contact"]), e, confidence=level) for e in ratio_kc]),
        f"the strengths of the two fields (Figs. 6-7): the largest kinetic pressure on the axis over the largest "
        f"contact pressure on the axis, per batch; holds if below {TOL['kinetic_over_contact']:g} at every aperture. "
        "Locally, at h_c, where the contact pressure has fallen towards the outlet, p_k/p_c is "
        + ", ".join(f"{v:.3g}" for v in ratio_local)))

    # -- partial kinetic pressure per size, at h_c on the axis
    sp = tables[SPECIES]
    big, norm, sp_curves = [], [], {}
    big_txt, norm_txt = [], []
    for k in keys:
        s = sp[sp.R_over_rb == k]
        h = hc[keys.index(k)].value
        radii = np.sort(s.radius.unique())
        pk, ratio = [], []
        for r in radii:
            sr = s[s.radius == r]
            pk.append(_profile_estimates(sr, "height", "kinetic_pressure", np.array([h]))[0])
            per = []
            for _, gb in sr.groupby("batch"):
                p_ = float(np.interp(h, gb.height, gb.kinetic_pressure))
                f_ = float(np.interp(h, gb.height, gb.solid_fraction))
                per.append(p_ / f_ if f_ > 0 else np.nan)
            ratio.append(batch_estimate(per))
        big.append(monotonic(pk, increasing=True, confidence=level))
        norm.append(greater(ratio[0], ratio[-1], confidence=level))
        big_txt.append(f"{k:g} r_b: largest/smallest {pk[-1].value / pk[0].value:.2f}" if pk[0].value else f"{k:g} r_b: n/a")
        norm_txt.append(f"{k:g} r_b: smallest/largest {ratio[0].value / ratio[-1].value:.2f}" if ratio[-1].value else
                        f"{k:g} r_b: n/a")
        sp_curves[k] = pd.DataFrame({"radius": radii, "p_k": [e.value for e in pk], "p_k_se": [e.stderr for e in pk],
                                     "p_k_over_phi": [e.value for e in ratio],
                                     "p_k_over_phi_se": [e.stderr for e in ratio]})
    curves["species_at_hc"] = sp_curves
    curves["species_axial"] = {k: sp[sp.R_over_rb == k].groupby(["radius", "height"], as_index=False)[
        ["kinetic_pressure", "solid_fraction"]].mean() for k in keys}
    rows.append(ClaimRow(
        "Partial kinetic pressure is larger for bigger particles", "Fig. 11: \"larger for bigger particles\"",
        "; ".join(big_txt), "batch-means error per size", all_of(big),
        "the 7 sizes' partial kinetic pressure on the axis at h_c; holds if it rises with the radius "
        "(monotonic: the rise resolved, no step resolved against it) at every aperture"))
    rows.append(ClaimRow(
        "Small particles carry more kinetic stress than their volume fraction",
        "Fig. 12: p_k,j / phi_j larger for small particles",
        "; ".join(norm_txt), "batch-means error per size", all_of(norm),
        "partial kinetic pressure / partial solid fraction on the axis at h_c; holds if the smallest "
        "size's exceeds the largest's (resolved) at every aperture"))

    # -- phi_bulk
    phis = [batch_estimate(by[k].phi_bulk) for k in keys]
    pooled = pooled_mean(phis)
    settled = runs.settled_bulk_solid_fraction.to_numpy(float)
    rows.append(ClaimRow(
        "Bulk solid fraction phi_bulk", f"{PHI_BULK_PAPER:.2f} +/- {TOL['phi_bulk']:.2f}",
        f"{_fmt(pooled)} (" + "; ".join(f"{k:g} r_b: {_fmt(e)}" for k, e in zip(keys, phis)) + ")",
        _ci(pooled), within(pooled, PHI_BULK_PAPER, TOL["phi_bulk"]),
        "the slab 3 grain diameters deep just under the free surface's lowest point, every frame of the steady "
        "window, mean of the apertures; holds if 0.60 within 0.02"
        + (f"; the settled bed's core before opening: {np.nanmean(settled):.3f}" if np.isfinite(settled).any() else "")))

    # -- maps and figures only
    rows.append(ClaimRow("Contact pressure map and its axial profile", "Fig. 6", "figures contact_pressure.png",
                         "-", SHOWN, "azimuthal and steady-window average"))
    rows.append(ClaimRow("Kinetic pressure maps and axial profiles against z/R", "Figs. 7-8",
                         "figures kinetic_pressure.png", "-", SHOWN, "azimuthal and steady-window average"))
    numbers["verdicts"] = {v: sum(r.verdict == v for r in rows) for v in (HOLDS, FAILS, NOT_RESOLVED, SHOWN)}
    curves["maps"] = tables[MAPS]
    curves["flow"] = tables[FLOW]
    curves["rescaled"] = dict(zip(keys, resc))
    curves["phi_c"] = {k: batch_estimate(by[k].phi_c) for k in keys}
    curves["v_c"] = {k: batch_estimate(by[k].v_c) for k in keys}
    curves["t_open"] = dict(zip(keys, runs.t_open))
    curves["window"] = {k: (float(runs.t_start[i]), float(runs.t_end[i])) for i, k in enumerate(keys)}
    curves["vz0"] = dict(zip(keys, vz0))
    curves["hc"] = dict(zip(keys, hc))
    numbers["R_by_key"] = R
    numbers["vz_exponent"] = b_v
    return PaperBAnalysis(rows, curves, numbers)
