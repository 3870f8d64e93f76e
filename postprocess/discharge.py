"""Discharged mass vs time and the steady mass flow rate."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd


@dataclass
class FlowRate:
    """Steady mass flow rate from a straight-line fit of discharged mass vs time.

    rate, stderr: kg/s; t_start, t_end: fit window, s; r2: coefficient of determination.
    """

    rate: float
    stderr: float
    t_start: float
    t_end: float
    n_samples: int
    r2: float


def steady_flow_rate(time, mass, t_open: float, skip: float = 0.2, min_remaining: float = 0.2,
                     mass_in_silo=None, initial_mass: float | None = None) -> FlowRate:
    """Fit the discharged ``mass`` (kg) against ``time`` (s) in the steady window.

    The window starts ``skip`` s after ``t_open`` (or after a fifth of the discharge, if
    shorter) and ends when less than ``min_remaining`` of ``initial_mass`` is left in the
    silo (the flow slows as the silo empties). Returns NaN rate if fewer than 5 samples fit.
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
        return FlowRate(float("nan"), float("nan"), start, t_end_data, int(len(t)), float("nan"))
    A = np.vstack([t, np.ones_like(t)]).T
    coef, res, *_ = np.linalg.lstsq(A, m, rcond=None)
    fit = A @ coef
    ss_res = float(((m - fit) ** 2).sum())
    ss_tot = float(((m - m.mean()) ** 2).sum())
    stderr = np.sqrt(ss_res / (len(t) - 2) / ((t - t.mean()) ** 2).sum())
    return FlowRate(float(coef[0]), float(stderr), float(t[0]), float(t[-1]), int(len(t)),
                    1.0 - ss_res / ss_tot if ss_tot > 0 else float("nan"))


def discharge_table(flow: pd.DataFrame, timestep: float, t_open: float) -> pd.DataFrame:
    """Time series of the discharge: time (s), time since opening, mass through the outlet,
    mass above the outlet, particles present."""
    t = flow["step"] * timestep
    return pd.DataFrame({"step": flow["step"], "time": t, "time_since_open": t - t_open,
                         "outlet_mass": flow["outlet_mass"], "mass_in_silo": flow["mass_silo"],
                         "mass_total": flow["mass_total"], "particles": flow["atoms"].astype(int)})
