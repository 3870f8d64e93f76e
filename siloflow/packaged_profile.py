"""The fast profiles siloflow ships: ``fast_profile.json`` beside this module (package data, read
through :mod:`siloflow.resources`), written from the committed accuracy benchmark by
``benchmarks/publish_fast_profile.py``.

The benchmark proves one profile per question a case can ask (:data:`QUESTIONS`: the flow rate
alone, the flow rate and the static wall pressure, everything it compares). A case asking for
``profile: fast`` runs the fastest published profile that bounds every benchmarked quantity its
``outputs.results`` ask for (:func:`choose_profile`); when none bounds them all, the one that bounds
the most, and the rest are said to be unbounded, with the error the benchmark measured for them.

The case schema copies the chosen profile into the case (``engine.fast_profile``) while
validating, so it is read here, below the schema; applying a profile to a case is
:mod:`siloflow.profiles`'.
"""
from __future__ import annotations

import json
from functools import lru_cache
from typing import Iterable, Optional

from .resources import fast_profile_file

#: the fast profiles as the accuracy benchmark recommended them (benchmarks/publish_fast_profile.py):
#: a package resource (an ``importlib.resources`` Traversable: read it, do not write it)
FAST_PROFILE_FILE = fast_profile_file()
#: the fields of a published profile a case carries (``siloflow.case.PinnedProfile``)
PINNED = ("question", "timestep_fraction", "overlap_ratio", "error_bounds", "tolerances", "speedup", "measured",
          "benchmark")
#: the quantities the accuracy benchmark compares (``siloflow.accuracy_bench.QUANTITIES``)
BENCH_QUANTITIES = ("flow_rate", "static_pressure", "dynamic_pressure_max", "solid_fraction", "coordination")
#: the questions a fast profile is proven for, narrowest first: the quantities each one bounds
QUESTIONS = {
    "flow_rate": ("flow_rate",),
    "flow_rate_and_static_pressure": ("flow_rate", "static_pressure"),
    "everything": BENCH_QUANTITIES,
}
#: what each of ``outputs.results`` asks of the benchmarked quantities (the others, free_surface,
#: coarse_graining, vtk, are benchmarked by no profile); the flow rate is always measured
RESULT_QUANTITIES = {
    "flow_rate": ("flow_rate",),
    "force_balance": ("static_pressure",),
    "wall_pressure": ("static_pressure", "dynamic_pressure_max"),
    "porosity": ("solid_fraction",),
    "coordination": ("coordination",),
    "force_chains": ("coordination",),
}


@lru_cache(maxsize=1)
def fast_profile() -> dict:
    """The packaged fast profiles' whole record (fast_profile.json): ``{"profiles": {question: record}}``."""
    return json.loads(FAST_PROFILE_FILE.read_text(encoding="utf-8"))


def asked_quantities(results: Optional[Iterable[str]]) -> tuple[str, ...]:
    """The benchmarked quantities a case's ``outputs.results`` ask for (None: everything), in
    :data:`BENCH_QUANTITIES`' order; the flow rate always (every run measures it)."""
    if results is None:
        return BENCH_QUANTITIES
    asked = {"flow_rate"} | {q for r in results for q in RESULT_QUANTITIES.get(r, ())}
    return tuple(q for q in BENCH_QUANTITIES if q in asked)


def choose_profile(results: Optional[Iterable[str]], profiles: Optional[dict] = None) -> tuple[str, dict]:
    """(question, record) of the published profile a case asking for ``results`` runs: the fastest
    that bounds every quantity asked (:func:`asked_quantities`); when none does, the one bounding the
    most of them (the fastest of those)."""
    profiles = fast_profile()["profiles"] if profiles is None else profiles
    asked = set(asked_quantities(results))

    def rank(item):
        bounded = len(asked & set(item[1]["error_bounds"]))
        return bounded == len(asked), bounded, item[1]["speedup"]
    return max(profiles.items(), key=rank)


def packaged_fast_profile(results: Optional[Iterable[str]] = None) -> dict:
    """The packaged fast profile for a case asking for ``results`` (``outputs.results``; None:
    everything), as the case carries it (``engine.fast_profile``)."""
    question, record = choose_profile(results)
    record = {**record, "question": question}
    return {k: record[k] for k in PINNED if record.get(k) is not None}
