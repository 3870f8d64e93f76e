"""A resumable table of engine runs, one row each (``runs.csv``), shared by ``siloflow bench`` and
``siloflow stability``: every planned run not yet in the table is run, and its row written as soon as
it ends, so a stopped study goes on where it stopped. A run that fails (the guard, the engine) is a
row too, with its reason: an unstable setting is a result, not an error of the study."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .errors import SiloflowError

TABLE_NAME = "runs.csv"


@dataclass
class PlannedRun:
    """One run of a study: its identifying columns (``key``), the case fields to run and the
    extra columns of its row."""

    key: dict
    case: dict
    columns: dict = field(default_factory=dict)


def read_rows(out: Path) -> list[dict]:
    """The rows of ``out/runs.csv`` (none if it does not exist)."""
    import pandas as pd
    table = Path(out) / TABLE_NAME
    return pd.read_csv(table).to_dict(orient="records") if table.is_file() else []


def _write_rows(rows: list[dict], out: Path) -> None:
    import pandas as pd
    from .atomic_files import write_text
    write_text(Path(out) / TABLE_NAME, pd.DataFrame(rows).to_csv(index=False))


def _free_folder(folder: Path) -> Path:
    """``folder``, or ``folder-retryN`` when a run interrupted there (its row never written) left it:
    the interrupted run is run anew, and its folder kept as it is."""
    k, path = 0, folder
    while path.exists():
        k += 1
        path = folder.with_name(f"{folder.name}-retry{k}")
    return path


def engine_wall_time(folder: Path) -> float:
    """The engine's wall time of a run folder, s (NaN when it recorded none)."""
    from .run_folder import RunFolder
    try:
        return float(RunFolder(folder).record.wall_time)
    except (SiloflowError, OSError, TypeError, ValueError):
        return float("nan")


def run_missing(out: Path, planned: list[PlannedRun], measure: Callable[[Path], dict],
                failed: Callable[[Path, str], dict], report: Callable[[str], None] = lambda s: None) -> list[dict]:
    """Run every planned run whose ``key`` is not yet a row of ``out/runs.csv`` (``siloflow.run``
    into ``out/runs/<case name>``); its row is the key, the columns, ``state``, ``reason``,
    ``folder`` and ``measure(folder)`` (complete) or ``failed(folder, reason)``. Returns all rows."""
    from .case_file import case_from_dict
    from .runs import run
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = read_rows(out)

    def key_of(d: dict) -> tuple:
        return tuple(sorted((k, str(d[k])) for k in planned[0].key)) if planned else ()

    done = {key_of(r) for r in rows}
    for p in planned:
        if key_of(p.key) in done:
            continue
        name = p.case["name"]
        folder = _free_folder(out / "runs" / name)
        row = {**p.key, **p.columns, "folder": str(folder.relative_to(out))}
        report(f"{name}: running")
        try:
            run(case_from_dict(p.case, name), folder)
            row.update(state="complete", reason="", **measure(folder))
        except SiloflowError as exc:
            reason = " ".join(str(exc).split())[:400]
            row.update(state="failed", reason=reason, **failed(folder, reason))
        rows.append(row)
        _write_rows(rows, out)
        report(f"{name}: {row['state']} ({row.get('wall_s', float('nan')):.1f} s)"
               + (f": {row['reason']}" if row["reason"] else ""))
    return rows
