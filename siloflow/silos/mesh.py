"""``geometry.kind: mesh``: the user's silo from STL ``files`` (times ``scale``), read and
measured when planned (``siloflow.geometry.container``): the circle inside its vertical walls
about its axis, their section half way up, an outlet circle or polygon (m)."""
from __future__ import annotations

from .base import SiloKind, round_region, vertical_discs


class Mesh(SiloKind):
    """A silo from STL: its pieces keep the user's triangles; it need not be symmetric."""

    name = "mesh"
    title = "silo from STL"
    case_model = "siloflow.case.geometry:MeshGeometry"
    walls_builder = "siloflow.geometry.container:container_meshes"
    user_triangles = True
    reads_files = True

    # ---------------------------------------------------------------- the case
    def outlet_fields(self, g) -> str:
        return "geometry.outlet times geometry.scale"

    def wall_height_field(self, g) -> str:
        return "the vertical walls of geometry.files"

    def shaping_fields(self, g, role: str, defect: str, sensors: str) -> list[str]:
        """The user's triangles, cut at the bands and sectors."""
        return {"band": [sensors, "sensors.sectors", "geometry.files"], "wall": [sensors, "geometry.files"],
                "outlet": ["geometry.outlet"]}.get(role, ["geometry.files", "geometry.scale"])

    # ---------------------------------------------------------------- the plan
    def bed_volume(self, g, height: float) -> float:
        return g.container.volume_below(height)

    def janssen_section(self, g, wall_friction: float) -> tuple[float, float]:
        """The vertical walls' section half way up."""
        area, perimeter = g.section
        return area, perimeter * wall_friction

    def insertion_region(self, g, p, pour: float, r: float, z_min: float, z_max: float) -> tuple[dict, float]:
        """A vertical cylinder in the circle inside its walls, as a cylinder's."""
        return round_region(g, pour, r, z_min, z_max)

    def silo_fields(self, g) -> dict:
        return {"radius": g.radius, "width": None, "thickness": None, "face_friction": None, "mesh_segments": None,
                "periodic_depth": False, "outlet_offset_y": g.outlet_offset_y,
                "outer_radius": g.container.outer_radius, "section_area": g.section[0],
                "section_perimeter": g.section[1], "outlet": "circle" if g.outlet.radius is not None else "polygon"}

    def outlet_reach(self, g) -> float:
        return g.container.outline.size

    def escape_limits(self, g, margin: float) -> dict:
        return {"escape_radius": g.container.outer_radius + margin, "escape_half_x": None, "escape_half_y": None}

    def wall_meshes(self, s, band_bounds, sectors: int, outlet_z: float, outlet_radius: float, container=None):
        """Its container (``siloflow.geometry.container``) cut at the bands and sectors."""
        return self.builder()(container, band_bounds, sectors, (s.outlet_offset, s.outlet_offset_y), outlet_z,
                              outlet_radius)

    # ---------------------------------------------------------------- post-processing
    def bed_discs(self, s, z0: float, z1: float, d: float) -> list[tuple]:
        return vertical_discs(s.radius, z0, z1, d)

    def janssen_diameter(self, s) -> float:
        """4 A / P of its vertical walls' section half way up."""
        return s.hydraulic_diameter

    def bed_area(self, s, measured: float) -> float:
        """Its vertical walls' section (the free surface's rings miss its corners)."""
        return s.section_area

    def beverloo_outlet(self, s):
        what = ("hydraulic diameter 4A/P of a polygon outlet (the round law approximated)" if s.outlet == "polygon"
                else "outlet width or diameter")
        return float("nan"), False, what

    def eccentric_sectors(self, sectors: int, offset: float, offset_y: float) -> tuple[int, list[int], list[tuple]]:
        """As a cylinder's, without mirror pairs: a silo from STL need not be symmetric."""
        near, far, _ = super().eccentric_sectors(sectors, offset, offset_y)
        return near, far, []


KIND = Mesh()
