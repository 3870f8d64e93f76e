"""The case's container (cylinder, cone hopper, planar slab) and its wall sensors (SI units)."""
from __future__ import annotations

import math
from typing import Annotated, Literal, Optional, Union

from pydantic import ConfigDict, Field, PrivateAttr, StringConstraints, ValidationInfo, field_validator, model_validator

from .fields import MIN_BAND_BOUNDARY, FiniteFloat, Int, NonNegative, Positive, Real, Strict

#: m: the tallest hopper accepted, like the wall's height bound (a half angle of 1e-7 degrees
#: makes a hopper 1e7 m tall, whose meshes would not fit in memory)
MAX_HOPPER_HEIGHT = 1000.0
#: m: the tallest vertical wall (geometry.height; a mesh silo's walls as scaled)
MAX_WALL_HEIGHT = 1000.0
#: degrees: the steepest hopper wall; a hopper is (R - r) / tan(half angle) tall and R - r is at least
#: a grain diameter (2 um), so below 1e-7 degrees no hopper fits in MAX_HOPPER_HEIGHT (and far below
#: it, tan underflows to 0)
MIN_HALF_ANGLE_DEG = 1e-7


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


def _offset_fits(outlet: str):
    """A field validator of ``outlet_offset``: the outlet (radius field ``outlet``), moved that far,
    must stay inside the silo's ``radius`` (the fields before it, when they are valid)."""
    def check(value, info: ValidationInfo):
        r, R = info.data.get(outlet), info.data.get("radius")
        if value and r is not None and R is not None and not value + r < R:
            raise ValueError(f"{value} m puts the outlet (radius {outlet} = {r} m) against or through the wall: "
                             f"outlet_offset + {outlet} must be smaller than radius ({R} m)")
        return value
    return field_validator("outlet_offset")(check)


def _outlet_offset():
    """The field of the outlet's offset from the silo axis (an eccentric outlet, EN 1991-4 §5.2.4)."""
    return Field(0.0, le=100, description="distance from the silo axis to the outlet's centre, along +x, m "
                 "(0: centred; eccentric: the sensor sectors are then centred on the outlet's azimuth)")


class CylinderGeometry(Strict):
    """Cylindrical silo with a flat bottom and a circular orifice, centred or ``outlet_offset``
    along +x (z = 0 at the bottom)."""

    kind: Literal["cylinder"]
    radius: Positive = Field(description="inner radius of the cylinder, m", le=100)
    height: Positive = Field(description="height of the cylinder wall, m", le=MAX_WALL_HEIGHT)
    orifice_radius: Positive = Field(description="radius of the orifice, m")
    outlet_offset: NonNegative = _outlet_offset()
    mesh_segments: Int = Field(64, ge=16, le=1024, description="facets around the circumference")

    _orifice_fits = model_validator(mode="after")(lambda self: _smaller(self, "orifice_radius", "radius"))
    _offset_fits = _offset_fits("orifice_radius")

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
    """Cylinder on a conical hopper whose outlet (radius ``outlet_radius``) is at z = 0. With an
    ``outlet_offset`` e the cone is oblique (its outlet circle's centre at x = e, its top the
    cylinder's): its walls are steeper on the outlet's side (tan = (R - r - e) / h) than opposite
    (tan = (R - r + e) / h), ``half_angle_deg`` setting the height h = (R - r) / tan(half angle)."""

    kind: Literal["hopper"]
    radius: Positive = Field(description="inner radius of the cylinder, m", le=100)
    height: Positive = Field(description="height of the cylinder wall above the cone, m", le=MAX_WALL_HEIGHT)
    half_angle_deg: Real = Field(description="hopper half angle from the vertical, degrees",
                                  ge=MIN_HALF_ANGLE_DEG, lt=90, allow_inf_nan=False)
    outlet_radius: Positive = Field(description="radius of the hopper outlet, m")
    outlet_offset: NonNegative = _outlet_offset()
    mesh_segments: Int = Field(64, ge=16, le=1024)

    _outlet_fits = model_validator(mode="after")(lambda self: _smaller(self, "outlet_radius", "radius"))
    _offset_fits = _offset_fits("outlet_radius")

    @property
    def half_width(self) -> float:
        return self.radius

    @property
    def hopper_height(self) -> float:
        """Height of the cone, m."""
        return (self.radius - self.outlet_radius) / math.tan(math.radians(self.half_angle_deg))


class _WalledAcrossX:
    """What a slab and a box share: side walls at x = -+ width/2, a flat floor at ``half_angle_deg``
    90, else a hopper whose walls facing x rise at that angle from the outlet's edges."""

    @property
    def half_width(self) -> float:
        return 0.5 * self.width

    @property
    def flat_floor(self) -> bool:
        """The outlet in a flat floor (``half_angle_deg`` 90): no hopper."""
        return self.half_angle_deg == 90

    @property
    def hopper_height(self) -> float:
        """Height of the hopper, m (0 on a flat floor)."""
        if self.flat_floor:
            return 0.0
        return (self.width - 2 * self.outlet_radius) / 2.0 / math.tan(math.radians(self.half_angle_deg))


class PlanarGeometry(_WalledAcrossX, Strict):
    """Quasi-2D slab silo (paper A): vertical side walls at x = +-width/2 on a wedge hopper of
    ``half_angle_deg`` from the vertical down to a slot of ``outlet_width`` at z = 0, closed by
    front and back faces at y = +-thickness/2 (about one grain apart). ``half_angle_deg: 90`` is a
    flat floor with the slot in it (no hopper). ``outlet_offset`` moves the slot's centre along +x
    (the wedge's two walls then differ: tan = (width/2 -+ offset - outlet_width/2) / its height).
    ``face_friction`` is the grains' friction on the faces: 0 (default) mimics a 2D model, which
    has no faces. ``periodic_depth`` removes the faces: the slab is periodic along y over
    ``thickness`` (which then holds several grains). The sensors are sections of both side walls
    (paper A: 10 per side)."""

    kind: Literal["planar"]
    width: Positive = Field(description="inner width between the side walls, m", le=100)
    height: Positive = Field(description="height of the vertical side walls above the hopper, m", le=MAX_WALL_HEIGHT)
    thickness: Positive = Field(description="distance between the front and back faces, m", le=100)
    half_angle_deg: Real = Field(60.0, ge=MIN_HALF_ANGLE_DEG, le=90, allow_inf_nan=False,
                                  description="hopper half angle from the vertical, degrees (90: a flat floor)")
    outlet_width: Positive = Field(description="width of the outlet slot, m")
    outlet_offset: Real = Field(0.0, ge=-100, le=100, allow_inf_nan=False,
                                description="the slot's centre at x = outlet_offset, m (0: centred)")
    face_friction: NonNegative = Field(0.0, le=10, description="grain friction on the front and back faces")
    periodic_depth: bool = Field(False, strict=True, description="periodic along y instead of front and back "
                                 "faces: no faces, no face friction; thickness is the periodic length, m")

    _outlet_fits = model_validator(mode="after")(lambda self: _smaller(self, "outlet_width", "width"))

    @field_validator("periodic_depth")
    @classmethod
    def _no_faces(cls, value, info: ValidationInfo):
        if value and info.data.get("face_friction"):
            raise ValueError(f"a periodic slab has no faces: face_friction ({info.data['face_friction']}) "
                             "must be 0 (or unset)")
        return value

    @field_validator("outlet_offset")
    @classmethod
    def _slot_fits(cls, value, info: ValidationInfo):
        w, ow = info.data.get("width"), info.data.get("outlet_width")
        if value and w is not None and ow is not None and not abs(value) + 0.5 * ow < 0.5 * w:
            raise ValueError(f"{value} m puts the slot (outlet_width {ow} m) against or through a side wall: "
                             f"|outlet_offset| + outlet_width / 2 must be smaller than width / 2 ({0.5 * w} m)")
        return value

    @property
    def outlet_radius(self) -> float:
        """Half width of the outlet slot, m."""
        return 0.5 * self.outlet_width


class BoxGeometry(_WalledAcrossX, Strict):
    """Rectangular silo (bin): vertical walls at x = +-width/2 and y = +-depth/2, on a flat floor
    (``half_angle_deg`` 90, the default) or a hopper down to the outlet at z = 0. The outlet is a
    ``rectangle`` (``outlet_width`` along x by ``outlet_length`` along y: a pyramidal hopper), a
    ``slot`` (``outlet_width`` across the whole depth: a wedge hopper, its end walls vertical) or a
    ``circle`` (``outlet_radius``; flat floor only), centred at (``outlet_offset``,
    ``outlet_offset_y``). ``half_angle_deg`` is the angle of the hopper's walls facing x from the
    vertical; those facing y share the hopper's height. The sensors are bands on each of the four
    walls (sector 0 at x = -width/2, 1 at +width/2, 2 at y = -depth/2, 3 at +depth/2)."""

    # the circle's radius is the field ``outlet_radius`` (dumped under that name too); the property
    # ``outlet_radius`` is every silo's outlet half width along x
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True, serialize_by_alias=True,
                              validate_by_name=False, validate_by_alias=True)

    kind: Literal["box"]
    width: Positive = Field(description="inner width along x, m", le=100)
    depth: Positive = Field(description="inner depth along y, m", le=100)
    height: Positive = Field(description="height of the vertical walls above the hopper, m", le=MAX_WALL_HEIGHT)
    half_angle_deg: Real = Field(90.0, ge=MIN_HALF_ANGLE_DEG, le=90, allow_inf_nan=False,
                                 description="hopper angle of the walls facing x, from the vertical, degrees "
                                             "(90: a flat floor)")
    outlet: Literal["rectangle", "slot", "circle"] = Field("rectangle", description="the outlet's shape")
    outlet_width: Optional[Positive] = Field(None, description="rectangle or slot: width along x, m")
    outlet_length: Optional[Positive] = Field(None, description="rectangle: length along y, m")
    outlet_radius_m: Optional[Positive] = Field(None, alias="outlet_radius", description="circle: radius, m")
    outlet_offset: Real = Field(0.0, ge=-100, le=100, allow_inf_nan=False, description="outlet centre's x, m")
    outlet_offset_y: Real = Field(0.0, ge=-100, le=100, allow_inf_nan=False, description="outlet centre's y, m")

    @model_validator(mode="after")
    def _outlet_fits(self):
        need = {"rectangle": ("outlet_width", "outlet_length"), "slot": ("outlet_width",),
                "circle": ("outlet_radius",)}[self.outlet]
        given = {"outlet_width": self.outlet_width, "outlet_length": self.outlet_length,
                 "outlet_radius": self.outlet_radius_m}
        missing = [k for k in need if given[k] is None]
        extra = [k for k, v in given.items() if v is not None and k not in need]
        if missing or extra:
            raise ValueError(f"outlet {self.outlet!r} takes {', '.join(need)}"
                             + (f"; missing {', '.join(missing)}" if missing else "")
                             + (f"; {', '.join(extra)} does not apply" if extra else ""))
        if self.outlet == "circle" and self.half_angle_deg != 90:
            raise ValueError("a circular outlet sits in a flat floor: half_angle_deg must be 90 (a rectangle or "
                             "slot outlet takes a hopper)")
        if self.outlet == "slot" and self.outlet_offset_y:
            raise ValueError("a slot spans the whole depth: outlet_offset_y must be 0")
        hx, hy = self.outlet_half_sizes
        inside_x = abs(self.outlet_offset) + hx < 0.5 * self.width
        inside_y = self.outlet == "slot" or abs(self.outlet_offset_y) + hy < 0.5 * self.depth
        if not (inside_x and inside_y):
            size = {"rectangle": "outlet_width x outlet_length", "slot": "outlet_width x depth",
                    "circle": "2 outlet_radius"}[self.outlet]
            raise ValueError(f"the outlet ({size}: {2 * hx:g} x {2 * hy:g} m at outlet_offset {self.outlet_offset:g}, "
                             f"outlet_offset_y {self.outlet_offset_y:g} m) must lie inside the floor (width x depth: "
                             f"{self.width:g} x {self.depth:g} m), clear of the walls (an outlet across the whole "
                             "depth is a slot)")
        if self.hopper_height > MAX_HOPPER_HEIGHT:
            raise ValueError(f"half_angle_deg ({self.half_angle_deg} deg) makes the hopper {self.hopper_height:.3g} m "
                             f"tall, more than {MAX_HOPPER_HEIGHT:g} m")
        return self

    @property
    def outlet_half_sizes(self) -> tuple[float, float]:
        """The outlet's half extents along x and y, m (a circle's radius both)."""
        if self.outlet == "circle":
            return self.outlet_radius_m, self.outlet_radius_m
        return 0.5 * self.outlet_width, (0.5 * self.depth if self.outlet == "slot" else 0.5 * self.outlet_length)

    @property
    def outlet_radius(self) -> float:
        """The outlet's half width along x (a circle's radius), m."""
        return self.outlet_half_sizes[0]


class MeshOutlet(Strict):
    """Where the user's silo opens (in the STL files' units, times ``scale``): the horizontal plane
    z = ``z`` and in it a circle (``center``, ``radius``) or a convex ``polygon``. The walls must
    have this opening, and nothing below it; siloflow closes it with a plate for the fill."""

    z: Real = Field(allow_inf_nan=False, ge=-1e6, le=1e6, description="height of the outlet's plane, file units")
    center: Optional[tuple[FiniteFloat, FiniteFloat]] = Field(None, description="circle: its centre (x, y), file "
                                                             "units (within 1e6, as z)")
    radius: Optional[Positive] = Field(None, le=1e6, description="circle: its radius, file units")
    polygon: Optional[list[tuple[FiniteFloat, FiniteFloat]]] = Field(
        None, min_length=3, max_length=1000, description="convex polygon: its corners (x, y), file units (within 1e6)")

    @model_validator(mode="after")
    def _one_shape(self):
        if (self.radius is None) == (self.polygon is None):
            raise ValueError("give either radius (with center) for a circle or polygon for a polygon")
        if self.radius is not None and self.center is None:
            raise ValueError("a circular outlet needs its center (x, y)")
        if self.polygon is not None:
            if self.center is not None:
                raise ValueError("a polygon outlet takes no center (its centroid is used)")
            p, n = self.polygon, len(self.polygon)
            sides = [(p[(i + 1) % n][0] - p[i][0], p[(i + 1) % n][1] - p[i][1]) for i in range(n)]
            turns = [math.atan2(a[0] * b[1] - a[1] * b[0], a[0] * b[0] + a[1] * b[1])
                     for a, b in zip(sides, sides[1:] + sides[:1])]
            # convex: every corner turns the same way, once round in all (a star turns more)
            one_way = all(x > 0 for x in turns) or all(x < 0 for x in turns)
            if not one_way or abs(abs(sum(turns)) - 2 * math.pi) > 1e-6:
                raise ValueError("polygon: the corners must make a convex polygon, in order, without repeats "
                                 "or three in a line")
        return self

    def scaled_polygon(self, scale: float) -> list[tuple[float, float]]:
        """The polygon's corners times ``scale``, counter-clockwise."""
        p = [(x * scale, y * scale) for x, y in self.polygon]
        return p if _polygon_sums(p)[0] > 0 else p[::-1]

    def scaled_center(self, scale: float) -> tuple[float, float]:
        """The circle's centre, or the polygon's centroid, times ``scale``."""
        if self.center is not None:
            return self.center[0] * scale, self.center[1] * scale
        a, cx, cy, _ = _polygon_sums(self.scaled_polygon(scale))
        return cx / (3 * a), cy / (3 * a)


def _polygon_sums(p: list[tuple[float, float]]) -> tuple[float, float, float, float]:
    """Of a closed polygon's corners ``p``: twice its signed area (positive counter-clockwise), six
    times its area's first moments about x = 0 and y = 0, and its perimeter (the shoelace sums)."""
    a = cx = cy = perimeter = 0.0
    for (x0, y0), (x1, y1) in zip(p, p[1:] + p[:1]):
        w = x0 * y1 - x1 * y0
        a, cx, cy = a + w, cx + (x0 + x1) * w, cy + (y0 + y1) * w
        perimeter += math.hypot(x1 - x0, y1 - y0)
    return a, cx, cy, perimeter


class MeshGeometry(Strict):
    """The user's own silo from STL files (ASCII or binary; relative paths from the case file), in
    any unit times ``scale`` (0.001 for mm). The walls are checked as a container: closed apart
    from the top and the ``outlet``, normals consistent, no duplicate or degenerate triangle.
    Above its floor or hopper the container must have vertical walls: siloflow cuts them into the
    sensor bands (``sensors``, heights above the top of the floor or hopper, as for a cylinder) and
    sectors about the vertical ``axis`` (x, y in file units; default the outlet's centre; sector 0
    faces an outlet off the axis). Height, hopper height and volume come from the mesh when the
    run is planned (``siloflow.derived.measured``)."""

    kind: Literal["mesh"]
    files: list[Annotated[str, StringConstraints(min_length=1, max_length=4096)]] = Field(
        min_length=1, max_length=20, description="STL files of the container's walls (paths of 1 to 4096 characters)")
    scale: Positive = Field(1.0, le=1000.0, description="factor from the files' units to m (0.001 for mm)")
    outlet: MeshOutlet
    axis: Optional[tuple[FiniteFloat, FiniteFloat]] = Field(None, description="the sectors' vertical axis (x, y), "
                                                            "file units (within 1e6; default: the outlet's centre)")

    _container: object = PrivateAttr(None)

    @property
    def origin(self) -> tuple[float, float, float]:
        """The silo frame's origin in the files' frame, m: the axis' x, y and the outlet's z."""
        ax = self.outlet.scaled_center(self.scale) if self.axis is None else \
            (self.axis[0] * self.scale, self.axis[1] * self.scale)
        return ax[0], ax[1], self.outlet.z * self.scale

    @property
    def outlet_center(self) -> tuple[float, float]:
        """The outlet's centre in the silo frame, m."""
        cx, cy = self.outlet.scaled_center(self.scale)
        ox, oy, _ = self.origin
        return cx - ox, cy - oy

    @property
    def outlet_offset(self) -> float:
        return self.outlet_center[0]

    @property
    def outlet_offset_y(self) -> float:
        return self.outlet_center[1]

    @property
    def outlet_radius(self) -> float:
        """The circle's radius; a polygon's half hydraulic diameter 2 A / P, m."""
        if self.outlet.radius is not None:
            return self.outlet.radius * self.scale
        twice_area, _, _, perimeter = _polygon_sums(self.outlet.scaled_polygon(self.scale))
        return twice_area / perimeter

    @property
    def measured(self) -> bool:
        """Whether the mesh has been read (``siloflow.derived.measured``)."""
        return self._container is not None

    @property
    def container(self):
        """The checked container (``siloflow.geometry.Container``) once measured."""
        if self._container is None:
            raise RuntimeError("the mesh silo's walls are read when the run is planned (siloflow.derived.measured)")
        return self._container

    @property
    def height(self) -> float:
        """Height of the vertical walls above the floor or hopper, m."""
        return self.container.height

    @property
    def hopper_height(self) -> float:
        """Height of the floor or hopper's top above the outlet, m (0: a flat floor)."""
        return self.container.base

    @property
    def radius(self) -> float:
        """The largest circle about the axis inside the vertical walls, m."""
        return self.container.inscribed_radius

    @property
    def half_width(self) -> float:
        return self.radius

    @property
    def section(self) -> tuple[float, float]:
        """Area (m2) and perimeter (m) of the vertical walls' cross-section half way up."""
        return self.container.mid_section

    @property
    def hydraulic_diameter(self) -> float:
        """4 A / P of that cross-section, m (Janssen's D)."""
        area, perimeter = self.section
        return 4.0 * area / perimeter


Geometry = Annotated[Union[CylinderGeometry, HopperGeometry, PlanarGeometry, BoxGeometry,
                           MeshGeometry],
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
            low = [h for h in self.heights if 0 < h < MIN_BAND_BOUNDARY]
            if low:
                raise ValueError(f"'heights' has a boundary {low[0]:g} m above the wall's base: give 0 or at least "
                                 f"{MIN_BAND_BOUNDARY:g} m (an atom's size)")
        return self


