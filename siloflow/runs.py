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

import os
import warnings
from functools import cached_property
from pathlib import Path
from typing import Iterator, Optional

import pandas as pd

from .errors import CaseError, ReadError, SetupError
from .run_folder import DUMPS, PLAN_NAME, RESULT_TABLES, RunFolder


class UnfinishedRunWarning(UserWarning):
    """The results read are those of a run that is not known to have finished (``Run(unfinished=True)``)."""


def _path(value, what: str) -> Path:
    """``value`` as a path (a str or os.PathLike, not empty), else ``SetupError`` naming ``what``."""
    if isinstance(value, (bytes, bytearray)) or not isinstance(value, (str, os.PathLike)) or not str(value):
        raise SetupError(f"{what} must be a folder path (a str or pathlib.Path), not {type(value).__name__} "
                         f"{value!r:.60}")
    return Path(value)


class Run:
    """A siloflow run folder, read-only: its state, plan, summary and tables (SI units).

    The results (``summary``, ``flow``, ``wall_pressure``, ``bands``) are those of a finished run:
    of a run in any other state (running, failed, interrupted, abandoned, or ``unknown`` when its
    status.json is missing) they are refused with a ``ReadError`` saying why, unless the folder is
    opened with ``unfinished=True``, which reads them with an :class:`UnfinishedRunWarning`."""

    def __init__(self, folder, unfinished: bool = False):
        self.folder = _path(folder, "the run folder")
        self.unfinished = bool(unfinished)
        self.run_folder = RunFolder(self.folder)
        if not self.run_folder.is_run_folder():
            raise ReadError(f"{self.folder} is not a siloflow run folder (no {PLAN_NAME})")

    def __repr__(self) -> str:
        return f"Run({str(self.folder)!r}, state={self.state!r})"

    @property
    def state(self) -> str:
        """rendered, running, complete, failed, interrupted, abandoned or unknown (status.json missing)."""
        return self.run_folder.state["state"]

    @property
    def status(self) -> dict:
        """The whole status: ``state`` and, where there is one, the ``reason``."""
        return self.run_folder.state

    def _finished(self) -> None:
        """Refuse (or, ``unfinished``, warn about) the results of a run not known to be complete."""
        status = self.status
        if status["state"] == "complete":
            return
        why = f"{self.folder} is {status['state']}" + (f" ({status['reason']})" if status.get("reason") else "")
        if not self.unfinished:
            raise ReadError(f"{why}: its results would not be those of a finished run; "
                            "siloflow.open_run(folder, unfinished=True) reads them anyway, with a warning")
        warnings.warn(f"{why}: these results are not those of a finished run", UnfinishedRunWarning, stacklevel=3)

    @property
    def plan(self):
        """The run plan (``siloflow.plan.RunPlan``): species, contacts, time step, stages, walls."""
        return self.run_folder.plan

    @property
    def record(self):
        """The engine run's record (``siloflow.run_folder.RunRecord``: wall time s, stage steps, ...)."""
        return self.run_folder.record

    def _results(self) -> Path:
        self._finished()
        if not self.run_folder.summary_file.is_file():
            from postprocess.first_results import analyse
            analyse(self.folder)
        return self.run_folder.results

    @cached_property
    def summary(self) -> dict:
        """results/summary.json: flow rate (kg/s) with its standard error, bands, force balance, ..."""
        self._results()
        return self.run_folder.read_summary()

    def _table(self, name: str) -> pd.DataFrame:
        path = self._results() / RESULT_TABLES[name]
        try:
            return pd.read_csv(path)
        except (OSError, ValueError) as exc:
            raise ReadError(f"cannot read {path}: {exc}") from None

    @cached_property
    def flow(self) -> pd.DataFrame:
        """Discharge series: step, time (s), time since opening, outlet mass (kg), mass in the
        silo (kg), total mass (kg), particles."""
        return self._table("flow")

    @cached_property
    def wall_pressure(self) -> pd.DataFrame:
        """Band pressure per sample: band, step, time (s), z_mid (m), pressure (Pa), shear force (N)."""
        return self._table("wall_pressure")

    @cached_property
    def bands(self) -> pd.DataFrame:
        """Per band: static pressure and shear, maximum dynamic pressure, discharge factor."""
        return self._table("bands")

    def frames(self, columns: Optional[list[str]] = None, every: int = 1) -> Iterator:
        """The particle dump frames (``postprocess.dumps.Frame``), one at a time."""
        from postprocess.dumps import read_frames
        files = self.run_folder.dump_files("particles")
        if files is None:
            if self.plan.outputs.dump_every is None:
                raise ReadError(f"{self.folder} has no particle dumps: its case asked for none (no "
                                "outputs.dump_interval and no result that needs frames in outputs.results)")
            raise ReadError(f"{self.folder} has no particle dumps in {DUMPS}, though the run was to write one every "
                            f"{self.plan.outputs.dump_every} steps: they are missing (deleted or moved), or the run "
                            f"({self.state}) stopped before the first")
        return read_frames(files, columns=columns, every=every)


def open_run(folder, unfinished: bool = False) -> Run:
    """The run folder ``folder`` (made by ``siloflow run`` or ``siloflow.run``); ``unfinished``:
    read the results of a run not known to be complete, with a warning (see :class:`Run`)."""
    return Run(folder, unfinished=unfinished)


def run(case, folder, force: bool = False, progress=None, allow_long: bool = False,
        allow_large_output: bool = False) -> Run:
    """Render ``case`` (a ``Case``, a dict of case fields or a case-file path) into ``folder``,
    run its engine, check the run and compute the first results, as ``siloflow run`` does;
    return the ``Run``. As there, a run over the step cap (``allow_long``) or whose estimated
    output exceeds the free disk (``allow_large_output``) is refused before anything is written."""
    from postprocess.first_results import analyse
    from .case import Case
    from .case_file import case_from_dict, load_case
    from .derived import check_run_length, derive
    from .disk_estimate import check_disk_space
    from .engine import get_engine
    from .engine.base import check_case
    keep = []
    _path(folder, "siloflow.run's folder")
    if not isinstance(case, (Case, dict, str, os.PathLike)) or isinstance(case, str) and not case:
        raise CaseError([("(case)", f"give a Case, a dict of case fields or a case-file path, not "
                                    f"{type(case).__name__} {case!r:.60}")], "siloflow.run")
    if isinstance(case, dict):
        case = case_from_dict(case)
    elif not isinstance(case, Case):
        keep = [case]
        case = load_case(case)
    engine = get_engine(case.engine.name)
    check_case(case, engine)
    plan = derive(case)
    check_run_length(plan, allow_long)
    check_disk_space(case, plan, folder, allow_large_output)
    folder = engine.prepare(case, folder, force=force, keep=keep, plan=plan)
    engine.execute(folder, progress=progress)
    engine.collect(folder)
    analyse(folder)
    return Run(folder)
