"""Numbers as a reader takes them in: a value with its standard error, no more digits than the
error supports, in a unit of a sensible size (a silo's 29 kg/s, a model silo's 36 g/s)."""
from __future__ import annotations

import math

#: mass-flow units, largest first: (name, kg/s per unit)
MASS_RATE_UNITS = (("t/s", 1e3), ("kg/s", 1.0), ("g/s", 1e-3), ("mg/s", 1e-6))
#: pressure units, largest first: (name, Pa per unit)
PRESSURE_UNITS = (("MPa", 1e6), ("kPa", 1e3), ("Pa", 1.0))


def _finite(x) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def unit_for(value: float, units) -> tuple[str, float]:
    """The largest of ``units`` ((name, size) pairs, largest first) in which |value| is at least 1
    (the smallest one for smaller values, zero and NaN)."""
    if _finite(value):
        for name, size in units:
            if abs(value) >= size:
                return name, size
    return units[-1]


def with_error(value, error, unit: str = "", digits: int = 2) -> str:
    """'36.2 +/- 1.1 unit': the error to ``digits`` significant figures and the value to the same
    decimal place; without a finite error, the value to 4 significant figures and 'error not
    resolved'."""
    suffix = f" {unit}" if unit else ""
    if not _finite(value):
        return f"n/a{suffix}"
    value = float(value)
    if not _finite(error) or float(error) <= 0:
        return f"{value:.4g}{suffix} (error not resolved)"
    error = float(error)
    place = digits - 1 - math.floor(math.log10(error))     # decimals that keep `digits` figures of the error
    error = round(error, place)
    place = digits - 1 - math.floor(math.log10(error))     # 0.096 -> 0.10 moves the place
    if place > 0:
        return f"{value:.{place}f} +/- {error:.{place}f}{suffix}"
    return f"{round(value, place):.0f} +/- {round(error, place):.0f}{suffix}"


def mass_rate(rate_kg_s, stderr_kg_s) -> str:
    """A mass flow rate (kg/s) with its standard error, in t/s, kg/s, g/s or mg/s by its size."""
    name, size = unit_for(rate_kg_s, MASS_RATE_UNITS)
    err = stderr_kg_s / size if _finite(stderr_kg_s) else stderr_kg_s
    return with_error(rate_kg_s / size if _finite(rate_kg_s) else rate_kg_s, err, name)


def pressure(value_pa, stderr_pa) -> str:
    """A pressure (Pa) with its standard error, in Pa, kPa or MPa by its size."""
    name, size = unit_for(value_pa, PRESSURE_UNITS)
    err = stderr_pa / size if _finite(stderr_pa) else stderr_pa
    return with_error(value_pa / size if _finite(value_pa) else value_pa, err, name)


def in_unit(value, units) -> str:
    """A value without an error, to 4 significant figures, in the largest of ``units`` that suits it
    (what :func:`with_error` writes before '(error not resolved)')."""
    name, size = unit_for(value, units)
    return with_error(value / size if _finite(value) else value, float("nan"), name).removesuffix(
        " (error not resolved)")


def mass_rate_value(rate_kg_s) -> str:
    """A mass flow rate (kg/s) without an error, in t/s, kg/s, g/s or mg/s by its size."""
    return in_unit(rate_kg_s, MASS_RATE_UNITS)


def pressure_value(value_pa) -> str:
    """A pressure (Pa) without an error, in Pa, kPa or MPa by its size."""
    return in_unit(value_pa, PRESSURE_UNITS)
