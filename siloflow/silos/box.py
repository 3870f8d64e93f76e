"""``geometry.kind: box``: a rectangular silo ``width`` (x) by ``depth`` (y), on a flat floor or a
pyramid's (a slot's: a wedge's) hopper down to a rectangle, slot or circle outlet (m)."""
from __future__ import annotations

import numpy as np

from .base import FlatSided, vertical_discs


class Box(FlatSided):
    """A box: its four walls are its sectors (x = -+ width/2, then y = -+ depth/2)."""

    name = "box"
    title = "box"
    case_model = "siloflow.case.geometry:BoxGeometry"
    lammps_walls = "siloflow.engine.lammps.deck:box_region_walls"
    walls_builder = "siloflow.geometry.silo_walls:box_meshes"
    side_walls = 4

    # ---------------------------------------------------------------- the case
    def outlet_fields(self, g) -> str:
        return "geometry.outlet_radius" if g.outlet == "circle" else "geometry.outlet_width"

    def particle_problems(self, g, p) -> list[str]:
        if p.kind == "clumps" or getattr(p, "dust", None) is not None:
            return ["geometry.kind box: a rectangular silo takes spheres (monodisperse or polydisperse) "
                    "without dust for now; clumps and dust: kind cylinder, hopper or planar"]
        return []

    def shaping_fields(self, g, role: str, defect: str, sensors: str) -> list[str]:
        """Its own fields: the outlet's by its shape, width and depth."""
        offset = ["geometry.outlet_offset"] if getattr(g, "outlet_offset", 0.0) else []
        offset += ["geometry.outlet_offset_y"] if g.outlet_offset_y else []
        outlet = {"rectangle": ["geometry.outlet_width", "geometry.outlet_length"], "slot": ["geometry.outlet_width"],
                  "circle": ["geometry.outlet_radius"]}[g.outlet]
        sides = ["geometry.width", "geometry.depth"]
        if defect == "edge" and role in ("hopper", "bottom", "plate", "outlet"):
            return outlet + offset + sides
        return {"band": [sensors, "geometry.height"] + sides, "wall": [sensors, "geometry.height"] + sides,
                "hopper": offset + ["geometry.half_angle_deg"] + outlet + sides,
                "bottom": offset + outlet + sides}.get(role, outlet + offset)

    # ---------------------------------------------------------------- the plan
    def bed_volume(self, g, height: float) -> float:
        """The hopper's frustum (a pyramid's or a wedge's), then the box."""
        hh, (hx, hy) = g.hopper_height, g.outlet_half_sizes
        h_w = min(height, hh)
        a0, a1 = 2 * hx, (g.width - 2 * hx) / hh if hh > 0 else 0.0           # width along x: a0 + a1 z
        b0, b1 = 2 * hy, (g.depth - 2 * hy) / hh if hh > 0 else 0.0
        hopper = a0 * b0 * h_w + (a0 * b1 + a1 * b0) * h_w ** 2 / 2 + a1 * b1 * h_w ** 3 / 3
        return hopper + g.width * g.depth * max(0.0, height - hh)

    def janssen_section(self, g, wall_friction: float) -> tuple[float, float]:
        return g.width * g.depth, 2 * (g.width + g.depth) * wall_friction

    def insertion_region(self, g, p, pour: float, r: float, z_min: float, z_max: float) -> tuple[dict, float]:
        """A block, centres only, a grain's radius (and 5 %) from the walls."""
        half_x, half_y = min(pour, g.half_width - 1.05 * r), min(pour, 0.5 * g.depth - 1.05 * r)
        return ({"shape": "block", "xlo": -half_x, "xhi": half_x, "ylo": -half_y, "yhi": half_y,
                 "z_min": z_min + r, "z_max": z_max - r}, 4 * half_x * half_y * (z_max - z_min))

    def silo_fields(self, g) -> dict:
        return {"radius": None, "width": g.width, "thickness": None, "face_friction": None, "mesh_segments": None,
                "periodic_depth": False, "depth": g.depth, "outlet": g.outlet,
                "outlet_half_y": g.outlet_half_sizes[1], "outlet_offset_y": g.outlet_offset_y}

    # ---------------------------------------------------------------- post-processing
    def half_depth(self, s) -> float:
        return 0.5 * s.depth

    def across(self, s, points: np.ndarray) -> np.ndarray:
        """The larger of |x| and |y| moved out to the half width: the core is two diameters from
        each of the four walls."""
        return np.maximum(np.abs(points[:, 0]), np.abs(points[:, 1]) + s.half_width - 0.5 * s.depth)

    def bed_discs(self, s, z0: float, z1: float, d: float) -> list[tuple]:
        """The vertical cylinder inscribed in its cross-section."""
        return vertical_discs(min(s.half_width, 0.5 * s.depth), z0, z1, d)

    def janssen_diameter(self, s) -> float:
        """4 A / P of its four walls."""
        return 4.0 * s.width * s.depth / (2.0 * (s.width + s.depth))

    def surface_thickness(self, s):
        """Strips across its width, its whole depth."""
        return s.depth

    def beverloo_outlet(self, s) -> tuple[float, bool, str]:
        """A rectangle's or slot's length along y (a round outlet: none), ending at walls or edges."""
        return 2 * s.outlet_half_y if s.outlet != "circle" else np.nan, True, "outlet width or diameter"

    def grid_half_depth(self, s):
        return s.half_depth

    def eccentric_sectors(self, sectors: int, offset: float, offset_y: float) -> tuple[int, list[int], list[tuple]]:
        """The wall on the side the outlet is farther off the middle, x (sectors 0, 1) or y (2, 3)."""
        if abs(offset_y) > abs(offset):
            return (3, [2], []) if offset_y > 0 else (2, [3], [])
        return super().eccentric_sectors(sectors, offset, offset_y)


KIND = Box()
