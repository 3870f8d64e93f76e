"""A resumable table of engine runs, one row each (``runs.csv``), shared by ``siloflow bench`` and
``siloflow stability``: every planned run not yet in the table is run, and its row written as soon as
it ends, so a stopped study goes on where it stopped. A run that fails (the guard, the engine) is a
row too, with its reason: an unstable setting is a result, not an error of the study."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .errors import SetupError, SiloflowError

TABLE_NAME = "runs.csv"


@dataclass
class PlannedRun:
    """One run of a study: its identifying columns (``key``), the case fields to run and the
    extra columns of its row."""

    key: dict
    case: dict
    columns: dict = field(default_factory=dict)


def key_text(value) -> str:
    """A key column's value as text that survives the CSV round trip: None and NaN are "", numbers
    their float's repr (a seed 7 and 7.0 read back are one key), text as it is."""
    if value is None:
        return ""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return "" if math.isnan(float(value)) else repr(float(value))
    return str(value)


def run_name(*parts) -> str:
    """A run's case name from its parts joined by '-', within the 64 characters a name may have: the
    first part (the case's name) is shortened when the whole would be longer."""
    tail = "-".join(str(p) for p in parts[1:])
    head = str(parts[0])[:max(0, 63 - len(tail))]
    return (f"{head}-{tail}" if head else tail)[:64]


def read_rows(out: Path) -> list[dict]:
    """The rows of ``out/runs.csv`` (none if it does not exist)."""
    import pandas as pd
    table = Path(out) / TABLE_NAME
    # text columns whose values can look like numbers (a hex digest "1234e567...", a host name)
    text = {"case_sha": str, "machine": str}
    return pd.read_csv(table, dtype=text).to_dict(orient="records") if table.is_file() else []


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


def case_digest(fields: dict) -> str:
    """SHA-256 (16 hex digits) of a study's case fields as its case file gives them (the parsed YAML,
    keys sorted), without ``name`` and ``seed``: the rows of one ``runs.csv`` must all come from one
    case (a study resumed on an edited case file would mix two). The file's fields, not the validated
    case: a siloflow that adds a defaulted field or publishes another fast profile does not change it.
    An insert's STL file counts by its bytes, not its path: an edited mesh is another case, a moved
    folder is not (an unreadable file counts as missing; the run that reads it says why)."""
    import hashlib
    import json
    kept = {k: v for k, v in fields.items() if k not in ("name", "seed")}
    if isinstance(kept.get("inserts"), list):
        kept["inserts"] = [dict(ins, file=_file_digest(ins["file"])) if isinstance(ins, dict) and "file" in ins
                           else ins for ins in kept["inserts"]]
    return hashlib.sha256(json.dumps(kept, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _file_digest(path) -> str:
    """``sha256:<hex>`` of a file's bytes, or ``missing`` when it cannot be read."""
    import hashlib
    try:
        return "sha256:" + hashlib.sha256(Path(str(path)).read_bytes()).hexdigest()
    except (OSError, ValueError):
        return "missing"


def machine_id() -> str:
    """Which machine, as booted, ran a study's runs (``<hostname>-<boot id prefix>``): wall times
    compare only between runs of one machine (a fresh machine may be twice as fast or slow)."""
    import socket
    try:
        boot = Path("/proc/sys/kernel/random/boot_id").read_text().strip()[:8]
    except OSError:
        boot = ""
    return f"{socket.gethostname()}-{boot}" if boot else socket.gethostname()


def engine_wall_time(folder: Path) -> float:
    """The engine's wall time of a run folder, s (NaN when it recorded none)."""
    from .run_folder import RunFolder
    try:
        return float(RunFolder(folder).record.wall_time)
    except (SiloflowError, OSError, TypeError, ValueError):
        return float("nan")


def run_missing(out: Path, planned: list[PlannedRun], measure: Callable[[Path], dict],
                failed: Callable[[Path, str], dict], report: Callable[[str], None] = lambda s: None,
                case_sha: str = "") -> list[dict]:
    """Run every planned run whose ``key`` is not yet a row of ``out/runs.csv`` (``siloflow.run``
    into ``out/runs/<case name>``, one after the other in this process, through the scheduler
    :func:`siloflow.scheduler.run_jobs`); its row is the key, the columns, ``state``, ``reason``,
    ``folder``, ``machine`` (:func:`machine_id`), ``case_sha`` (:func:`case_digest` of the study's
    case) and ``measure(folder)`` (complete) or ``failed(folder, reason)``. Returns all rows.
    ``SetupError`` before anything runs when the table holds rows of another case (rows written
    before the column existed are taken as they are)."""
    from .case_file import case_from_dict
    from .scheduler import InOrder, Job, Outcome, run_jobs
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = read_rows(out)
    other = sorted({str(r.get("case_sha")) for r in rows if key_text(r.get("case_sha")) not in ("", case_sha)})
    if case_sha and other:
        raise SetupError(f"{out / TABLE_NAME} holds runs of another case (case_sha {', '.join(other)}, this case "
                         f"{case_sha}): the case file changed since; write this study to a new folder (-o)")

    def key_of(d: dict) -> tuple:
        return tuple(sorted((k, key_text(d.get(k))) for k in planned[0].key)) if planned else ()

    done = {key_of(r) for r in rows}
    folders: dict[str, Path] = {}
    of_job: dict[str, PlannedRun] = {}

    def work(p: PlannedRun):
        def run_it():
            from . import runs              # looked up when it runs: siloflow.runs.run as it is then
            name = p.case["name"]
            folders[name] = folder = _free_folder(out / "runs" / name)
            report(f"{name}: running")
            runs.run(case_from_dict(p.case, name), folder)
        return run_it

    def ended(job: Job, outcome: Outcome) -> None:
        p, folder = of_job[job.name], folders[job.name]
        row = {**p.key, **p.columns, "folder": str(folder.relative_to(out)), "machine": machine_id(),
               "case_sha": case_sha}
        if outcome.ok:
            row.update(state="complete", reason="", **measure(folder))
        else:
            reason = " ".join(outcome.reason.split())[:400]
            if not folder.exists():          # refused before anything ran (the step cap, the disk, ...):
                report(f"{job.name}: not run: {reason}")   # no result to keep; the next call tries again
                return
            row.update(state="failed", reason=reason, **failed(folder, reason))
        rows.append(row)
        _write_rows(rows, out)
        report(f"{job.name}: {row['state']} ({row.get('wall_s', float('nan')):.1f} s)"
               + (f": {row['reason']}" if row["reason"] else ""))

    jobs = []
    for p in planned:
        if key_of(p.key) in done:
            continue
        of_job[p.case["name"]] = p
        jobs.append(Job(p.case["name"], work(p)))
    run_jobs(InOrder(jobs), 1, ended, isolate=False)
    return rows
