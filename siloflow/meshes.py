"""Wall meshes of a silo, generated as triangle arrays and written as ASCII STL.

z = 0 is the outlet plane. Every cylinder band is split into ``sectors`` azimuthal
meshes, so that each (band, sector) is a force sensor whose net radial force is
not cancelled by the opposite side of the ring (ENGINE_NOTES.md).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from stl import mesh as stl_mesh
from stl import Mode

from .case import Case, CylinderGeometry, HopperGeometry, PlanarGeometry


#: longest/shortest side of the cylinder facets
MAX_FACET_ASPECT = 10.0


@dataclass
class WallMesh:
    """One STL wall.

    ``role`` is ``band`` (a wall sensor), ``wall`` (cylinder wall not sensed),
    ``bottom``, ``cone``, ``plate`` (the orifice plate) or ``outlet`` (the counting disc,
    not a wall). Bands carry their height range z0..z1 (m, absolute) and angular range
    theta0..theta1 (rad) on a cylinder of ``radius`` (m).
    """

    name: str
    role: str
    triangles: np.ndarray = field(repr=False)
    band: int | None = None
    sector: int | None = None
    z0: float | None = None
    z1: float | None = None
    theta0: float | None = None
    theta1: float | None = None
    radius: float | None = None
    normal: tuple[float, float] | None = None     # sensors: horizontal direction the grains push
    projected_area: float | None = None           # sensors: |vector area| along ``normal``, m2

    @property
    def area(self) -> float:
        """Sum of triangle areas, m2."""
        t = self.triangles
        return float(0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum())

    def info(self) -> dict:
        """JSON-ready description (no triangles)."""
        keys = ("name", "role", "band", "sector", "z0", "z1", "theta0", "theta1", "radius", "normal",
                "projected_area")
        out = {k: getattr(self, k) for k in keys}
        out["area"] = self.area
        out["file"] = f"meshes/{self.name}.stl"
        out["n_triangles"] = int(len(self.triangles))
        return out


def _grid_triangles(points: np.ndarray) -> np.ndarray:
    """Triangulate a structured (nu+1, nv+1, 3) grid of points into 2 nu nv triangles."""
    a = points[:-1, :-1].reshape(-1, 3)
    b = points[1:, :-1].reshape(-1, 3)
    c = points[1:, 1:].reshape(-1, 3)
    d = points[:-1, 1:].reshape(-1, 3)
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def surface_of_revolution(r0: float, z0: float, r1: float, z1: float, theta0: float, theta1: float,
                          n_theta: int, n_axial: int) -> np.ndarray:
    """Triangles of the surface swept by the segment (r0, z0)-(r1, z1) over theta0..theta1."""
    theta = np.linspace(theta0, theta1, n_theta + 1)
    s = np.linspace(0.0, 1.0, n_axial + 1)
    r = r0 + (r1 - r0) * s
    z = z0 + (z1 - z0) * s
    pts = np.stack([r[:, None] * np.cos(theta)[None, :],
                    r[:, None] * np.sin(theta)[None, :],
                    np.broadcast_to(z[:, None], (len(s), len(theta)))], axis=-1)
    return _grid_triangles(pts)


def disc(radius: float, z: float, n_theta: int, inner_radius: float = 0.0) -> np.ndarray:
    """Triangles of a horizontal disc (or annulus when ``inner_radius`` > 0) at height z.

    Radial rings keep the triangles' aspect ratio near 1.
    """
    h = 2 * math.pi * radius / n_theta
    if inner_radius > 0:
        n_r = max(1, math.ceil((radius - inner_radius) / h))
        return surface_of_revolution(inner_radius, z, radius, z, 0.0, 2 * math.pi, n_theta, n_r)
    # centre fan plus rings
    n_r = max(1, math.ceil(radius / h))
    r_in = radius / n_r
    theta = np.linspace(0.0, 2 * math.pi, n_theta + 1)
    ring = np.stack([r_in * np.cos(theta), r_in * np.sin(theta), np.full_like(theta, z)], -1)
    centre = np.array([0.0, 0.0, z])
    fan = np.stack([np.broadcast_to(centre, (n_theta, 3)), ring[:-1], ring[1:]], 1)
    if n_r == 1:
        return fan
    rest = surface_of_revolution(r_in, z, radius, z, 0.0, 2 * math.pi, n_theta, n_r - 1)
    return np.concatenate([fan, rest])


def band_boundaries(case: Case) -> list[float]:
    """Band boundaries in m above the cylinder's base (the top of the hopper, if any)."""
    s = case.sensors
    if s.heights is not None:
        return list(s.heights)
    h = case.geometry.height
    return [h * i / s.bands for i in range(s.bands + 1)]


def silo_meshes(case: Case, outlet_z: float, outlet_radius: float) -> list[WallMesh]:
    """All meshes of a silo (cylinder, hopper or slab) and its inserts, in the order the deck lists them.

    ``outlet_z``, ``outlet_radius``: position and size of the counting disc below the orifice.
    """
    g = case.geometry
    if isinstance(g, PlanarGeometry):
        meshes = slab_meshes(case, outlet_z, outlet_radius)
    elif isinstance(g, (CylinderGeometry, HopperGeometry)):
        meshes = cylinder_meshes(case, outlet_z, outlet_radius)
    else:
        raise NotImplementedError(f"no meshes for geometry kind {g.kind!r}")
    return meshes[:-1] + insert_meshes(case) + meshes[-1:]          # the counting mesh stays last


def cylinder_meshes(case: Case, outlet_z: float, outlet_radius: float) -> list[WallMesh]:
    """Meshes of a cylindrical silo or hopper (see :func:`silo_meshes`)."""
    g = case.geometry
    R = g.radius
    base = g.hopper_height
    n_seg = g.mesh_segments
    sectors = case.sensors.sectors
    per_sector = max(1, math.ceil(n_seg / sectors))
    n_ring = per_sector * sectors
    h_facet = 2 * math.pi * R / n_ring
    meshes: list[WallMesh] = []

    def cylinder_piece(name, role, z_lo, z_hi, th0, th1, n_th, **kw):
        # the wall is straight along z: tall facets are exact and keep the triangle count
        # (which dominates LIGGGHTS' mesh-wall cost) low
        n_ax = max(1, math.ceil((z_hi - z_lo) / (MAX_FACET_ASPECT * h_facet)))
        tris = surface_of_revolution(R, z_lo, R, z_hi, th0, th1, n_th, n_ax)
        sensor = {}
        if role == "band":   # a sector's net force is along its mid direction (postprocess.wall_pressure)
            tc = 0.5 * (th0 + th1)
            sensor = {"normal": (math.cos(tc), math.sin(tc)),
                      "projected_area": 2.0 * R * (z_hi - z_lo) * math.sin(0.5 * (th1 - th0))}
        meshes.append(WallMesh(name, role, tris, z0=z_lo, z1=z_hi, theta0=th0, theta1=th1,
                               radius=R, **sensor, **kw))

    bounds = band_boundaries(case)
    if bounds[0] > 0:
        cylinder_piece("wall_below", "wall", base, base + bounds[0], 0.0, 2 * math.pi, n_ring)
    for b, (lo, hi) in enumerate(zip(bounds, bounds[1:])):
        for s in range(sectors):
            th0, th1 = 2 * math.pi * s / sectors, 2 * math.pi * (s + 1) / sectors
            cylinder_piece(f"band{b:02d}_s{s:02d}", "band", base + lo, base + hi, th0, th1,
                           per_sector, band=b, sector=s)
    if bounds[-1] < g.height:
        cylinder_piece("wall_above", "wall", base + bounds[-1], base + g.height, 0.0, 2 * math.pi, n_ring)

    r_out = g.outlet_radius
    if isinstance(g, HopperGeometry):
        slant = math.hypot(R - r_out, base)
        n_ax = max(1, math.ceil(slant / h_facet))
        meshes.append(WallMesh("cone", "cone", surface_of_revolution(r_out, 0.0, R, base, 0.0,
                                                                    2 * math.pi, n_ring, n_ax)))
    else:
        meshes.append(WallMesh("bottom", "bottom", disc(R, 0.0, n_ring, inner_radius=r_out)))
    meshes.append(WallMesh("plate", "plate", disc(r_out, 0.0, n_ring)))
    meshes.append(WallMesh("outlet", "outlet", disc(outlet_radius, outlet_z, n_ring)))
    return meshes


def rectangle(origin, e1, e2, n1: int, n2: int) -> np.ndarray:
    """Triangles of the parallelogram origin + u e1 + v e2 (u, v in [0, 1]) on an n1 x n2 grid."""
    u = np.linspace(0.0, 1.0, n1 + 1)
    v = np.linspace(0.0, 1.0, n2 + 1)
    pts = (np.asarray(origin, float)[None, None, :] + u[:, None, None] * np.asarray(e1, float)
           + v[None, :, None] * np.asarray(e2, float))
    return _grid_triangles(pts)


def _divisions(length: float, facet: float) -> int:
    return max(1, math.ceil(length / facet - 1e-9))


def slab_meshes(case: Case, outlet_z: float, outlet_half: float) -> list[WallMesh]:
    """Meshes of a quasi-2D slab silo (x across, y through the slab, z up; z = 0 the outlet):
    side walls cut into sensor sections (sector 0 at x = -width/2, sector 1 at +width/2),
    the wedge hopper, the front and back faces (role ``face``), the plate and the counting
    rectangle ``outlet_half`` wide at ``outlet_z`` (m)."""
    g = case.geometry
    a, b, hh, top = g.half_width, 0.5 * g.thickness, g.hopper_height, g.hopper_height + g.height
    w0 = g.outlet_radius
    # faces: few large facets (every grain touches the faces: their facet count is what costs);
    # thin walls: one facet across, at most MAX_FACET_ASPECT times longer
    facet = max(g.width / 2.0, g.thickness)
    long = MAX_FACET_ASPECT * g.thickness                # thin walls' facets along their length
    meshes: list[WallMesh] = []

    def side_piece(name, role, side, z_lo, z_hi, **kw):
        x = -a if side == 0 else a
        tris = rectangle((x, -b, z_lo), (0.0, 2 * b, 0.0), (0.0, 0.0, z_hi - z_lo), 1, _divisions(z_hi - z_lo, long))
        sensor = {"normal": (-1.0 if side == 0 else 1.0, 0.0), "projected_area": 2 * b * (z_hi - z_lo)} \
            if role == "band" else {}
        meshes.append(WallMesh(name, role, tris, z0=z_lo, z1=z_hi, sector=side, **sensor, **kw))

    bounds = band_boundaries(case)
    for side in (0, 1):
        if bounds[0] > 0:
            side_piece(f"wall_below_s{side:02d}", "wall", side, hh, hh + bounds[0])
    for k, (lo, hi) in enumerate(zip(bounds, bounds[1:])):
        for side in (0, 1):
            side_piece(f"band{k:02d}_s{side:02d}", "band", side, hh + lo, hh + hi, band=k)
    for side in (0, 1):
        if bounds[-1] < g.height:
            side_piece(f"wall_above_s{side:02d}", "wall", side, hh + bounds[-1], top)
    slant = math.hypot(a - w0, hh)
    for side, sign in ((0, -1.0), (1, 1.0)):
        meshes.append(WallMesh(f"hopper_s{side:02d}", "hopper", rectangle(
            (sign * w0, -b, 0.0), (0.0, 2 * b, 0.0), (sign * (a - w0), 0.0, hh), 1, _divisions(slant, long)), sector=side))
    # faces: the silo's outline in x-z (wedge, then the full width), on a grid of trapezoid rows
    nz_h, nz_v = _divisions(hh, facet), _divisions(g.height, facet)
    z = np.concatenate([np.linspace(0.0, hh, nz_h + 1), np.linspace(hh, top, nz_v + 1)[1:]])
    half = np.where(z < hh, w0 + (a - w0) * z / max(hh, 1e-300), a)
    nx = _divisions(g.width, facet)
    u = np.linspace(-1.0, 1.0, nx + 1)
    for side, y in ((0, -b), (1, b)):
        pts = np.stack([half[:, None] * u[None, :], np.full((len(z), nx + 1), y),
                        np.broadcast_to(z[:, None], (len(z), nx + 1))], axis=-1)
        meshes.append(WallMesh(f"face_s{side:02d}", "face", _grid_triangles(pts), sector=side))
    meshes.append(WallMesh("plate", "plate", rectangle((-w0, -b, 0.0), (2 * w0, 0.0, 0.0), (0.0, 2 * b, 0.0),
                                                       _divisions(2 * w0, facet), 1)))
    meshes.append(WallMesh("outlet", "outlet", rectangle((-outlet_half, -1.5 * b, outlet_z),
                                                         (2 * outlet_half, 0.0, 0.0), (0.0, 3 * b, 0.0),
                                                         _divisions(2 * outlet_half, facet), 1)))
    return meshes


class MeshError(ValueError):
    """A user mesh file that cannot be used (unreadable, not STL, non-finite, degenerate, outside)."""


#: user STL files larger than this are refused (a silo insert needs far fewer triangles)
MAX_USER_MESH_BYTES = 50_000_000


def read_user_mesh(path, scale: float = 1.0) -> np.ndarray:
    """Triangles (n, 3, 3), m, of a user's ASCII or binary STL file, checked: finite vertices and
    no degenerate (zero-area) triangle. Raises ``MeshError`` saying what is wrong."""
    path = Path(path)
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise MeshError(f"cannot read {path}: {exc.strerror}") from None
    if size > MAX_USER_MESH_BYTES:
        raise MeshError(f"{path} is larger than {MAX_USER_MESH_BYTES} bytes")
    try:
        tris = np.array(stl_mesh.Mesh.from_file(str(path)).vectors, dtype=float)
    except Exception as exc:        # numpy-stl raises many kinds on foreign bytes
        raise MeshError(f"{path} is not an STL file ({type(exc).__name__}: {str(exc)[:120]})") from None
    if tris.ndim != 3 or len(tris) == 0:
        raise MeshError(f"{path} holds no triangles")
    tris = tris * scale
    if not np.all(np.isfinite(tris)):
        raise MeshError(f"{path} has non-finite vertex coordinates")
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    extent = float(np.ptp(tris.reshape(-1, 3), axis=0).max())
    bad = int((area <= 1e-12 * extent * extent).sum())
    if bad:
        raise MeshError(f"{path} has {bad} degenerate (zero-area) triangle(s) of {len(tris)}")
    return tris


def check_inside(case: Case, tris: np.ndarray) -> None:
    """Refuse a mesh that reaches outside the silo (LIGGGHTS needs walls inside its box)."""
    g = case.geometry
    p = tris.reshape(-1, 3)
    top = g.hopper_height + g.height
    if isinstance(g, PlanarGeometry):
        inside = (np.abs(p[:, 0]) <= g.half_width) & (np.abs(p[:, 1]) <= 0.5 * g.thickness)
    else:
        inside = np.hypot(p[:, 0], p[:, 1]) <= g.radius
    inside &= (p[:, 2] >= 0.0) & (p[:, 2] <= top)
    if not inside.all():
        lo, hi = p.min(axis=0), p.max(axis=0)
        raise MeshError(f"the mesh reaches outside the silo (it spans x {lo[0]:.4g}..{hi[0]:.4g}, y "
                        f"{lo[1]:.4g}..{hi[1]:.4g}, z {lo[2]:.4g}..{hi[2]:.4g} m; check 'scale')")


def insert_meshes(case: Case) -> list[WallMesh]:
    """The case's user walls, read from their files (relative paths from the working folder)."""
    return [WallMesh(ins.mesh_name, "insert", read_user_mesh(ins.file, ins.scale)) for ins in case.inserts]


def write_stl(wall: WallMesh, path) -> None:
    """Write ``wall`` as ASCII STL (LIGGGHTS 3.8 reads ASCII), atomically."""
    m = stl_mesh.Mesh(np.zeros(len(wall.triangles), dtype=stl_mesh.Mesh.dtype))
    m.vectors[:] = wall.triangles
    m.update_normals()
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "wb") as fh:
        m.save(wall.name, fh=fh, mode=Mode.ASCII, update_normals=False)
    os.replace(tmp, path)
