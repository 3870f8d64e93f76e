"""The instability guard every run carries: it reads the signals an engine reports at each thermo
output and says when the run must stop, before it produces garbage.

Signals (limits in :class:`siloflow.plan.Guard`, set from ``engine.guard`` of the case):

- ``not_finite``: a kinetic or potential energy, speed or overlap that is NaN or infinite;
- ``overlap``: the deepest pair overlap beyond ``max_overlap_fraction`` of the smallest radius;
- ``speed``: a grain faster than ``speed_factor`` times the free fall from the top of the silo;
- ``escape``: grains beyond the walls (or, for spheres, atoms gone without passing the outlet);
- ``energy``: the kinetic energy growing by ``energy_growth`` in a stage without sources
  (settling and static stages: no insertion, no deletion, no moving wall), once it is above
  ``ENERGY_FLOOR`` of the potential energy.

Engine-neutral: an engine calls :meth:`RunGuard.check` with the values of one thermo row.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

from .plan import Guard

#: stages in which nothing adds or removes energy: kinetic energy can only decay there
CLOSED_STAGES = ("settle", "resettle", "static")
#: kinetic/potential energy below which growth is not judged (a settled bed is at 1e-6 and below)
ENERGY_FLOOR = 1e-2
#: grains that may stray beyond the walls during the fill, as a fraction of the atoms: a pour loses a
#: few to splashes, which the run's check records (as LIGGGHTS' FILL_LOSS_LIMIT of 1 % of the atoms)
FILL_ESCAPES = 0.01
#: the usual remedies, named by case field
_STEP_FIX = "lower engine.timestep_fraction (or use engine.profile: reference)"


@dataclass(frozen=True)
class GuardTrip:
    """Why the guard stopped a run: the signal, where, the value against its limit, and the fix."""

    signal: str
    stage: str
    step: int
    value: float
    limit: float
    message: str
    cause: str
    fix: str


class RunGuard:
    """Watches one run's thermo rows against the plan's :class:`~siloflow.plan.Guard` limits."""

    def __init__(self, limits: Guard):
        self.limits = limits
        self._stage: Optional[str] = None
        self._ke_min = math.inf
        #: the largest speed (m/s) and pair overlap (m) of the rows checked, whether or not the guard is on
        self.peaks = {"speed": -math.inf, "overlap": -math.inf}

    def peak_record(self) -> Optional[dict]:
        """The peaks as the run record keeps them (``max_speed`` m/s, ``max_overlap`` m; no contact yet
        reads 0), None when no row with a grain was checked (LIGGGHTS' max over no atoms is -1e20)."""
        if not math.isfinite(self.peaks["speed"]) or self.peaks["speed"] < 0:
            return None
        return {"max_speed": self.peaks["speed"], "max_overlap": max(self.peaks["overlap"], 0.0)}

    def check(self, stage: Optional[str], step: int, ke: float, pe: float, speed: Optional[float] = None,
              overlap: Optional[float] = None, escaped: Optional[float] = None,
              lost: Optional[int] = None, atoms: int = 0) -> Optional[GuardTrip]:
        """The first signal that trips on this row (None when all is well). ``ke``, ``pe``: J;
        ``speed``: fastest grain, m/s; ``overlap``: deepest pair overlap, m (negative: no contact);
        ``escaped``: grains beyond the walls; ``lost``: atoms gone without passing the outlet;
        ``atoms``: atoms in the box (in the fill, up to ``FILL_ESCAPES`` of them may stray)."""
        g = self.limits
        for key, v in (("speed", speed), ("overlap", overlap)):
            if v is not None and math.isfinite(v):
                self.peaks[key] = max(self.peaks[key], v)
        if not g.enabled:
            return None
        stage = stage or "start"
        if stage != self._stage:
            self._stage, self._ke_min = stage, math.inf

        def trip(signal, value, limit, message, cause, fix):
            return GuardTrip(signal, stage, step, float(value), float(limit), message, cause, fix)

        values = {"kinetic energy": ke, "potential energy": pe, "fastest speed": speed, "deepest overlap": overlap}
        for name, v in values.items():
            if v is not None and not math.isfinite(v):
                return trip("not_finite", v, 0.0, f"the {name} is {v} at step {step} ({stage} stage)",
                            "the integration blew up: the time step is too large for the contacts", _STEP_FIX)
        if overlap is not None and overlap > g.max_overlap:
            return trip("overlap", overlap, g.max_overlap,
                        f"two grains overlap by {overlap:.3g} m at step {step} ({stage} stage), "
                        f"{overlap / g.grain_radius:.2g} of the smallest radius (limit {g.max_overlap_fraction:g})",
                        "contacts too soft for the load, or a time step too large to resolve the impacts",
                        f"{_STEP_FIX}; raise engine.stiffness_scale (or the Young's moduli / kn); or raise "
                        "engine.guard.max_overlap if such overlaps are intended")
        if speed is not None and speed > g.max_speed:
            return trip("speed", speed, g.max_speed,
                        f"a grain moves at {speed:.3g} m/s at step {step} ({stage} stage), faster than "
                        f"{g.max_speed:.3g} m/s: more than gravity can give it (energy from nowhere)",
                        "a numerical instability: overlapping grains pushed apart by a time step too large "
                        "for their stiffness", f"{_STEP_FIX}")
        allowed = FILL_ESCAPES * atoms if stage == "fill" else 0.0
        if escaped is not None and escaped > max(0.5, allowed):
            return trip("escape", escaped, 0.0,
                        f"{int(round(escaped))} grain(s) are beyond the walls at step {step} ({stage} stage)",
                        "grains passed through a wall: a time step too large for the wall contact, or walls too "
                        "soft for the load", f"{_STEP_FIX}; raise the wall stiffness")
        if lost is not None and lost > 0:
            return trip("escape", lost, 0.0,
                        f"{lost} atom(s) left the simulation without passing the outlet by step {step} "
                        f"({stage} stage)", "grains passed through a wall and out of the box",
                        f"{_STEP_FIX}; raise the wall stiffness")
        if stage in CLOSED_STAGES and pe > 0:
            self._ke_min = min(self._ke_min, ke)
            if ke > ENERGY_FLOOR * pe and ke > g.energy_growth * self._ke_min:
                return trip("energy", ke, g.energy_growth * self._ke_min,
                            f"the kinetic energy grew from {self._ke_min:.3g} J to {ke:.3g} J at step {step} in "
                            f"the {stage} stage, where nothing feeds it", "a numerical instability "
                            "(the time step or the stiffness)", _STEP_FIX)
        return None
