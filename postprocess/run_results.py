"""What the analyses of a run folder hand the report layer: :class:`RunResults`, data only
(the summary, tables, and what each figure is drawn from). ``postprocess.first_results.analyse_run``
fills it; ``postprocess.report.write_run`` writes it under results/."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd


@dataclass
class RunResults:
    """A run folder's results, computed and not yet written.

    folder: the run folder; out: its results folder; summary: summary.json's content; tables:
    {file name (``.csv`` or ``.parquet``): DataFrame}, in writing order (report.html lists the CSV
    ones in it); discharge, bands (tidy band pressures, None without sensors), band_table
    (bands.csv) and t_open (s): what the first-results figure shows; analyses: the frame analyses
    whose figure the report draws (``<name>.png``), in order; force_chains: {figure name:
    ``force_chains.ForceChains``}; design: the EN 1991-4 loads (``siloflow.design_loads.DesignLoads``)
    drawn beside the bands, or None.
    """

    folder: Path
    out: Path
    summary: dict = field(default_factory=dict)
    tables: dict = field(default_factory=dict)
    discharge: pd.DataFrame | None = None
    bands: pd.DataFrame | None = None
    band_table: pd.DataFrame | None = None
    t_open: float = float("nan")
    analyses: list = field(default_factory=list)
    force_chains: dict = field(default_factory=dict)
    design: Any = None

    def add_analysis(self, analysis, figure: bool = True) -> None:
        """Add a frame analysis' table (``<name>.csv`` and ``<name>.parquet``) and, with ``figure``
        and a non-empty table, its figure."""
        table = analysis.results.table
        self.tables.update({f"{analysis.name}.csv": table, f"{analysis.name}.parquet": table})
        if figure and not table.empty:
            self.analyses.append(analysis)
