"""``geometry.kind: planar``: a slab ``width`` wide (x) and ``thickness`` deep (y) between two
faces, on a flat floor or a wedge hopper down to a slot ``outlet_width`` wide (m); periodic along y
over its thickness without faces (``periodic_depth``)."""
from __future__ import annotations

import math

import numpy as np

from .base import FlatSided

#: the fewest grain diameters a periodic slab's depth holds (a grain must not touch its own image)
PERIODIC_GRAINS = 3.0


class Planar(FlatSided):
    """A slab: its two side walls are its sectors, its faces have a friction of their own."""

    name = "planar"
    title = "slab"
    case_model = "siloflow.case.geometry:PlanarGeometry"
    lammps_walls = "siloflow.engine.lammps.deck:slab_walls"
    walls_builder = "siloflow.geometry.silo_walls:slab_meshes"
    slab = True
    side_walls = 2

    # ---------------------------------------------------------------- the case
    def outlet_fields(self, g) -> str:
        return "geometry.outlet_width / 2"

    def particle_problems(self, g, p) -> list[str]:
        """Clumps lie flat (wheat only); a periodic slab takes spheres without dust and at least
        :data:`PERIODIC_GRAINS` diameters; a walled one is 1 % thicker than the grains."""
        problems = []
        # the grains' thickness across the slab: spheres their diameter, wheat lies flat in it
        across = p.width if p.kind == "clumps" and p.shape == "wheat" else 2 * p.max_radius
        if p.kind == "clumps" and p.shape != "wheat":
            problems.append("geometry.kind planar: clumps in a slab need shape 'wheat' (inserted flat)")
        if g.periodic_depth:
            if p.kind == "clumps" or getattr(p, "dust", None) is not None:
                problems.append("geometry.periodic_depth: a periodic slab takes spheres without dust (clumps and "
                                "dust are held to a one-grain slab's mid-plane)")
            if g.thickness < PERIODIC_GRAINS * 2 * p.max_radius:
                problems.append(f"geometry.thickness ({g.thickness} m) of a periodic slab must hold at least "
                                f"{PERIODIC_GRAINS:g} grain diameters ({PERIODIC_GRAINS * 2 * p.max_radius:.6g} m): "
                                "a grain must not touch its own periodic image")
        elif g.thickness <= 1.01 * across:
            problems.append(f"geometry.thickness ({g.thickness} m) must exceed the grains' thickness "
                            f"({across:.6g} m) by 1 %")
        return problems

    def shaping_fields(self, g, role: str, defect: str, sensors: str) -> list[str]:
        offset = ["geometry.outlet_offset"] if getattr(g, "outlet_offset", 0.0) else []
        if defect == "edge" and role in ("hopper", "cone", "bottom", "plate", "outlet"):
            return ["geometry.outlet_width", "geometry.width", "geometry.half_angle_deg", "geometry.thickness"] + offset
        return {"band": [sensors, "geometry.height", "geometry.thickness"],
                "wall": [sensors, "geometry.height", "geometry.thickness"],
                "hopper": offset + ["geometry.half_angle_deg", "geometry.outlet_width", "geometry.width",
                                    "geometry.thickness"],
                "bottom": offset + ["geometry.outlet_width", "geometry.width", "geometry.thickness"],
                "face": offset + ["geometry.half_angle_deg", "geometry.outlet_width", "geometry.width",
                                  "geometry.height"],
                }.get(role, ["geometry.outlet_width", "geometry.thickness"] + offset)

    def design_refusal(self, covered: str) -> str:
        return ("geometry.kind planar: EN 1991-4's rectangular silos need both plan dimensions, "
                "and a slab one grain thick is not a silo the standard covers; design loads are "
                f"computed for kind {covered}")

    # ---------------------------------------------------------------- the plan
    def bed_volume(self, g, height: float) -> float:
        """The wedge hopper's trapezoid, then the full width, times the thickness."""
        h_w = min(height, g.hopper_height)      # 0 on a flat floor (no wedge); an offset slot shears it
        w_top = g.outlet_width + (2.0 * h_w * math.tan(math.radians(g.half_angle_deg)) if h_w > 0 else 0.0)
        area = 0.5 * (g.outlet_width + w_top) * h_w + g.width * max(0.0, height - g.hopper_height)
        return area * g.thickness

    def janssen_section(self, g, wall_friction: float) -> tuple[float, float]:
        """The side walls grip with the wall friction, the faces with theirs."""
        return g.width * g.thickness, 2 * g.thickness * wall_friction + 2 * g.width * g.face_friction

    def insertion_region(self, g, p, pour: float, r: float, z_min: float, z_max: float) -> tuple[dict, float]:
        """A block through the thickness, centres only (all_in no: a clump's bounding sphere is
        wider than the slab); wheat lies flat in the slab, so its half thickness is its sphere
        radius; a periodic slab's whole length (centres wrap)."""
        half_t = 0.5 * g.thickness - (0.5 * p.width if p.kind == "clumps" else r)
        if g.periodic_depth:
            half_t = 0.5 * g.thickness
        half_x = min(pour, g.half_width - 1.05 * r)
        return ({"shape": "block", "xlo": -half_x, "xhi": half_x, "ylo": -half_t, "yhi": half_t,
                 "z_min": z_min + r, "z_max": z_max - r}, 2 * half_x * g.thickness * (z_max - z_min))

    def silo_fields(self, g) -> dict:
        return {"radius": None, "width": g.width, "thickness": g.thickness, "face_friction": g.face_friction,
                "mesh_segments": None, "periodic_depth": g.periodic_depth}

    # ---------------------------------------------------------------- post-processing
    def half_depth(self, s) -> float:
        return 0.5 * s.thickness

    def across(self, s, points: np.ndarray) -> np.ndarray:
        """The distance from the mid-plane x = 0 (the faces do not count)."""
        return np.abs(points[:, 0])

    def bed_discs(self, s, z0: float, z1: float, d: float) -> list[tuple]:
        """Discs through the thickness (cylinders along y) at mid-bed, as large as the bed allows."""
        half = 0.5 * (z1 - z0)
        mid, t = (0.0, 0.0, 0.5 * (z0 + z1)), 0.5 * s.thickness
        return [("bulk_core", mid, min(s.half_width - 2.0 * d, half), 1, -t, t),
                ("cross_section", mid, min(s.half_width, half), 1, -t, t)]

    def janssen_diameter(self, s) -> float:
        """4 A / P with P the side walls, and the faces only when they have friction."""
        perimeter = 2.0 * s.thickness + (2.0 * s.width if s.face_friction > 0 else 0.0)
        return 4.0 * s.width * s.thickness / perimeter

    def surface_thickness(self, s):
        return s.thickness

    def beverloo_outlet(self, s) -> tuple[float, bool, str]:
        """The slot runs through the thickness, from face to face."""
        return s.thickness, False, "outlet width or diameter"

    def grid_slab(self, s):
        return s.thickness


KIND = Planar()
