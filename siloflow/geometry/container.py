"""The user's own silo (``geometry.kind: mesh``): STL files read, checked as a container, measured
(height, hopper, cross-section, volume below a height) and cut into sensor bands and sectors.

The silo frame: z = 0 is the outlet plane, the sectors' axis is x = y = 0. A container is the
walls' triangles, oriented outward (away from the grains), closed apart from the opening at the
top and the outlet. Every problem names the file and the triangle (its index in the file, from 0).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components
from scipy.spatial import cKDTree

from .quality import LIGGGHTS_PRECISION, as_written, min_angles
from .triangulation import disc
from .user_meshes import MeshError, read_user_mesh
from .wall_mesh import WallMesh

#: |n_z| below which a triangle counts as a vertical wall (n its unit normal; 0.006 deg of tilt)
VERTICAL_TOLERANCE = 1e-4
#: vertices closer than this fraction of the container's extent are one vertex (STL repeats them)
WELD_TOLERANCE = 1e-7
#: a cut passing nearer a triangle's vertex than this fraction of its longest edge goes through the
#: vertex: no sliver (the piece keeps the whole triangle, off the cut by at most this much)
CUT_SNAP = 0.01
#: the outlet's rim may be this far (fraction of its radius) from the given circle or polygon
OUTLET_TOLERANCE = 1e-3


@dataclass(frozen=True)
class Source:
    """Where a triangle came from: ``files[k]`` and the index in that file, for messages."""

    files: tuple[str, ...]
    offsets: tuple[int, ...]            # index of each file's first triangle in the container

    def name(self, t: int) -> str:
        k = int(np.searchsorted(self.offsets, t, side="right")) - 1
        return f"triangle {t - self.offsets[k]} of {self.files[k]}"


@dataclass(frozen=True)
class Outline:
    """The outlet's outline in the silo frame (m): a circle (``center``, ``radius``) or a convex
    polygon (``polygon``, counter-clockwise)."""

    center: tuple[float, float]
    radius: float | None = None
    polygon: tuple[tuple[float, float], ...] | None = None

    def distance(self, xy: np.ndarray) -> np.ndarray:
        """Distance (m) of points (n, 2) from the outline."""
        if self.radius is not None:
            return np.abs(np.hypot(xy[:, 0] - self.center[0], xy[:, 1] - self.center[1]) - self.radius)
        poly = np.asarray(self.polygon)
        a, b = poly, np.roll(poly, -1, axis=0)
        ab = b - a
        t = np.clip(np.einsum("nkj,kj->nk", xy[:, None, :] - a[None], ab) / np.einsum("kj,kj->k", ab, ab), 0, 1)
        nearest = a[None] + t[..., None] * ab[None]
        return np.linalg.norm(xy[:, None, :] - nearest, axis=-1).min(axis=1)

    @property
    def area(self) -> float:
        if self.radius is not None:
            return math.pi * self.radius ** 2
        return polygon_area(np.asarray(self.polygon))

    @property
    def size(self) -> float:
        """Its largest distance from the centre, m."""
        if self.radius is not None:
            return self.radius
        return float(np.hypot(*(np.asarray(self.polygon) - self.center).T).max())


def enclosed_volume(tris: np.ndarray) -> float:
    """Volume (m3) enclosed by triangles (n, 3, 3) facing out, and by horizontal planes closing them
    (whose flux is zero): sum(A (c_x n_x + c_y n_y)) / 2 at the centroids c, the divergence theorem
    with the field (x, y, 0) / 2. Negative when the triangles face in."""
    if len(tris) == 0:
        return 0.0
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])      # 2 A n
    c = tris.mean(axis=1)
    return float((c[:, 0] * n[:, 0] + c[:, 1] * n[:, 1]).sum() / 4.0)


def polygon_area(xy: np.ndarray) -> float:
    """Signed area of a closed polygon (n, 2), m2 (positive counter-clockwise)."""
    x, y = xy[:, 0], xy[:, 1]
    return float(0.5 * (x * np.roll(y, -1) - np.roll(x, -1) * y).sum())


@dataclass(frozen=True)
class Container:
    """A checked container in the silo frame (m): ``triangles`` (n, 3, 3) oriented outward;
    ``top`` its highest point; ``base`` the top of its floor or hopper (the walls above are
    vertical); ``inscribed_radius`` the smallest horizontal distance from the axis to the vertical
    walls; ``outer_radius`` the largest from the axis to any vertex; ``rim`` the outlet's rim
    (k, 2), in order; ``outline`` the outlet as given; ``mid_section`` the vertical walls'
    cross-section half way up (:func:`section`)."""

    triangles: np.ndarray = field(repr=False)
    top: float
    base: float
    inscribed_radius: float
    outer_radius: float
    rim: np.ndarray = field(repr=False)
    outline: Outline
    source: np.ndarray = field(repr=False)     # the files' triangles as read, times scale (m, float32 values)
    mid_section: tuple[float, float]          # area (m2) and perimeter (m) of the section half way up the walls

    @property
    def height(self) -> float:
        """Height of the vertical walls above the floor or hopper, m."""
        return self.top - self.base

    @property
    def flat_floor(self) -> bool:
        """Whether everything below the vertical walls is the floor at z = 0."""
        return self.base == 0.0

    def volume_below(self, h: float) -> float:
        """Volume inside the container below the height ``h``, m3 (:func:`enclosed_volume` of the
        walls below h: the outlet and the cut at h are horizontal)."""
        below, _ = split(self.triangles, self.triangles[..., 2] - h)
        return enclosed_volume(below)



def section(tris: np.ndarray, z: float) -> tuple[float, float]:
    """Area (m2) and perimeter (m) of the horizontal cross-section at ``z`` of outward triangles."""
    p, q = slice_at(tris, z)
    area = 0.5 * float((p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]).sum())
    return area, float(np.hypot(*(q - p).T).sum())


def slice_at(tris: np.ndarray, z: float) -> tuple[np.ndarray, np.ndarray]:
    """The cross-section of outward triangles at height ``z``: its segments' ends (k, 2) and (k, 2),
    each walked with the outside on its right (counter-clockwise round the inside)."""
    s = tris[..., 2] - z
    crossing = (s.min(axis=1) < 0) & (s.max(axis=1) > 0)
    starts, ends = [], []
    for tri, sv in zip(tris[crossing], s[crossing]):
        pts = [tri[i] + sv[i] / (sv[i] - sv[(i + 1) % 3]) * (tri[(i + 1) % 3] - tri[i])
               for i in range(3) if (sv[i] < 0) != (sv[(i + 1) % 3] < 0)]
        if len(pts) != 2:
            continue
        p, q = pts[0][:2], pts[1][:2]
        n = np.cross(tri[1] - tri[0], tri[2] - tri[0])[:2]
        d = q - p
        if d[1] * n[0] - d[0] * n[1] < 0:
            p, q = q, p
        starts.append(p)
        ends.append(q)
    return np.reshape(starts, (-1, 2)), np.reshape(ends, (-1, 2))


def split(tris: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (n, 3, 3) cut by a plane, given each vertex's signed value ``s`` (n, 3) (linear
    in space, zero on the plane): the pieces on the side s <= 0 and on the side s > 0, each
    oriented as its triangle. A vertex within ``CUT_SNAP`` of its triangle's longest edge from the
    plane counts as on it; the quadrilateral a cut leaves is split along its better diagonal."""
    tris, s = np.asarray(tris, float), np.asarray(s, float)
    if len(tris) == 0:
        return tris, tris
    s = np.where(np.abs(s) <= _snap(tris, s), 0.0, s)
    low = (s <= 0).all(axis=1)
    high = (s >= 0).all(axis=1) & ~low
    mixed = ~(low | high)
    lows, highs = [tris[low]], [tris[high]]
    if mixed.any():
        t, v = tris[mixed], s[mixed]
        sign = np.sign(v)
        # the first vertex: a vertex on the plane (the others either side), else the lone one
        zero = sign == 0
        lone = (sign != np.roll(sign, -1, axis=1)) & (np.roll(sign, -1, axis=1) == np.roll(sign, -2, axis=1))
        first = np.where(zero.any(axis=1), zero.argmax(axis=1), lone.argmax(axis=1))
        order = (first[:, None] + np.arange(3)) % 3
        t = np.take_along_axis(t, order[..., None], axis=1)
        v = np.take_along_axis(v, order, axis=1)
        on = v[:, 0] == 0
        # a vertex on the plane: one cut across the opposite edge
        if on.any():
            a, b, c = t[on, 0], t[on, 1], t[on, 2]
            sb, sc = v[on, 1:2], v[on, 2:3]
            x = b + sb / (sb - sc) * (c - b)
            one, two = np.stack([a, b, x], 1), np.stack([a, x, c], 1)
            b_low = (sb[:, 0] < 0)
            lows += [one[b_low], two[~b_low]]
            highs += [one[~b_low], two[b_low]]
        cut = ~on
        if cut.any():
            a, b, c = t[cut, 0], t[cut, 1], t[cut, 2]
            sa, sb, sc = v[cut, 0:1], v[cut, 1:2], v[cut, 2:3]
            x1 = a + sa / (sa - sb) * (b - a)
            x2 = a + sa / (sa - sc) * (c - a)
            tip = np.stack([a, x1, x2], 1)
            q1 = [np.stack([x1, b, c], 1), np.stack([x1, c, x2], 1)]
            q2 = [np.stack([x1, b, x2], 1), np.stack([b, c, x2], 1)]
            better = np.minimum(min_angles(q1[0]), min_angles(q1[1])) >= np.minimum(min_angles(q2[0]),
                                                                                     min_angles(q2[1]))
            quad = [np.where(better[:, None, None], q1[k], q2[k]) for k in range(2)]
            a_low = sa[:, 0] < 0
            lows += [tip[a_low], quad[0][~a_low], quad[1][~a_low]]
            highs += [tip[~a_low], quad[0][a_low], quad[1][a_low]]
    return np.concatenate(lows).reshape(-1, 3, 3), np.concatenate(highs).reshape(-1, 3, 3)


def _snap(tris: np.ndarray, s: np.ndarray) -> np.ndarray:
    """How near (in units of ``s``) the plane a vertex counts as on it: ``CUT_SNAP`` of the
    triangle's longest edge, measured along the plane value's gradient in the triangle (the
    largest change of s per unit length over its edges)."""
    edges = tris - np.roll(tris, -1, axis=1)
    length = np.linalg.norm(edges, axis=2)
    rate = (np.abs(s - np.roll(s, -1, axis=1)) / np.maximum(length, 1e-300)).max(axis=1)
    return (CUT_SNAP * length.max(axis=1) * rate)[:, None]


def read_container(files, scale: float, outline: Outline, origin: tuple[float, float, float]) -> Container:
    """Read the STL ``files`` (times ``scale``, to m), move them so that ``origin`` (the axis' x, y and
    the outlet plane's z, m) is the silo frame's 0, and check them as a container with its outlet
    ``outline`` (silo frame). Raises ``MeshError`` naming the file and triangle of the first problem
    of each kind, and how to fix it."""
    parts, offsets = [], []
    for path in files:
        offsets.append(sum(len(p) for p in parts))
        parts.append(as_written(read_user_mesh(path, scale)))
    source = Source(tuple(str(f) for f in files), tuple(offsets))
    source_tris = np.concatenate(parts)
    tris = source_tris - np.asarray(origin, float)
    points = tris.reshape(-1, 3)
    tol = max(WELD_TOLERANCE * float(np.ptp(points, axis=0).max()), LIGGGHTS_PRECISION)
    if points[:, 2].min() < -tol:
        k = int(np.argmin(points[:, 2])) // 3
        raise MeshError(f"{source.name(k)} reaches {-points[:, 2].min():.4g} m below the outlet plane: the outlet "
                        "must be the container's lowest point, and geometry.outlet.z its plane")
    verts, edges, owner, boundary = _surface(points, tol, source)
    top = float(points[:, 2].max())
    rim = _rim(verts, edges, owner, boundary, top, tol, outline, source)

    volume = enclosed_volume(tris)
    if volume < 0:                          # the normals point inward: turn every triangle
        tris, volume = tris[:, ::-1], -volume
    if not volume > 0:
        raise MeshError("the walls enclose no volume: check the files and 'scale'")
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    vertical = np.abs(n[:, 2]) < VERTICAL_TOLERANCE
    base = float(tris[~vertical][..., 2].max()) if (~vertical).any() else 0.0
    base = 0.0 if base <= tol else base
    if not top - base > 0:
        raise MeshError("the walls have no vertical part above the floor or hopper: siloflow's sensor bands and "
                        "insertion need vertical walls at the top")
    walls = tris[vertical]
    xy = np.concatenate([walls[:, [0, 1]], walls[:, [1, 2]], walls[:, [2, 0]]])[..., :2]
    inscribed = float(_segment_distance(xy).min())
    mid = _section_height(tris, base, top, tol)
    mid_section = section(tris, mid)
    if not mid_section[0] > 0:
        raise MeshError(f"the vertical walls' cross-section at z = {mid:.6g} m (silo frame) encloses no area: the "
                        "walls above the floor or hopper must go all round the silo")
    if not _inside(tris, mid):
        raise MeshError(f"the sectors' axis (geometry.axis, default the outlet's centre; x = y = 0 in the silo "
                        f"frame) lies outside the vertical walls' cross-section at z = {mid:.6g} m: give "
                        "geometry.axis inside the walls, in the files' units")
    return Container(tris, top, base, inscribed, float(np.hypot(verts[:, 0], verts[:, 1]).max()),
                     rim, outline, source_tris, mid_section)


def _section_height(tris: np.ndarray, base: float, top: float, tol: float) -> float:
    """Where the vertical walls' cross-section is measured, m: half way up, or, when vertices lie
    within ``tol`` of that height (CAD exports often put a ring of them there), the middle of the
    nearest gap between the vertices' heights. Above ``base`` every triangle is vertical, so the
    section is the same at any height between base and top; a cut through vertices would miss
    the triangles that only touch it."""
    mid = base + 0.5 * (top - base)
    z = tris[..., 2].ravel()
    if np.abs(z - mid).min() > tol:
        return mid
    levels = np.unique(np.concatenate([[base, top], z[(z > base) & (z < top)]]))
    centres = 0.5 * (levels[:-1] + levels[1:])[np.diff(levels) > 2 * tol]
    return float(centres[np.argmin(np.abs(centres - mid))]) if len(centres) else mid


def _xyz(p) -> str:
    return ", ".join(f"{v:.6g}" for v in p)


def _surface(points: np.ndarray, tol: float, source: Source):
    """Check triangles (their corners ``points``, 3 a triangle) as one consistently oriented surface:
    corners within ``tol`` welded; no degenerate or duplicate triangle, no edge of more than two
    triangles, no triangle turned against its neighbours. Returns the welded vertices (m, 3), the
    directed edges as vertex ids (3 a triangle), each edge's triangle and the boundary edges' indices."""
    flat_ids = _weld(points, tol)
    verts = np.zeros((flat_ids.max() + 1, 3))
    verts[flat_ids] = points                # each welded vertex at one of its points
    ids = flat_ids.reshape(-1, 3)
    triple = np.sort(ids, axis=1)
    degenerate = (triple[:, 0] == triple[:, 1]) | (triple[:, 1] == triple[:, 2])
    if degenerate.any():
        raise MeshError(f"{source.name(int(np.argmax(degenerate)))} has two corners closer than {tol:.3g} m "
                        "(degenerate): remove it")
    _, first, counts = np.unique(triple, axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        t = int(first[np.flatnonzero(counts > 1)[0]])
        twin = next(int(k) for k in np.flatnonzero((triple == triple[t]).all(axis=1)) if k != t)
        raise MeshError(f"{source.name(twin)} repeats {source.name(t)} (a duplicate triangle): remove one")
    edges = np.stack([ids, np.roll(ids, -1, axis=1)], axis=-1).reshape(-1, 2)      # directed, 3 per triangle
    owner = np.repeat(np.arange(len(ids)), 3)
    _, inverse, uses = np.unique(np.sort(edges, axis=1), axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    if (uses > 2).any():
        names = ", ".join(source.name(int(owner[k])) for k in np.flatnonzero(uses[inverse] > 2)[:3])
        raise MeshError(f"{names} share an edge with further triangles (more than two triangles on one edge): "
                        "the walls must form one surface; separate parts belong under 'inserts'")
    _orient(edges, owner, inverse, uses, len(ids), source)
    return verts, edges, owner, np.flatnonzero(uses[inverse] == 1)


def _rim(verts, edges, owner, boundary, top: float, tol: float, outline: Outline, source: Source) -> np.ndarray:
    """The outlet's rim (k, 2), in order, from the surface's boundary edges: every one must be at
    the top or on the outlet's plane, and those on the plane must follow ``outline`` all round."""
    bz = verts[:, 2][edges[boundary]]
    at_top = (np.abs(bz - top) <= tol).all(axis=1)
    at_outlet = (np.abs(bz) <= tol).all(axis=1)
    open_edges = boundary[~(at_top | at_outlet)]
    if len(open_edges):
        k = open_edges[0]
        a, b = verts[edges[k]]
        raise MeshError(f"{source.name(int(owner[k]))} has an open edge from ({_xyz(a)}) to ({_xyz(b)}) m in the silo "
                        f"frame (z = 0 the outlet): the walls may be open only at the top (z = {top:.6g} m) and at "
                        f"the outlet (the plane geometry.outlet.z); close the gap (or {len(open_edges) - 1} more) in "
                        "the CAD model, or give the opening's plane")
    rim_edges = boundary[at_outlet]
    if len(rim_edges) == 0:
        raise MeshError("the walls have no opening at the outlet's plane: geometry.outlet.z must be the plane of "
                        "the opening in the walls (in the files' units)")
    rim = _loop(edges[rim_edges], verts)
    off = outline.distance(rim)
    if off.max() > OUTLET_TOLERANCE * outline.size + tol:
        k = int(np.argmax(off))
        raise MeshError(f"the walls' opening at the outlet plane does not follow geometry.outlet: its edge point "
                        f"({rim[k, 0]:.6g}, {rim[k, 1]:.6g}) m (silo frame) is {off[k]:.3g} m off the outlet's "
                        f"outline; give the opening's own centre and radius (or polygon), in the files' units")
    hole = abs(polygon_area(rim))
    if not 0.9 * outline.area <= hole <= 1.001 * outline.area:
        raise MeshError(f"the walls' opening at the outlet plane has {hole:.4g} m2, the outlet "
                        f"{outline.area:.4g} m2: the outlet lies outside the opening or covers only part of it")
    return rim


def _weld(points: np.ndarray, tol: float) -> np.ndarray:
    """Vertex ids (n,): points closer than ``tol`` share one."""
    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")
    n = len(points)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n)) if len(pairs) else \
        coo_matrix((n, n))
    return connected_components(graph, directed=False)[1]


def _orient(edges, owner, inverse, uses, n_tris: int, source: Source) -> None:
    """Refuse triangles turned against their neighbours: on an edge shared by two triangles the
    two walk it in opposite directions. The orientation is carried from each part's first
    triangle; the smaller set (the turned ones) is named."""
    shared = np.flatnonzero(uses[inverse] == 2)
    order = np.argsort(inverse[shared], kind="stable")
    pair = shared[order].reshape(-1, 2)
    a, b = owner[pair[:, 0]], owner[pair[:, 1]]
    same = (edges[pair[:, 0]] == edges[pair[:, 1]]).all(axis=1)         # walked the same way: one is turned
    if not same.any():
        return
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n_tris, n_tris)).tocsr()
    graph = graph + graph.T
    flipped = np.zeros(n_tris, bool)
    seen = np.zeros(n_tris, bool)
    relation = {}
    for i, j, s in zip(a, b, same):
        relation[(i, j)] = relation[(j, i)] = bool(s)
    for start in range(n_tris):
        if seen[start]:
            continue
        nodes, parents = breadth_first_order(graph, start, directed=False, return_predecessors=True)
        seen[nodes] = True
        for v in nodes[1:]:
            flipped[v] = flipped[parents[v]] ^ relation[(parents[v], v)]
    bad = np.flatnonzero(flipped) if flipped.sum() <= n_tris - flipped.sum() else np.flatnonzero(~flipped)
    names = ", ".join(source.name(int(t)) for t in bad[:3])
    more = f" and {len(bad) - 3} more" if len(bad) > 3 else ""
    raise MeshError(f"{names}{more} face the other way from "
                    "their neighbours (flipped normals): turn them so that all normals point out of the silo "
                    "(e.g. 'unify normals' in the CAD or mesh tool)")


def _loop(rim_edges: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The rim's points (k, 2) in order, from its boundary edges (vertex ids)."""
    nxt = {int(a): int(b) for a, b in rim_edges}
    start = int(rim_edges[0, 0])
    order, v = [start], nxt.get(start)
    while v is not None and v != start and len(order) <= len(nxt):
        order.append(v)
        v = nxt.get(v)
    if len(order) != len(nxt):
        raise MeshError("the walls' opening at the outlet plane is not one closed loop: the outlet must be one hole")
    return points[order, :2]


def _segment_distance(seg: np.ndarray) -> np.ndarray:
    """Distance from the origin to segments (n, 2, 2), m."""
    a, b = seg[:, 0], seg[:, 1]
    ab = b - a
    t = np.clip(-np.einsum("ij,ij->i", a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0, 1)
    return np.hypot(*(a + t[:, None] * ab).T)


def _inside(tris: np.ndarray, z: float) -> bool:
    """Whether the axis is inside the cross-section at ``z`` of triangles: a ray along +x crosses
    it an odd number of times."""
    p, q = slice_at(tris, z)
    spans = (p[:, 1] > 0) != (q[:, 1] > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = p[:, 0] - p[:, 1] * (q[:, 0] - p[:, 0]) / (q[:, 1] - p[:, 1])
    return int((spans & (x > 0)).sum()) % 2 == 1


def sector_of(xy: np.ndarray, sectors: int, phase: float) -> np.ndarray:
    """The sector (0..sectors-1) of points (n, 2) about the axis, sector 0 from ``phase`` (rad)."""
    theta = np.mod(np.arctan2(xy[:, 1], xy[:, 0]) - phase, 2 * math.pi)
    return np.minimum((theta / (2 * math.pi / sectors)).astype(int), sectors - 1)


def cut_walls(tris: np.ndarray, heights, sectors: int, phase: float) -> dict:
    """Vertical walls (n, 3, 3) cut at the ``heights`` (m, increasing) and along the sectors'
    half-planes (``sectors`` from ``phase``, rad): {(piece, sector): triangles}, piece -1 below the
    first height, k between heights k and k + 1, len(heights) - 1 above the last (sector None for
    the pieces outside the heights)."""
    for h in heights:
        lo, hi = split(tris, tris[..., 2] - h)
        tris = np.concatenate([lo, hi])
    for k in range(sectors):
        th = phase + 2 * math.pi * k / sectors
        s = -math.sin(th) * tris[..., 0] + math.cos(th) * tris[..., 1]
        lo, hi = split(tris, s)
        tris = np.concatenate([lo, hi])
    c = tris.mean(axis=1)
    piece = np.searchsorted(np.asarray(heights), c[:, 2]) - 1
    sector = sector_of(c[:, :2], sectors, phase)
    out = {}
    top = len(heights) - 1
    for p in np.unique(piece):
        mask = piece == p
        if p < 0 or p >= top:
            out[(int(p) if p < 0 else top, None)] = tris[mask]
            continue
        for s in range(sectors):
            m = mask & (sector == s)
            if m.any():
                out[(int(p), s)] = tris[m]
    return out


def vector_area(tris: np.ndarray) -> np.ndarray:
    """Sum of the triangles' area times unit normal (3,), m2."""
    return 0.5 * np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]).sum(axis=0)


def plate(rim: np.ndarray) -> np.ndarray:
    """Triangles closing the outlet's rim (k, 2) at z = 0, a fan from its centroid, facing down
    (out of the silo)."""
    c = rim.mean(axis=0)
    a, b = rim, np.roll(rim, -1, axis=0)
    tris = np.stack([np.broadcast_to(c, a.shape), a, b], axis=1)
    tris = np.concatenate([tris, np.zeros(tris.shape[:2] + (1,))], axis=2)
    if polygon_area(rim) > 0:               # counter-clockwise from above: the fan faces up; turn it
        tris = tris[:, ::-1]
    return tris


def sector_phase(offset_x: float, offset_y: float, sectors: int) -> float:
    """Where sector 0 starts, rad: at 0 for an outlet on the axis (as a cylinder's); else half a
    sector before the outlet's azimuth, so that sector 0 faces it."""
    if offset_x == 0.0 and offset_y == 0.0:
        return 0.0
    return math.atan2(offset_y, offset_x) - math.pi / sectors


def container_meshes(container: Container, band_bounds, sectors: int, outlet_center: tuple[float, float],
                     outlet_z: float, outlet_radius: float) -> list:
    """Meshes of the user's silo, in the order the deck lists them: the vertical walls cut into the
    unsensed pieces below and above the bands (role ``wall``) and the bands' sectors (``band``:
    normal and projected area the horizontal part of their vector area, so that a uniform
    pressure p gives the force p times that area along the normal), the floor (``bottom``, flat)
    or hopper (``hopper``) below the vertical walls, the plate closing the outlet's rim, and the
    counting disc of ``outlet_radius`` at ``outlet_z`` under the outlet's centre (m). Every wall is
    written facing the grains, as siloflow's own walls are (the container's triangles face out: each
    is turned, back to the file's order when the file faced in)."""
    c = container
    lower, walls = split(c.triangles, c.triangles[..., 2] - c.base)
    heights = [c.base + b for b in band_bounds]
    phase = sector_phase(outlet_center[0], outlet_center[1], sectors)
    pieces = cut_walls(walls, heights, sectors, phase)
    meshes = []
    below = pieces.pop((-1, None), None)
    above = pieces.pop((len(heights) - 1, None), None)
    if below is not None:
        meshes.append(WallMesh("wall_below", "wall", below))
    for k in range(len(heights) - 1):
        for s in range(sectors):
            tris = pieces.get((k, s))
            th0, th1 = phase + 2 * math.pi * s / sectors, phase + 2 * math.pi * (s + 1) / sectors
            if tris is None:
                raise MeshError(f"band {k} (z {heights[k]:.6g} to {heights[k + 1]:.6g} m) has no wall in sector {s} "
                                f"({math.degrees(th0):.4g} to {math.degrees(th1):.4g} deg about the axis)")
            area = vector_area(tris)[:2]
            size = float(np.hypot(*area))
            meshes.append(WallMesh(f"band{k:02d}_s{s:02d}", "band", tris, band=k, sector=s, z0=heights[k],
                                   z1=heights[k + 1], theta0=th0, theta1=th1,
                                   normal=(float(area[0] / size), float(area[1] / size)), projected_area=size))
    if above is not None:
        meshes.append(WallMesh("wall_above", "wall", above))
    if len(lower):
        meshes.append(WallMesh("bottom" if c.flat_floor else "hopper", "bottom" if c.flat_floor else "hopper", lower))
    meshes.append(WallMesh("plate", "plate", plate(c.rim)))
    for m in meshes:
        m.triangles = np.ascontiguousarray(m.triangles[:, ::-1])       # facing the grains
    counting = disc(outlet_radius, outlet_z, 32)
    counting[..., 0] += outlet_center[0]
    counting[..., 1] += outlet_center[1]
    meshes.append(WallMesh("outlet", "outlet", counting))
    return meshes
