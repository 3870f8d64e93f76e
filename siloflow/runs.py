"""The Python entry point to run folders: ``siloflow.open_run(folder)`` and ``siloflow.run(case, folder)``.

For scripts and notebooks (sweeps)::

    import siloflow
    r = siloflow.open_run("runs/quick")
    r.state                          # 'complete', 'failed', ...
    r.summary["flow_rate"]["rate"]   # kg/s
    r.flow                           # discharge time series (DataFrame, SI)
    r.wall_pressure                  # band pressure per sample (DataFrame, Pa)
    for frame in r.frames(): ...     # the particle dumps, one frame at a time

The tables are read from what ``siloflow post`` wrote (``results/``); a folder not yet
post-processed is analysed on first access.
"""
from __future__ import annotations

import json
from functools import cached_property
from pathlib import Path
from typing import Iterator, Optional

import pandas as pd

from .errors import ReadError

RESULTS = "results"


class Run:
    """A siloflow run folder, read-only: its state, summary and tables (SI units)."""

    def __init__(self, folder):
        self.folder = Path(folder)
        if not (self.folder / "derived.json").is_file():
            raise ReadError(f"{self.folder} is not a siloflow run folder (no derived.json)")

    def __repr__(self) -> str:
        return f"Run({str(self.folder)!r}, state={self.state!r})"

    @property
    def state(self) -> str:
        """rendered, running, complete, failed, interrupted or abandoned."""
        from .engine.base import run_state
        return run_state(self.folder)["state"]

    @cached_property
    def record(self):
        """The engine run's record (``siloflow.engine.RunRecord``: wall time s, stage steps, ...)."""
        from .engine.base import RunRecord
        try:
            return RunRecord(**json.loads((self.folder / "run_record.json").read_text()))
        except (OSError, ValueError, TypeError) as exc:
            raise ReadError(f"{self.folder} has no readable run_record.json: {exc}") from None

    def _results(self) -> Path:
        out = self.folder / RESULTS
        if not (out / "summary.json").is_file():
            from postprocess.first_results import analyse
            analyse(self.folder)
        return out

    @cached_property
    def summary(self) -> dict:
        """results/summary.json: flow rate (kg/s) with its standard error, bands, force balance, ..."""
        return json.loads((self._results() / "summary.json").read_text())

    def _table(self, name: str) -> pd.DataFrame:
        try:
            return pd.read_csv(self._results() / name)
        except (OSError, ValueError) as exc:
            raise ReadError(f"cannot read {self.folder / RESULTS / name}: {exc}") from None

    @cached_property
    def flow(self) -> pd.DataFrame:
        """Discharge series: step, time (s), time since opening, outlet mass (kg), mass in the
        silo (kg), total mass (kg), particles."""
        return self._table("discharge.csv")

    @cached_property
    def wall_pressure(self) -> pd.DataFrame:
        """Band pressure per sample: band, step, time (s), z_mid (m), pressure (Pa), shear force (N)."""
        return self._table("wall_pressure.csv")

    @cached_property
    def bands(self) -> pd.DataFrame:
        """Per band: static pressure and shear, maximum dynamic pressure, discharge factor."""
        return self._table("bands.csv")

    def frames(self, columns: Optional[list[str]] = None, every: int = 1) -> Iterator:
        """The particle dump frames (``postprocess.dumps.Frame``), one at a time."""
        from postprocess.dumps import read_frames
        dumps = self.folder / "output" / "dumps"
        if not any(dumps.glob("dump.*.txt")):
            raise ReadError(f"{self.folder} has no particle dumps (outputs.dump_interval was not set)")
        return read_frames(str(dumps / "dump.*.txt"), columns=columns, every=every)


def open_run(folder) -> Run:
    """The run folder ``folder`` (made by ``siloflow run`` or ``siloflow.run``)."""
    return Run(folder)


def run(case, folder, force: bool = False, progress=None) -> Run:
    """Render ``case`` (a ``Case`` or a case-file path) into ``folder``, run its engine, check the
    run and compute the first results, as ``siloflow run`` does; return the ``Run``."""
    from postprocess.first_results import analyse
    from .case import Case, load_case
    from .engine import get_engine
    keep = []
    if not isinstance(case, Case):
        keep = [case]
        case = load_case(case)
    engine = get_engine(case.engine.name)
    folder = engine.prepare(case, folder, force=force, keep=keep)
    engine.execute(folder, progress=progress)
    engine.collect(folder)
    analyse(folder)
    return Run(folder)
