"""Numerical profiles: named sets of the settings that trade run time against accuracy.

``engine.profile`` of a case chooses one:

- ``custom``: the case's own ``engine.timestep_fraction`` (default 0.15) and ``engine.stiffness_scale``
  (default 1);
- ``reference``: the papers' numerical settings: dt = t_c/50 (paper B), full stiffness, the dust at
  its true density;
- ``fast``: the fastest combination ``siloflow bench`` found whose 95 % error bounds are within its
  tolerances, read from ``fast_profile.json`` beside this module (written from the committed
  benchmark, ``benchmarks/results/accuracy/``), with those bounds.

:func:`effective_case` applies a profile to a case before the run plan is derived; the plan records
which profile ran, its settings and the error bounds that come with it (``RunPlan.profile``).
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Optional

from .case import DEFAULT_TIMESTEP_FRACTION, Case
from .errors import CaseError

#: the fast profile as the accuracy benchmark recommended it (siloflow bench --publish)
FAST_PROFILE_FILE = Path(__file__).with_name("fast_profile.json")
#: the papers' numerical settings: paper B's dt = t_c/50, full stiffness, true dust density
REFERENCE = {"timestep_fraction": 0.02, "stiffness_scale": 1.0}


@lru_cache(maxsize=1)
def fast_profile() -> dict:
    """The fast profile's record: ``timestep_fraction``, ``stiffness_scale``, ``speedup`` (with
    ``speedup_lo``/``speedup_hi``), ``error_bounds`` {quantity: relative 95 % bound},
    ``tolerances``, ``benchmark`` (the case and command that measured it)."""
    return json.loads(FAST_PROFILE_FILE.read_text())


def profile_settings(case: Case) -> dict:
    """The numerical settings a case runs with: ``profile``, ``timestep_fraction``,
    ``stiffness_scale``, and for ``fast`` the benchmark's ``speedup`` and ``error_bounds``."""
    e = case.engine
    if e.profile == "custom":
        return {"profile": "custom",
                "timestep_fraction": e.timestep_fraction if e.timestep_fraction is not None else DEFAULT_TIMESTEP_FRACTION,
                "stiffness_scale": e.stiffness_scale if e.stiffness_scale is not None else 1.0}
    if e.profile == "reference":
        return {"profile": "reference", **REFERENCE}
    fast = fast_profile()
    return {"profile": "fast", "timestep_fraction": fast["timestep_fraction"],
            "stiffness_scale": fast["stiffness_scale"], "speedup": fast.get("speedup"),
            "error_bounds": fast.get("error_bounds", {}), "tolerances": fast.get("tolerances", {}),
            "benchmark": fast.get("benchmark", "")}


def _scaled(section: Optional[dict], keys: tuple[str, ...], scale: float) -> None:
    if section is None:
        return
    for k in keys:
        if section.get(k) is not None:
            section[k] = section[k] * scale


def effective_case(case: Case) -> Case:
    """The case as it runs: the profile's time-step fraction written into ``engine.timestep_fraction``
    and its stiffness scale applied to every Young's modulus (hertz, hooke) or spring (linear), then
    validated again (a scaled modulus below the schema's floor is refused, naming
    ``engine.stiffness_scale``). The reference profile runs dust at its true density: a case that
    scales it is refused. ``engine.profile`` is kept; ``engine.stiffness_scale`` becomes 1 (applied)."""
    from .case_file import case_from_dict
    s = profile_settings(case)
    dust = getattr(case.particles, "dust", None)
    if s["profile"] == "reference" and dust is not None and dust.density_scale != 1.0:
        raise CaseError([("particles.dust.density_scale", "profile 'reference' runs the dust at its true "
                          "density: remove density_scale, or use profile: custom")])
    data = case.model_dump(mode="json")
    scale = s["stiffness_scale"]
    if scale != 1.0:
        m = data["materials"]
        moduli, springs = ("youngs_modulus",), ("kn", "kt")
        for part in ("particle", "wall"):
            _scaled(m[part], moduli, scale)
        for pair in ("particle_particle", "particle_wall"):
            _scaled(m[pair], springs, scale)
        d = data["particles"].get("dust")
        if d is not None:
            _scaled(d, moduli, scale)
            for pair in ("dust_dust", "dust_particle", "dust_wall"):
                _scaled(d[pair], springs, scale)
    data["engine"].update(timestep_fraction=s["timestep_fraction"], stiffness_scale=None,
                          profile="custom")
    try:
        out = case_from_dict(data, "the case with its profile applied")
    except CaseError as exc:
        raise CaseError([("engine.stiffness_scale" if scale != 1.0 else field, f"{s['profile']} profile "
                          f"(stiffness x {scale:g}): {msg}") for field, msg in exc.problems]) from None
    # the effective case keeps the profile's name (the plan records it); its settings are now explicit
    return out.model_copy(update={"engine": out.engine.model_copy(update={"profile": s["profile"]})})


def with_profile(case: Case, name: str) -> tuple[Case, list[str]]:
    """The case run with the profile ``name`` (``siloflow run --profile``): a profile other than
    custom replaces the case's ``engine.timestep_fraction`` and ``engine.stiffness_scale``; returns
    the case and the fields it replaced. An unknown name is a ``CaseError`` naming the option."""
    from .case import PROFILE_NAMES
    from .case_file import case_from_dict
    if name not in PROFILE_NAMES:
        raise CaseError([("--profile", f"'{name}' is not a profile; choose one of {', '.join(PROFILE_NAMES)}")])
    data = case.model_dump(mode="json")
    dropped = []
    if name != "custom":
        for f in ("timestep_fraction", "stiffness_scale"):
            if data["engine"].get(f) is not None:
                dropped.append(f"engine.{f}")
                data["engine"][f] = None
    data["engine"]["profile"] = name
    return case_from_dict(data, f"the case with --profile {name}"), dropped
