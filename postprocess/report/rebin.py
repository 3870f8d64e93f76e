"""Writing a re-binned run's wall pressure (``postprocess.rebin``) into its results folder."""
from __future__ import annotations

import time
from pathlib import Path

from siloflow.atomic_files import write_json
from siloflow.run_folder import RESULTS, record_products

from .files import write_table

#: the re-binned bands' table and its summary, in results/
REBINNED_TABLE = "rebinned_bands.csv"
REBINNED_SUMMARY = "rebinned_bands.json"


def write_rebinned(folder, rebinned) -> Path:
    """Write ``results/rebinned_bands.csv`` (per band and sector: static and discharge pressure with
    their errors and frames) and ``rebinned_bands.json`` (edges, sectors, error method, the side
    wall's force per frame) into run folder ``folder``; returns the table's path."""
    since = time.time()
    out = Path(folder) / RESULTS
    out.mkdir(exist_ok=True)
    write_table(rebinned.table, out / REBINNED_TABLE)
    write_json(out / REBINNED_SUMMARY, {
        "edges_m_above_side_base": rebinned.edges, "sectors": rebinned.sectors, "frames": len(rebinned.totals),
        "error_method": rebinned.error_method,
        "side_wall_force_per_frame_N": rebinned.totals.to_dict(orient="list")})
    record_products(folder, out, since)
    return out / REBINNED_TABLE
