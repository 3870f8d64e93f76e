"""Reading case files: at most ``MAX_CASE_BYTES`` of a regular file, parsed with a hardened safe
YAML loader (unique keys, no aliases or tags, depth at most ``MAX_CASE_DEPTH``) and validated into
a ``Case`` (:mod:`siloflow.case`), or a ``CaseError`` listing every problem with its field path
(or its line, for YAML errors). The inserts' mesh files are only located here (relative to the
case file); they are read and checked with the walls, when the run plan is made.

The reading itself, which needs nothing of the schema, is :mod:`siloflow.case_reader` (below
:mod:`siloflow.case`, whose ``Case.from_yaml`` uses it too); this module binds it to ``Case``.
"""
from __future__ import annotations

import yaml

from .case import Case
from .case_reader import (MAX_CASE_BYTES, MAX_CASE_DEPTH, locate_inserts, parse_case_yaml,  # noqa: F401
                          read_case, read_case_bytes, validate_case, validation_problems)


def case_from_dict(data, source: str = "case") -> Case:
    """Validate a mapping; raise ``CaseError`` listing every problem."""
    return validate_case(Case, data, source)


def load_case(path) -> Case:
    """Read and validate a YAML case file, raising ``CaseError`` on any problem."""
    return read_case(Case, path)


def case_to_yaml(case: Case) -> str:
    """The validated case as YAML (every default filled in)."""
    return yaml.safe_dump(case.model_dump(mode="json"), sort_keys=False)
