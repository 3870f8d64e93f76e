"""A run folder as one row of a study's table: its headline numbers (SI), read from its run record
and ``results/summary.json``. One function, :func:`run_row`, for the sweep table (``sweep.csv``),
the bench (``siloflow bench``) and the stability envelope (``siloflow stability``); each takes the
columns it reports."""
from __future__ import annotations

import math
from pathlib import Path

from postprocess.flow_rate import flow_verdict

from .errors import SiloflowError

#: a band counts as loaded when its static pressure exceeds this fraction of the largest band's
LOADED_BAND = 0.05
#: the numbers of a row, each NaN (``fill_from_cache``, ``clogged``: None) where the folder holds none
ROW_KEYS = ("wall_s", "fill_from_cache", "flow_rate", "flow_rate_stderr", "flow_rate_fit_se", "flow_rate_batch_se",
            "clogged", "steady_t_start_s", "steady_t_end_s",
            "force_balance_ratio", "static_pressure", "dynamic_pressure_max", "solid_fraction", "coordination",
            "max_speed", "max_overlap_fraction", "speed_ratio", "overlap_ratio")


def number(value) -> float:
    """``value`` as a float if it is a number (not a bool: a measurement that could not be made is a
    dict with its reason, or absent), else NaN."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return math.nan
    return float(value)


def _section(summary: dict, name: str) -> dict:
    value = summary.get(name)
    return value if isinstance(value, dict) else {}


def _summary_numbers(s: dict) -> dict:
    """The summary's headline numbers: flow rate (kg/s) and its errors, force balance, the loaded
    bands' mean static and maximum dynamic pressure (Pa), solid fraction, coordination."""
    nan = math.nan
    fr = _section(s, "flow_rate")
    row = {"flow_rate": number(fr.get("rate")), "flow_rate_stderr": number(fr.get("stderr"))}
    if "fit_stderr" in fr:      # the headline stderr is batch means (summaries before it: the line's)
        row["flow_rate_fit_se"], row["flow_rate_batch_se"] = number(fr["fit_stderr"]), number(fr.get("stderr"))
    else:
        row["flow_rate_fit_se"], row["flow_rate_batch_se"] = number(fr.get("stderr")), number(fr.get("batch_stderr"))
    verdict = flow_verdict(s)
    row.update({key: verdict[key] for key in ("clogged", "steady_t_start_s", "steady_t_end_s")})
    row["force_balance_ratio"] = number(_section(s, "force_balance").get("ratio"))
    row["static_pressure"] = row["dynamic_pressure_max"] = nan
    bands = [b for b in s.get("bands") or [] if isinstance(b, dict) and b.get("static_pressure") is not None]
    if bands:
        top = max(b["static_pressure"] for b in bands)
        loaded = [b for b in bands if b["static_pressure"] > LOADED_BAND * top]
        row["static_pressure"] = number(sum(b["static_pressure"] for b in loaded) / len(loaded))
        dyn = [b.get("dynamic_max_pressure") for b in loaded if b.get("dynamic_max_pressure") is not None]
        row["dynamic_pressure_max"] = number(sum(dyn) / len(dyn)) if dyn else nan
    frames = _section(s, "frame_analyses")
    row["solid_fraction"] = number(frames.get("bulk_solid_fraction"))
    coordination = frames.get("coordination_settled")
    row["coordination"] = number(coordination.get("z_mean")) if isinstance(coordination, dict) else nan
    return row


def _peaks(run, seen) -> dict:
    """The largest speed (m/s) and pair overlap (fraction of the smallest grain radius) the run
    reached (the guard's ``guard_peaks``), each against the guard's limit (1 = at the limit)."""
    nan = math.nan
    out = {"max_speed": nan, "max_overlap_fraction": nan, "speed_ratio": nan, "overlap_ratio": nan}
    if not seen:
        return out
    try:
        g = run.plan.guard
    except (SiloflowError, OSError, TypeError, ValueError):
        return out
    if g is None:
        return out
    speed, overlap = seen["max_speed"], seen["max_overlap"]
    return {"max_speed": speed, "max_overlap_fraction": overlap / g.grain_radius, "speed_ratio": speed / g.max_speed,
            "overlap_ratio": overlap / g.max_overlap}


def run_row(folder) -> dict:
    """The headline numbers of run folder ``folder`` (:data:`ROW_KEYS`), NaN where it holds none
    (a run that failed, never started, or was not post-processed): ``wall_s`` the engine's wall
    time (s, from the run record, else the summary); ``fill_from_cache`` whether its settled bed
    came from the fill cache (None if unknown); ``flow_rate`` (kg/s) with ``flow_rate_stderr``
    (the summary's headline, batch means), ``flow_rate_fit_se`` and ``flow_rate_batch_se``;
    ``clogged`` (whether its discharge clogged; None if unknown) and ``steady_t_start_s``,
    ``steady_t_end_s`` (the steady window detected in its discharge, s; ``flow_rate.flow_verdict``);
    ``force_balance_ratio`` (the settled bed's supports over its weight); ``static_pressure`` and
    ``dynamic_pressure_max`` (Pa: means over the bands the settled bed loads); ``solid_fraction``
    (bulk, settled); ``coordination`` (settled mean); and, from the instability guard's peaks,
    ``max_speed`` (m/s), ``max_overlap_fraction`` (of the smallest grain radius), ``speed_ratio``
    and ``overlap_ratio`` (against the guard's limits)."""
    from .run_folder import RunFolder
    run = RunFolder(Path(folder))
    row = {key: math.nan for key in ROW_KEYS}
    row["fill_from_cache"] = row["clogged"] = None
    seen = None
    try:
        record = run.record
        row["wall_s"] = number(record.wall_time)
        if isinstance(record.fill_cache, dict) and isinstance(record.fill_cache.get("hit"), bool):
            row["fill_from_cache"] = record.fill_cache["hit"]
        seen = record.guard_peaks
    except (SiloflowError, OSError, TypeError, ValueError):
        pass
    row.update(_peaks(run, seen))
    try:
        summary = run.read_summary()
    except (SiloflowError, OSError, ValueError):
        return row
    if not isinstance(summary, dict):
        return row
    row.update(_summary_numbers(summary))
    if math.isnan(row["wall_s"]):
        row["wall_s"] = number(summary.get("engine_wall_time_s"))
    return row
