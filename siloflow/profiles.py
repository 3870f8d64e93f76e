"""Numerical profiles: named sets of the settings that trade run time against accuracy.

``engine.profile`` of a case chooses one:

- ``custom``: the case's own ``engine.timestep_fraction`` (default 0.15) and ``engine.stiffness_scale``
  (default 1);
- ``reference``: the papers' numerical settings: dt = t_c/50 (paper B), full stiffness, the dust at
  its true density;
- ``fast``: the setting ``siloflow bench`` recommended for the results the case asks
  (``outputs.results``: the flow rate alone, with the static wall pressure, everything), with the
  95 % error bounds it was proven to (``fast_profile.json``, read by :mod:`siloflow.packaged_profile`,
  written from the committed benchmark by ``benchmarks/publish_fast_profile.py``); what the case asks
  that the profile does not bound is recorded as unbounded, with the error the benchmark measured. It is a time-step fraction and a softness: the contacts
  are softened until two of the smallest grains meeting at the fill's impact speed overlap by
  ``overlap_ratio`` of their radius, as the benchmark's recommended stiffness did in its case. A
  case already that soft keeps its stiffness: the profile never stiffens, and never softens a soft
  case further. A validated case asking for ``fast`` carries a copy (``engine.fast_profile``), so
  its run folder resumes with the profile it started with.

:func:`effective_case` applies a profile before the run plan is derived; the plan records which
profile ran, its settings and the bounds that come with it (``RunPlan.profile``).
"""
from __future__ import annotations

import math

from .case import DEFAULT_TIMESTEP_FRACTION, PROFILE_NAMES, Case
from .errors import CaseError
from .packaged_profile import FAST_PROFILE_FILE, PINNED, asked_quantities, fast_profile, packaged_fast_profile  # noqa: F401 (their old home)

#: the papers' numerical settings: paper B's dt = t_c/50, full stiffness, true dust density
REFERENCE = {"timestep_fraction": 0.02, "stiffness_scale": 1.0}


def impact_overlap_ratio(case: Case, stiffness_scale: float = 1.0) -> float:
    """The deepest overlap of two of the smallest grains meeting head-on at the fill's impact speed
    (free fall from the top of the silo after the insertion speed), as a fraction of their radius,
    at the case's stiffness x ``stiffness_scale``, undamped: Hertz (15 m* v^2 / (16 Y* sqrt(R*)))^(2/5),
    a linear spring (hooke, linear) v sqrt(m* / kn). A dimensionless softness, independent of the
    time step."""
    from . import contact_physics as cp
    from .species import INSERTION_SPEED, species_of
    smallest = min((sp for sp in species_of(case) if sp.stream == "grains"), key=lambda sp: sp.radius)
    m = case.materials
    m_eff, r_eff = smallest.density * smallest.volume / 2.0, smallest.radius / 2.0
    g = case.geometry
    v = cp.free_fall_speed(g.hopper_height + g.height, case.gravity, INSERTION_SPEED)
    if m.model in ("hertz", "hooke"):
        e, nu = m.particle.youngs_modulus * stiffness_scale, m.particle.poisson_ratio
        y_eff = cp.effective_modulus(e, nu, e, nu)
        if m.model == "hertz":
            delta = (15.0 * m_eff * v ** 2 / (16.0 * y_eff * math.sqrt(r_eff))) ** 0.4
            return delta / smallest.radius
        kn = cp.hooke_kn(m_eff, r_eff, y_eff, m.characteristic_velocity)
    else:
        kn = m.particle_particle.kn * stiffness_scale
    return v * math.sqrt(m_eff / kn) / smallest.radius


def softening_for(case: Case, overlap_ratio: float) -> float:
    """The stiffness scale (<= 1) that brings the case's impact overlap to ``overlap_ratio``: the
    overlap goes as the stiffness to the -2/5 (Hertz modulus, hooke's modulus) or -1/2 (linear kn)."""
    now = impact_overlap_ratio(case)
    if now >= overlap_ratio:
        return 1.0
    exponent = 2.0 if case.materials.model == "linear" else 2.5
    return (now / overlap_ratio) ** exponent


def profile_settings(case: Case) -> dict:
    """The numerical settings a case runs with: ``profile``, ``timestep_fraction``,
    ``stiffness_scale``, and for ``fast`` its ``overlap_ratio``, ``speedup``, ``error_bounds``,
    ``tolerances``, ``benchmark``, the ``question`` it was proven for, the benchmarked quantities the
    case asks that it does not bound (``unbounded``) and the errors measured at it (``measured``)."""
    e = case.engine
    if e.profile == "custom":
        return {"profile": "custom",
                "timestep_fraction": e.timestep_fraction if e.timestep_fraction is not None else DEFAULT_TIMESTEP_FRACTION,
                "stiffness_scale": e.stiffness_scale if e.stiffness_scale is not None else 1.0}
    if e.profile == "reference":
        return {"profile": "reference", **REFERENCE}
    fast = e.fast_profile
    return {"profile": "fast", "timestep_fraction": fast.timestep_fraction,
            "stiffness_scale": softening_for(case, fast.overlap_ratio), "overlap_ratio": fast.overlap_ratio,
            "speedup": fast.speedup, "error_bounds": dict(fast.error_bounds), "tolerances": dict(fast.tolerances),
            "benchmark": fast.benchmark, "question": fast.question,
            "unbounded": [q for q in asked_quantities(case.outputs.results) if q not in fast.error_bounds],
            "measured": {q: list(v) for q, v in fast.measured.items()}}


def _scaled(section, keys: tuple[str, ...], scale: float) -> None:
    if section is None:
        return
    for k in keys:
        if section.get(k) is not None:
            section[k] = section[k] * scale


def effective_case(case: Case, settings: dict | None = None) -> Case:
    """The case as it runs, as a ``custom`` case: the profile's time-step fraction written into
    ``engine.timestep_fraction`` and its stiffness scale applied to every Young's modulus (hertz,
    hooke) or spring (linear), then, when a modulus changed, validated again (a scaled modulus below
    the schema's floor is refused, naming ``engine.stiffness_scale``). Applying it twice changes nothing more. The
    reference profile runs dust at its true density: a case that scales it is refused."""
    from .case_file import case_from_dict
    s = settings if settings is not None else profile_settings(case)
    dust = getattr(case.particles, "dust", None)
    if s["profile"] == "reference" and dust is not None and dust.density_scale != 1.0:
        raise CaseError([("particles.dust.density_scale", "profile 'reference' runs the dust at its true "
                          "density: remove density_scale, or use profile: custom")])
    scale = s["stiffness_scale"]
    engine = {"profile": "custom", "timestep_fraction": s["timestep_fraction"], "stiffness_scale": None,
              "fast_profile": None}
    if scale == 1.0:                   # no modulus changes: nothing the schema must check again
        return case.model_copy(update={"engine": case.engine.model_copy(update=engine)})
    data = case.model_dump(mode="json")
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
    data["engine"].update(engine)
    try:
        return case_from_dict(data, "the case with its profile applied")
    except CaseError as exc:
        why = (", the softening the grains' impact from the silo's top needs at materials.particle's stiffness"
               if s["profile"] == "fast" else "")
        raise CaseError([("engine.stiffness_scale", f"{s['profile']} profile (stiffness x {scale:.3g}{why}): "
                          f"{field}: {msg}") for field, msg in exc.problems]) from None


def with_profile(case: Case, name: str) -> tuple[Case, list[str]]:
    """The case run with the profile ``name`` (``siloflow run --profile``): a profile other than
    custom replaces the case's ``engine.timestep_fraction`` and ``engine.stiffness_scale``; returns
    the case and the fields it replaced. An unknown name is a ``CaseError`` naming the option."""
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
    if name != data["engine"]["profile"]:
        data["engine"]["fast_profile"] = None
    data["engine"]["profile"] = name
    return case_from_dict(data, f"the case with --profile {name}"), dropped
