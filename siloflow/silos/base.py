"""The interface of a silo kind (``docs/new_silo.md``): what the planner, the engines' decks and
post-processing ask of a ``geometry.kind``. A kind is an instance of a :class:`SiloKind` subclass
in its own module; every method takes the case's geometry (``g``, ``siloflow.case.geometry``) or
the plan's silo (``s``, ``siloflow.plan.Silo``), read by attribute only, so that this package
imports neither. Lengths m, areas m2, volumes m3, angles as the case gives them."""
from __future__ import annotations

import math
from importlib import import_module

import numpy as np

from ..errors import ReadError


class SiloKind:
    """One silo kind. Class attributes say what it is; methods compute what is its own."""

    #: the case's ``geometry.kind``
    name: str = ""
    #: what a report calls it
    title: str = ""
    #: ``"module:class"`` of its case model (``siloflow.case.geometry``, a member of the ``Geometry``
    #: union, which owns the case's fields and their checks)
    case_model: str = ""
    #: ``"module:function"`` building its walls' meshes (``siloflow.geometry``), imported when a plan
    #: is made (as the engine registry imports an engine), so that post-processing never reaches it
    walls_builder: str = ""
    #: ``"module:function"`` of its LAMMPS region walls ((plan, floor_dz) -> ``LammpsWall`` list,
    #: ``siloflow.engine.lammps.deck``); empty when LAMMPS cannot build them
    lammps_walls: str = ""
    #: its walls are the user's triangles (held to LIGGGHTS' limits, not siloflow's)
    user_triangles: bool = False
    #: the case names files the planner reads (``geometry.files``): located beside the case file,
    #: measured when planned, copied into the run folder
    reads_files: bool = False
    #: a slab: thin along y, its grains held near the x-z plane (the decks' processor grid, clumps
    #: moving in the plane), its front and back faces with a contact law of their own
    #: (``geometry.face_friction``)
    slab: bool = False
    #: its floor is flat and may be lowered after settling (``fill.mobilise``)
    mobile_floor: bool = False
    #: the wall's normal force from band pressures (2 pi R per unit height) is compared with the
    #: force balance of a flat-floored cylinder
    wall_force_balance: bool = False
    #: EN 1991-4's circular silo it is (``siloflow.design_loads``): ``flat`` bottomed or ``hopper``;
    #: None for none the standard covers
    en1991: str | None = None

    # ---------------------------------------------------------------- the case
    def outlet_fields(self, g) -> str:
        """The case fields that size the outlet, for messages."""
        raise NotImplementedError

    def wall_height_field(self, g) -> str:
        """The case field that sets the vertical walls' height, for messages."""
        return "geometry.height"

    def particle_problems(self, g, p) -> list[str]:
        """What the kind refuses of the case's particles ``p`` (messages naming the fields)."""
        return []

    def lammps_problems(self, g) -> list[tuple[str, str]]:
        """What LAMMPS' region walls cannot build of this silo, as (case field, message); LAMMPS
        refuses walls of the user's triangles and clumps in a slab by :attr:`user_triangles` and
        :attr:`slab`."""
        return []

    def shaping_fields(self, g, role: str, defect: str, sensors: str) -> list[str]:
        """The case fields that shape a wall of ``role``, likeliest culprit first (``defect``
        ``edge``: a too short edge, ``angle``: a too small one; ``sensors``: the field of the bands)."""
        raise NotImplementedError

    def design_refusal(self, covered: str) -> str:
        """Why EN 1991-4's design loads are not computed for it; ``covered``: the kinds they are."""
        return f"geometry.kind {self.name!r}: design loads need kind {covered}"

    # ---------------------------------------------------------------- the plan
    def bed_volume(self, g, height: float) -> float:
        """Volume of the silo below ``height`` (m above the outlet), m3."""
        raise NotImplementedError

    def janssen_section(self, g, wall_friction: float) -> tuple[float, float]:
        """The vertical part's cross-section area (m2) and its grip: the sum of wall friction
        coefficient times the perimeter it acts on (m)."""
        raise NotImplementedError

    def insertion_region(self, g, p, pour: float, r: float, z_min: float, z_max: float) -> tuple[dict, float]:
        """The fill's insertion region (``siloflow.plan.InsertionRegion`` fields) between ``z_min``
        and ``z_max`` for grains of largest radius ``r`` poured over ``pour`` (half width, m), and
        its volume (m3)."""
        raise NotImplementedError

    def silo_fields(self, g) -> dict:
        """The plan's ``Silo`` fields of this kind (beyond kind, half width, heights, outlet radius
        and offset)."""
        raise NotImplementedError

    def sensor_sectors(self, g, sectors: int) -> int:
        """Sectors per sensor band; ``sectors`` the case's."""
        return sectors

    def outlet_reach(self, g) -> float:
        """How far the outlet reaches from its centre (m): the counting disc covers it."""
        return g.outlet_radius

    def escape_limits(self, g, margin: float) -> dict:
        """The guard's escape limits (``siloflow.plan.Guard``: ``escape_radius``, ``escape_half_x``,
        ``escape_half_y``), ``margin`` beyond the walls."""
        raise NotImplementedError

    def wall_meshes(self, s, band_bounds, sectors: int, outlet_z: float, outlet_radius: float, container=None):
        """The walls' meshes of the plan's silo ``s`` (``siloflow.geometry.silo_meshes``)."""
        return self.builder()(s, band_bounds, sectors, outlet_z, outlet_radius)

    def builder(self):
        """The function :attr:`walls_builder` names."""
        return resolve(self.walls_builder)

    def primitive_sides(self, s) -> list[dict]:
        """The side walls as LIGGGHTS primitives (``siloflow.engine.liggghts.side_walls``): ``fid``,
        ``style``, ``args`` (m), ``sector`` (None: every sector); empty when they stay meshes."""
        return []

    def inside(self, s, points: np.ndarray) -> np.ndarray:
        """Which ``points`` (n x 3, m) lie within the silo's plan outline."""
        return np.hypot(points[:, 0], points[:, 1]) <= s.radius

    # ---------------------------------------------------------------- post-processing
    def half_depth(self, s) -> float:
        """Half the extent along y, m."""
        return s.reach

    def across(self, s, points: np.ndarray) -> np.ndarray:
        """How far across the section ``points`` (n x 3) lie, m: the distance from the axis, to be
        compared with the half width (the bed's core is two diameters inside it)."""
        return np.hypot(points[:, 0], points[:, 1])

    def bed_discs(self, s, z0: float, z1: float, d: float) -> list[tuple]:
        """The bed's measurement cylinders ``bulk_core`` and ``cross_section`` between heights
        ``z0`` and ``z1`` for grains of diameter ``d``: (name, centre, radius, axis, t0, t1), m."""
        raise NotImplementedError

    def janssen_diameter(self, s) -> float:
        """The D of Janssen's law (a cylinder's diameter, else 4 A / P of the walls with friction), m."""
        raise NotImplementedError

    def surface_thickness(self, s):
        """The free surface's strips' depth (m), None for rings about the axis."""
        return None

    def bed_area(self, s, measured: float) -> float:
        """The bed's whole cross-section, m2; ``measured`` the free surface's."""
        return measured

    def beverloo_outlet(self, s) -> tuple[float, bool, str]:
        """Beverloo's outlet length L (m, NaN for a round orifice), whether L ends at walls or
        edges, and what its D0 is."""
        return np.nan, False, "outlet width or diameter"

    def grid_slab(self, s):
        """Coarse-graining: a slab's thickness (m), else None."""
        return None

    def grid_half_depth(self, s):
        """Coarse-graining: a Cartesian grid's half extent along y (m), else None (r-z grid)."""
        return None

    def eccentric_sectors(self, sectors: int, offset: float, offset_y: float) -> tuple[int, list[int], list[tuple]]:
        """An eccentric outlet's near sector, the far ones, and the mirror pairs equal by symmetry."""
        near = 0
        far = [sectors // 2] if sectors % 2 == 0 else [sectors // 2, sectors // 2 + 1]
        pairs = [(k, sectors - k) for k in range(1, (sectors + 1) // 2) if k != sectors - k]
        return near, far, pairs

    def wall_bins(self, s, sectors, plan_sectors: int, r_min: float):
        """Re-binning the side wall's contacts (``postprocess.rebin``): a function of (xw, yw, zw)
        -> (on the side wall, sector), the sectors' count, each sector's (theta0, theta1) or width
        (m), and the radius (None for flat walls). ``sectors`` asked (None: the plan's)."""
        raise ReadError(f"re-binning a {self.name} silo's walls is not supported (its sensor pieces are its own "
                        "meshes)")


def resolve(ref: str):
    """What a ``"module:name"`` reference names, its module imported now."""
    module, name = ref.split(":")
    return getattr(import_module(module), name)


class FlatSided(SiloKind):
    """A silo of flat side walls, which are its sectors: x = -+ half width, then (four of them)
    y = -+ half depth."""

    #: its side walls: 2 (at x only) or 4
    side_walls: int = 2

    def sides(self, s) -> list[tuple[float, str]]:
        """Each side wall's position (m) and axis (``x``, ``y``), sectors in order."""
        a, b = s.half_width, self.half_depth(s)
        return [(-a, "x"), (a, "x")] + ([(-b, "y"), (b, "y")] if self.side_walls == 4 else [])

    def sensor_sectors(self, g, sectors: int) -> int:
        """Its side walls."""
        return self.side_walls

    def escape_limits(self, g, margin: float) -> dict:
        return {"escape_radius": None, "escape_half_x": g.half_width + margin,
                "escape_half_y": self.half_depth(g) + margin}

    def wall_meshes(self, s, band_bounds, sectors: int, outlet_z: float, outlet_radius: float, container=None):
        return self.builder()(s, band_bounds, outlet_z, outlet_radius)

    def primitive_sides(self, s) -> list[dict]:
        return [{"fid": f"side_s{k:02d}", "style": f"{axis}plane", "args": [pos], "sector": k}
                for k, (pos, axis) in enumerate(self.sides(s))]

    def inside(self, s, points: np.ndarray) -> np.ndarray:
        return (np.abs(points[:, 0]) <= s.half_width) & (np.abs(points[:, 1]) <= self.half_depth(s))

    def eccentric_sectors(self, sectors: int, offset: float, offset_y: float) -> tuple[int, list[int], list[tuple]]:
        """Sectors 0, 1 the walls at x = -+ width/2: the near one on the outlet's side."""
        near, far = (1, [0]) if offset > 0 else (0, [1])
        return near, far, []

    def wall_bins(self, s, sectors, plan_sectors: int, r_min: float):
        """Contacts within a quarter grain of a side wall's plane; no other sectors than its walls."""
        if sectors is not None:
            raise ReadError(f"a {self.title} silo's sectors are its walls: give --bands without --sectors")
        a, b = s.half_width, self.half_depth(s)
        base = s.hopper_height
        tol = 0.25 * r_min
        sides = self.sides(s)

        def classify(xw, yw, zw):
            sector = np.full(len(xw), -1)
            for k, (pos, axis) in enumerate(sides):
                coord = xw if axis == "x" else yw
                sector = np.where((sector < 0) & (np.abs(coord - pos) <= tol), k, sector)
            return (sector >= 0) & (zw >= base - tol), np.maximum(sector, 0)
        lengths = [2 * b if axis == "x" else 2 * a for _, axis in sides]
        return classify, len(sides), lengths, None


def vertical_discs(radius: float, z0: float, z1: float, d: float) -> list[tuple]:
    """:meth:`SiloKind.bed_discs` of vertical cylinders about the axis of ``radius`` (m)."""
    return [("bulk_core", (0.0, 0.0, 0.0), radius - 2.0 * d, 2, z0, z1),
            ("cross_section", (0.0, 0.0, 0.0), radius, 2, z0, z1)]


def round_region(g, pour: float, r: float, z_min: float, z_max: float) -> tuple[dict, float]:
    """:meth:`SiloKind.insertion_region` of a vertical cylinder about the axis, 0.6 grain radii inside
    the circle of ``g.radius`` (centres and radius)."""
    region_radius = min(pour, g.radius - 0.6 * r)
    return ({"shape": "cylinder", "radius": region_radius, "z_min": z_min, "z_max": z_max},
            math.pi * region_radius ** 2 * (z_max - z_min))
