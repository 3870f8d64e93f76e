"""Discharged mass vs time, the steady mass flow rate, and the one straight-line fit
(``straight_line_fit``) that every rate in postprocess is measured with."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from .batch_means import batch_means_stderr


@dataclass
class LineFit:
    """Least-squares straight line ``values = intercept + slope * time`` (time in s).

    slope: units of ``values`` per s (kg/s for a discharged mass in kg); stderr: standard
    error of the slope, same units, from the residual variance with n - 2 degrees of freedom;
    intercept: units of ``values`` at t = 0 s; r2: coefficient of determination (NaN when
    the values are constant); t_start, t_end: first and last sample time, s.
    """

    slope: float
    stderr: float
    intercept: float
    r2: float
    t_start: float
    t_end: float
    n_samples: int


def straight_line_fit(time, values) -> LineFit:
    """Ordinary least-squares line through (``time`` (s), ``values``).

    Closed form about the mean time (well conditioned even far from t = 0):
    slope = sum(dt dv) / sum(dt^2), stderr = sqrt(ss_res / (n - 2) / sum(dt^2)), with
    dt = t - mean(t), dv = v - mean(v), ss_res the sum of squared residuals. This is the
    stderr of np.polyfit(deg=1, cov=True) and of scipy.stats.linregress. Fewer than 3
    samples, or all at the same time: NaN slope, stderr, intercept and r2. NaN in the
    data gives NaN results.
    """
    t = np.asarray(time, float)
    v = np.asarray(values, float)
    if t.shape != v.shape or t.ndim != 1:
        raise ValueError(f"time and values must be 1-d and of the same length, not {t.shape} and {v.shape}")
    n = len(t)
    nan = float("nan")
    t_start, t_end = (float(t[0]), float(t[-1])) if n else (nan, nan)
    t_mean = float(t.mean()) if n else nan
    dt = t - t_mean
    stt = float(dt @ dt)
    if n < 3 or stt == 0.0:
        return LineFit(nan, nan, nan, nan, t_start, t_end, n)
    v_mean = float(v.mean())
    dv = v - v_mean
    slope = float(dt @ dv) / stt
    res = dv - slope * dt
    ss_res = float(res @ res)
    ss_tot = float(dv @ dv)
    return LineFit(slope=slope, stderr=math.sqrt(ss_res / (n - 2) / stt),
                   intercept=v_mean - slope * t_mean,
                   r2=1.0 - ss_res / ss_tot if ss_tot > 0 else nan,
                   t_start=t_start, t_end=t_end, n_samples=n)


@dataclass
class FlowRate:
    """A rate fitted by a straight line over a window: the one rate type of postprocess.

    rate: the fit's slope (kg/s for a mass in kg; ``flow_rate.linear_rate``: units of its values
    per s); stderr: its standard error, same units; t_start, t_end: the window, s; n_samples.
    The steady mass flow rate (:func:`steady_flow_rate`) also measures r2 (coefficient of
    determination), fit_stderr (the straight line's own standard error, which takes the samples
    as independent and understates the error several times) and batches (the batch means its
    stderr comes from: the samples are autocorrelated, and this is the error that matches the
    spread of seeds, ``benchmarks/results/coverage``; 0 and a NaN stderr when the window holds
    too few samples for batches). A rate that does not measure one of these leaves it None, and
    :meth:`record` leaves it out.
    """

    rate: float
    stderr: float
    t_start: float
    t_end: float
    n_samples: int
    r2: float | None = None
    fit_stderr: float | None = None
    batches: int | None = None

    def record(self) -> dict:
        """The rate as summary.json states it: its fields, those left None omitted."""
        return {k: v for k, v in asdict(self).items() if v is not None}


def steady_flow_rate(time, mass, t_open: float, skip: float = 0.2, min_remaining: float = 0.2,
                     mass_in_silo=None, initial_mass: float | None = None) -> FlowRate:
    """Fit the discharged ``mass`` (kg) against ``time`` (s) in the steady window.

    The window starts ``skip`` s after ``t_open`` (or after a fifth of the discharge, if
    shorter) and ends when less than ``min_remaining`` of ``initial_mass`` is left in the
    silo (the flow slows as the silo empties). The rate is ``straight_line_fit``'s slope (kg/s
    for mass in kg); its error is the batch-means error of the sample rates (:class:`FlowRate`).
    Returns NaN rate if fewer than 5 samples fit.
    """
    time = np.asarray(time, float)
    mass = np.asarray(mass, float)
    t_end_data = time.max() if len(time) else t_open
    start = t_open + min(skip, 0.2 * max(t_end_data - t_open, 0.0))
    keep = time >= start
    if mass_in_silo is not None and initial_mass:
        keep &= np.asarray(mass_in_silo, float) >= min_remaining * initial_mass
    t, m = time[keep], mass[keep]
    if len(t) < 5:
        return FlowRate(float("nan"), float("nan"), start, t_end_data, int(len(t)), float("nan"), float("nan"), 0)
    fit = straight_line_fit(t, m)
    # the straight line's stderr treats the samples' residuals as independent; they are not (a run's
    # rate fluctuates over many samples), so the batch means of the sample-to-sample rates say more
    batch_se, batches = batch_means_stderr(np.diff(m) / np.diff(t))
    return FlowRate(fit.slope, batch_se, fit.t_start, fit.t_end, fit.n_samples, fit.r2, fit.stderr, batches)


#: a discharge clogged when nothing left the silo over this share of its duration, to its end
CLOG_WINDOW = 0.4


def clog(time_since_open, outlet_mass, mass_in_silo, initial_mass: float, min_remaining: float = 0.2,
         window: float = CLOG_WINDOW) -> dict | None:
    """Whether a discharge clogged: at least ``min_remaining`` of ``initial_mass`` (kg) was still in
    the silo (more than a flat bottom's dead zone; :func:`steady_flow_rate` ends its window there too)
    and no mass left through the outlet over the last ``window`` of the discharge (times in s since
    the outlet opened, masses in kg). None if it flowed to its end or emptied; else the time of the
    last outflow (s since opening), the mass out before it and the mass left (kg): the flow rate of
    such a run is not a steady one."""
    t = np.asarray(time_since_open, float)
    out = np.asarray(outlet_mass, float)
    left = np.asarray(mass_in_silo, float)
    after = t >= 0
    t, out, left = t[after], out[after], left[after]
    if len(t) < 2 or t[-1] <= 0 or not left[-1] >= min_remaining * initial_mass:
        return None
    late = t >= (1 - window) * t[-1]
    if out[-1] > out[late][0]:
        return None
    moved = np.flatnonzero(out < out[-1])
    return {"t_last_outflow_s": float(t[moved[-1] + 1]) if len(moved) else 0.0,
            "discharged_mass_kg": float(out[-1]), "mass_left_kg": float(left[-1]), "window": window}


def discharge_table(flow: pd.DataFrame, timestep: float, t_open: float) -> pd.DataFrame:
    """From a run folder's ``flow`` table (``siloflow.run_folder.FLOW_SCHEMA``), time series of the discharge: time (s), time since opening, mass through the outlet,
    mass above the outlet, particles present."""
    t = flow["step"] * timestep
    return pd.DataFrame({"step": flow["step"], "time": t, "time_since_open": t - t_open,
                         "outlet_mass": flow["discharged_mass"], "mass_in_silo": flow["mass_silo"],
                         "mass_total": flow["mass_total"], "particles": flow["atoms"].astype(int)})
