"""The one reader of a study's case file (``siloflow sweep``, ``bench``, ``stability``, the
benchmarks' run tables): its fields, to derive each run's case from, and the case they validate to."""
from __future__ import annotations

from pathlib import Path


def read_study_case(path) -> tuple[dict, object]:
    """(fields, validated ``Case``) of the case file ``path``, checked whole first as ``siloflow
    validate`` reads it (``load_case``: every problem of the case itself); the fields' inserts'
    files are absolute paths (located relative to the case file), so the study's runs, whose case
    files are written elsewhere, still find them. Raises ``CaseError``."""
    from .case_file import load_case, parse_case_yaml, read_case_bytes
    path = Path(path)
    case = load_case(path)
    fields = parse_case_yaml(read_case_bytes(path), str(path))
    for insert, located in zip(fields.get("inserts") or [], case.inserts):
        insert["file"] = located.file
    return fields, case
