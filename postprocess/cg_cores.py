"""Numba-compiled accumulation cores of the coarse-graining, and their tables.

Every core adds, for each source (a particle, or a point of a contact's branch line
integral), its weights times the kernel (m^-3) at each grid node within the cutoff into a
sums array; the grids of :mod:`postprocess.cg_grids` sort the sources and call them:

* :func:`accumulate_cartesian`: cell centres of a regular grid (or a slab average through y);
* :func:`accumulate_rz`, :func:`accumulate_rz_gaussian`: the azimuthal average over (r, z)
  nodes, by the kernel's ring moments <phi>, <phi cos a>, <phi cos^2 a> over the relative
  azimuth a of source and node, integrated by Gauss-Legendre (:data:`GL_A_X`, :data:`GL_U`);
* :func:`moment_table`: the same ring moments tabulated for the lattice method
  (:mod:`postprocess.cg_lattice`);
* :func:`line_sources`: the Gauss-Legendre points r_j + s b and tensor weights w_s f (x) b
  (N m) of each contact's branch; :func:`to_local_rz`: points and tensors in the local
  (r, theta, z) basis.

Lengths in m, kernel values in m^-3, weights in whatever units the caller's columns carry
(kg, kg m/s, kg m2/s2, N m): a sum is that unit per m3.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .cg_kernels import GAUSSIAN, LUCY, kernel_value, slab_kernel_value

#: the particle block's columns: m (kg), p = m v (3, kg m/s), m v v (6: xx yy zz xy xz yz, or
#: rr tt zz rt rz tz; kg m2/s2); per m3 once summed with the kernel
PARTICLE_COLUMNS = ["m", "p0", "p1", "p2", "t00", "t11", "t22", "t01", "t02", "t12"]
#: each particle column's moment code for the axisymmetric average: 0 <phi>, 1 <phi cos a>,
#: 2 <phi cos^2 a> and <phi sin^2 a> (two slots), 3 <phi cos 2a>
PARTICLE_CODES = np.array([0, 1, 1, 0, 2, 2, 0, 3, 1, 1], dtype=np.int64)
#: the moment codes of the contact stress, full tensor (N m): 00 01 02 10 11 12 20 21 22
CONTACT_CODES = np.array([2, 2, 1, 2, 2, 1, 1, 1, 0], dtype=np.int64)

#: Gauss-Legendre nodes and weights on [-1, 1] over the azimuth a in [0, a_c] (16 points), used
#: when the kernel's support reaches a_c > pi/2 (sources near the axis)
GL_A_X, GL_A_W = np.polynomial.legendre.leggauss(16)
#: Gauss-Legendre (nodes, weights) on [-1, 1] per kernel kind over u = sqrt((1 - cos a) / kappa),
#: kappa <= 1: the Gaussian is smooth in u; Lucy's sqrt(d0 + ...) is nearly |u| when d0 is small
#: and needs more points (both checked to 1e-10 against quad)
GL_U = {GAUSSIAN: np.polynomial.legendre.leggauss(10), LUCY: np.polynomial.legendre.leggauss(32)}


# ----------------------------------------------------------------------------- Cartesian

@njit(parallel=True, cache=True)
def accumulate_cartesian(origin, spacing, shape, pos, weights, dest, lo, hi, kind, norm, cutoff, width, slab, out):
    """out[iz, iy, ix, dest[i, d] + c] += weights[i, c] * phi(node - pos[i]) for every source i
    (sorted by z; lo/hi: source index range within reach of node plane iz). ``slab`` (ny = 1):
    phi is the kernel integrated over y divided by the cell's y extent (a slab average)."""
    nx, ny, nz = shape[0], shape[1], shape[2]
    ncomp = weights.shape[1]
    ndest = dest.shape[1]
    c2 = cutoff * cutoff
    for iz in prange(nz):
        zc = origin[2] + (iz + 0.5) * spacing[2]
        for i in range(lo[iz], hi[iz]):
            dz = zc - pos[i, 2]
            rem = c2 - dz * dz
            if rem <= 0.0:
                continue
            reach = math.sqrt(rem)
            ix0 = max(0, int(math.floor((pos[i, 0] - reach - origin[0]) / spacing[0] - 0.5)))
            ix1 = min(nx - 1, int(math.ceil((pos[i, 0] + reach - origin[0]) / spacing[0] - 0.5)))
            if slab:
                iy0, iy1 = 0, 0
            else:
                iy0 = max(0, int(math.floor((pos[i, 1] - reach - origin[1]) / spacing[1] - 0.5)))
                iy1 = min(ny - 1, int(math.ceil((pos[i, 1] + reach - origin[1]) / spacing[1] - 0.5)))
            for iy in range(iy0, iy1 + 1):
                dy = origin[1] + (iy + 0.5) * spacing[1] - pos[i, 1]
                for ix in range(ix0, ix1 + 1):
                    dx = origin[0] + (ix + 0.5) * spacing[0] - pos[i, 0]
                    if slab:
                        phi = slab_kernel_value(kind, norm, cutoff, width, dx * dx + dz * dz) / spacing[1]
                    else:
                        phi = kernel_value(kind, norm, cutoff, width, dx * dx + dy * dy + dz * dz)
                    if phi == 0.0:
                        continue
                    for d in range(ndest):
                        base = dest[i, d]
                        if base < 0:
                            continue
                        for c in range(ncomp):
                            out[iz, iy, ix, base + c] += weights[i, c] * phi


# ----------------------------------------------------------------------------- axisymmetric (r, z)

@njit(cache=True)
def _deposit(cell, weights, dest, codes, m0, m1, mc2):
    """Add one source's weights, times the kernel moment each component's code asks for, into
    the (field, slot) sums of one (r, z) node; ``dest`` holds the column blocks it goes to."""
    ms2 = m0 - mc2
    m2 = mc2 - ms2
    for d in range(dest.shape[0]):
        base = dest[d]
        if base < 0:
            continue
        for c in range(weights.shape[0]):
            w = weights[c]
            code = codes[c]
            if code == 0:
                cell[base + c, 0] += w * m0
            elif code == 1:
                cell[base + c, 0] += w * m1
            elif code == 2:
                cell[base + c, 0] += w * mc2
                cell[base + c, 1] += w * ms2
            else:
                cell[base + c, 0] += w * m2


@njit(cache=True)
def _ring_moments(kind, norm, cutoff, width, d0, two_rr, gl_x, gl_w, u_x, u_w):
    """Azimuthal averages (1/2 pi) int phi {1, cos a, cos^2 a} da of the kernel on a ring, for a
    source and node whose distance is sqrt(d0 + two_rr (1 - cos a)) at relative azimuth a.

    The support is |a| < a_c with 1 - cos a_c = kappa = (c^2 - d0) / two_rr. For kappa <= 1
    the substitution 1 - cos a = kappa u^2 (da = 2 sqrt(kappa) du / sqrt(2 - kappa u^2))
    makes the integrand a smooth function of u on [0, 1] without trigonometry; otherwise
    (a_c > pi/2, sources near the axis) Gauss-Legendre runs over a in [0, a_c]."""
    rem = cutoff * cutoff - d0
    if two_rr <= 0.0:                       # node or source on the axis: a full ring at one distance
        phi = kernel_value(kind, norm, cutoff, width, d0)
        return phi, 0.0, 0.5 * phi
    kappa = rem / two_rr
    m0 = 0.0
    m1 = 0.0
    mc2 = 0.0
    if kappa <= 1.0:
        sk = math.sqrt(kappa)
        for q in range(u_x.shape[0]):
            u = 0.5 * (u_x[q] + 1.0)
            ku2 = kappa * u * u
            w = u_w[q] * sk / math.sqrt(2.0 - ku2) * kernel_value(kind, norm, cutoff, width, d0 + two_rr * ku2)
            ca = 1.0 - ku2
            m0 += w
            m1 += w * ca
            mc2 += w * ca * ca
        return m0 / math.pi, m1 / math.pi, mc2 / math.pi
    amax = math.pi if kappa >= 2.0 else math.acos(1.0 - kappa)
    half = 0.5 * amax
    for q in range(gl_x.shape[0]):
        a = half * (gl_x[q] + 1.0)
        ca = math.cos(a)
        w = gl_w[q] * kernel_value(kind, norm, cutoff, width, d0 + two_rr * (1.0 - ca))
        m0 += w
        m1 += w * ca
        mc2 += w * ca * ca
    scale = half / math.pi
    return m0 * scale, m1 * scale, mc2 * scale


@njit(parallel=True, cache=True)
def moment_table(kind, norm, cutoff, width, r_nodes, rho_src, dz_vals, gl_x, gl_w, u_x, u_w, out):
    """out[:, q, ir, j] = ring moments (<phi>, <phi cos a>, <phi cos^2 a>) for a node at radius
    r_nodes[ir] and a source at signed radius rho_src[j], dz_vals[q] apart in z. A negative
    radius is the mirror image through the axis: <phi cos a> changes sign (cg_lattice)."""
    c2 = cutoff * cutoff
    for q in prange(dz_vals.shape[0]):
        for ir in range(r_nodes.shape[0]):
            r = r_nodes[ir]
            for j in range(rho_src.shape[0]):
                rho = abs(rho_src[j])
                d0 = (r - rho) * (r - rho) + dz_vals[q] * dz_vals[q]
                if d0 >= c2:
                    continue
                m0, m1, mc2 = _ring_moments(kind, norm, cutoff, width, d0, 2.0 * r * rho, gl_x, gl_w, u_x, u_w)
                out[0, q, ir, j] = m0
                out[1, q, ir, j] = m1 if rho_src[j] >= 0.0 else -m1
                out[2, q, ir, j] = mc2


@njit(parallel=True, cache=True)
def accumulate_rz(dr, nr, z0, dz_cell, nz, rho_s, z_s, weights, codes, dest, lo, hi,
                  kind, norm, cutoff, width, gl_x, gl_w, u_x, u_w, out):
    """Axisymmetric accumulation: out[iz, ir, dest + c, slot] += weights * kernel moment."""
    c2 = cutoff * cutoff
    for iz in prange(nz):
        zc = z0 + (iz + 0.5) * dz_cell
        for i in range(lo[iz], hi[iz]):
            ddz = zc - z_s[i]
            rem = c2 - ddz * ddz
            if rem <= 0.0:
                continue
            reach = math.sqrt(rem)
            rho = rho_s[i]
            ir0 = max(0, int(math.floor((rho - reach) / dr - 0.5)))
            ir1 = min(nr - 1, int(math.ceil((rho + reach) / dr - 0.5)))
            for ir in range(ir0, ir1 + 1):
                r = (ir + 0.5) * dr
                d0 = (r - rho) * (r - rho) + ddz * ddz
                if d0 >= c2:
                    continue
                m0, m1, mc2 = _ring_moments(kind, norm, cutoff, width, d0, 2.0 * r * rho, gl_x, gl_w, u_x, u_w)
                _deposit(out[iz, ir], weights[i], dest[i], codes, m0, m1, mc2)


@njit(parallel=True, cache=True, fastmath=True)
def accumulate_rz_gaussian(dr, nr, z0, dz_cell, nz, rho_s, z_s, weights, codes, dest, norm, cutoff, width,
                           gl_x, gl_w, u_x, u_w, nchunks, out):
    """The Gaussian's axisymmetric accumulation, exact like :func:`accumulate_rz` but faster:
    in the u form the kernel is norm e^{-4u^2} e^{-delta (1 - u^2)} with delta = ((r - rho)^2 +
    dz^2) / 4w^2, whose last factor splits into a radial and a vertical table per source, so the
    pair loop needs no exponential. Sources are split into ``nchunks`` chunks, each summed into
    its own copy of the grid (out[chunk]); the caller adds the copies."""
    n = rho_s.shape[0]
    nq = u_x.shape[0]
    c2 = cutoff * cutoff
    inv4w2 = 1.0 / (4.0 * width * width)
    u2 = np.empty(nq)
    cq = np.empty(nq)
    one_minus = np.empty(nq)
    for q in range(nq):
        u = 0.5 * (u_x[q] + 1.0)
        u2[q] = u * u
        cq[q] = u_w[q] * norm * math.exp(-4.0 * u * u) / math.pi
        one_minus[q] = (1.0 - u * u) * inv4w2
    maxr = int(math.ceil(2.0 * cutoff / dr)) + 2
    maxz = int(math.ceil(2.0 * cutoff / dz_cell)) + 2
    per = (n + nchunks - 1) // nchunks
    for ch in prange(nchunks):
        A = np.empty((maxr, nq))
        B = np.empty((maxz, nq))
        rr = np.empty(maxr)
        drr = np.empty(maxr)
        dzz = np.empty(maxz)
        grid = out[ch]
        for i in range(ch * per, min(n, (ch + 1) * per)):
            rho = rho_s[i]
            ir0 = max(0, int(math.floor((rho - cutoff) / dr - 0.5)))
            ir1 = min(nr - 1, int(math.ceil((rho + cutoff) / dr - 0.5)))
            iz0 = max(0, int(math.floor((z_s[i] - cutoff - z0) / dz_cell - 0.5)))
            iz1 = min(nz - 1, int(math.ceil((z_s[i] + cutoff - z0) / dz_cell - 0.5)))
            if ir1 < ir0 or iz1 < iz0:
                continue
            for k in range(ir1 - ir0 + 1):
                r = (ir0 + k + 0.5) * dr
                rr[k] = r
                drr[k] = (r - rho) * (r - rho)
                for q in range(nq):
                    A[k, q] = math.exp(-drr[k] * one_minus[q])
            for k in range(iz1 - iz0 + 1):
                dz = z0 + (iz0 + k + 0.5) * dz_cell - z_s[i]
                dzz[k] = dz * dz
                for q in range(nq):
                    B[k, q] = math.exp(-dzz[k] * one_minus[q])
            for kz in range(iz1 - iz0 + 1):
                iz = iz0 + kz
                for kr in range(ir1 - ir0 + 1):
                    d0 = drr[kr] + dzz[kz]
                    if d0 >= c2:
                        continue
                    two_rr = 2.0 * rr[kr] * rho
                    kappa = (c2 - d0) / two_rr if two_rr > 0.0 else 2.0
                    if kappa <= 1.0:
                        m0 = 0.0
                        m1 = 0.0
                        mc2 = 0.0
                        for q in range(nq):
                            x = kappa * u2[q]
                            t = cq[q] * A[kr, q] * B[kz, q] / math.sqrt(2.0 - x)
                            cx = 1.0 - x
                            m0 += t
                            m1 += t * cx
                            mc2 += t * cx * cx
                        sk = math.sqrt(kappa)
                        m0 *= sk
                        m1 *= sk
                        mc2 *= sk
                    else:
                        m0, m1, mc2 = _ring_moments(GAUSSIAN, norm, cutoff, width, d0, two_rr, gl_x, gl_w, u_x, u_w)
                    _deposit(grid[iz, ir0 + kr], weights[i], dest[i], codes, m0, m1, mc2)


# ----------------------------------------------------------------------------- contact line sources

@njit(cache=True)
def line_sources(pos_i, pos_j, force, need, start, nodes, weights, pts, tens):
    """Points r_j + s b and tensors w_s f (x) b of every contact's Gauss-Legendre rule."""
    for c in range(pos_i.shape[0]):
        n = need[c]
        for q in range(n):
            k = start[c] + q
            s = nodes[n, q]
            w = weights[n, q]
            for a in range(3):
                b_a = pos_i[c, a] - pos_j[c, a]
                pts[k, a] = pos_j[c, a] + s * b_a
            for a in range(3):
                fa = w * force[c, a]
                for b in range(3):
                    tens[k, a, b] = fa * (pos_i[c, b] - pos_j[c, b])


@njit(parallel=True, cache=True)
def to_local_rz(pts, tens, x0, y0, pos, local):
    """pos = (rho, 0, z) of each point about the axis (x0, y0); local = R T R^T with R's rows
    e_r = (c, s, 0), e_theta = (-s, c, 0), e_z (on the axis: e_r = x)."""
    for k in prange(pts.shape[0]):
        x = pts[k, 0] - x0
        y = pts[k, 1] - y0
        rho = math.sqrt(x * x + y * y)
        c, s = (x / rho, y / rho) if rho > 0.0 else (1.0, 0.0)
        pos[k, 0] = rho
        pos[k, 1] = 0.0
        pos[k, 2] = pts[k, 2]
        xx, xy, xz, yx, yy, yz, zx, zy, zz = (tens[k, 0], tens[k, 1], tens[k, 2], tens[k, 3], tens[k, 4],
                                              tens[k, 5], tens[k, 6], tens[k, 7], tens[k, 8])
        cc, ss, cs = c * c, s * s, c * s
        local[k, 0] = cc * xx + cs * (xy + yx) + ss * yy
        local[k, 1] = cc * xy - ss * yx + cs * (yy - xx)
        local[k, 2] = c * xz + s * yz
        local[k, 3] = cc * yx - ss * xy + cs * (yy - xx)
        local[k, 4] = ss * xx - cs * (xy + yx) + cc * yy
        local[k, 5] = c * yz - s * xz
        local[k, 6] = c * zx + s * zy
        local[k, 7] = c * zy - s * zx
        local[k, 8] = zz
