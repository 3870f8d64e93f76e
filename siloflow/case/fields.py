"""Field types and physical limits shared by every section of the case schema (SI units)."""
from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, StringConstraints

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
#: m/s2: a fifth of the weakest surface gravity of the asteroids granular DEM studies model (Bennu,
#: 6e-5 m/s2); in weaker gravity a grain's weight is below the cohesive forces these contact laws omit
MIN_GRAVITY = 1e-5
#: s: the shortest settling check; a grain of 1 um (the smallest) falls its own diameter in 63 us
#: under the strongest gravity accepted (1000 m/s2): checks 60 times more often see nothing settle
MIN_CHECK_INTERVAL = 1e-6
#: m/s: the slowest characteristic (impact) velocity of model hooke; grains dropped from one diameter
#: meet at sqrt(2 g d), 6 mm/s for 1 um grains; slower, kn (which goes as V^0.4) softens the contacts
#: until grains pass through each other (and V^2 underflows to a zero stiffness)
MIN_CHARACTERISTIC_VELOCITY = 1e-3
#: m: a sensor band boundary above the wall's base is at least an atom's size up (a thinner band
#: is no band; LIGGGHTS' own precision, 1e-8 m, then refuses its mesh, naming sensors.heights)
MIN_BAND_BOUNDARY = 1e-10
GrainRadius = Annotated[Positive, Field(ge=MIN_GRAIN_RADIUS)]


class Strict(BaseModel):
    """Base of every section: unknown keys are errors, NaN/inf refused."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)

