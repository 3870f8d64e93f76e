"""What a case writes (results, samples, dumps) and its run guard."""
from __future__ import annotations

from typing import Literal, Optional

from pydantic import Field, model_validator

from .fields import MAX_STAGE_TIME, Positive, Real, Strict

RESULTS = ("flow_rate", "force_balance", "wall_pressure", "porosity", "free_surface", "coordination",
           "force_chains", "coarse_graining", "vtk")


class Outputs(Strict):
    """What the run writes. ``results`` lists what the run is for; the deck then holds only what
    those results need (no sensor meshes without ``wall_pressure``, no wall-force sampling without
    it or ``force_balance``, no dumps without a frame analysis, no contact dumps without
    ``coordination``, ``force_chains`` or ``coarse_graining``). Unset: everything the other fields
    ask for (sensors always, dumps when ``dump_interval`` is set)."""

    results: Optional[list[Literal[RESULTS]]] = Field(
        None, max_length=len(RESULTS), description="what the run is for (flow_rate is always measured): "
        + ", ".join(RESULTS) + "; unset: everything")
    sample_interval: Positive = Field(0.005, description="wall forces and flow sampled this often, s", le=100)
    dump_interval: Optional[Positive] = Field(None, le=MAX_STAGE_TIME, description="particle dumps this often, "
                                              "s (none if unset; at most the whole run, siloflow.derived)")
    vtk: bool = Field(False, description="also write VTK particle files for ParaView")
    contacts: bool = Field(True, description="with dumps: also dump pair contacts (positions, ids, "
                           "forces) for coordination numbers and force chains")
    figures: bool = True

    @model_validator(mode="after")
    def _results_fit(self):
        if self.results is not None:
            if len(set(self.results)) != len(self.results):
                raise ValueError("outputs.results lists a result twice")
        return self


class Guard(Strict):
    """The instability guard of every run (``siloflow.guard``): the engine reports these signals at
    each thermo output and the run is stopped, naming the signal and its fix, when one trips."""

    enabled: bool = Field(True, description="watch the run (off only to study an instability)")
    max_overlap: Real = Field(0.5, gt=0, le=2, allow_inf_nan=False,
                              description="deepest pair overlap allowed, as a fraction of the smallest "
                              "grain radius: beyond half a radius grains are passing through each other "
                              "(softened contacts reach 0.2-0.5 in fill impacts; lower it to be strict)")
    speed_factor: Real = Field(2.0, ge=1.0, le=1000, allow_inf_nan=False,
                               description="fastest grain allowed, as a multiple of the free-fall speed "
                               "over the silo's height (plus the insertion speed): faster needs energy "
                               "from nowhere")
    energy_growth: Real = Field(10.0, gt=1.0, le=1e6, allow_inf_nan=False,
                                description="kinetic energy growth (factor) that trips the guard in a stage "
                                "without sources (settling, static), once it is above 1 % of the "
                                "potential energy")
    escape_margin: Real = Field(1.0, ge=0.1, le=100, allow_inf_nan=False,
                                description="grain diameters beyond the walls at which a grain counts "
                                "as escaped")


#: the profiles a case can ask for (``siloflow.profiles``); custom: the case's own settings
