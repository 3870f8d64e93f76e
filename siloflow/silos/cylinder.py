"""``geometry.kind: cylinder``: a vertical cylinder of ``radius`` on a flat floor with a round
orifice of ``orifice_radius`` (m), off the axis by ``outlet_offset``; the base of the round kinds
(hopper, and the user's STL silo measured as the circle inside its walls)."""
from __future__ import annotations

import math

import numpy as np

from .base import SiloKind, round_region, vertical_discs


class Cylinder(SiloKind):
    """A flat-floored cylinder; its sensor bands are cut into ``sensors.sectors`` about the axis."""

    name = "cylinder"
    title = "cylinder"
    case_model = "siloflow.case.geometry:CylinderGeometry"
    lammps_walls = "siloflow.engine.lammps.deck:cylinder_walls"
    walls_builder = "siloflow.geometry.silo_walls:cylinder_meshes"
    mobile_floor = True
    wall_force_balance = True
    en1991 = "flat"
    #: the field of the orifice's radius
    orifice_field = "geometry.orifice_radius"

    # ---------------------------------------------------------------- the case
    def outlet_fields(self, g) -> str:
        return self.orifice_field

    def shaping_fields(self, g, role: str, defect: str, sensors: str) -> list[str]:
        offset = ["geometry.outlet_offset"] if getattr(g, "outlet_offset", 0.0) else []
        orifice = self.orifice_field
        if defect == "edge" and role in ("hopper", "cone", "bottom", "plate", "outlet"):
            return [orifice, "geometry.mesh_segments", "geometry.radius"] + offset
        return {"band": [sensors, "geometry.height", "geometry.mesh_segments", "sensors.sectors"],
                "wall": [sensors, "geometry.height", "geometry.mesh_segments"],
                "cone": offset + ["geometry.half_angle_deg", orifice, "geometry.radius", "geometry.mesh_segments"],
                "bottom": offset + [orifice, "geometry.radius", "geometry.mesh_segments"],
                }.get(role, [orifice, "geometry.mesh_segments"])

    # ---------------------------------------------------------------- the plan
    def bed_volume(self, g, height: float) -> float:
        return math.pi * g.radius ** 2 * height

    def janssen_section(self, g, wall_friction: float) -> tuple[float, float]:
        return math.pi * g.radius ** 2, 2 * math.pi * g.radius * wall_friction

    def insertion_region(self, g, p, pour: float, r: float, z_min: float, z_max: float) -> tuple[dict, float]:
        return round_region(g, pour, r, z_min, z_max)

    def silo_fields(self, g) -> dict:
        return {"radius": g.radius, "width": None, "thickness": None, "face_friction": None,
                "mesh_segments": g.mesh_segments, "periodic_depth": False}

    def escape_limits(self, g, margin: float) -> dict:
        return {"escape_radius": g.half_width + margin, "escape_half_x": None, "escape_half_y": None}

    def primitive_sides(self, s) -> list[dict]:
        return [{"fid": "side", "style": "zcylinder", "args": [s.radius, 0.0, 0.0], "sector": None}]

    # ---------------------------------------------------------------- post-processing
    def bed_discs(self, s, z0: float, z1: float, d: float) -> list[tuple]:
        return vertical_discs(s.radius, z0, z1, d)

    def janssen_diameter(self, s) -> float:
        return 2.0 * s.radius

    def wall_bins(self, s, sectors, plan_sectors: int, r_min: float):
        """Sectors about the axis (a phase of half a sector with an eccentric outlet, so that sector
        0 faces it), within the facets' sag and a quarter grain of the radius."""
        n = sectors or plan_sectors
        R, base = s.radius, s.hopper_height
        sag = R * (1.0 - math.cos(math.pi / (s.mesh_segments or 1000)))
        tol = sag + 0.25 * r_min
        phase = -math.pi / n if s.outlet_offset else 0.0

        def classify(xw, yw, zw):
            rho = np.hypot(xw, yw)
            on = (np.abs(rho - R) <= tol) & (zw >= base - tol)
            theta = np.mod(np.arctan2(yw, xw) - phase, 2 * math.pi)
            sector = np.minimum((theta / (2 * math.pi / n)).astype(int), n - 1)
            return on, sector
        spans = [(phase + 2 * math.pi * k / n, phase + 2 * math.pi * (k + 1) / n) for k in range(n)]
        return classify, n, spans, R


KIND = Cylinder()
