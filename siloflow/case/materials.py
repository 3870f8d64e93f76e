"""The case's materials: grains, walls and the contact laws between them (SI units)."""
from __future__ import annotations

from typing import Literal, Optional

from pydantic import Field, model_validator

from .fields import (
    MAX_YOUNGS_MODULUS,
    MIN_CHARACTERISTIC_VELOCITY,
    MIN_DENSITY,
    MIN_YOUNGS_MODULUS,
    NonNegative,
    Positive,
    Real,
    Strict,
)


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
        None, ge=MIN_CHARACTERISTIC_VELOCITY, le=1000, description="impact speed that sets kn of model 'hooke', m/s")
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


