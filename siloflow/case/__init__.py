"""The case schema: a pydantic model of everything a silo simulation needs.

All quantities are SI (m, kg, s, Pa, N/m). Unknown keys are errors, numbers must
be finite, integers strict (``true`` is not 1), and every string that can reach a deck or a
file name is restricted to a safe alphabet. Case files are read by :mod:`siloflow.case_file`
(``Case.from_yaml(path)``); a dict of fields is validated with ``Case.model_validate(data)``.

The schema is split by section (``fields``, ``geometry``, ``materials``, ``particles``,
``stages``, ``outputs``, ``engine_settings``, ``analysis``, ``model``); every name is importable
from ``siloflow.case``.
"""
from __future__ import annotations

from .analysis import (  # noqa: F401
    DESIGN_RANGES,
    Analysis,
    DesignSettings,
    MeasurementRegion,
    WallInsert,
)
from .engine_settings import (  # noqa: F401
    DEFAULT_TIMESTEP_FRACTION,
    PROFILE_FIELDS,
    PROFILE_NAMES,
    BenchQuantity,
    EngineSettings,
    PinnedProfile,
    TimestepFraction,
)
from .fields import (  # noqa: F401
    MAX_STAGE_TIME,
    MAX_YOUNGS_MODULUS,
    MIN_DENSITY,
    MIN_GRAIN_RADIUS,
    MIN_TIMESTEP_FRACTION,
    MIN_YOUNGS_MODULUS,
    SAFE_NAME_PATTERN,
    FiniteFloat,
    Fraction,
    GrainRadius,
    Int,
    NonNegative,
    Positive,
    Real,
    SafeName,
    Strict,
    _refuse_bool,
)
from .geometry import (  # noqa: F401
    MAX_HOPPER_HEIGHT,
    BoxGeometry,
    CylinderGeometry,
    Geometry,
    HopperGeometry,
    MeshGeometry,
    MeshOutlet,
    PlanarGeometry,
    WallSensors,
    _smaller,
)
from .materials import (  # noqa: F401
    Materials,
    PairContact,
    ParticleMaterial,
    WallMaterial,
    _contact_problems,
)
from .model import (  # noqa: F401
    STATIC_WINDOW_SAMPLES,
    Case,
    _particle_problems,
    _sampling_problems,
    _with_static_window,
    default_static_window,
)
from .outputs import (  # noqa: F401
    RESULTS,
    Guard,
    Outputs,
)
from .particles import (  # noqa: F401
    Clumps,
    ClumpSphere,
    Dust,
    MonodisperseSpheres,
    Particles,
    PolydisperseSpheres,
    paper_b_radii,
)
from .stages import (  # noqa: F401
    Discharge,
    Fill,
    Mobilise,
    Opening,
    Settle,
)

__all__ = ['Analysis', 'BenchQuantity', 'BoxGeometry', 'Case', 'ClumpSphere', 'Clumps', 'CylinderGeometry', 'DEFAULT_TIMESTEP_FRACTION', 'DESIGN_RANGES', 'DesignSettings', 'Discharge', 'Dust', 'EngineSettings', 'Fill', 'FiniteFloat', 'Fraction', 'Geometry', 'GrainRadius', 'Guard', 'HopperGeometry', 'Int', 'MAX_HOPPER_HEIGHT', 'MAX_STAGE_TIME', 'MAX_YOUNGS_MODULUS', 'MIN_DENSITY', 'MIN_GRAIN_RADIUS', 'MIN_TIMESTEP_FRACTION', 'MIN_YOUNGS_MODULUS', 'Materials', 'MeasurementRegion', 'MeshGeometry', 'MeshOutlet', 'Mobilise', 'MonodisperseSpheres', 'NonNegative', 'Opening', 'Outputs', 'PROFILE_FIELDS', 'PROFILE_NAMES', 'PairContact', 'ParticleMaterial', 'Particles', 'PinnedProfile', 'PlanarGeometry', 'PolydisperseSpheres', 'Positive', 'RESULTS', 'Real', 'SAFE_NAME_PATTERN', 'STATIC_WINDOW_SAMPLES', 'SafeName', 'Settle', 'Strict', 'TimestepFraction', 'WallInsert', 'WallMaterial', 'WallSensors', 'default_static_window', 'paper_b_radii']
