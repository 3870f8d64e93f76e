"""Rigid clumps of overlapping spheres (paper A's multi-element wheat grain).

A clump is given by its sphere centres (m, body frame) and radii (m). Its volume is
the volume of the *union* of the spheres: overlaps are counted once. ``union_volume``
computes it deterministically with the divergence theorem,

    V = 1/3 sum_i  integral over the exposed part of sphere i of  x . n dA,

where the exposed part of sphere i at polar angle theta is a set of azimuth intervals
found in closed form (each other sphere cuts one interval), the azimuth integral is
analytic and the polar integral adaptive (scipy quad, split at the kinks). LIGGGHTS
estimates the same volume by Monte Carlo (``ntry``); the two are compared in the tests.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import integrate

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class ClumpShape:
    """Sphere centres (n, 3) and radii (n,) of a clump, m, in the body frame."""

    centers: tuple[tuple[float, float, float], ...]
    radii: tuple[float, ...]

    def __post_init__(self):
        c = np.asarray(self.centers, float)
        r = np.asarray(self.radii, float)
        if c.ndim != 2 or c.shape[1] != 3 or len(r) != len(c) or len(r) == 0:
            raise ValueError("a clump needs n sphere centres (x, y, z) and n radii")
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(r)) and np.all(r > 0)):
            raise ValueError("clump sphere centres must be finite and radii positive")
        for i in range(len(r)):
            for j in range(i + 1, len(r)):
                if np.allclose(c[i], c[j], rtol=0, atol=1e-12 * r.max()) and abs(r[i] - r[j]) < 1e-12 * r.max():
                    raise ValueError(f"clump spheres {i} and {j} are the same sphere")

    @property
    def n_spheres(self) -> int:
        return len(self.radii)

    @property
    def sphere_volume_sum(self) -> float:
        """Sum of the sphere volumes (overlaps counted repeatedly), m3."""
        return float(sum(4.0 / 3.0 * math.pi * r ** 3 for r in self.radii))

    @property
    def volume(self) -> float:
        """Volume of the union of the spheres, m3."""
        return union_volume(self.centers, self.radii)

    @property
    def bounding_radius(self) -> float:
        """Radius of the smallest sphere about the centroid of the centres that holds the clump, m
        (an upper bound of the minimal bounding sphere)."""
        c = np.asarray(self.centers, float)
        mid = c.mean(axis=0)
        return float(np.max(np.linalg.norm(c - mid, axis=1) + np.asarray(self.radii)))

    def connected(self) -> bool:
        """True when the spheres form one overlapping body."""
        c = np.asarray(self.centers, float)
        r = np.asarray(self.radii, float)
        reached, frontier = {0}, [0]
        while frontier:
            i = frontier.pop()
            for j in range(len(r)):
                if j not in reached and np.linalg.norm(c[i] - c[j]) < r[i] + r[j]:
                    reached.add(j)
                    frontier.append(j)
        return len(reached) == len(r)


def wheat_grain(length: float = 6e-3, width: float = 4e-3) -> ClumpShape:
    """Paper A's wheat grain: three equal spheres of diameter ``width`` on the x axis, the outer
    centres (length - width)/2 from the middle one, so the clump is ``length`` long (m)."""
    if not 0 < width <= length < 3 * width:
        raise ValueError("a three-sphere grain needs width <= length < 3 width (the spheres must overlap)")
    s = 0.5 * (length - width)
    r = 0.5 * width
    return ClumpShape(centers=((-s, 0.0, 0.0), (0.0, 0.0, 0.0), (s, 0.0, 0.0)), radii=(r, r, r))


def _merge(intervals):
    """Union of azimuth intervals (each within [0, 2 pi]) as a sorted, disjoint list."""
    intervals.sort()
    out = []
    for a, b in intervals:
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return out


def _covered(theta: float, ci, ri: float, others) -> list | None:
    """Azimuth intervals of sphere i (centre ci, radius ri) at polar angle ``theta`` that lie
    inside another sphere; None when the whole circle is covered."""
    s, c = math.sin(theta), math.cos(theta)
    intervals = []
    for dx, dy, dz, rho, alpha, h in others:
        if rho * s < 1e-15 * ri:
            if c * dz > h:
                return None
            continue
        q = (h - c * dz) / (s * rho)
        if q >= 1.0:
            continue
        if q <= -1.0:
            return None
        half = math.acos(q)
        a, b = (alpha - half) % TWO_PI, (alpha + half) % TWO_PI
        if a < b:
            intervals.append([a, b])
        else:
            intervals += [[a, TWO_PI], [0.0, b]]
    return _merge(intervals)


def _exposed_integral(theta: float, ci, ri: float, others) -> float:
    """Integral over the exposed azimuths at ``theta`` of (x . n) sin(theta) (without R^2)."""
    s, c = math.sin(theta), math.cos(theta)
    total = 0.0
    for p1, p2 in _exposed_arcs(theta, ci, ri, others):
        total += (s * (ci[0] * (math.sin(p2) - math.sin(p1)) - ci[1] * (math.cos(p2) - math.cos(p1)))
                  + (ci[2] * c + ri) * (p2 - p1))
    return total * s


def _triple_points(ci, ri, cj, rj, ck, rk) -> list[np.ndarray]:
    """Points where the surfaces of three spheres meet (0 or 2; the integrand's inner kinks)."""
    n1, n2 = cj - ci, ck - ci
    b1 = 0.5 * (ri * ri - rj * rj + n1 @ n1)      # p.n1 = b1, p.n2 = b2 (p relative to ci)
    b2 = 0.5 * (ri * ri - rk * rk + n2 @ n2)
    u = np.cross(n1, n2)
    uu = u @ u
    if uu < 1e-24 * (n1 @ n1) * (n2 @ n2):
        return []                                  # centres on a line: no isolated points
    p0 = (b1 * np.cross(n2, u) + b2 * np.cross(u, n1)) / uu
    # p0 solves both plane equations; the line is p0 + t u, cut by |p| = ri
    a, b, c = uu, 2.0 * (p0 @ u), p0 @ p0 - ri * ri
    disc = b * b - 4 * a * c
    if disc < 0:
        return []
    root = math.sqrt(disc)
    return [p0 + (-b - root) / (2 * a) * u, p0 + (-b + root) / (2 * a) * u]


def _exposed_pieces(c, r):
    """Per sphere i not buried in another: (i, others, polar breakpoints) for the integrals over
    its exposed surface; ``others`` describes the spheres that cut it (see :func:`_covered`),
    empty when the whole sphere is exposed."""
    pieces = []
    for i in range(len(r)):
        others, breaks, buried = [], [], False
        for j in range(len(r)):
            if j == i:
                continue
            d = c[j] - c[i]
            dist = float(np.linalg.norm(d))
            if dist >= r[i] + r[j]:
                continue                                   # apart
            if dist + r[i] <= r[j] and not (dist == 0 and r[i] == r[j] and j > i):
                buried = True                              # sphere i lies inside sphere j
                break
            if dist + r[j] <= r[i]:
                continue                                   # j inside i covers none of i's surface
            h = (r[i] ** 2 + dist ** 2 - r[j] ** 2) / (2.0 * r[i])
            others.append((d[0], d[1], d[2], math.hypot(d[0], d[1]), math.atan2(d[1], d[0]), h))
            theta_d = math.acos(max(-1.0, min(1.0, d[2] / dist)))
            beta = math.acos(max(-1.0, min(1.0, h / dist)))
            breaks += [theta_d - beta, theta_d + beta]
        if buried:
            continue
        near = [j for j in range(len(r)) if j != i and np.linalg.norm(c[j] - c[i]) < r[i] + r[j]]
        for a_, j in enumerate(near):
            for k in near[a_ + 1:]:
                for point in _triple_points(c[i], r[i], c[j], r[j], c[k], r[k]):
                    breaks.append(math.acos(max(-1.0, min(1.0, point[2] / r[i]))))
        points = sorted({0.0, math.pi, *[b for b in breaks if 0.0 < b < math.pi]})
        pieces.append((i, others, points))
    return pieces


def _exposed_arcs(theta: float, ci, ri: float, others) -> list:
    """Exposed azimuth intervals of sphere i at polar angle ``theta``."""
    covered = _covered(theta, ci, ri, others)
    if covered is None:
        return []
    edges, start = [], 0.0
    for a, b in covered:
        if a > start:
            edges.append((start, a))
        start = max(start, b)
    if start < TWO_PI:
        edges.append((start, TWO_PI))
    return edges


def union_volume(centers, radii, rtol: float = 1e-10) -> float:
    """Volume (m3) of the union of spheres (``centers`` (n, 3), ``radii`` (n,), m)."""
    c = np.asarray(centers, float)
    r = np.asarray(radii, float)
    c = c - c.mean(axis=0)          # x . n is measured from here: keep it small
    total = 0.0
    for i, others, points in _exposed_pieces(c, r):
        if not others:
            total += 4.0 / 3.0 * math.pi * r[i] ** 3
            continue
        part = 0.0
        for a, b in zip(points, points[1:]):
            if b - a > 1e-14:
                value, _ = integrate.quad(_exposed_integral, a, b, args=(c[i], r[i], others),
                                          epsabs=rtol * (float(np.linalg.norm(c[i])) + r[i]), epsrel=rtol,
                                          limit=200)
                part += value
        total += r[i] ** 2 * part / 3.0
    return float(total)


def _exposed_moment(theta: float, ci, ri: float, others) -> np.ndarray:
    """Integrand over theta of the first moment: the exposed azimuths' integral of
    (x_k^2 / 2) n_k sin(theta), x = ci + ri n, for k = x, y, z (without ri^2)."""
    s, c = math.sin(theta), math.cos(theta)
    out = np.zeros(3)
    for p1, p2 in _exposed_arcs(theta, ci, ri, others):
        # int cos, cos^2, cos^3 and sin, sin^2, sin^3 over [p1, p2]
        c1 = math.sin(p2) - math.sin(p1)
        c2 = 0.5 * (p2 - p1) + 0.25 * (math.sin(2 * p2) - math.sin(2 * p1))
        c3 = c1 - (math.sin(p2) ** 3 - math.sin(p1) ** 3) / 3.0
        s1 = -(math.cos(p2) - math.cos(p1))
        s2 = 0.5 * (p2 - p1) - 0.25 * (math.sin(2 * p2) - math.sin(2 * p1))
        s3 = s1 + (math.cos(p2) ** 3 - math.cos(p1) ** 3) / 3.0
        out[0] += ci[0] ** 2 * s * c1 + 2 * ci[0] * ri * s * s * c2 + ri * ri * s ** 3 * c3
        out[1] += ci[1] ** 2 * s * s1 + 2 * ci[1] * ri * s * s * s2 + ri * ri * s ** 3 * s3
        out[2] += (ci[2] + ri * c) ** 2 * c * (p2 - p1)
    return 0.5 * out * s


def union_centroid(centers, radii, rtol: float = 1e-10) -> np.ndarray:
    """Centroid (m) of the union of spheres, exact to ``rtol``: the first moment by the
    divergence theorem, int_V x_k dV = int_S (x_k^2 / 2) n_k dS over the exposed surface."""
    c0 = np.asarray(centers, float)
    r = np.asarray(radii, float)
    mid = c0.mean(axis=0)
    c = c0 - mid
    moment = np.zeros(3)
    size = float(np.abs(c).max() + r.max())
    for i, others, points in _exposed_pieces(c, r):
        if not others:
            moment += 4.0 / 3.0 * math.pi * r[i] ** 3 * c[i]
            continue
        for a, b in zip(points, points[1:]):
            if b - a > 1e-14:
                value, _ = integrate.quad_vec(_exposed_moment, a, b, args=(c[i], r[i], others),
                                              epsabs=rtol * size ** 2, epsrel=rtol, limit=400)
                moment += r[i] ** 2 * value
    return mid + moment / union_volume(c0, r, rtol)


def union_area(centers, radii) -> float:
    """Area (m2) of the union of circles (``centers`` (n, 2), ``radii`` (n,), m), exact: Green's
    theorem over the exposed arcs of every circle, A = 1/2 sum over arcs of (x dy - y dx)."""
    c = np.asarray(centers, float)
    r = np.asarray(radii, float)
    c = c - c.mean(axis=0) if len(c) else c
    total = 0.0
    for i in range(len(r)):
        covered, buried = [], False
        for j in range(len(r)):
            if j == i:
                continue
            d = c[j] - c[i]
            dist = float(math.hypot(d[0], d[1]))
            if dist >= r[i] + r[j] or dist + r[j] <= r[i] and not (dist == 0 and r[i] == r[j]):
                continue
            if dist + r[i] <= r[j]:
                if dist == 0 and r[i] == r[j] and j < i:
                    continue                               # the same circle: counted once
                buried = True
                break
            half = math.acos(max(-1.0, min(1.0, (r[i] ** 2 + dist ** 2 - r[j] ** 2) / (2.0 * r[i] * dist))))
            alpha = math.atan2(d[1], d[0])
            a, b = (alpha - half) % TWO_PI, (alpha + half) % TWO_PI
            covered += [[a, b]] if a < b else [[a, TWO_PI], [0.0, b]]
        if buried:
            continue
        start = 0.0
        arcs = []
        for a, b in _merge(covered):
            if a > start:
                arcs.append((start, a))
            start = max(start, b)
        if start < TWO_PI:
            arcs.append((start, TWO_PI))
        x, y, R = c[i, 0], c[i, 1], r[i]
        for p1, p2 in arcs:   # x = x0 + R cos t, y = y0 + R sin t
            total += 0.5 * (R * R * (p2 - p1) + x * R * (math.sin(p2) - math.sin(p1))
                            + y * R * (math.cos(p1) - math.cos(p2)))
    return float(total)


def union_inertia(centers, radii, about, cells: int = 160) -> np.ndarray:
    """Inertia tensor per unit density (m5; times the density: kg m2) of the union of spheres about
    the point ``about`` (m): the second moments integrated on a grid of ``cells`` per side of the
    bounding box, cell centres inside any sphere counted (a midpoint rule: relative error about
    1e-4 at 160 cells for a wheat grain). Returns the 3x3 tensor int (|x|^2 I - x x^T) dV."""
    c = np.asarray(centers, float) - np.asarray(about, float)
    r = np.asarray(radii, float)
    lo, hi = (c - r[:, None]).min(axis=0), (c + r[:, None]).max(axis=0)
    h = (hi - lo) / cells
    axes = [lo[k] + h[k] * (np.arange(cells) + 0.5) for k in range(3)]
    out = np.zeros((3, 3))
    yz = np.stack(np.meshgrid(axes[1], axes[2], indexing="ij"), axis=-1).reshape(-1, 2)
    for x in axes[0]:                      # one slab of cells at a time: memory stays small
        pts = np.column_stack([np.full(len(yz), x), yz])
        inside = np.zeros(len(pts), bool)
        for ci, ri in zip(c, r):
            inside |= ((pts - ci) ** 2).sum(axis=1) <= ri * ri
        p = pts[inside]
        out += np.eye(3) * (p * p).sum() - p.T @ p
    return out * float(np.prod(h))
