"""The case's particles: monodisperse or polydisperse spheres, clumps, dust (SI units)."""
from __future__ import annotations

from typing import Annotated, Literal, Optional, Union

from pydantic import Field, model_validator

from .fields import (
    MAX_YOUNGS_MODULUS,
    MIN_DENSITY,
    MIN_YOUNGS_MODULUS,
    FiniteFloat,
    Fraction,
    GrainRadius,
    Int,
    Positive,
    Real,
    Strict,
)
from .materials import PairContact


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
        from ..clumps import ClumpShape, wheat_grain
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


