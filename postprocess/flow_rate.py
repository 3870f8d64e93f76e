"""Flow rate two ways (paper B) and the Beverloo fit.

* Wf(t): the rate at which mass leaves through the outlet, from the discharged mass (kg) vs
  time (s) (LIGGGHTS massflow/mesh, or any cumulative count).
* Wr(t) = -dh/dt * A * rho_p * phi_bulk: from the speed of the free surface h(t) (m) in the
  cylinder section (area A, m2), with the bulk solid fraction phi_bulk.
* Steady state: the longest stretch in which the rate stays within a tolerance of its median.
* Beverloo: W = C rho_b sqrt(g) (D0 - k d)^(5/2), C and k fitted across runs, with standard errors;
  a run that clogged or never flowed steadily is no point of it (:func:`flow_verdict`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.optimize import curve_fit

from siloflow.run_folder import RunFolder
from siloflow.errors import ReadError
from siloflow.silos.registry import silo_kind

from .analysis_base import FrameAnalysis
from .discharge import FlowRate, straight_line_fit


def rate_series(time, cumulative, window: int = 5) -> np.ndarray:
    """d(cumulative)/dt (units/s) by a least-squares slope over ``window`` samples centred on each one."""
    t = np.asarray(time, float)
    m = np.asarray(cumulative, float)
    half = max(1, window // 2)
    out = np.full(len(t), np.nan)
    for k in range(len(t)):
        lo, hi = max(0, k - half), min(len(t), k + half + 1)
        if hi - lo >= 3:
            tt = t[lo:hi] - t[lo:hi].mean()
            out[k] = float((tt * (m[lo:hi] - m[lo:hi].mean())).sum() / (tt * tt).sum())
    return out


def steady_window(rate, tolerance: float = 0.15) -> tuple[int, int]:
    """Index range [i0, i1) of the longest run of samples whose rate is within ``tolerance``
    (relative) of the median of the positive rates; (0, 0) if there is none."""
    rate = np.asarray(rate, float)
    good = np.isfinite(rate) & (rate > 0)
    if not good.any():
        return 0, 0
    med = float(np.median(rate[good]))
    ok = good & (np.abs(rate - med) <= tolerance * med)
    best, start = (0, 0), None
    for k, flag in enumerate(np.append(ok, False)):
        if flag and start is None:
            start = k
        elif not flag and start is not None:
            if k - start > best[1] - best[0]:
                best = (start, k)
            start = None
    return best


def linear_rate(time, values) -> FlowRate:
    """Slope (units of ``values`` per s) of ``values`` against ``time`` (s) and its standard
    error, by ``discharge.straight_line_fit``, as a :class:`discharge.FlowRate` (rate, stderr,
    window, n_samples; no r2, fit_stderr or batches); all NaN but n_samples if fewer than 3
    samples."""
    t = np.asarray(time, float)
    v = np.asarray(values, float)
    if len(t) < 3:
        return FlowRate(float("nan"), float("nan"), float("nan"), float("nan"), len(t))
    fit = straight_line_fit(t, v)
    return FlowRate(fit.slope, fit.stderr, fit.t_start, fit.t_end, fit.n_samples)


class FreeSurface(FrameAnalysis):
    """Height (m) of the free surface per frame, averaged over the whole cross-section.

    The cross-section (radius ``radius`` about (``x0``, ``y0``)) is cut into ``annuli`` rings
    of equal area (default: about 8 (R/d)^2 / 64, at least 2). In each ring the solid
    fraction profile phi(z) is binned (bins of one grain diameter, grain volume at its
    centre) and the surface is where phi falls below half the ring's bulk value (the median
    of its filled bins), interpolated between bins. The surface height is the mean over the
    rings: for a crater or a heap this tracks the volume of the bed, unlike the highest grain.
    Grains below ``z_min`` (the hopper, the outlet) are ignored.

    A slab silo (``thickness`` given): the cross-section is |x - x0| < ``radius`` (its half
    width) by the thickness, cut into strips of equal width instead of rings.
    """

    name = "free_surface"

    def __init__(self, radius: float, x0: float = 0.0, y0: float = 0.0, z_min: float = 0.0,
                 annuli: int | None = None, timestep: float = 1.0, thickness: float | None = None):
        super().__init__()
        self.radius, self.x0, self.y0, self.z_min, self.annuli, self.dt = radius, x0, y0, z_min, annuli, timestep
        self.thickness = thickness

    @property
    def area(self) -> float:
        """Area of the cross-section, m2."""
        if self.thickness is not None:
            return 2.0 * self.radius * self.thickness
        return np.pi * self.radius ** 2

    def _single_frame(self, frame, contacts):
        pos, rad = frame.positions(), frame.radii()
        if self.thickness is not None:
            r = np.abs(pos[:, 0] - self.x0)
        else:
            r = np.hypot(pos[:, 0] - self.x0, pos[:, 1] - self.y0)
        keep = (r < self.radius) & (pos[:, 2] > self.z_min)
        row = {"time": frame.timestep * self.dt, "surface_height": np.nan, "grains": int(keep.sum())}
        if keep.sum() < 10:
            return [row]
        d = 2.0 * float(rad[keep].mean())
        if self.thickness is not None:     # strips of equal width (and area)
            n = self.annuli or int(np.clip(round(self.radius / d / 4.0), 2, 20))
            ring = np.minimum((n * r[keep] / self.radius).astype(int), n - 1)
        else:                              # rings of equal area
            n = self.annuli or int(np.clip(round((self.radius / d) ** 2 / 8.0), 2, 20))
            ring = np.minimum((n * (r[keep] / self.radius) ** 2).astype(int), n - 1)
        z = pos[keep, 2]
        vol = 4.0 / 3.0 * np.pi * rad[keep] ** 3
        edges = np.arange(self.z_min, z.max() + 2 * d, d)
        heights = []
        for k in range(n):
            m = ring == k
            phi = np.histogram(z[m], edges, weights=vol[m])[0] / (self.area / n * d)
            filled = phi[phi > 0]
            if len(filled) < 2:
                continue
            half = 0.5 * float(np.median(filled))
            above = np.flatnonzero(phi >= half)
            top = above[-1]
            centres = 0.5 * (edges[:-1] + edges[1:])
            if top + 1 < len(phi):   # interpolate the crossing between bin top and top + 1
                f = (phi[top] - half) / (phi[top] - phi[top + 1])
                heights.append(centres[top] + f * d)
            else:
                heights.append(centres[top])
        if heights:
            row["surface_height"] = float(np.mean(heights))
            row["rings"] = len(heights)
            row["surface_spread"] = float(np.max(heights) - np.min(heights))
        return [row]


def surface_flow_rate(time, height, area: float, bulk_density: float) -> FlowRate:
    """Wr (kg/s) from a straight-line fit of the free-surface height: -dh/dt A rho_bulk, with
    ``area`` (m2) the cross-section and ``bulk_density`` (kg/m3) the bed's mass per volume."""
    fit = linear_rate(time, height)
    scale = area * bulk_density
    return FlowRate(-fit.rate * scale, fit.stderr * scale, fit.t_start, fit.t_end, fit.n_samples)


def beverloo(D0, d, C: float, k: float, rho_b, g: float = 9.81, slot_length=None, slot_ends=False):
    """Beverloo mass flow rate (kg/s) of a circular orifice of diameter D0 (m), grains of diameter d
    (m): C rho_b sqrt(g) (D0 - k d)^(5/2). With ``slot_length`` L (m), a rectangular outlet of width
    D0 and length L: C rho_b sqrt(g) (L - k d) (D0 - k d)^(3/2) where ``slot_ends`` (per outlet:
    a box's rectangle or slot between walls), else C rho_b sqrt(g) L (D0 - k d)^(3/2) (a slab's
    slot: a periodic depth has no ends, a walled slab's faces are about a grain apart)."""
    d = np.asarray(d, float)
    span = np.maximum(np.asarray(D0, float) - k * d, 0.0)
    if slot_length is None:
        return C * np.asarray(rho_b, float) * np.sqrt(g) * span ** 2.5
    L = np.asarray(slot_length, float)
    length = np.where(np.asarray(slot_ends, bool), np.maximum(L - k * d, 0.0), L)
    return C * np.asarray(rho_b, float) * np.sqrt(g) * length * span ** 1.5


#: the parameters a Beverloo fit finds (C and k); it needs at least one run more than these
BEVERLOO_PARAMETERS = 2
#: the largest rms relative residual of a Beverloo fit given as a result. Steady discharges of one
#: material follow the law to a few per cent (a fit to rates with 1 % noise leaves 1-2 %); a fit that
#: misses its runs by a fifth on average describes none of them (a clog or a run not yet in steady
#: flow among them, orifices near k d, or another law), and its C and k are no answer
MAX_RMS_RELATIVE_RESIDUAL = 0.20


def as_number(value) -> float:
    """``value`` as a float if it is a number (not a bool), else NaN."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return float("nan")
    return float(value)


def flow_verdict(summary: dict) -> dict:
    """What a run's summary (``results/summary.json``) says of its discharge as one steady flow:
    ``clogged`` (True when the post-processing found it clogged, ``discharge.clog``, or the engine
    stopped its until_steady discharge as clogged; False; None when the summary predates clog
    detection), ``steady_t_start_s`` and ``steady_t_end_s`` (the steady window detected from the
    rate, s; NaN without one) and ``unsteady``: why its flow rate is no steady one, '' when it is
    (not clogged, a steady window detected, a finite positive flow rate). A detected window of too
    few samples to be resolved is kept: the flow rate is the straight line over its own window."""
    def section(name):
        value = summary.get(name)
        return value if isinstance(value, dict) else None

    clog, stop, steady, rate = section("clogged"), section("discharge_stop"), section("steady_window_detected"), \
        section("flow_rate") or {}
    stopped = stop is not None and stop.get("reason") == "clogged"
    clogged = True if clog is not None or stopped else (False if "clogged" in summary else None)
    why = ""
    if clog is not None:
        why = (f"its discharge clogged: {as_number(clog.get('discharged_mass_kg')) * 1000:.3g} g out, nothing after "
               f"t = {as_number(clog.get('t_last_outflow_s')):.3g} s from opening")
    elif stopped:
        why = "its discharge clogged: the engine stopped it when nothing flowed"
    elif "steady_window_detected" in summary and steady is None:
        why = "no steady discharge was detected in it (its rate never held near its median)"
    elif not as_number(rate.get("rate")) > 0:
        why = "its results hold no steady flow rate"
    return {"clogged": clogged, "steady_t_start_s": as_number((steady or {}).get("t_start")),
            "steady_t_end_s": as_number((steady or {}).get("t_end")), "unsteady": why}


@dataclass
class BeverlooFit:
    """C and k of Beverloo's law fitted over ``n_runs`` runs, with their standard errors and their
    covariance ``C_k_covariance``; ``errors_given``: the covariance is from the runs' own flow-rate
    errors (absolute), else scaled by the fit's residuals (then Student's t with n - 2 degrees of
    freedom, not the normal law, gives its intervals)."""
    C: float
    C_stderr: float
    k: float
    k_stderr: float
    n_runs: int
    rms_relative_residual: float
    C_k_covariance: float = float("nan")
    errors_given: bool = False


def fit_beverloo(D0, d, W, rho_b, g: float = 9.81, W_stderr=None, slot_length=None, slot_ends=False) -> BeverlooFit:
    """Fit C and k of Beverloo's law to flow rates ``W`` (kg/s) of runs with orifice diameters
    ``D0`` (m), grain diameters ``d`` (m) and bulk densities ``rho_b`` (kg/m3); needs >= 3 runs
    with at least 2 different D0/d (:data:`BEVERLOO_PARAMETERS` + 1 runs: C, k and one to check them).
    ``slot_length`` (m, per run): slots of width D0, the two-dimensional law (:func:`beverloo`).
    Standard errors from the fit covariance (scaled by the residuals, or by ``W_stderr`` when given).
    The fit is returned whatever its residual: :func:`check_beverloo_fit` refuses a poor one."""
    D0, d, W, rho_b = (np.asarray(a, float) * np.ones(len(np.atleast_1d(W))) for a in (D0, d, W, rho_b))
    L = None if slot_length is None else np.asarray(slot_length, float) * np.ones(len(W))
    ends = np.asarray(slot_ends, bool) * np.ones(len(W), bool)
    if len(W) < BEVERLOO_PARAMETERS + 1 or len(np.unique(np.round(D0 / d, 9))) < 2:
        raise ValueError(f"a Beverloo fit needs at least {BEVERLOO_PARAMETERS + 1} runs (C and k, and one more to "
                         f"check them) and 2 different orifice/grain size ratios; it was given {len(W)} run(s) of "
                         f"{len(np.unique(np.round(D0 / d, 9)))} ratio(s)")

    # W^(1/n) is linear in D0 and d (n = 5/2, a slot's 3/2): (W / (C rho_b sqrt g [L]))^(1/n) = D0 - k d
    n = 2.5 if L is None else 1.5
    y = (W / (rho_b * np.sqrt(g) * (1.0 if L is None else L))) ** (1.0 / n)
    A = np.column_stack([D0, -d])
    (a, b), *_ = np.linalg.lstsq(A, y, rcond=None)
    c0, k0 = (max(a, 1e-6)) ** n, b / max(a, 1e-6)

    def model(X, C, k):
        return beverloo(X[0], X[1], C, k, X[2], g, None if L is None else X[3], ends)

    sigma = None if W_stderr is None else np.asarray(W_stderr, float) * np.ones(len(W))
    if sigma is not None and not np.all(np.isfinite(sigma) & (sigma > 0)):
        sigma = None                # a run without a resolved error: weigh by the residuals instead
    X = np.vstack([D0, d, rho_b] + ([] if L is None else [L]))
    popt, pcov = curve_fit(model, X, W, p0=[c0, k0], sigma=sigma, absolute_sigma=sigma is not None, maxfev=20000)
    res = (W - model(X, *popt)) / W
    finite = bool(np.all(np.isfinite(pcov)))
    err = np.sqrt(np.diag(pcov)) if finite else np.array([np.nan, np.nan])
    return BeverlooFit(float(popt[0]), float(err[0]), float(popt[1]), float(err[1]), len(W),
                       float(np.sqrt(np.mean(res ** 2))), float(pcov[0, 1]) if finite else float("nan"),
                       sigma is not None)


def check_beverloo_fit(fit: BeverlooFit, max_residual: float = MAX_RMS_RELATIVE_RESIDUAL) -> None:
    """Refuse (``ValueError``) a fit that is no answer: an rms relative residual above
    ``max_residual`` (:data:`MAX_RMS_RELATIVE_RESIDUAL`), or C, k or the residual not a number."""
    values = (fit.C, fit.k, fit.rms_relative_residual)
    if not all(np.isfinite(values)):
        raise ValueError(f"the Beverloo fit gave no numbers (C = {fit.C}, k = {fit.k}, rms residual "
                         f"{fit.rms_relative_residual})")
    if fit.rms_relative_residual > max_residual:
        raise ValueError(f"the Beverloo fit misses its {fit.n_runs} runs by {fit.rms_relative_residual:.1%} (rms "
                         f"relative residual; at most {max_residual:.0%} is taken as a fit), so C = {fit.C:.4g} and "
                         f"k = {fit.k:.4g} describe none of them")


def beverloo_diameter(plan, folder) -> tuple[float, float, str]:
    """Beverloo's grain diameter d (m), the grains' mean density (kg/m3) and what d is, from a run
    plan: one size, its diameter; several sizes of sphere, the mass-weighted mean diameter
    sum(w_i d_i) over the fill's mass fractions w_i (the mean the mass flow weighs, the usual choice
    for a polydisperse Beverloo fit, and k then refers to it)."""
    grains = plan.grains
    if not grains or any(sp.kind != "sphere" for sp in grains):
        raise ReadError(f"{folder}: Beverloo's d needs spheres (a clump has no one diameter)")
    if len(grains) == 1:
        return 2 * grains[0].radius, grains[0].density, "grain diameter"
    weights = plan.fill.mass_fractions
    d = float(sum(w * 2 * sp.radius for w, sp in zip(weights, grains)))
    density = float(sum(w * sp.density for w, sp in zip(weights, grains)))
    return d, density, f"mass-weighted mean diameter of {len(grains)} sizes"


#: Beverloo's constants for spheres through a round orifice (../shared/REFERENCES.md: C about 0.58, k about
#: 1.5), with which a run's own flow rate is set beside the law's prediction
BEVERLOO_C, BEVERLOO_K = 0.58, 1.5


def beverloo_inputs(plan, summary: dict, folder) -> dict:
    """What Beverloo's law needs of a run (its plan and ``results/summary.json``): orifice diameter
    D0 (a slab's slot width), grain diameter d (several sizes: their mass-weighted mean, ``d_is``
    says which; :func:`beverloo_diameter`), outlet length L (a slab's depth, a box's rectangle or slot;
    NaN for a round orifice) (m), L_ends (the outlet's length ends at walls or edges: Beverloo's
    L - k d), D0_is (what D0 is: a silo from STL with a polygon outlet gives its hydraulic diameter
    4 A / P, the round law approximated), bulk density rho_b (kg/m3, measured in the settled bed when
    dumps exist, else packing fraction x rho_p, ``rho_b_source`` says which) and gravity g (m/s2).
    ``ReadError`` for grains of no one diameter (clumps)."""
    d, density, d_is = beverloo_diameter(plan, folder)
    fa = summary.get("frame_analyses") or {}
    measured = fa.get("bulk_density_kg_m3")
    measured = measured if isinstance(measured, (int, float)) and not isinstance(measured, bool) else None
    rho_b = measured or plan.fill.packing_fraction * density
    g = plan.geometry
    L, L_ends, D0_is = silo_kind(g.kind).beverloo_outlet(g)
    return {"D0": 2 * g.outlet_radius, "d": d, "d_is": d_is, "L": L, "L_ends": L_ends, "D0_is": D0_is,
            "rho_b": float(rho_b), "g": plan.gravity,
            "rho_b_source": "measured" if measured else "case packing fraction"}


def beverloo_prediction(plan, summary: dict, folder, C: float = BEVERLOO_C, k: float = BEVERLOO_K) -> dict:
    """Beverloo's flow rate for a run (kg/s) with the literature's C and k for spheres
    (:data:`BEVERLOO_C`, :data:`BEVERLOO_K`) and the run's own D0, d and bulk density
    (:func:`beverloo_inputs`): {rate, C, k, D0, d, L, rho_b, rho_b_source, d_is, D0_is}, or
    {error} where the law has no one grain diameter. A prediction, not a measurement: C and k
    vary with the grains (C 0.55-0.65, k 1.3-2.9 in the literature)."""
    try:
        x = beverloo_inputs(plan, summary, folder)
    except ReadError as exc:
        return {"error": str(exc).removeprefix(f"{folder}: ")}
    slot = bool(np.isfinite(x["L"]))
    rate = float(beverloo(x["D0"], x["d"], C, k, x["rho_b"], x["g"], x["L"] if slot else None, x["L_ends"]))
    return {"rate": rate, "C": C, "k": k, **{key: x[key] for key in ("D0", "d", "L", "rho_b", "rho_b_source", "d_is",
                                                                    "D0_is")}}


def beverloo_table(folders) -> pd.DataFrame:
    """One row per analysed run folder: :func:`beverloo_inputs` (D0, d, L, rho_b, g, what they are),
    steady flow rate W and its standard error (kg/s), ``clogged`` and ``left_out``: why the run is no
    point of a fit ('' when it is one: :func:`flow_verdict`; W is NaN when it has none)."""
    rows = []
    for folder in folders:
        run = RunFolder(folder)
        summary = run.read_summary()
        verdict = flow_verdict(summary)
        rate = summary.get("flow_rate") if isinstance(summary.get("flow_rate"), dict) else {}
        x = beverloo_inputs(run.plan, summary, folder)
        rows.append({"run": str(folder), **{key: x[key] for key in ("D0", "d", "d_is", "L", "L_ends", "D0_is",
                                                                  "rho_b")},
                     "W": as_number(rate.get("rate")), "W_stderr": as_number(rate.get("stderr")), "g": x["g"],
                     "rho_b_source": x["rho_b_source"], "clogged": verdict["clogged"], "left_out": verdict["unsteady"]})
    return pd.DataFrame(rows)
