"""The case's stages: the fill (settle, mobilise) and the opening and discharge (s)."""
from __future__ import annotations

from typing import Literal, Optional

from pydantic import Field, model_validator

from .fields import MIN_CHECK_INTERVAL, Fraction, Int, Positive, Real, Strict


class Settle(Strict):
    """Settling ends when kinetic / potential energy (above the outlet) drops below ``ke_pe_ratio``."""

    ke_pe_ratio: Real = Field(1e-5, gt=0, lt=1, allow_inf_nan=False)
    check_interval: Positive = Field(0.02, description="time between checks, s", ge=MIN_CHECK_INTERVAL, le=10)
    max_time: Positive = Field(2.0, description="cap on settling time, s", le=1e4)
    static_window: Positive = Field(None, description="time the settled bed is sampled for static "
                                    "wall loads before the orifice opens, s; default: STATIC_WINDOW_SAMPLES "
                                    "samples and at least two settling checks (default_static_window)", le=100)

    @model_validator(mode="after")
    def _check_within_cap(self):
        if self.check_interval > self.max_time:
            raise ValueError(f"fill.settle.check_interval ({self.check_interval} s) is longer than the settling it "
                             f"checks (fill.settle.max_time {self.max_time} s): the settling would overrun its cap")
        return self


class Mobilise(Strict):
    """After settling, the floor (bottom and orifice plate) is lowered by ``floor_drop`` grain
    diameters over ``time`` and the bed settles again: it slides down along the wall and mobilises
    the wall friction a poured bed leaves unused (Ovarlez, Fond and Clement, PRE 67, 060302, 2003).
    At most a quarter diameter: the gap opened under the wall stays far narrower than a grain."""

    floor_drop: Real = Field(0.1, gt=0, le=0.25, allow_inf_nan=False, description="in grain diameters")
    time: Positive = Field(0.05, le=10, description="time the floor takes to move, s")


class Fill(Strict):
    """How the silo is filled: a particle count, or a fill height converted with ``packing_fraction``.

    ``protocol``: ``rain``, batches dropped from a tall region above the bed (the default), or
    ``pour``, a slow continuous pour from a thin layer at the top lasting ``pour_time``. Paper A's
    ``frictionless`` fill and a ``mobilise`` step after settling combine with either."""

    count: Optional[Int] = Field(None, ge=1, le=50_000_000)
    height: Optional[Positive] = Field(None, description="target bed height above the outlet, m")
    packing_fraction: Fraction = Field(0.6, description="solid fraction used to convert height to count")
    insertion_z_min: Optional[Positive] = Field(None, description="bottom of the insertion region, m "
                                                "(default: upper quarter of the silo)")
    insertion_z_max: Optional[Positive] = Field(None, description="top of the insertion region, m")
    batch_volume_fraction: Real = Field(0.15, gt=0, le=0.4, allow_inf_nan=False,
                                         description="solid fraction of one insertion batch in the region")
    pour_radius: Optional[Positive] = Field(None, le=100, description="radius (a slab: half width) of the "
                                            "pouring region about the axis, m; default the whole cross-section "
                                            "(distributed fill); small: a central fill (paper A)")
    frictionless: bool = Field(False, description="paper A: particle-particle friction is 0 while pouring and "
                               "restored to its value before settling (a denser bed)")
    protocol: Literal["rain", "pour"] = "rain"
    pour_time: Positive = Field(1.0, le=1e4, description="pour: how long the pour lasts, s")
    mobilise: Optional[Mobilise] = Field(None, description="lower the floor after settling, then settle again")
    settle: Settle = Settle()

    @model_validator(mode="after")
    def _one_of(self):
        if (self.count is None) == (self.height is None):
            raise ValueError("give exactly one of 'count' or 'height'")
        return self


class Opening(Strict):
    """The orifice plate is moved down, away from the outlet (robust with wall-contact computes)."""

    method: Literal["move_plate"] = "move_plate"
    speed: Positive = Field(1.0, description="plate speed, m/s", le=100)


class Discharge(Strict):
    """After settling the orifice opens; the run lasts ``duration``, or until the silo is empty
    (``until_empty``), or until the steady flow rate is known to ``precision`` (``until_steady``:
    the relative standard error of the mean of the rates of ``batch_time`` chunks, batch means,
    from ``min_batches`` chunks after the first ``startup_time``); both end at ``max_time``."""

    duration: Optional[Positive] = Field(None, description="discharge time after opening, s", le=1e5)
    until_empty: bool = False
    until_steady: bool = False
    empty_fraction: Real = Field(0.01, gt=0, lt=1, allow_inf_nan=False,
                                  description="'empty' when less than this fraction of the mass remains")
    max_time: Positive = Field(60.0, description="cap on an until_empty or until_steady discharge, s", le=1e5)
    precision: Real = Field(0.02, gt=1e-4, lt=1, allow_inf_nan=False,
                            description="until_steady: relative standard error of the steady flow rate")
    batch_time: Positive = Field(0.05, le=100, description="until_steady: length of the chunks whose rates are "
                                 "averaged (longer than the flow's correlation time), s")
    min_batches: Int = Field(5, ge=3, le=100_000, description="until_steady: fewest chunks before it may stop")
    startup_time: Real = Field(0.2, ge=0, le=1e4, allow_inf_nan=False,
                               description="until_steady: start-up after opening left out of the rate, s")
    opening: Opening = Opening()

    @model_validator(mode="after")
    def _one_of(self):
        if (self.duration is not None) + self.until_empty + self.until_steady != 1:
            raise ValueError("give one of 'duration', 'until_empty: true' or 'until_steady: true'")
        if self.until_steady and self.startup_time + self.min_batches * self.batch_time > self.max_time:
            raise ValueError(f"until_steady needs max_time ({self.max_time} s) of at least startup_time + "
                             "min_batches x batch_time")
        return self


#: the results a case can ask for, and what each needs of the deck (siloflow.derived.outputs_plan)
