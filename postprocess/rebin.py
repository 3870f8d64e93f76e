"""Wall pressure in bands and sectors chosen after the run: a finished run's side-wall contacts
(its wall-contact dumps, and on LIGGGHTS its primitive side walls' touching grains), binned by
contact position into the bands and sectors asked for (``siloflow post RUN --bands ... --sectors N``).

The run's own bands come from the engine's sampled wall forces (``output/wall_forces.csv``, every
``outputs.sample_interval``, each the mean of several samples); re-binned bands come from the
contacts dumped at every such interval (one instantaneous sample each; mesh walls' contacts only
every ``outputs.dump_interval``), so they have larger errors, which are stated. The
pieces tile the side wall (the lowest reaches down, the highest up, without bound), so the forces of
any two binnings of a frame sum to the same side-wall force.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pandas as pd

from siloflow.errors import ReadError
from siloflow.run_folder import RunFolder
from siloflow.silos.registry import silo_kind

from .batch_means import batch_means_stderr
from .cg_run import primitive_wall_files
from .dumps import PRIMITIVE_CONTACT_COLUMNS, frames_by_step, primitive_wall_contacts, read_frames


@dataclass
class RebinnedBands:
    """``pieces``: per frame and piece (``step``, ``band`` (-1 below the first edge, ``len(edges) - 1``
    above the last), ``sector``, ``fx fy fz``: N, the force on the wall, ``pressure``: Pa, normal,
    NaN outside the bands); ``table``: per band and sector the static window's and the steady
    discharge's mean pressure with its standard error over frames (batch means from 10 frames,
    else the frames' sd / sqrt(n), said in ``error_method``); ``totals``: per frame the side
    wall's force from all its contacts (N)."""

    pieces: pd.DataFrame
    table: pd.DataFrame
    totals: pd.DataFrame
    edges: list[float]
    sectors: int
    error_method: str


def _side_frames(run: RunFolder):
    layout = run.dump_layout
    walls = run.dump_files("wall_contacts") if layout.wall_contact_columns else None
    if not walls:
        raise ReadError(f"{run.path}: the run dumped no wall contacts (outputs.contacts and outputs.dump_interval): "
                        "nothing to re-bin")
    streams = [read_frames(walls, columns=layout.wall_contact_columns)]
    for w, files in primitive_wall_files(run):
        if files:
            streams.append(primitive_wall_contacts(f, w["style"], w["args"])
                           for f in read_frames(files, columns=PRIMITIVE_CONTACT_COLUMNS))
    return frames_by_step(*streams)


def _side_geometry(plan, sectors: int | None):
    """(which side of the wall each contact is on: a function of (xw, yw, zw) -> (on side, sector,
    horizontal outward normal nx, ny)), the sectors' count, and each sector's (theta0, theta1) or
    width along the wall (m)."""
    g = plan.geometry
    return silo_kind(g.kind).wall_bins(g, sectors, plan.sensors.sectors, min(sp.radius for sp in plan.species))


def rebin_run(folder, heights: Sequence[float], sectors: int | None = None) -> RebinnedBands:
    """Re-bin a finished run's side-wall contacts into bands with edges ``heights`` (m above the
    side wall's base, increasing) and ``sectors`` (a cylinder's; None: the run's own)."""
    run = folder if isinstance(folder, RunFolder) else RunFolder(folder)
    plan = run.plan
    edges = [float(h) for h in heights]
    if len(edges) < 2 or any(not math.isfinite(h) for h in edges) or any(b <= a for a, b in zip(edges, edges[1:])):
        raise ReadError(f"--bands needs at least two increasing finite heights (m above the side wall's base), "
                        f"got {heights}")
    if sectors is not None and not 1 <= sectors <= 360:
        raise ReadError(f"--sectors must be 1 to 360, got {sectors}")
    classify, n_sectors, spans, radius = _side_geometry(plan, sectors)
    base = plan.geometry.hopper_height
    z_edges = np.asarray(edges) + base
    rows, totals = [], []
    for frame in _side_frames(run):
        d = frame.data
        xw, yw, zw = (d[c].to_numpy(float) for c in ("xw", "yw", "zw"))
        on, sector = classify(xw, yw, zw)
        f_wall = -d.loc[on, ["fx", "fy", "fz"]].to_numpy(float)      # the dumps carry the force on the grain
        band = np.searchsorted(z_edges, zw[on], side="right") - 1       # -1 below, len - 1 above
        totals.append((frame.timestep, *f_wall.sum(axis=0)))
        key = pd.DataFrame({"band": band, "sector": sector[on], "fx": f_wall[:, 0], "fy": f_wall[:, 1],
                            "fz": f_wall[:, 2]}).groupby(["band", "sector"]).sum()
        full = pd.MultiIndex.from_product([range(-1, len(edges)), range(n_sectors)], names=["band", "sector"])
        key = key.reindex(full, fill_value=0.0).reset_index()
        key.insert(0, "step", frame.timestep)
        rows.append(key)
    if not rows:
        raise ReadError(f"{run.path}: no wall-contact frames to re-bin")
    pieces = pd.concat(rows, ignore_index=True)
    inside = (pieces.band >= 0) & (pieces.band < len(edges) - 1)
    height = np.where(inside, np.diff(z_edges, append=np.nan)[pieces.band.clip(0, len(edges) - 1)], np.nan)
    if radius is not None:              # a cylinder's sector: the radial force along its middle, over 2 R h sin(dtheta/2)
        t0 = np.array([spans[s][0] for s in pieces.sector])
        t1 = np.array([spans[s][1] for s in pieces.sector])
        tc = 0.5 * (t0 + t1)
        area = 2.0 * radius * height * np.sin(0.5 * (t1 - t0)) if n_sectors > 1 else np.nan * height
        normal = pieces.fx * np.cos(tc) + pieces.fy * np.sin(tc)
        if n_sectors == 1:      # a full ring has no net radial force: its pressure needs sectors
            normal = normal * np.nan
    else:
        length = np.array([spans[s] for s in pieces.sector])
        area = length * height
        signs = {0: (-1.0, 0.0), 1: (1.0, 0.0), 2: (0.0, -1.0), 3: (0.0, 1.0)}
        nx = np.array([signs[s][0] for s in pieces.sector])
        ny = np.array([signs[s][1] for s in pieces.sector])
        normal = pieces.fx * nx + pieces.fy * ny
    pieces["pressure"] = np.where(inside, normal / area, np.nan)
    totals = pd.DataFrame(totals, columns=["step", "fx", "fy", "fz"])
    table, method = _statistics(run, pieces[inside], z_edges)
    return RebinnedBands(pieces, table, totals, edges, n_sectors, method)


def _statistics(run: RunFolder, pieces: pd.DataFrame, z_edges) -> tuple[pd.DataFrame, str]:
    """Per band and sector: mean pressure and its error over the static window's frames and the
    steady discharge's (the run's summary: its steady window)."""
    record = run.record
    steps = {k: int(v) for k, v in record.stage_steps.items()}
    dt = run.plan.dt
    summary = run.read_summary()
    steady = summary.get("flow_rate", {})
    t0, t1 = steady.get("t_start"), steady.get("t_end")
    sample = run.plan.outputs.sample_steps      # as the run's own bands: the static stage's first sample left out
    static = (pieces.step > steps["static"] + sample) & (pieces.step <= steps["open"])
    dynamic = (pieces.step > steps["open"]) & (pieces.step * dt >= (t0 if t0 is not None else np.inf)) & \
              (pieces.step * dt <= (t1 if t1 is not None else -np.inf))
    out = []
    method = "batch means from 10 frames on, else sd / sqrt(frames)"
    for (band, sector), grp in pieces.groupby(["band", "sector"]):
        row = {"band": int(band), "sector": int(sector), "z_lo": float(z_edges[band]), "z_hi": float(z_edges[band + 1])}
        for name, mask in (("static", static), ("dynamic", dynamic)):
            p = grp.pressure[mask.loc[grp.index]].to_numpy(float)
            p = p[np.isfinite(p)]
            se, _ = batch_means_stderr(p) if len(p) >= 10 else (float(np.std(p, ddof=1) / math.sqrt(len(p)))
                                                                 if len(p) >= 2 else float("nan"), 0)
            row.update({f"{name}_pressure": float(p.mean()) if len(p) else float("nan"),
                        f"{name}_pressure_stderr": float(se), f"{name}_frames": int(len(p))})
        out.append(row)
    return pd.DataFrame(out), method
