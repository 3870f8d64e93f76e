"""The case schema: a pydantic model of everything a silo simulation needs.

All quantities are SI (m, kg, s, Pa, N/m). Unknown keys are errors, numbers must
be finite, integers strict (``true`` is not 1), and every string that can reach a deck or a
file name is restricted to a safe alphabet. Case files are read by :mod:`siloflow.case_file`
(``Case.from_yaml(path)``); a dict of fields is validated with ``Case.model_validate(data)``.
"""
from __future__ import annotations

import math
from typing import Annotated, Literal, Optional, Union

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, StringConstraints, model_validator

from .engines import ENGINES


#: Names that reach decks and file names: letters, digits, ``_ . -``, not starting with ``.`` or ``-``.
SAFE_NAME_PATTERN = r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$"
SafeName = Annotated[str, StringConstraints(pattern=SAFE_NAME_PATTERN)]



def _refuse_bool(value):
    """A number field refuses YAML's true/false (pydantic would read them as 1.0 and 0.0)."""
    if isinstance(value, bool):
        raise ValueError("must be a number, not true/false")
    return value


#: a float that is not a bool
Real = Annotated[float, BeforeValidator(_refuse_bool)]
#: strict integer: true/false (count 1), 5.0 and "5" are refused
Int = Annotated[int, Field(strict=True)]
Positive = Annotated[Real, Field(gt=0, allow_inf_nan=False)]
FiniteFloat = Annotated[Real, Field(allow_inf_nan=False, ge=-1e6, le=1e6)]
NonNegative = Annotated[Real, Field(ge=0, allow_inf_nan=False)]
Fraction = Annotated[Real, Field(gt=0, le=1, allow_inf_nan=False)]

# Physical floors of the grains' properties; the consequences of values near them are warned
# about by siloflow.derived.physics_warnings (overlap under the bed's weight, air drag).
#: m: below 1 um Brownian motion and van der Waals adhesion dominate, which these dry contact laws omit
MIN_GRAIN_RADIUS = 1e-6
#: kg/m3: the density of air at 20 C; lighter grains would float, and siloflow models no gas
MIN_DENSITY = 1.2
#: Pa: ten times softer than the softest grains of silo experiments (hydrogel spheres, ~10 kPa);
#: benchmarks use 1e6 Pa on purpose, so the consequence (overlap) is a warning, not a refusal
MIN_YOUNGS_MODULUS = 1e3
#: Pa: stiffer than diamond (1.2e12 Pa) with a margin
MAX_YOUNGS_MODULUS = 1e13
#: below 1/1000 of the contact time the step adds only cost and round-off, no accuracy
MIN_TIMESTEP_FRACTION = 1e-3
#: s: the longest stage a case may ask for (discharge.duration and max_time); an interval is never longer
MAX_STAGE_TIME = 1e5
GrainRadius = Annotated[Positive, Field(ge=MIN_GRAIN_RADIUS)]


class Strict(BaseModel):
    """Base of every section: unknown keys are errors, NaN/inf refused."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


# --------------------------------------------------------------------------- geometry
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


# --------------------------------------------------------------------------- sensors
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


# --------------------------------------------------------------------------- materials
class ParticleMaterial(Strict):
    density: Positive = Field(description="solid density, kg/m3", ge=MIN_DENSITY,
                              le=1e5)  # le: four times osmium, the densest element (22.6e3)
    youngs_modulus: Optional[Positive] = Field(None, description="Pa (Hertz model)", ge=MIN_YOUNGS_MODULUS,
                                               le=MAX_YOUNGS_MODULUS)
    poisson_ratio: Real = Field(0.3, gt=-1, lt=0.5, allow_inf_nan=False)


class WallMaterial(Strict):
    youngs_modulus: Optional[Positive] = Field(None, description="Pa (Hertz model)", ge=MIN_YOUNGS_MODULUS,
                                               le=MAX_YOUNGS_MODULUS)
    poisson_ratio: Real = Field(0.3, gt=-1, lt=0.5, allow_inf_nan=False)


class PairContact(Strict):
    """Contact parameters of one material pair."""

    friction: NonNegative = Field(description="Coulomb sliding friction coefficient", le=10)
    restitution: Real = Field(0.5, gt=0, le=1, allow_inf_nan=False,
                               description="normal coefficient of restitution")
    rolling_friction: NonNegative = Field(0.0, le=10, description="rolling friction coefficient (cdt)")
    kn: Optional[Positive] = Field(None, description="normal spring stiffness, N/m (linear model)", le=1e12)
    kt: Optional[Positive] = Field(None, description="tangential spring stiffness, N/m (linear model)", le=1e12)


def _contact_problems(model: str, field: str, pair: "PairContact") -> list[str]:
    """kn/kt must be given with model 'linear' and only then."""
    given = pair.kn is not None or pair.kt is not None
    if model == "linear" and (pair.kn is None or pair.kt is None):
        return [f"{field}: kn and kt are required by model 'linear'"]
    if model != "linear" and given:
        computed = "are computed by model 'hooke'; give them with model 'linear'" if model == "hooke" else \
            f"belong to model 'linear', not '{model}'"
        return [f"{field}: kn/kt {computed}"]
    return []


class Materials(Strict):
    """Particle and wall materials and the contact law of each pair."""

    model: Literal["hertz", "linear", "hooke"] = Field(
        "hertz", description="hertz: Hertz-Mindlin from Young's modulus; linear: PFC-style kn/kt springs; "
        "hooke (paper B): linear springs with kn from Young's modulus and a characteristic velocity, "
        "kt = tangential_stiffness_ratio kn, per pair of sizes")
    particle: ParticleMaterial
    wall: WallMaterial = WallMaterial()
    particle_particle: PairContact
    particle_wall: PairContact
    tangential_damping_ratio: Real = Field(
        0.1, ge=0, le=1, allow_inf_nan=False, description="gamma_t / gamma_n (linear and hooke models)")
    characteristic_velocity: Optional[Positive] = Field(
        None, le=1000, description="impact speed that sets kn of model 'hooke', m/s")
    tangential_stiffness_ratio: Real = Field(
        2.0 / 7.0, gt=0, le=1, allow_inf_nan=False, description="kt / kn (model 'hooke'; paper B: 2/7)")

    @model_validator(mode="after")
    def _model_parameters(self):
        problems = []
        for name in ("particle_particle", "particle_wall"):
            problems += _contact_problems(self.model, name, getattr(self, name))
        if self.model in ("hertz", "hooke"):
            for part in ("particle", "wall"):
                if getattr(self, part).youngs_modulus is None:
                    problems.append(f"{part}.youngs_modulus is required by model '{self.model}'")
        if self.model == "hooke" and self.characteristic_velocity is None:
            problems.append("characteristic_velocity is required by model 'hooke'")
        if problems:
            raise ValueError("; ".join(problems))
        return self


# --------------------------------------------------------------------------- particles
class Dust(Strict):
    """Small spheres with their own material, added at a number ratio to the grains (paper A:
    0.5 mm balls of density 2000, one per ten clumps). Dust usually sets the time step; the
    ``density_scale`` remedy multiplies the dust density (mass scaling: contact times grow as
    its square root) and its effect on results is measured in benchmarks/dust_density_scaling.py."""

    radius: GrainRadius = Field(description="dust sphere radius, m", le=1.0)
    density: Positive = Field(description="dust solid density, kg/m3", ge=MIN_DENSITY, le=1e5)
    number_ratio: Real = Field(description="dust spheres per grain (paper A: 0.1)", gt=0, le=100,
                                allow_inf_nan=False)
    youngs_modulus: Optional[Positive] = Field(None, description="Pa (hertz and hooke models)",
                                               ge=MIN_YOUNGS_MODULUS, le=MAX_YOUNGS_MODULUS)
    poisson_ratio: Real = Field(0.3, gt=-1, lt=0.5, allow_inf_nan=False)
    dust_dust: PairContact
    dust_particle: PairContact
    dust_wall: PairContact
    density_scale: Real = Field(1.0, ge=1.0, le=1e6, allow_inf_nan=False,
                                 description="time-step remedy: the dust runs with density x this factor "
                                 "(1 = no scaling)")

    @property
    def run_density(self) -> float:
        """Density the dust is simulated with, kg/m3."""
        return self.density * self.density_scale


class MonodisperseSpheres(Strict):
    """Spheres of one radius."""

    kind: Literal["spheres"]
    radius: GrainRadius = Field(description="sphere radius, m", le=1.0)
    dust: Optional[Dust] = None

    @property
    def radii(self) -> list[float]:
        return [self.radius]

    @property
    def number_fractions(self) -> list[float]:
        return [1.0]

    @property
    def max_radius(self) -> float:
        return self.radius

    @property
    def min_radius(self) -> float:
        return self.radius


class PolydisperseSpheres(Strict):
    """Spheres of several radii, inserted at random with the given fractions.

    ``basis`` says whether ``fractions`` count particles (``number``) or mass (``mass``);
    LIGGGHTS' particledistribution/discrete takes mass fractions, and siloflow converts
    (all sizes have the particle density, so mass goes as r^3).
    """

    kind: Literal["polydisperse_spheres"]
    radii: list[GrainRadius] = Field(min_length=2, max_length=20, description="sphere radii, m")
    fractions: list[Fraction] = Field(min_length=2, max_length=20, description="fraction of each radius; sum 1")
    basis: Literal["number", "mass"] = Field(description="what the fractions count")
    protocol: Literal["insert", "shrink_after_settling"] = Field(
        "insert", description="insert: pour the mixture; shrink_after_settling (paper B): pour and settle "
        "grains of the largest radius, shrink them at random to the size classes, settle again")

    @model_validator(mode="after")
    def _distribution(self):
        if len(self.fractions) != len(self.radii):
            raise ValueError(f"fractions has {len(self.fractions)} entries for {len(self.radii)} radii")
        if len(set(self.radii)) != len(self.radii):
            raise ValueError("radii must be distinct")
        if max(self.radii) > 1.0:
            raise ValueError("radii must be <= 1 m")
        if abs(sum(self.fractions) - 1.0) > 1e-6:
            raise ValueError(f"fractions must sum to 1 (they sum to {sum(self.fractions):.9g})")
        return self

    @property
    def number_fractions(self) -> list[float]:
        if self.basis == "number":
            return list(self.fractions)
        inv = [f / r ** 3 for f, r in zip(self.fractions, self.radii)]
        return [v / sum(inv) for v in inv]

    @property
    def mass_fractions(self) -> list[float]:
        if self.basis == "mass":
            return list(self.fractions)
        w = [f * r ** 3 for f, r in zip(self.fractions, self.radii)]
        return [v / sum(w) for v in w]

    @property
    def max_radius(self) -> float:
        return max(self.radii)

    @property
    def min_radius(self) -> float:
        return min(self.radii)


def paper_b_radii(rb: float, sizes: int = 7) -> list[float]:
    """Paper B's size classes: ``sizes`` radii in arithmetic progression with difference rb/16,
    from rb down. The paper states seven sizes, a difference of rb/16 and a smallest radius of
    rb/2 + rb/16, which cannot all hold (that would take eight sizes); this keeps the seven
    sizes and the difference, so the smallest radius is rb/2 + rb/8."""
    return [rb - k * rb / 16.0 for k in range(sizes)]


class ClumpSphere(Strict):
    center: tuple[FiniteFloat, FiniteFloat, FiniteFloat] = Field(description="m, body frame")
    radius: GrainRadius = Field(le=1.0, description="m")


class Clumps(Strict):
    """Rigid clumps of overlapping spheres (LIGGGHTS multisphere): paper A's wheat grain
    (``shape: wheat``, three spheres of diameter ``width`` making a grain ``length`` long) or
    any ``spheres`` list. Mass and inertia follow the union volume."""

    kind: Literal["clumps"]
    shape: Literal["wheat", "spheres"] = "wheat"
    length: GrainRadius = Field(6e-3, le=1.0, description="wheat grain length, m")
    width: GrainRadius = Field(4e-3, le=1.0, description="wheat grain width (sphere diameter), m")
    spheres: Optional[list[ClumpSphere]] = Field(None, min_length=2, max_length=50,
                                                 description="clump spheres (shape 'spheres')")
    monte_carlo_tries: Int = Field(1_000_000, ge=10_000, le=100_000_000,
                                   description="LIGGGHTS' Monte Carlo samples for mass and inertia")
    dust: Optional[Dust] = None

    @model_validator(mode="after")
    def _shape(self):
        if self.shape == "spheres":
            if self.spheres is None:
                raise ValueError("shape 'spheres' needs a 'spheres' list")
        elif self.spheres is not None:
            raise ValueError("'spheres' is only read with shape: spheres (shape is 'wheat')")
        else:
            if not self.width <= self.length < 3 * self.width:
                raise ValueError(f"a wheat grain needs width <= length < 3 width (got length {self.length} m, "
                                 f"width {self.width} m)")
        clump = self.clump
        if not clump.connected():
            raise ValueError("the clump's spheres must overlap into one body")
        return self

    @property
    def clump(self):
        from .clumps import ClumpShape, wheat_grain
        if self.shape == "wheat":
            return wheat_grain(self.length, self.width)
        return ClumpShape(centers=tuple(s.center for s in self.spheres), radii=tuple(s.radius for s in self.spheres))

    @property
    def radii(self) -> list[float]:
        return [max(self.clump.radii)]

    @property
    def number_fractions(self) -> list[float]:
        return [1.0]

    @property
    def max_radius(self) -> float:
        """Bounding radius of the clump, m (geometry margins)."""
        return self.clump.bounding_radius

    @property
    def min_radius(self) -> float:
        return min(self.clump.radii)


Particles = Annotated[Union[MonodisperseSpheres, PolydisperseSpheres, Clumps], Field(discriminator="kind")]


# --------------------------------------------------------------------------- stages
class Settle(Strict):
    """Settling ends when kinetic / potential energy (above the outlet) drops below ``ke_pe_ratio``."""

    ke_pe_ratio: Real = Field(1e-5, gt=0, lt=1, allow_inf_nan=False)
    check_interval: Positive = Field(0.02, description="time between checks, s", le=10)
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
PROFILE_NAMES = ("custom", "reference", "fast")
#: the engine fields a profile other than custom owns
PROFILE_FIELDS = ("profile", "timestep_fraction", "stiffness_scale", "fast_profile")
#: time-step fraction of the custom profile when the case gives none
DEFAULT_TIMESTEP_FRACTION = 0.15
#: the quantities the accuracy benchmark bounds (``siloflow.accuracy_bench.QUANTITIES``)
BenchQuantity = Literal["flow_rate", "static_pressure", "dynamic_pressure_max", "solid_fraction", "coordination"]
TimestepFraction = Annotated[Real, Field(ge=MIN_TIMESTEP_FRACTION, le=1, allow_inf_nan=False)]


class PinnedProfile(Strict):
    """The fast profile as this case runs it: copied from siloflow's benchmarked profile
    (``siloflow/fast_profile.json``) when a case asking for ``profile: fast`` is read, and kept in
    the run folder's case.yaml, so a run resumes with the profile it started with."""

    timestep_fraction: TimestepFraction
    overlap_ratio: Real = Field(gt=0, le=1, allow_inf_nan=False,
                                description="the contacts are softened until two of the smallest grains meeting "
                                "at the fill's impact speed overlap by this fraction of their radius (never "
                                "stiffened: a softer case keeps its stiffness)")
    error_bounds: dict[BenchQuantity, Annotated[Real, Field(ge=0, le=1e3, allow_inf_nan=False)]] = {}
    tolerances: dict[BenchQuantity, Annotated[Real, Field(ge=0, le=1e3, allow_inf_nan=False)]] = {}
    speedup: Optional[Positive] = None
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

    @model_validator(mode="before")
    @classmethod
    def _pin_fast_profile(cls, data):
        """``profile: fast`` runs the benchmarked profile of this siloflow, copied into the case."""
        if isinstance(data, dict) and data.get("profile") == "fast" and data.get("fast_profile") is None:
            from .packaged_profile import packaged_fast_profile
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


class MeasurementRegion(Strict):
    """A porosity measurement region (post-processing only; never reaches a deck), m.

    sphere: ``center``, ``radius``. cylinder: axis along ``axis`` from ``t0`` to ``t1``.
    circle: a 2D measure circle in the plane ``axis`` = ``plane`` (planar silos, paper A).
    """

    name: SafeName
    shape: Literal["sphere", "cylinder", "circle"]
    center: tuple[FiniteFloat, FiniteFloat, FiniteFloat]
    radius: Positive = Field(le=100)
    axis: Literal["x", "y", "z"] = "y"
    t0: FiniteFloat = 0.0
    t1: FiniteFloat = 0.0
    plane: FiniteFloat = 0.0

    @model_validator(mode="after")
    def _extent(self):
        if self.shape == "cylinder" and not self.t1 > self.t0:
            raise ValueError("a cylinder region needs t1 > t0 (its extent along its axis, m)")
        return self


class WallInsert(Strict):
    """A wall read from the user's STL file (ASCII or binary): an insert, a baffle, a roof. It is
    read as a mesh, checked (finite, no degenerate triangles, inside the silo) and written anew
    by siloflow into the run folder as ``meshes/insert_<name>.stl``: the file's bytes never
    reach the deck. Its net force is recorded like every wall's."""

    name: SafeName
    file: str = Field(min_length=1, max_length=4096, description="STL file; relative paths are relative "
                      "to the case file")
    scale: Positive = Field(1.0, le=1000.0, description="factor from the file's units to m (0.001 for mm)")

    @property
    def mesh_name(self) -> str:
        return f"insert_{self.name}"


class Analysis(Strict):
    """What the post-processing measures beyond the defaults."""

    porosity_regions: list[MeasurementRegion] = Field(
        default_factory=list, max_length=1000,
        description="measurement regions (paper A: nine circles); default: the bulk core of the settled bed")
    relative_density: Optional[Real] = Field(
        None, ge=0, le=1, allow_inf_nan=False,
        description="Dr of the real material, for paper A's 2D -> 3D porosity conversion of circle regions")
    porosity_conversion: Literal["as_printed", "hexagonal"] = Field(
        "as_printed", description="reading of paper A's Eqs. 36-37 (see postprocess.porosity)")


#: physical ranges of the explicit design values (``siloflow.design_loads.bulk_solid`` checks the same):
#: unit weight N/m3 from expanded-polystyrene beads (~150) to tungsten powder (~1e5); K from well
#: below the Annex E solids (0.36-0.63; Jaky's 1 - sin phi_i is 0.13 at phi_i 60 deg) to 1, the
#: hydrostatic ratio (a stored solid is not in a passive state); wall friction mu from PTFE-lined
#: walls to tan 56 deg (a wall rougher than the solid's internal friction shears the solid instead)
DESIGN_RANGES = {"unit_weight": (100.0, 1e5), "K": (0.1, 1.0), "mu": (0.05, 1.5)}


class DesignSettings(Strict):
    """The bulk solid of the EN 1991-4 design loads (``siloflow design``; never reaches a deck):
    a row of the Annex E table (``material``, see ``siloflow.design_loads.MATERIALS``) or explicit
    values, which replace the table's and are used for every load case. Without ``material``,
    ``unit_weight``, ``K`` and ``mu`` are required."""

    material: Optional[str] = Field(None, max_length=64, description="EN 1991-4 Annex E solid (e.g. wheat, "
                                    "maize, sand, cement); none: the explicit values")
    unit_weight: Optional[Positive] = Field(None, ge=DESIGN_RANGES["unit_weight"][0],
                                            le=DESIGN_RANGES["unit_weight"][1],
                                            description="bulk unit weight gamma, N/m3")
    K: Optional[Positive] = Field(None, ge=DESIGN_RANGES["K"][0], le=DESIGN_RANGES["K"][1],
                                  description="lateral pressure ratio")
    mu: Optional[Positive] = Field(None, ge=DESIGN_RANGES["mu"][0], le=DESIGN_RANGES["mu"][1],
                                   description="wall friction coefficient")
    phi_r_deg: Optional[Positive] = Field(None, lt=90, description="angle of repose, degrees")
    C_op: Optional[NonNegative] = Field(None, le=10, description="patch load solid reference factor")
    wall_type: Literal["D1", "D2", "D3"] = Field("D2", description="wall friction category: D1 low, "
                                                   "D2 moderate (smooth steel), D3 high (concrete, rough)")
    action_assessment_class: Int = Field(2, ge=1, le=3, description="EN 1991-4 action assessment class")
    eccentricity: NonNegative = Field(0.0, le=100, description="filling / outlet eccentricity e, m")

    @model_validator(mode="after")
    def _solid(self):
        if self.material is not None:
            from .design_loads import MATERIAL_NAMES      # lazily: design_loads stays free of the schema
            if self.material not in MATERIAL_NAMES:
                raise ValueError(f"design.material {self.material!r} is not in the EN 1991-4 Annex E table; "
                                 "one of: " + ", ".join(MATERIAL_NAMES))
        else:
            missing = [k for k in ("unit_weight", "K", "mu") if getattr(self, k) is None]
            if missing:
                raise ValueError("design: give a material or the explicit values; missing "
                                 + ", ".join(f"design.{k}" for k in missing))
        return self


#: samples in the default static window: 5 batches of 4 for the batch-means error of each static
#: band pressure (postprocess.batch_means needs 10 samples at least)
STATIC_WINDOW_SAMPLES = 20


def default_static_window(sample_interval: float, check_interval: float) -> float:
    """The static window (s) when the case sets none: ``STATIC_WINDOW_SAMPLES`` wall-force samples
    of ``sample_interval`` (s), and at least two settling checks of ``check_interval`` (s), the
    time over which the bed was judged settled."""
    return max(STATIC_WINDOW_SAMPLES * sample_interval, 2 * check_interval)


def _with_static_window(data):
    """The raw case ``data`` with ``fill.settle.static_window`` set to its default if it is not
    given (a copy; anything malformed is left for validation to name)."""
    if not isinstance(data, dict) or not isinstance(data.get("fill"), dict):
        return data
    fill = dict(data["fill"])
    settle = fill.get("settle", {})
    if not isinstance(settle, dict) or settle.get("static_window") is not None:
        return data
    outputs = data.get("outputs", {})
    sample = outputs.get("sample_interval") if isinstance(outputs, dict) else None
    sample = sample if sample is not None else Outputs.model_fields["sample_interval"].default
    check = settle.get("check_interval", Settle.model_fields["check_interval"].default)
    if isinstance(sample, bool) or isinstance(check, bool) or not all(
            isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in (sample, check)):
        return data
    fill["settle"] = {**settle, "static_window": min(default_static_window(float(sample), float(check)), 100.0)}
    return {**data, "fill": fill}


class Case(Strict):
    """A complete, validated silo case (``Case.from_yaml(path)``, ``Case.model_validate(dict)``)."""

    @model_validator(mode="before")
    @classmethod
    def _default_static_window(cls, data):
        return _with_static_window(data)

    @classmethod
    def from_yaml(cls, path) -> "Case":
        """Read and validate a YAML case file (``siloflow.case_file.load_case``, read by
        ``siloflow.case_reader``); ``CaseError`` lists every problem with its field path."""
        from .case_reader import read_case
        return read_case(Case, path)

    name: SafeName
    description: str = Field("", max_length=2000, description="free text, never written into a deck")
    gravity: Positive = Field(9.81, le=1000, description="m/s2, acting along -z")
    geometry: Geometry
    sensors: WallSensors
    materials: Materials
    particles: Particles
    fill: Fill
    discharge: Discharge
    outputs: Outputs = Outputs()
    engine: EngineSettings = EngineSettings()
    analysis: Analysis = Analysis()
    inserts: list[WallInsert] = Field(default_factory=list, max_length=20,
                                      description="extra walls from STL files (inserts, baffles)")
    seed: Int = Field(12345, ge=0, le=2**31 - 1)
    design: Optional[DesignSettings] = Field(None, description="EN 1991-4 design loads' bulk solid "
                                             "(siloflow design); post-processing only")

    @model_validator(mode="after")
    def _consistent(self):
        g, p, f = self.geometry, self.particles, self.fill
        problems = []
        problems += _particle_problems(self)
        d = 2 * p.max_radius
        field = {"spheres": "particles.radius", "clumps": "particles.length"}.get(p.kind, "particles.radii")
        outlet = "geometry.outlet_width" if g.kind == "planar" else "outlet radius"
        if p.max_radius >= g.outlet_radius:
            problems.append(f"{field} ({p.max_radius:.6g} m) must be smaller than the {outlet} "
                            f"(half width {g.outlet_radius} m): nothing could leave")
        if 3 * d > g.half_width:
            problems.append(f"{field} ({p.max_radius:.6g} m) is too large for a silo of half width "
                            f"{g.half_width} m (need >= 3 particle diameters)")
        if g.kind == "planar":
            # the grains' thickness across the slab: spheres their diameter, wheat lies flat in it
            across = p.width if p.kind == "clumps" and p.shape == "wheat" else 2 * p.max_radius
            if p.kind == "clumps" and p.shape != "wheat":
                problems.append("geometry.kind planar: clumps in a slab need shape 'wheat' (inserted flat)")
            if g.thickness <= 1.01 * across:
                problems.append(f"geometry.thickness ({g.thickness} m) must exceed the grains' thickness "
                                f"({across:.6g} m) by 1 %")
        top = g.hopper_height + g.height
        if f.mobilise is not None and g.kind != "cylinder":
            problems.append(f"fill.mobilise lowers a flat floor: it needs geometry.kind cylinder, not {g.kind} "
                            "(a hopper or slab floor cannot move down without opening a gap at its walls)")
        if f.height is not None and f.height >= top:
            problems.append(f"fill.height ({f.height} m) must be below the top of the silo ({top:.6g} m)")
        zmin, zmax = f.insertion_z_min, f.insertion_z_max
        if zmax is not None and zmax > top:
            problems.append(f"fill.insertion_z_max ({zmax} m) is above the top of the silo ({top:.6g} m)")
        if zmin is not None and zmin < g.hopper_height:
            problems.append(f"fill.insertion_z_min ({zmin} m) must be above the hopper "
                            f"({g.hopper_height:.6g} m)")
        if zmin is not None and zmax is not None and zmax - zmin < 2 * d:
            problems.append("fill.insertion_z_max must exceed insertion_z_min by 2 particle diameters")
        if f.pour_radius is not None and not 2 * d <= f.pour_radius <= g.half_width:
            problems.append(f"fill.pour_radius ({f.pour_radius} m) must be between two grain diameters "
                            f"({2 * d:.6g} m) and the silo's half width ({g.half_width} m)")
        names = [i.name for i in self.inserts]
        if len(set(names)) != len(names):
            problems.append("inserts: names must be unique")
        if self.sensors.heights is not None and self.sensors.heights[-1] > g.height:
            problems.append(f"sensors.heights: last boundary ({self.sensors.heights[-1]} m) is above "
                            f"the vertical wall ({g.height} m)")
        problems += _sampling_problems(self)
        if problems:
            raise ValueError("; ".join(problems))
        return self


def _sampling_problems(case: "Case") -> list[str]:
    """The sample interval must fit the stages it measures: the discharge (flow rate, dynamic
    wall loads) and the static window (post-processing averages only samples taken wholly inside
    it, which needs two intervals)."""
    si, dis, static = case.outputs.sample_interval, case.discharge, case.fill.settle.static_window
    field, t_dis = ("discharge.duration", dis.duration) if dis.duration is not None else \
        ("discharge.max_time", dis.max_time)
    problems = []
    if si > t_dis:
        problems.append(f"outputs.sample_interval ({si} s) is longer than the discharge ({field} {t_dis} s): "
                        "no sample of the flow or the dynamic wall loads would be written")
    if static < 2 * si:
        problems.append(f"fill.settle.static_window ({static} s) must be at least two "
                        f"outputs.sample_interval (2 x {si} s): the static wall loads are averaged over "
                        "samples taken wholly inside the window")
    return problems


def _particle_problems(case: "Case") -> list[str]:
    """Cross-section checks of the particles: dust contact laws and sizes."""
    p, model = case.particles, case.materials.model
    problems = []
    dust = getattr(p, "dust", None)
    if dust is not None:
        for name in ("dust_dust", "dust_particle", "dust_wall"):
            problems += _contact_problems(model, f"particles.dust.{name}", getattr(dust, name))
        if model != "linear" and dust.youngs_modulus is None:
            problems.append(f"particles.dust.youngs_modulus is required by model '{model}'")
        if dust.radius >= p.min_radius:
            problems.append(f"particles.dust.radius ({dust.radius} m) must be smaller than the grains "
                            f"({p.min_radius} m)")
    return problems                 # what an engine cannot do is its own check: Engine.check
