"""The fast profile siloflow ships: ``fast_profile.json`` beside this module (package data, read
through :mod:`siloflow.resources`), written from the committed accuracy benchmark by
``benchmarks/publish_fast_profile.py``.

The case schema copies it into a case asking for ``profile: fast`` (``engine.fast_profile``) while
validating, so it is read here, below the schema; applying a profile to a case is
:mod:`siloflow.profiles`'.
"""
from __future__ import annotations

import json
from functools import lru_cache

from .resources import fast_profile_file

#: the fast profile as the accuracy benchmark recommended it (benchmarks/publish_fast_profile.py):
#: a package resource (an ``importlib.resources`` Traversable: read it, do not write it)
FAST_PROFILE_FILE = fast_profile_file()
#: the fields of fast_profile.json a case carries (``siloflow.case.PinnedProfile``)
PINNED = ("timestep_fraction", "overlap_ratio", "error_bounds", "tolerances", "speedup", "benchmark")


@lru_cache(maxsize=1)
def fast_profile() -> dict:
    """The packaged fast profile's whole record (fast_profile.json)."""
    return json.loads(FAST_PROFILE_FILE.read_text(encoding="utf-8"))


def packaged_fast_profile() -> dict:
    """The packaged fast profile as a case carries it (``engine.fast_profile``)."""
    return {k: fast_profile()[k] for k in PINNED if fast_profile().get(k) is not None}
