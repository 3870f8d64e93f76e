"""The case's engine settings: engine, ranks, profile, time step and stiffness scaling."""
from __future__ import annotations

from typing import Annotated, Literal, Optional

from pydantic import Field, model_validator

from ..engines import ENGINES
from ..packaged_profile import BENCH_QUANTITIES, QUESTIONS, packaged_fast_profile
from .fields import MIN_TIMESTEP_FRACTION, Int, Positive, Real, Strict
from .outputs import Guard

PROFILE_NAMES = ("custom", "reference", "fast")
#: the engine fields a profile other than custom owns
PROFILE_FIELDS = ("profile", "timestep_fraction", "stiffness_scale", "fast_profile")
#: time-step fraction of the custom profile when the case gives none
DEFAULT_TIMESTEP_FRACTION = 0.15
#: the quantities the accuracy benchmark bounds (``siloflow.accuracy_bench.QUANTITIES``)
BenchQuantity = Literal[BENCH_QUANTITIES]
TimestepFraction = Annotated[Real, Field(ge=MIN_TIMESTEP_FRACTION, le=1, allow_inf_nan=False)]


class PinnedProfile(Strict):
    """The fast profile as this case runs it: copied from siloflow's benchmarked profiles
    (``siloflow/fast_profile.json``) when a case asking for ``profile: fast`` is read (the one for
    the results it asks, ``siloflow.packaged_profile.choose_profile``), and kept in the run folder's
    case.yaml, so a run resumes with the profile it started with."""

    question: Optional[Literal[tuple(QUESTIONS)]] = Field(None, description="the question the profile was proven "
                                                          "for (none: pinned by a siloflow with one fast profile)")
    timestep_fraction: TimestepFraction
    overlap_ratio: Real = Field(gt=0, le=1, allow_inf_nan=False,
                                description="the contacts are softened until two of the smallest grains meeting "
                                "at the fill's impact speed overlap by this fraction of their radius (never "
                                "stiffened: a softer case keeps its stiffness)")
    error_bounds: dict[BenchQuantity, Annotated[Real, Field(ge=0, le=1e3, allow_inf_nan=False)]] = {}
    tolerances: dict[BenchQuantity, Annotated[Real, Field(ge=0, le=1e3, allow_inf_nan=False)]] = {}
    speedup: Optional[Positive] = None
    measured: dict[BenchQuantity, Annotated[list[Annotated[Real, Field(ge=-1e3, le=1e3, allow_inf_nan=False)]],
                                            Field(min_length=3, max_length=3)]] = Field(
        {}, description="relative error and its 95 % interval [error, low, high] the benchmark measured at this "
        "profile for each quantity, bounded or not")
    benchmark: str = Field("", max_length=500, description="where the bounds were measured (never reaches a deck)")


class EngineSettings(Strict):
    """Which engine runs the case (one of ``siloflow.engines.ENGINES``), on how many MPI ranks, at
    what time step and stiffness. What an engine cannot do of a case is its own check
    (``Engine.check``). ``profile`` names a set of numerical settings (``siloflow.profiles``):
    ``reference`` (the papers': dt = t_c/50, full stiffness, true dust density), ``fast`` (the
    benchmark's recommendation, with its error bounds) or ``custom`` (the case's own
    ``timestep_fraction`` and ``stiffness_scale``, which the other two set and refuse)."""

    name: Literal[tuple(ENGINES)] = "liggghts"
    ranks: Int = Field(1, ge=1, le=1024, description="MPI ranks")
    profile: Literal[PROFILE_NAMES] = Field("custom", description="numerical settings: custom (this "
                                            "section's), reference (the papers'), fast (benchmarked)")
    timestep_fraction: Optional[TimestepFraction] = Field(
        None, description="time step "
                                                  "as a fraction of the critical (contact) time (custom "
                                                  f"profile; default {DEFAULT_TIMESTEP_FRACTION})")
    stiffness_scale: Optional[Real] = Field(None, ge=1e-8, le=1.0, allow_inf_nan=False,
                                            description="contact stiffness x this factor: Young's moduli "
                                            "(hertz, hooke) or kn and kt (linear) of every material and "
                                            "pair (custom profile; default 1)")
    fast_profile: Optional[PinnedProfile] = Field(None, description="the fast profile's settings and bounds "
                                                  "(filled in from siloflow's benchmarked profile when not given)")
    guard: Guard = Guard()
    side_walls: Literal["meshes", "primitive"] = Field(
        "primitive", description="LIGGGHTS: the side walls of a generated silo as primitive walls whose band "
        "forces are binned in the engine (the default: 3.0x the demo's engine rate, equal to the sensor meshes "
        "over 10 seeds, docs/engines.md), or as sensor meshes (each band sector a mesh)")

    @model_validator(mode="before")
    @classmethod
    def _pin_fast_profile(cls, data):
        """``profile: fast`` runs a benchmarked profile of this siloflow, copied into the case: the
        case's own (``Case``) picks it by its results; settings read alone get everything's."""
        if isinstance(data, dict) and data.get("profile") == "fast" and data.get("fast_profile") is None:
            data = {**data, "fast_profile": packaged_fast_profile()}
        return data

    @model_validator(mode="after")
    def _profile_owns_settings(self):
        if self.profile != "custom":
            given = [f for f in ("timestep_fraction", "stiffness_scale") if getattr(self, f) is not None]
            if given:
                raise ValueError(f"profile '{self.profile}' sets {' and '.join(given)}: remove "
                                 f"{' and '.join('engine.' + f for f in given)}, or use profile: custom")
        if self.profile != "fast" and self.fast_profile is not None:
            raise ValueError(f"engine.fast_profile belongs to profile 'fast', not '{self.profile}': remove it")
        return self


