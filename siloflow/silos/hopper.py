"""``geometry.kind: hopper``: a cylinder above a conical hopper of ``half_angle_deg`` from the
vertical down to its outlet of ``outlet_radius`` (m), oblique when the outlet is off the axis."""
from __future__ import annotations

import math

from .cylinder import Cylinder


class Hopper(Cylinder):
    """A cylinder on a cone; its floor cannot move and it has no force balance of a flat floor."""

    name = "hopper"
    title = "hopper"
    case_model = "siloflow.case.geometry:HopperGeometry"
    lammps_walls = "siloflow.engine.lammps.deck:hopper_walls"
    mobile_floor = False
    wall_force_balance = False
    en1991 = "hopper"
    orifice_field = "geometry.outlet_radius"

    def lammps_problems(self, g) -> list[tuple[str, str]]:
        """An eccentric outlet needs an oblique cone."""
        if not g.outlet_offset:
            return []
        return [("geometry.outlet_offset", "LAMMPS' cone region is a right cone, so it has no "
                                           "oblique hopper for an eccentric outlet: set outlet_offset: "
                                           "0, or use engine.name: liggghts (mesh walls)")]

    def bed_volume(self, g, height: float) -> float:
        """The cone's frustum up to ``height``, then the cylinder."""
        R, hh = g.radius, g.hopper_height
        t = math.tan(math.radians(g.half_angle_deg))
        h_cone = min(height, hh)
        r_top = g.outlet_radius + h_cone * t
        cone = math.pi * h_cone / 3 * (g.outlet_radius ** 2 + g.outlet_radius * r_top + r_top ** 2)
        return cone + math.pi * R ** 2 * max(0.0, height - hh)


KIND = Hopper()
