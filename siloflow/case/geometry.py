"""The case's container (cylinder, cone hopper, planar slab) and its wall sensors (SI units)."""
from __future__ import annotations

import math
from typing import Annotated, Literal, Optional, Union

from pydantic import Field, model_validator

from .fields import Int, NonNegative, Positive, Real, Strict

#: m: the tallest hopper accepted, like the wall's height bound (a half angle of 1e-7 degrees
#: makes a hopper 1e7 m tall, whose meshes would not fit in memory)
MAX_HOPPER_HEIGHT = 1000.0


def _smaller(model, small: str, large: str):
    """Validator body: field ``small`` (an outlet) must be smaller than field ``large``; a hopper
    must not be taller than ``MAX_HOPPER_HEIGHT``."""
    a, b = getattr(model, small), getattr(model, large)
    if a >= b:
        raise ValueError(f"{small} ({a} m) must be smaller than {large} ({b} m)")
    if model.hopper_height > MAX_HOPPER_HEIGHT:
        raise ValueError(f"half_angle_deg ({model.half_angle_deg} deg) makes the hopper {model.hopper_height:.3g} m "
                         f"tall, more than {MAX_HOPPER_HEIGHT:g} m")
    return model


class CylinderGeometry(Strict):
    """Cylindrical silo with a flat bottom and a centred circular orifice (z = 0 at the bottom)."""

    kind: Literal["cylinder"]
    radius: Positive = Field(description="inner radius of the cylinder, m", le=100)
    height: Positive = Field(description="height of the cylinder wall, m", le=1000)
    orifice_radius: Positive = Field(description="radius of the centred orifice, m")
    mesh_segments: Int = Field(64, ge=16, le=1024, description="facets around the circumference")

    _orifice_fits = model_validator(mode="after")(lambda self: _smaller(self, "orifice_radius", "radius"))

    @property
    def outlet_radius(self) -> float:
        return self.orifice_radius

    @property
    def half_width(self) -> float:
        return self.radius

    @property
    def hopper_height(self) -> float:
        return 0.0


class HopperGeometry(Strict):
    """Cylinder on a conical hopper whose outlet (radius ``outlet_radius``) is at z = 0."""

    kind: Literal["hopper"]
    radius: Positive = Field(description="inner radius of the cylinder, m", le=100)
    height: Positive = Field(description="height of the cylinder wall above the cone, m", le=1000)
    half_angle_deg: Real = Field(description="hopper half angle from the vertical, degrees",
                                  gt=0, lt=90, allow_inf_nan=False)
    outlet_radius: Positive = Field(description="radius of the hopper outlet, m")
    mesh_segments: Int = Field(64, ge=16, le=1024)

    _outlet_fits = model_validator(mode="after")(lambda self: _smaller(self, "outlet_radius", "radius"))

    @property
    def half_width(self) -> float:
        return self.radius

    @property
    def hopper_height(self) -> float:
        """Height of the cone, m."""
        return (self.radius - self.outlet_radius) / math.tan(math.radians(self.half_angle_deg))


class PlanarGeometry(Strict):
    """Quasi-2D slab silo (paper A): vertical side walls at x = +-width/2 on a wedge hopper of
    ``half_angle_deg`` from the vertical down to a slot of ``outlet_width`` at z = 0, closed by
    front and back faces at y = +-thickness/2 (about one grain apart). ``face_friction`` is the
    grains' friction on the faces: 0 (default) mimics a 2D model, which has no faces. The
    sensors are sections of both side walls (paper A: 10 per side)."""

    kind: Literal["planar"]
    width: Positive = Field(description="inner width between the side walls, m", le=100)
    height: Positive = Field(description="height of the vertical side walls above the hopper, m", le=1000)
    thickness: Positive = Field(description="distance between the front and back faces, m", le=100)
    half_angle_deg: Real = Field(60.0, gt=0, lt=90, allow_inf_nan=False,
                                  description="hopper half angle from the vertical, degrees")
    outlet_width: Positive = Field(description="width of the outlet slot, m")
    face_friction: NonNegative = Field(0.0, le=10, description="grain friction on the front and back faces")

    _outlet_fits = model_validator(mode="after")(lambda self: _smaller(self, "outlet_width", "width"))

    @property
    def outlet_radius(self) -> float:
        """Half width of the outlet slot, m."""
        return 0.5 * self.outlet_width

    @property
    def half_width(self) -> float:
        return 0.5 * self.width

    @property
    def hopper_height(self) -> float:
        """Height of the wedge hopper, m."""
        return (self.width - self.outlet_width) / 2.0 / math.tan(math.radians(self.half_angle_deg))


Geometry = Annotated[Union[CylinderGeometry, HopperGeometry, PlanarGeometry],
                     Field(discriminator="kind")]


class WallSensors(Strict):
    """Horizontal bands up the cylinder wall, each split into ``sectors`` azimuthal meshes."""

    bands: Optional[Int] = Field(None, ge=1, le=100, description="number of equal bands")
    heights: Optional[list[NonNegative]] = Field(
        None, description="band boundaries in m above the cylinder's base, increasing", max_length=101)
    sectors: Int = Field(4, ge=3, le=32, description="azimuthal sectors per band (>= 3: a full "
                         "ring's radial forces cancel)")

    @model_validator(mode="after")
    def _one_of(self):
        if (self.bands is None) == (self.heights is None):
            raise ValueError("give exactly one of 'bands' (a count) or 'heights' (boundaries)")
        if self.heights is not None:
            if len(self.heights) < 2:
                raise ValueError("'heights' needs at least two boundaries")
            if any(b <= a for a, b in zip(self.heights, self.heights[1:])):
                raise ValueError("'heights' must be strictly increasing")
        return self


