"""The case's post-processing settings: measurement regions, wall inserts, EN 1991-4 design."""
from __future__ import annotations

from typing import Literal, Optional

from pydantic import Field, model_validator

from .fields import FiniteFloat, Int, NonNegative, Positive, Real, SafeName, Strict


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
#: walls to tan 56 deg (a wall rougher than the solid's internal friction shears the solid instead);
#: the angle of repose phi_r (deg) from 5, below the 6 deg at which even frictionless spheres heap
#: (their macroscopic friction angle), to 70, past Carr's "very, very poor" flow (> 66 deg): a
#: steeper heap stands by cohesion, outside EN 1991-4's solids (Annex E: 29-47 deg); the squat
#: silo's Y_R has the exponent -(1 + tan phi_r), which a phi_r near 90 deg sends to infinity
DESIGN_RANGES = {"unit_weight": (100.0, 1e5), "K": (0.1, 1.0), "mu": (0.05, 1.5), "phi_r": (5.0, 70.0)}


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
    phi_r_deg: Optional[Positive] = Field(None, ge=DESIGN_RANGES["phi_r"][0], le=DESIGN_RANGES["phi_r"][1],
                                          description="angle of repose, degrees")
    C_op: Optional[NonNegative] = Field(None, le=10, description="patch load solid reference factor")
    wall_type: Literal["D1", "D2", "D3"] = Field("D2", description="wall friction category: D1 low, "
                                                   "D2 moderate (smooth steel), D3 high (concrete, rough)")
    action_assessment_class: Int = Field(2, ge=1, le=3, description="EN 1991-4 action assessment class")
    eccentricity: NonNegative = Field(0.0, le=100, description="filling / outlet eccentricity e, m")

    @model_validator(mode="after")
    def _solid(self):
        if self.material is not None:
            from ..design_loads import (
                MATERIAL_NAMES,  # lazily: design_loads stays free of the schema
            )
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
