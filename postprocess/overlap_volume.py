"""Exact volumes and areas of overlap between spheres, circles and cylinders (m, m2, m3).

Used to measure solid fraction in a measurement region from the part of each grain that
lies inside it, not by counting centres. All functions are vectorised over particles.
"""
from __future__ import annotations

import numpy as np

# Gauss-Legendre nodes for the piecewise-smooth integrals below (exact for polynomials of degree 47)
_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)


def sphere_volume(r):
    return 4.0 / 3.0 * np.pi * np.asarray(r, float) ** 3


def sphere_sphere_overlap(R, r, d):
    """Volume (m3) of the intersection of spheres of radii ``R`` and ``r`` whose centres are ``d`` apart."""
    R, r, d = np.broadcast_arrays(*(np.asarray(a, float) for a in (R, r, d)))
    out = np.zeros(R.shape)
    inside = d <= np.abs(R - r)
    out[inside] = sphere_volume(np.minimum(R, r)[inside])
    lens = (d < R + r) & ~inside
    Rl, rl, dl = R[lens], r[lens], d[lens]
    # pi (R + r - d)^2 (d^2 + 2d(R + r) - 3(R - r)^2) / (12 d), written so that nothing cancels
    # when d is tiny (then |R - r| < d is tinier still)
    out[lens] = np.pi * (Rl + rl - dl) ** 2 * (dl + 2 * (Rl + rl) - 3 * (Rl - rl) ** 2 / dl) / 12.0
    return out


def circle_circle_overlap(R, r, d):
    """Area (m2) of the intersection of circles of radii ``R`` and ``r`` with centres ``d`` apart."""
    R, r, d = np.broadcast_arrays(*(np.asarray(a, float) for a in (R, r, d)))
    out = np.zeros(R.shape)
    inside = d <= np.abs(R - r)
    out[inside] = np.pi * np.minimum(R, r)[inside] ** 2
    lens = (d < R + r) & ~inside
    Rl, rl, dl = R[lens], r[lens], d[lens]
    a1 = np.clip((dl ** 2 + rl ** 2 - Rl ** 2) / (2 * dl * rl), -1.0, 1.0)
    a2 = np.clip((dl ** 2 + Rl ** 2 - rl ** 2) / (2 * dl * Rl), -1.0, 1.0)
    k = (-dl + rl + Rl) * (dl + rl - Rl) * (dl - rl + Rl) * (dl + rl + Rl)
    out[lens] = rl ** 2 * np.arccos(a1) + Rl ** 2 * np.arccos(a2) - 0.5 * np.sqrt(np.maximum(k, 0.0))
    return out


def sphere_cylinder_overlap(Rc, r, d, t0, t1):
    """Volume (m3) of a sphere of radius ``r`` inside the cylinder of radius ``Rc`` spanning
    axial coordinates ``t0..t1`` relative to the sphere centre; ``d`` is the distance of the
    sphere centre from the cylinder axis.

    The volume is the integral over the axial coordinate of the circle-circle overlap of the
    sphere's cross-section with the cylinder's. The integrand is a polynomial except at the
    axial positions where the two circles touch; the integral is split there and each piece
    integrated with 24-point Gauss-Legendre (relative error < 1e-7, tested against limits).
    """
    Rc, r, d, t0, t1 = np.broadcast_arrays(*(np.asarray(a, float) for a in (Rc, r, d, t0, t1)))
    lo = np.maximum(t0, -r)
    hi = np.minimum(t1, r)
    out = np.zeros(Rc.shape)
    for idx in np.flatnonzero(hi > lo):
        rr, RR, dd = r.flat[idx], Rc.flat[idx], d.flat[idx]
        cuts = [lo.flat[idx], hi.flat[idx]]
        for rho in (abs(RR - dd), RR + dd):  # cross-section radius at which the circles touch
            if rho < rr:
                s = np.sqrt(rr * rr - rho * rho)
                cuts += [s, -s]
        cuts = np.unique(np.clip(cuts, lo.flat[idx], hi.flat[idx]))
        a, b = cuts[:-1], cuts[1:]
        t = 0.5 * (b - a)[:, None] * _GL_X[None, :] + 0.5 * (a + b)[:, None]
        rho = np.sqrt(np.maximum(rr * rr - t * t, 0.0))
        area = circle_circle_overlap(RR, rho, dd)
        out.flat[idx] = float((0.5 * (b - a)[:, None] * _GL_W[None, :] * area).sum())
    return out


def _weighted(values, weights, idx) -> float:
    """Sum of ``values`` (of the rows ``idx``), each times its row's weight if weights are given."""
    return float(values.sum() if weights is None else (values * weights[idx]).sum())


def solid_volume_in_sphere(center, radius, positions, radii, tree=None, weights=None) -> float:
    """Solid volume (m3) of spheres (``positions`` (n,3), ``radii`` (n,)) inside the measurement
    sphere; ``tree`` is an optional scipy cKDTree of ``positions``; ``weights`` (n,) the share
    of each sphere's volume that is its own (clumps: see postprocess.porosity.grain_weights)."""
    idx = _candidates(center, radius + radii.max(initial=0.0), positions, tree)
    if len(idx) == 0:
        return 0.0
    d = np.linalg.norm(positions[idx] - np.asarray(center, float), axis=1)
    return _weighted(sphere_sphere_overlap(radius, radii[idx], d), weights, idx)


def solid_volume_in_cylinder(center, radius, axis: int, t0: float, t1: float, positions, radii, tree=None,
                             weights=None) -> float:
    """Solid volume (m3) of spheres inside a measurement cylinder of ``radius`` whose axis runs
    along coordinate ``axis`` (0, 1, 2) through ``center`` and spans ``t0..t1`` on that axis."""
    center = np.asarray(center, float)
    keep = [k for k in range(3) if k != axis]
    half = 0.5 * (t1 - t0)
    reach = np.hypot(radius, half) + radii.max(initial=0.0)
    mid = center.copy()
    mid[axis] = 0.5 * (t0 + t1)
    idx = _candidates(mid, reach, positions, tree)
    if len(idx) == 0:
        return 0.0
    p = positions[idx]
    d = np.hypot(p[:, keep[0]] - center[keep[0]], p[:, keep[1]] - center[keep[1]])
    return _weighted(sphere_cylinder_overlap(radius, radii[idx], d, t0 - p[:, axis], t1 - p[:, axis]), weights, idx)


def solid_area_in_circle(center, radius, axis: int, plane: float, positions, radii, tree=None,
                         weights=None) -> float:
    """Solid area (m2) of the sections of spheres by the plane ``coordinate[axis] == plane``
    inside the circle of ``radius`` about ``center`` in that plane (a 2D measurement circle)."""
    center = np.asarray(center, float)
    keep = [k for k in range(3) if k != axis]
    h = np.abs(positions[:, axis] - plane)
    cut = h < radii
    idx = np.flatnonzero(cut)
    if len(idx) == 0:
        return 0.0
    rho = np.sqrt(radii[idx] ** 2 - h[idx] ** 2)
    p = positions[idx]
    d = np.hypot(p[:, keep[0]] - center[keep[0]], p[:, keep[1]] - center[keep[1]])
    return _weighted(circle_circle_overlap(radius, rho, d), weights, idx)


def _candidates(center, reach: float, positions, tree):
    if tree is not None:
        return np.asarray(tree.query_ball_point(np.asarray(center, float), reach), dtype=int)
    d2 = ((positions - np.asarray(center, float)) ** 2).sum(axis=1)
    return np.flatnonzero(d2 < reach * reach)
