"""Triangulations of the walls' surfaces: structured grids, surfaces of revolution and discs, graded rings and the Delaunay refinement of planar polygons (m)."""
from __future__ import annotations

import math

import numpy as np

from .quality import (
    GRADING,
    MAX_FACET_ASPECT,
    MAX_MESH_TRIANGLES,
    MIN_RING_POINTS,
    REFINE_ANGLE_DEG,
    ROW_ASPECT,
    MeshQualityError,
    _budget,
    _good,
)


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


def disc(radius: float, z: float, n_theta: int, inner_radius: float = 0.0, rows: int | None = None) -> np.ndarray:
    """Triangles of a horizontal disc (or annulus when ``inner_radius`` > 0) at height z.

    Radial rings keep the triangles' aspect ratio near 1; ``rows``: that many rings instead (1: a
    disc is a fan about its centre, an annulus one ring of long triangles).
    """
    h = 2 * math.pi * radius / n_theta
    if inner_radius > 0:
        n_r = rows or max(1, math.ceil((radius - inner_radius) / h))
        return surface_of_revolution(inner_radius, z, radius, z, 0.0, 2 * math.pi, n_theta, n_r)
    # centre fan plus rings
    n_r = rows or max(1, math.ceil(radius / h))
    r_in = radius / n_r
    theta = np.linspace(0.0, 2 * math.pi, n_theta + 1)
    ring = np.stack([r_in * np.cos(theta), r_in * np.sin(theta), np.full_like(theta, z)], -1)
    centre = np.array([0.0, 0.0, z])
    fan = np.stack([np.broadcast_to(centre, (n_theta, 3)), ring[:-1], ring[1:]], 1)
    if n_r == 1:
        return fan
    rest = surface_of_revolution(r_in, z, radius, z, 0.0, 2 * math.pi, n_theta, n_r - 1)
    return np.concatenate([fan, rest])


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
