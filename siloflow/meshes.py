"""Wall meshes of a silo, generated as triangle arrays and written as ASCII STL.

z = 0 is the outlet plane. Every cylinder band is split into ``sectors`` azimuthal
meshes, so that each (band, sector) is a force sensor whose net radial force is
not cancelled by the opposite side of the ring (docs/engine_facts.md).

Mesh quality: LIGGGHTS 3.8 refuses a mesh with a triangle whose smallest angle is below the
``curvature`` of ``fix mesh/surface`` (default 0.256 deg, ``SurfaceMesh::qualityCheck``: "The minumum
angle of mesh element ... is lower than the specified curvature ... Bad mesh") and merges nodes
closer than its ``precision`` (1e-8 m). Every generated wall is checked (:func:`check_wall`): its
smallest angle is at least ``MIN_ANGLE_DEG`` and its shortest edge at least ``MIN_EDGE``. The simple
structured grids are kept where they meet that; elsewhere (flat or steep hoppers, orifices much
smaller than the silo or nearly as wide, thin bands) the surface is triangulated anew with graded
rings (surfaces of revolution) or a Delaunay refinement (the slab's faces). A geometry that no
triangulation within ``MAX_MESH_TRIANGLES`` can mesh is refused with a ``CaseError`` naming the
geometry fields that shape the wall.
"""
from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from stl import mesh as stl_mesh
from stl import Mode

from .case import Case, CylinderGeometry, HopperGeometry, PlanarGeometry
from .errors import CaseError, SetupError


#: longest/shortest side of the cylinder facets
MAX_FACET_ASPECT = 10.0
#: LIGGGHTS' default ``curvature`` of fix mesh/surface, deg: acos(1 - 1e-5). A triangle with a smaller
#: angle stops the run ("Bad mesh, cannot continue").
LIGGGHTS_CURVATURE_DEG = math.degrees(math.acos(1.0 - 1e-5))
#: LIGGGHTS warns about triangles with an angle below this, deg ("highly skewed element")
LIGGGHTS_SKEWED_DEG = 0.5
#: LIGGGHTS' default mesh ``precision``, m: nodes closer than this are taken as one node
LIGGGHTS_PRECISION = 1e-8
#: smallest extent of a mesh LIGGGHTS accepts, m: a smaller one stops the run ("Mesh error - root
#: causes: (a) mesh empty or (b) dimensions too small"). Measured on LIGGGHTS 3.8: a 96 um square
#: refused, a 100 um square and a 2 mm x 48 um strip accepted (its largest extent counts)
LIGGGHTS_MIN_MESH_EXTENT = 1e-4
#: smallest angle of every triangle siloflow generates, deg (8 x LIGGGHTS' curvature, 4 x its warning)
MIN_ANGLE_DEG = 2.0
#: shortest edge of every triangle siloflow generates, m (10 x LIGGGHTS' precision)
MIN_EDGE = 10 * LIGGGHTS_PRECISION
#: most triangles of one generated wall (an ASCII STL of about 140 MB)
MAX_MESH_TRIANGLES = 500_000
#: re-triangulations: most cell aspect of the graded rings' end rows, growth of the ring spacing
#: per unit distance (m/m), fewest points of a ring, and the Delaunay refinement's target smallest
#: angle (deg)
ROW_ASPECT = 4.0
GRADING = 0.5
MIN_RING_POINTS = 6
REFINE_ANGLE_DEG = 25.0


class MeshQualityError(ValueError):
    """A generated wall that cannot be triangulated well: ``reason``, and the ``wall``'s name and role
    once known (:func:`silo_meshes` turns it into a ``CaseError``)."""

    def __init__(self, reason: str, wall: str = "", role: str = "", kind: str = "angle"):
        super().__init__(f"{wall}: {reason}" if wall else reason)
        self.reason, self.wall, self.role, self.kind = reason, wall, role, kind


# --------------------------------------------------------------------------- quality
def _edges(tris: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """Edge vectors (edge k from vertex k to k+1) and their lengths (n, 3) of triangles (n, 3, 3)."""
    t = np.asarray(tris, dtype=float)
    e = [t[:, 1] - t[:, 0], t[:, 2] - t[:, 1], t[:, 0] - t[:, 2]]
    return e, np.sqrt(np.stack([np.einsum("ij,ij->i", v, v) for v in e], axis=1))


def triangle_angles(tris: np.ndarray) -> np.ndarray:
    """Angles (n, 3) of triangles (n, 3, 3), deg, at each vertex; 0 for a degenerate triangle. As
    LIGGGHTS measures them (calcObtuseAngleIndex): from the unit edge vectors at each vertex."""
    e, length = _edges(tris)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.stack([-np.einsum("ij,ij->i", e[k], e[k - 1]) / (length[:, k] * length[:, k - 1])
                        for k in range(3)], axis=1)
    return np.degrees(np.arccos(np.clip(np.nan_to_num(cos, nan=1.0), -1.0, 1.0)))


def min_angles(tris: np.ndarray) -> np.ndarray:
    """Smallest angle of each triangle, deg."""
    return triangle_angles(tris).min(axis=1) if len(tris) else np.zeros(0)


def aspect_ratios(tris: np.ndarray) -> np.ndarray:
    """Longest edge over the shortest height of each triangle (1.15 for an equilateral one; inf when
    degenerate)."""
    e, length = _edges(tris)
    double_area = np.linalg.norm(np.cross(e[0], e[2]), axis=1)
    longest = length.max(axis=1)
    with np.errstate(divide="ignore"):
        return np.where(double_area > 0, longest * longest / np.maximum(double_area, 1e-300), np.inf)


@dataclass(frozen=True)
class MeshQuality:
    """Smallest angle (deg), largest aspect ratio, shortest edge (m) and size of a mesh."""

    min_angle: float
    max_aspect: float
    min_edge: float
    n_triangles: int
    worst: int              # index of the triangle with the smallest angle

    def problem(self, min_angle: float = MIN_ANGLE_DEG, min_edge: float = MIN_EDGE) -> str | None:
        """What makes the mesh unusable (None if nothing does)."""
        if self.n_triangles == 0:
            return "it has no triangles"
        if self.min_angle < min_angle:
            return (f"triangle {self.worst} has a smallest angle of {self.min_angle:.3g} deg (aspect ratio "
                    f"{self.max_aspect:.3g}); siloflow needs >= {min_angle:g} deg (LIGGGHTS refuses triangles "
                    f"below its curvature, {LIGGGHTS_CURVATURE_DEG:.3g} deg)")
        if self.min_edge < min_edge:
            return (f"it has an edge of {self.min_edge:.3g} m; LIGGGHTS merges mesh nodes closer than "
                    f"{LIGGGHTS_PRECISION:g} m, so siloflow needs edges >= {min_edge:g} m")
        return None


def mesh_quality(tris: np.ndarray) -> MeshQuality:
    """Quality figures of a triangle array (n, 3, 3) in m."""
    if len(tris) == 0:
        return MeshQuality(0.0, math.inf, 0.0, 0, -1)
    angles = min_angles(tris)
    _, length = _edges(tris)
    worst = int(np.argmin(angles))
    return MeshQuality(float(angles[worst]), float(aspect_ratios(tris).max()), float(length.min()), len(tris), worst)


def as_written(tris: np.ndarray) -> np.ndarray:
    """The triangles as LIGGGHTS reads them back: STL stores float32 coordinates."""
    return np.asarray(tris).astype(np.float32).astype(np.float64)


def _good(tris: np.ndarray) -> bool:
    return len(tris) > 0 and mesh_quality(as_written(tris)).problem() is None


def _budget(n_triangles: int, what: str) -> None:
    if n_triangles > MAX_MESH_TRIANGLES:
        raise MeshQualityError(f"{what} needs {n_triangles} triangles to keep every angle >= {MIN_ANGLE_DEG:g} "
                               f"deg, more than siloflow writes for one wall ({MAX_MESH_TRIANGLES})", kind="budget")


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


# --------------------------------------------------------------------------- re-triangulation tools
def _zip(a: np.ndarray, ua: np.ndarray, b: np.ndarray, ub: np.ndarray) -> np.ndarray:
    """Triangles between two polylines ``a`` (na, 3) and ``b`` (nb, 3) running the same way, with
    parameters ``ua``, ``ub`` increasing from 0 to 1 along them: each step advances along the line
    whose next point comes first (ties: ``b``), so no triangle spans far along either line. For
    ``a`` below ``b`` (a grid's rows i and i+1) the triangles are oriented as :func:`_grid_triangles` does."""
    na, nb = len(a), len(b)
    keys = np.concatenate([ua[1:], ub[1:]])
    is_a = np.concatenate([np.ones(na - 1, bool), np.zeros(nb - 1, bool)])
    order = np.lexsort((is_a, keys))                 # by parameter, b's point first on a tie
    is_a = is_a[order]
    i = np.concatenate([[0], np.cumsum(is_a)[:-1]])       # state before each step
    j = np.concatenate([[0], np.cumsum(~is_a)[:-1]])
    third = np.where(is_a[:, None], a[np.minimum(i + 1, na - 1)], b[np.minimum(j + 1, nb - 1)])
    first, second = a[i], b[j]
    # a step along a: (a_i, b_j, a_i+1); along b: (a_i, b_j, b_j+1)
    return np.stack([first, second, third], axis=1)


def _ring(r: float, z: float, n: int, m: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Points (n m + 1, 3) and parameters of the closed n-gon of radius r (m) at height z (m), corners
    at angles 2 pi j / n, each side split into m equal parts (the last point repeats the first, as
    :func:`surface_of_revolution`'s rings do)."""
    theta = np.linspace(0.0, 2 * math.pi, n + 1)
    corners = np.stack([r * np.cos(theta), r * np.sin(theta)], axis=-1)
    if m > 1:
        f = np.arange(m) / m
        xy = (corners[:-1, None, :] + f[None, :, None] * (corners[1:] - corners[:-1])[:, None, :]).reshape(-1, 2)
        xy = np.concatenate([xy, corners[-1:]])
    else:
        xy = corners
    u = np.linspace(0.0, 1.0, n * m + 1)
    return np.column_stack([xy, np.full(len(xy), z)]), u


def _chord(r: float, n: int) -> float:
    return 2.0 * r * math.sin(math.pi / n)


def _ring_spacing(length: float, e0: float, e1: float, cap: float):
    """sigma(s): a ring spacing (m) at distance s (m) from the first ring: at most ``cap`` (m), growing
    away from the ends' spacings ``e0`` and ``e1`` (m; inf: no constraint) by ``GRADING`` times the
    distance from them."""
    def sigma(s):
        s = np.asarray(s, dtype=float)
        out = np.full(s.shape, cap)
        if math.isfinite(e0):
            out = np.minimum(out, e0 + GRADING * s)
        if math.isfinite(e1):
            out = np.minimum(out, e1 + GRADING * (length - s))
        return out
    return sigma


def _row_positions(length: float, sigma, ends: tuple[float, float], beta: float,
                   max_rows: int = MAX_MESH_TRIANGLES) -> np.ndarray | None:
    """Positions (m) of rows from 0 to ``length``, spaced about ``beta`` times sigma(s); None if that
    takes more than ``max_rows`` rows."""
    grid = [np.linspace(0.0, length, 4001)]
    for k, e in enumerate(ends):       # geometric near an end with fine spacing
        if math.isfinite(e) and e < length:
            g = np.geomspace(1e-3 * e, length, 2000)
            grid.append(g if k == 0 else length - g)
    s = np.unique(np.clip(np.concatenate(grid), 0.0, length))
    inv = 1.0 / (beta * sigma(s))
    t = np.concatenate([[0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(s))])
    if not t[-1] < max_rows:
        return None
    k = max(1, int(round(t[-1])))
    rows = np.interp(np.linspace(0.0, t[-1], k + 1), t, s)
    rows[0], rows[-1] = 0.0, length
    return rows


def _rings_to_triangles(rings: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Triangles between consecutive rings (points, parameters); a one-point ring is a fan's centre."""
    parts = []
    for (pa, ua), (pb, ub) in zip(rings, rings[1:]):
        centre = len(pa) == 1 or len(pb) == 1
        if len(pa) == 1:
            pa, ua = np.repeat(pa, 2, axis=0), np.array([0.0, 1.0])
        if len(pb) == 1:
            pb, ub = np.repeat(pb, 2, axis=0), np.array([0.0, 1.0])
        tri = _zip(pa, ua, pb, ub)
        if centre:                           # the fan's steps along the centre's two copies are empty
            tri = tri[np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) > 0]
        parts.append(tri)
    return np.concatenate(parts)


def graded_disc(r0: float, r1: float, z: float, n: int) -> np.ndarray:
    """Triangles of the horizontal annulus r0..r1 (m; a disc when r0 = 0) at height z (m) whose
    boundaries are the n-gons of :func:`disc` (their sides split evenly where the annulus is narrow),
    filled with rings whose point spacing is about their distance and grows by at most ``GRADING``
    times the distance from a boundary (the disc is flat: inner rings may have fewer points). No
    sliver next to a small orifice, however many ``mesh_segments``, nor in a narrow ring."""
    length = r1 - r0
    sig0 = _chord(r0, n) if r0 > 0 else math.inf
    sig1 = _chord(r1, n)
    cap = min(sig1 if r0 == 0 else max(sig0, sig1), ROW_ASPECT * length)
    m0 = max(1, math.ceil(sig0 / cap - 1e-9)) if r0 > 0 else 1
    m1 = max(1, math.ceil(sig1 / cap - 1e-9))
    e0, e1 = sig0 / m0, sig1 / m1
    sigma = _ring_spacing(length, e0, e1, cap)
    s = _row_positions(length, sigma, (e0, e1), 1.0)
    if s is None:
        _budget(MAX_MESH_TRIANGLES + 1, f"a disc from r = {r0:.3g} to {r1:.3g} m with {n} sides")
    r = r0 + s
    counts = [(n, m0) if r0 > 0 else None]
    counts += [(max(MIN_RING_POINTS, int(round(2 * math.pi * r[k] / float(sigma(s[k]))))), 1)
               for k in range(1, len(s) - 1)]
    counts.append((n, m1))
    points = [1 if c is None else c[0] * c[1] + 1 for c in counts]
    _budget(sum(p + q - 2 for p, q in zip(points, points[1:])),
            f"a disc from r = {r0:.3g} to {r1:.3g} m with {n} sides")
    return _rings_to_triangles([(np.array([[0.0, 0.0, z]]), np.array([0.0, 1.0])) if c is None
                                else _ring(r[k], z, *c) for k, c in enumerate(counts)])


def revolution_rows(r0: float, z0: float, r1: float, z1: float, n: int) -> np.ndarray:
    """Triangles of the surface swept about the z axis by the segment (r0, z0)-(r1, z1) (m, r0, r1
    > 0, a cone): every ring is the n-gon of :func:`surface_of_revolution` (sides split evenly where the
    cone is a narrow band), so the surface is the same polygonal cone, and the rings are spaced by
    their own side length, so the facets stay near square from a small outlet to the cylinder
    (stretched up to ``MAX_FACET_ASPECT`` along the cone when even rows would exceed
    ``MAX_MESH_TRIANGLES``, as the cylinder's facets are)."""
    length = math.hypot(r1 - r0, z1 - z0)
    m = max(1, math.ceil(max(_chord(r0, n), _chord(r1, n)) / (ROW_ASPECT * length) - 1e-9))
    k = n * m

    def sigma(s):
        return _chord(1.0, k) * (r0 + (r1 - r0) * np.asarray(s, dtype=float) / length)
    s, n_tri = None, MAX_MESH_TRIANGLES + 1
    for beta in (1.0, 3.0, MAX_FACET_ASPECT):
        s = _row_positions(length, sigma, (_chord(r0, k), _chord(r1, k)), beta, MAX_MESH_TRIANGLES // (2 * k) + 1)
        if s is not None and 2 * k * (len(s) - 1) <= MAX_MESH_TRIANGLES:
            n_tri = 2 * k * (len(s) - 1)
            break
    _budget(n_tri, f"a cone {length:.3g} m long from r = {r0:.3g} to {r1:.3g} m with {n} sides")
    f = s / length
    return _rings_to_triangles([_ring(r0 + (r1 - r0) * fk, z0 + (z1 - z0) * fk, n, m) for fk in f])


def _balanced(l1: float, l2: float, n1: int, n2: int, aspect: float = MAX_FACET_ASPECT) -> tuple[int, int]:
    """Divisions (n1, n2) of a rectangle l1 x l2 (m), raised where needed so that no cell is more
    than ``aspect`` times longer one way than the other."""
    c1, c2 = l1 / n1, l2 / n2
    if c1 > aspect * c2:
        n1 = math.ceil(l1 / (aspect * c2) - 1e-9)
    elif c2 > aspect * c1:
        n2 = math.ceil(l2 / (aspect * c1) - 1e-9)
    return n1, n2


def _refine_polygon(poly: np.ndarray, size: float, min_angle: float = REFINE_ANGLE_DEG,
                    max_points: int = MAX_MESH_TRIANGLES // 2) -> tuple[np.ndarray, np.ndarray]:
    """Quality triangulation of a convex polygon (m, 2; m, counter-clockwise, no angle below 90 deg)
    by Delaunay refinement (Ruppert's algorithm): encroached boundary pieces are halved and the
    circumcentres of triangles with an angle below ``min_angle`` (deg) or a circumradius above
    0.7 ``size`` (m) are inserted, until none is left. Returns points (k, 2) and counter-clockwise
    triangles (n, 3) of indices. Triangles grade from small features (a narrow slot) to ``size``."""
    from scipy.spatial import Delaunay, QhullError, cKDTree

    poly = np.asarray(poly, dtype=float)
    sides = np.roll(poly, -1, axis=0) - poly
    boundary = int(np.ceil(np.linalg.norm(sides, axis=1) / size).sum())
    if boundary > max_points:
        raise MeshQualityError(f"the outline needs more than {max_points} points", kind="budget")
    pts = [p for p in poly]
    chains = []                                   # per polygon side: point indices from its start to its end
    for k in range(len(poly)):
        a, b = poly[k], poly[(k + 1) % len(poly)]
        n = max(1, math.ceil(np.linalg.norm(b - a) / size - 1e-9))
        chain = [k]
        for i in range(1, n):
            pts.append(a + (b - a) * (i / n))
            chain.append(len(pts) - 1)
        chains.append(chain + [(k + 1) % len(poly)])
    cos_limit = math.cos(math.radians(min_angle))
    tri, final = None, False
    for _ in range(400):
        p = np.asarray(pts)
        seg = np.array([(c[i], c[i + 1]) for c in chains for i in range(len(c) - 1)])
        centre = 0.5 * (p[seg[:, 0]] + p[seg[:, 1]])
        half = 0.5 * np.linalg.norm(p[seg[:, 0]] - p[seg[:, 1]], axis=1)
        split = set()
        for s, near in enumerate(cKDTree(p).query_ball_point(centre, half * (1 - 1e-9))):
            if any(j != seg[s, 0] and j != seg[s, 1] for j in near):
                split.add(s)
        new = []
        if not split:
            try:
                tri = Delaunay(p).simplices
            except QhullError as exc:
                raise MeshQualityError(f"the outline cannot be triangulated ({str(exc).splitlines()[0]})") from None
            a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
            cross = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
            flip = cross < 0
            tri[flip] = tri[flip][:, [0, 2, 1]]
            b, c, cross = np.where(flip[:, None], c, b), np.where(flip[:, None], b, c), np.abs(cross)
            la, lb, lc = (np.linalg.norm(c - b, axis=1), np.linalg.norm(a - c, axis=1), np.linalg.norm(b - a, axis=1))
            longest = np.maximum(np.maximum(la, lb), lc)
            ok = cross > 1e-12 * longest * longest
            with np.errstate(invalid="ignore", divide="ignore"):
                cosines = np.stack([(lb**2 + lc**2 - la**2) / (2 * lb * lc), (la**2 + lc**2 - lb**2) / (2 * la * lc),
                                    (la**2 + lb**2 - lc**2) / (2 * la * lb)], axis=1)
                radius = la * lb * lc / (2 * np.where(ok, cross, 1.0))
            bad = ok & ((cosines.max(axis=1) > cos_limit) | (radius > 0.7 * size))
            if not bad.any():
                final = True
                break
            # circumcentres of the bad triangles, largest first
            d = 2 * cross
            ab, ac = b - a, c - a
            ux = (ac[:, 1] * (ab**2).sum(1) - ab[:, 1] * (ac**2).sum(1)) / np.where(ok, d, 1.0)
            uy = (ab[:, 0] * (ac**2).sum(1) - ac[:, 0] * (ab**2).sum(1)) / np.where(ok, d, 1.0)
            cc = a + np.stack([ux, uy], axis=1)
            idx = np.flatnonzero(bad)
            idx = idx[np.argsort(-radius[idx])]
            cc, rr = cc[idx], radius[idx]
            seg_tree = cKDTree(centre)
            near_seg = seg_tree.query_ball_point(cc, half.max())
            inside = ((sides[None, :, 0] * (cc[:, None, 1] - poly[None, :, 1])
                       - sides[None, :, 1] * (cc[:, None, 0] - poly[None, :, 0])) > 0).all(axis=1)
            candidate = []
            for k in range(len(cc)):
                enc = [s for s in near_seg[k] if np.linalg.norm(cc[k] - centre[s]) < half[s]]
                if enc:
                    split.update(enc)
                elif inside[k]:
                    candidate.append(k)
            if candidate:
                cand = np.array(candidate)
                neigh = cKDTree(cc[cand]).query_ball_point(cc[cand], rr[cand])
                accepted = np.zeros(len(cand), bool)
                for k in range(len(cand)):          # an independent set: no two cavities overlap
                    if not any(accepted[j] for j in neigh[k] if j < k):
                        accepted[k] = True
                new = list(cc[cand[accepted]])
        if split:
            flat = [(ci, i) for ci, c in enumerate(chains) for i in range(len(c) - 1)]
            by_chain: dict[int, set[int]] = {}
            for s in split:
                ci, i = flat[s]
                by_chain.setdefault(ci, set()).add(i)
            for ci, where in by_chain.items():
                c = chains[ci]
                out = []
                for i in range(len(c) - 1):
                    out.append(c[i])
                    if i in where:
                        pts.append(0.5 * (np.asarray(pts[c[i]]) + np.asarray(pts[c[i + 1]])))
                        out.append(len(pts) - 1)
                out.append(c[-1])
                chains[ci] = out
        if not split and not new:
            break
        pts.extend(new)
        if len(pts) > max_points:
            raise MeshQualityError(f"the outline needs more than {max_points} points", kind="budget")
    p = np.asarray(pts)
    if not final:
        tri = Delaunay(p).simplices
        a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
        cross = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
        tri[cross < 0] = tri[cross < 0][:, [0, 2, 1]]
    return p, tri


def band_boundaries(case: Case) -> list[float]:
    """Band boundaries in m above the cylinder's base (the top of the hopper, if any)."""
    s = case.sensors
    if s.heights is not None:
        return list(s.heights)
    h = case.geometry.height
    return [h * i / s.bands for i in range(s.bands + 1)]


def silo_meshes(case: Case, outlet_z: float, outlet_radius: float, sensors: bool = True) -> list[WallMesh]:
    """All meshes of a silo (cylinder, hopper or slab) and its inserts, in the order the deck lists them.

    ``outlet_z``, ``outlet_radius``: position and size of the counting disc below the orifice.
    Without ``sensors`` the side walls' pieces (bands and the rest) are one mesh ``wall`` of the
    same facets: no result reads their pressure. Every generated wall is checked
    (:func:`check_wall`); one that cannot be triangulated well is refused with a ``CaseError``
    naming the geometry fields that shape it.
    """
    g = case.geometry
    try:
        if isinstance(g, PlanarGeometry):
            meshes = slab_meshes(case, outlet_z, outlet_radius)
        elif isinstance(g, (CylinderGeometry, HopperGeometry)):
            meshes = cylinder_meshes(case, outlet_z, outlet_radius)
        else:
            raise NotImplementedError(f"no meshes for geometry kind {g.kind!r}")
        if not sensors:
            meshes = merge_side_walls(meshes)
        for w in meshes:
            check_wall(w)
    except MeshQualityError as exc:
        fields = shaping_fields(case, exc.role, exc.kind)
        raise CaseError([(fields[0], f"the wall mesh '{exc.wall}' cannot be triangulated for LIGGGHTS: "
                          f"{exc.reason}; change {' or '.join(fields)}")], case.name) from None
    return meshes[:-1] + insert_meshes(case) + meshes[-1:]          # the counting mesh stays last


def merge_side_walls(meshes: list[WallMesh]) -> list[WallMesh]:
    """The meshes with every side-wall piece (roles ``band`` and ``wall``) merged into one plain
    wall ``wall`` of the same triangles, where the first piece was."""
    side = [m for m in meshes if m.role in ("band", "wall")]
    if not side:
        return meshes
    merged = WallMesh("wall", "wall", np.concatenate([m.triangles for m in side]))
    first = meshes.index(side[0])
    rest = [m for m in meshes if m.role not in ("band", "wall")]
    return rest[:first] + [merged] + rest[first:]


def check_wall(wall: WallMesh) -> None:
    """Raise ``MeshQualityError`` if a generated wall, as written (float32), has a triangle with an
    angle below ``MIN_ANGLE_DEG`` or an edge shorter than ``MIN_EDGE``."""
    quality = mesh_quality(as_written(wall.triangles))
    problem = quality.problem()
    if problem:
        kind = "edge" if quality.n_triangles and quality.min_angle >= MIN_ANGLE_DEG else "angle"
        raise MeshQualityError(problem, wall.name, wall.role, kind)
    points = np.asarray(wall.triangles).reshape(-1, 3)
    extent = float((points.max(axis=0) - points.min(axis=0)).max())
    if extent < 1.05 * LIGGGHTS_MIN_MESH_EXTENT:      # 5 % margin over the measured limit
        raise MeshQualityError(f"the mesh is {extent:.3g} m across; LIGGGHTS refuses meshes smaller than about "
                               f"{LIGGGHTS_MIN_MESH_EXTENT:g} m ('Mesh error ... dimensions too small')",
                               wall.name, wall.role, "edge")


def shaping_fields(case: Case, role: str, kind: str = "angle") -> list[str]:
    """The case fields that shape a wall of ``role``, the likeliest culprit first (for ``kind``
    'edge', a too short edge: the outlet's size, which sets the hopper's shortest sides)."""
    g = case.geometry
    sensors = "sensors.heights" if case.sensors.heights is not None else "sensors.bands"
    if kind == "edge" and role in ("hopper", "cone", "bottom", "plate", "outlet"):
        if isinstance(g, PlanarGeometry):
            return ["geometry.outlet_width", "geometry.width", "geometry.half_angle_deg", "geometry.thickness"]
        orifice = "geometry.outlet_radius" if isinstance(g, HopperGeometry) else "geometry.orifice_radius"
        return [orifice, "geometry.mesh_segments", "geometry.radius"]
    if isinstance(g, PlanarGeometry):
        return {"band": [sensors, "geometry.height", "geometry.thickness"],
                "wall": [sensors, "geometry.height", "geometry.thickness"],
                "hopper": ["geometry.half_angle_deg", "geometry.outlet_width", "geometry.width", "geometry.thickness"],
                "face": ["geometry.half_angle_deg", "geometry.outlet_width", "geometry.width", "geometry.height"],
                }.get(role, ["geometry.outlet_width", "geometry.thickness"])
    orifice = "geometry.outlet_radius" if isinstance(g, HopperGeometry) else "geometry.orifice_radius"
    return {"band": [sensors, "geometry.height", "geometry.mesh_segments", "sensors.sectors"],
            "wall": [sensors, "geometry.height", "geometry.mesh_segments"],
            "cone": ["geometry.half_angle_deg", orifice, "geometry.radius", "geometry.mesh_segments"],
            "bottom": [orifice, "geometry.radius", "geometry.mesh_segments"],
            }.get(role, [orifice, "geometry.mesh_segments"])


def _wall(name: str, role: str, build, **kw) -> WallMesh:
    """``WallMesh(name, role, build(), **kw)``, with a triangulation failure named after the wall."""
    try:
        return WallMesh(name, role, build(), **kw)
    except MeshQualityError as exc:
        raise MeshQualityError(exc.reason, name, role, exc.kind) from None


def _structured_or_graded(count: int, structured, graded) -> np.ndarray:
    """The structured triangles (``count`` of them) where they are good, else the graded ones."""
    if count <= MAX_MESH_TRIANGLES:
        tris = structured()
        if _good(tris):
            return tris
    return graded()


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
    side = _chord(g.outlet_radius, n_ring)
    if side < MIN_EDGE:                  # the orifice's polygon itself: no need to mesh the rest first
        raise MeshQualityError(f"its {n_ring}-gon of radius {g.outlet_radius:.3g} m has sides of {side:.3g} m; "
                               f"LIGGGHTS merges mesh nodes closer than {LIGGGHTS_PRECISION:g} m, so siloflow "
                               f"needs edges >= {MIN_EDGE:g} m", "plate", "plate", "edge")

    def cylinder_tris(z_lo, z_hi, th0, th1, n_th):
        dz = z_hi - z_lo
        if not dz > 0:
            raise MeshQualityError(f"it spans no height (z {z_lo:.9g} to {z_hi:.9g} m)")
        # the wall is straight along z: tall facets are exact and keep the triangle count
        # (which dominates LIGGGHTS' mesh-wall cost) low
        n_ax = max(1, math.ceil(dz / (MAX_FACET_ASPECT * h_facet)))
        if 2 * n_th * n_ax <= MAX_MESH_TRIANGLES:
            tris = surface_of_revolution(R, z_lo, R, z_hi, th0, th1, n_th, n_ax)
            if _good(tris):
                return tris
        # a piece much lower than its facets are wide: split each facet along its chord (flat, so the
        # wall stays the same polygon) into pieces at most MAX_FACET_ASPECT times wider than high
        m = max(1, math.ceil(h_facet / (MAX_FACET_ASPECT * dz) - 1e-9))
        _budget(2 * n_th * m * n_ax, f"a piece {dz:.3g} m high of facets {h_facet:.3g} m wide")
        theta = np.linspace(th0, th1, n_th + 1)
        corners = np.stack([R * np.cos(theta), R * np.sin(theta)], axis=-1)
        f = np.arange(m) / m
        xy = (corners[:-1, None, :] + f[None, :, None] * (corners[1:] - corners[:-1])[:, None, :]).reshape(-1, 2)
        xy = np.concatenate([xy, corners[-1:]])
        z = np.linspace(z_lo, z_hi, n_ax + 1)
        pts = np.concatenate([np.broadcast_to(xy[None], (len(z),) + xy.shape),
                              np.broadcast_to(z[:, None, None], (len(z), len(xy), 1))], axis=-1)
        return _grid_triangles(pts)

    def cylinder_piece(name, role, z_lo, z_hi, th0, th1, n_th, **kw):
        sensor = {}
        if role == "band":   # a sector's net force is along its mid direction (postprocess.wall_pressure)
            tc = 0.5 * (th0 + th1)
            sensor = {"normal": (math.cos(tc), math.sin(tc)),
                      "projected_area": 2.0 * R * (z_hi - z_lo) * math.sin(0.5 * (th1 - th0))}
        meshes.append(_wall(name, role, lambda: cylinder_tris(z_lo, z_hi, th0, th1, n_th), z0=z_lo, z1=z_hi,
                            theta0=th0, theta1=th1, radius=R, **sensor, **kw))

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

    def disc_tris(radius, z, inner=0.0):
        h = 2 * math.pi * radius / n_ring
        n_r = max(1, math.ceil((radius - inner) / h))
        count = 2 * n_ring * n_r if inner > 0 else n_ring * (2 * n_r - 1)
        return _structured_or_graded(count, lambda: disc(radius, z, n_ring, inner_radius=inner),
                                     lambda: graded_disc(inner, radius, z, n_ring))

    r_out = g.outlet_radius
    if isinstance(g, HopperGeometry):
        slant = math.hypot(R - r_out, base)
        n_ax = max(1, math.ceil(slant / h_facet))
        meshes.append(_wall("cone", "cone", lambda: _structured_or_graded(
            2 * n_ring * n_ax, lambda: surface_of_revolution(r_out, 0.0, R, base, 0.0, 2 * math.pi, n_ring, n_ax),
            lambda: revolution_rows(r_out, 0.0, R, base, n_ring))))
    else:
        meshes.append(_wall("bottom", "bottom", lambda: disc_tris(R, 0.0, r_out)))
    meshes.append(_wall("plate", "plate", lambda: disc_tris(r_out, 0.0)))
    meshes.append(_wall("outlet", "outlet", lambda: disc_tris(outlet_radius, outlet_z)))
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


def _balanced_rectangle(origin, e1, e2, n1: int, n2: int) -> np.ndarray:
    """:func:`rectangle` of the perpendicular sides e1, e2 (m), with n1, n2 raised so that no cell is
    more than ``MAX_FACET_ASPECT`` times longer one way than the other."""
    l1, l2 = float(np.linalg.norm(e1)), float(np.linalg.norm(e2))
    if not (l1 > 0 and l2 > 0):
        raise MeshQualityError(f"it has a side of zero length ({l1:.3g} x {l2:.3g} m)")
    if 2 * n1 * n2 <= MAX_MESH_TRIANGLES:
        tris = rectangle(origin, e1, e2, n1, n2)
        if _good(tris):                          # the grid asked for is good: keep it
            return tris
    n1, n2 = _balanced(l1, l2, n1, n2)
    _budget(2 * n1 * n2, f"a {l1:.3g} x {l2:.3g} m rectangle")
    return rectangle(origin, e1, e2, n1, n2)


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
        sensor = {"normal": (-1.0 if side == 0 else 1.0, 0.0), "projected_area": 2 * b * (z_hi - z_lo)} \
            if role == "band" else {}
        meshes.append(_wall(name, role, lambda: _balanced_rectangle(
            (x, -b, z_lo), (0.0, 2 * b, 0.0), (0.0, 0.0, z_hi - z_lo), 1, _divisions(z_hi - z_lo, long)),
            z0=z_lo, z1=z_hi, sector=side, **sensor, **kw))

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
        meshes.append(_wall(f"hopper_s{side:02d}", "hopper", lambda sign=sign: _balanced_rectangle(
            (sign * w0, -b, 0.0), (0.0, 2 * b, 0.0), (sign * (a - w0), 0.0, hh), 1, _divisions(slant, long)),
            sector=side))
    # faces: the silo's outline in x-z (wedge, then the full width), on a grid of trapezoid rows where
    # that grid is good, else triangulated anew (a nearly flat or very steep wedge, a narrow slot)
    nz_h, nz_v = _divisions(hh, facet), _divisions(g.height, facet)
    nx = _divisions(g.width, facet)

    def face_grid(y):
        z = np.concatenate([np.linspace(0.0, hh, nz_h + 1), np.linspace(hh, top, nz_v + 1)[1:]])
        half = np.where(z < hh, w0 + (a - w0) * z / max(hh, 1e-300), a)
        u = np.linspace(-1.0, 1.0, nx + 1)
        pts = np.stack([half[:, None] * u[None, :], np.full((len(z), nx + 1), y),
                        np.broadcast_to(z[:, None], (len(z), nx + 1))], axis=-1)
        return _grid_triangles(pts)

    outline = None

    def face_refined(y):
        nonlocal outline
        if outline is None:
            outline = _refine_polygon(np.array([(-w0, 0.0), (w0, 0.0), (a, hh), (a, top), (-a, top), (-a, hh)]),
                                      facet)
        p, tri = outline
        xyz = np.column_stack([p[:, 0], np.full(len(p), y), p[:, 1]])
        return xyz[tri[:, [0, 2, 1]]]            # counter-clockwise in x-z: normal +y, like the grid's

    for side, y in ((0, -b), (1, b)):
        meshes.append(_wall(f"face_s{side:02d}", "face", lambda y=y: _structured_or_graded(
            2 * nx * (nz_h + nz_v), lambda: face_grid(y), lambda: face_refined(y)), sector=side))
    meshes.append(_wall("plate", "plate", lambda: _balanced_rectangle(
        (-w0, -b, 0.0), (2 * w0, 0.0, 0.0), (0.0, 2 * b, 0.0), _divisions(2 * w0, facet), 1)))
    meshes.append(_wall("outlet", "outlet", lambda: _balanced_rectangle(
        (-outlet_half, -1.5 * b, outlet_z), (2 * outlet_half, 0.0, 0.0), (0.0, 3 * b, 0.0),
        _divisions(2 * outlet_half, facet), 1)))
    return meshes


class MeshError(ValueError):
    """A user mesh file that cannot be used (unreadable, not STL, non-finite, degenerate, outside)."""


#: user STL files larger than this are refused (a silo insert needs far fewer triangles)
MAX_USER_MESH_BYTES = 50_000_000


def read_user_mesh(path, scale: float = 1.0) -> np.ndarray:
    """Triangles (n, 3, 3), m, of a user's ASCII or binary STL file, checked: finite vertices and
    no degenerate (zero-area) triangle. Raises ``MeshError`` saying what is wrong."""
    from .atomic_files import read_regular_bytes
    path = Path(path)
    try:
        raw = read_regular_bytes(path, MAX_USER_MESH_BYTES, "a mesh")
    except ValueError as exc:
        raise MeshError(str(exc)) from None
    try:
        tris = np.array(stl_mesh.Mesh.from_file(str(path), fh=io.BytesIO(raw)).vectors, dtype=float)
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
    angles = min_angles(tris)
    bad = int((angles < LIGGGHTS_CURVATURE_DEG).sum())
    if bad:
        raise MeshError(f"{path} has {bad} sliver triangle(s) of {len(tris)} (the smallest angle is "
                        f"{angles.min():.3g} deg, triangle {int(np.argmin(angles))}): LIGGGHTS refuses angles below "
                        f"{LIGGGHTS_CURVATURE_DEG:.3g} deg ('Bad mesh'); re-mesh the file with better triangles")
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
    """The case's user walls, read from their files (relative paths from the working folder) and
    checked (:func:`read_user_mesh`, :func:`check_inside`). Raises ``CaseError`` naming each
    insert whose file cannot be used."""
    problems, meshes = [], []
    for k, ins in enumerate(case.inserts):
        try:
            tris = read_user_mesh(ins.file, ins.scale)
            check_inside(case, tris)
        except MeshError as exc:
            problems.append((f"inserts[{k}].file", str(exc)))
            continue
        # as the run folder's STL copy holds it (float32): a render from the copy is the same
        meshes.append(WallMesh(ins.mesh_name, "insert", as_written(tris)))
    if problems:
        raise CaseError(problems, case.name)
    return meshes


def write_stl(wall: WallMesh, path) -> None:
    """Write ``wall`` as ASCII STL (LIGGGHTS 3.8 reads ASCII), atomically. A mesh LIGGGHTS would
    refuse (an angle below its curvature, an edge below its precision) is never written: ``SetupError``."""
    problem = mesh_quality(as_written(wall.triangles)).problem(LIGGGHTS_CURVATURE_DEG, LIGGGHTS_PRECISION)
    if problem:
        raise SetupError(f"mesh {wall.name} would be refused by LIGGGHTS ('Bad mesh'): {problem}")
    m = stl_mesh.Mesh(np.zeros(len(wall.triangles), dtype=stl_mesh.Mesh.dtype))
    m.vectors[:] = wall.triangles
    m.update_normals()
    from .atomic_files import atomic_path
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        m.save(wall.name, fh=fh, mode=Mode.ASCII, update_normals=False)
