"""Coarse-grained continuum fields from particles (paper B, Section 2.1; MercuryCG's definitions).

For a kernel phi (``cg_kernels``), particles i (mass m_i, position r_i, velocity v_i, species
s_i) and contacts (force f_ij on i from j, branch b_ij = r_i - r_j):

    rho(x)      = sum_i m_i phi(x - r_i)                          mass density, kg/m3
    P(x)        = sum_i m_i v_i phi(x - r_i)                      momentum density, kg/(m2 s)
    V           = P / rho                                         velocity, m/s
    sigma_k     = sum_i m_i v'_i v'_i phi,  v'_i = v_i - V(x)     kinetic stress, Pa
                = sum_i m_i v_i v_i phi - rho V V                 (computed this way, one pass)
    sigma_k^a   = sum_{i in a} m_i v'_i v'_i phi                  partial kinetic stress; sums to sigma_k
    sigma_c     = sum_ij f_ij (x) b_ij int_0^1 phi(x - r_j - s b_ij) ds   contact stress, Pa
                  (compressive positive; the line integral by Gauss-Legendre, 2-16 points by
                  branch length over kernel width: see line_points_needed)
    phi_s = rho / rho_p (with species: sum_a rho_a / rho_a,p),  pressures p = trace / 3.

Grids:
* Cartesian: cell centres of a regular grid.
* axisymmetric (r, z): the azimuthal average of the 3D field, (1/2 pi) int F(r, theta, z)
  dtheta, per unit volume, with vectors and tensors in the local (r, theta, z) basis. The
  average is taken analytically over the source's azimuth relative to the node: for a source
  at radius rho and a node at r, the kernel moments <phi>, <phi cos a>, <phi cos^2 a>,
  <phi cos 2a> over the relative azimuth a are integrated exactly over the kernel's support
  |a| < a_c by Gauss-Legendre (smooth integrand: < 1e-12 relative).
* planar (x, z) for a slab silo: a Cartesian grid with one cell across the slab and
  ``slab=True``: averages through the thickness T, sum_i ... phi2(x - r_i) / T with phi2 the
  kernel integrated over y (``cg_kernels.slab_kernel_value``), whatever T is against w.

Everything is streamed by frame: :class:`CoarseGraining` accumulates sums per frame and
time-averages them (or keeps per-frame fields), so memory is one frame plus the grid.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .analysis_base import StepCursor, paired
from .cg_kernels import GAUSSIAN, LUCY, Kernel, kernel_value, slab_kernel_value
from .clump_bodies import body_centres, body_contacts, body_frame

# particle block: m, p (3), m v v (6: xx yy zz xy xz yz, or rr tt zz rt rz tz)
PARTICLE_COLUMNS = ["m", "p0", "p1", "p2", "t00", "t11", "t22", "t01", "t02", "t12"]
# moment codes for the axisymmetric average: 0 <phi>, 1 <phi cos a>, 2 <phi cos^2 a> and
# <phi sin^2 a> (two slots), 3 <phi cos 2a>
PARTICLE_CODES = np.array([0, 1, 1, 0, 2, 2, 0, 3, 1, 1], dtype=np.int64)
# contact stress, full tensor: 00 01 02 10 11 12 20 21 22
CONTACT_CODES = np.array([2, 2, 1, 2, 2, 1, 1, 1, 0], dtype=np.int64)

_GL_A_X, _GL_A_W = np.polynomial.legendre.leggauss(16)   # azimuth, a_c > pi/2
# u = sqrt((1 - cos a) / kappa), kappa <= 1: the Gaussian is smooth in u; Lucy's sqrt(d0 + ...) is
# nearly |u| when d0 is small and needs more points (both checked to 1e-10 against quad)
_GL_U = {GAUSSIAN: np.polynomial.legendre.leggauss(10), LUCY: np.polynomial.legendre.leggauss(32)}


# ----------------------------------------------------------------------------- numba cores

@njit(parallel=True, cache=True)
def _accumulate_cartesian(origin, spacing, shape, pos, weights, dest, lo, hi, kind, norm, cutoff, width, slab, out):
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
def _moment_table(kind, norm, cutoff, width, r_nodes, rho_src, dz_vals, gl_x, gl_w, u_x, u_w, out):
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
def _accumulate_rz(dr, nr, z0, dz_cell, nz, rho_s, z_s, weights, codes, dest, lo, hi,
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
def _accumulate_rz_gaussian(dr, nr, z0, dz_cell, nz, rho_s, z_s, weights, codes, dest, norm, cutoff, width,
                            gl_x, gl_w, u_x, u_w, nchunks, out):
    """The Gaussian's axisymmetric accumulation, exact like :func:`_accumulate_rz` but faster:
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


# ----------------------------------------------------------------------------- sources

def particle_weights(mass, vel):
    """(n, 10) particle block: m, m v, m v v (xx yy zz xy xz yz) in the basis ``vel`` is given in."""
    m = np.asarray(mass, float)
    v = np.asarray(vel, float)
    return np.column_stack([m, m[:, None] * v,
                            m * v[:, 0] * v[:, 0], m * v[:, 1] * v[:, 1], m * v[:, 2] * v[:, 2],
                            m * v[:, 0] * v[:, 1], m * v[:, 0] * v[:, 2], m * v[:, 1] * v[:, 2]])


def to_cylindrical(pos, vectors):
    """rho (m), theta, and ``vectors`` (n, 3) in the local (r, theta, z) basis at each position."""
    x, y = pos[:, 0], pos[:, 1]
    rho = np.hypot(x, y)
    safe = np.where(rho > 0, rho, 1.0)
    c, s = np.where(rho > 0, x / safe, 1.0), np.where(rho > 0, y / safe, 0.0)
    out = np.column_stack([c * vectors[:, 0] + s * vectors[:, 1], -s * vectors[:, 0] + c * vectors[:, 1],
                           vectors[:, 2]])
    return rho, out, c, s


def line_points_needed(branch_length, kernel: Kernel) -> np.ndarray:
    """Gauss-Legendre points for each contact's line integral: 2 + ceil(2 L / s), s the kernel's
    length scale (sqrt(2) w for the Gaussian, c / 3 for Lucy); 2 to 16. A branch as long as the
    kernel's standard deviation gets 4 points, paper B's w = rb/2 with L = 2 rb gets 8."""
    scale = math.sqrt(2.0) * kernel.width if kernel.kind == GAUSSIAN else kernel.cutoff / 3.0
    return np.clip(2 + np.ceil(2.0 * np.asarray(branch_length, float) / scale), 2, 16).astype(int)


def contact_points(pos_i, pos_j, force, n_s=None, kernel: Kernel | None = None):
    """Quadrature points along each branch (r_j -> r_i) and the tensor weights w_s f (x) b.

    ``n_s``: points per contact (int), or None to choose per contact by
    :func:`line_points_needed` for ``kernel``. Returns (points (k, 3), tensors (k, 3, 3))."""
    pos_i = np.ascontiguousarray(pos_i, float)
    pos_j = np.ascontiguousarray(pos_j, float)
    force = np.ascontiguousarray(force, float)
    if n_s is None:
        if kernel is None:
            raise ValueError("contact_points needs n_s or the kernel")
        need = line_points_needed(np.linalg.norm(pos_i - pos_j, axis=1), kernel)
    else:
        need = np.full(len(pos_i), int(n_s))
    need = need.astype(np.int64)
    start = np.concatenate([[0], np.cumsum(need)]).astype(np.int64)
    nmax = int(need.max(initial=1))
    nodes = np.zeros((nmax + 1, nmax))
    weights = np.zeros((nmax + 1, nmax))
    for n in np.unique(need):
        nodes[n, :n], weights[n, :n] = gl_line_points(int(n))
    pts = np.empty((start[-1], 3))
    tens = np.empty((start[-1], 3, 3))
    _line_sources(pos_i, pos_j, force, need, start, nodes, weights, pts, tens)
    return pts, tens


@njit(cache=True)
def _line_sources(pos_i, pos_j, force, need, start, nodes, weights, pts, tens):
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


def _z_ranges(z_sorted, z_nodes, cutoff):
    return (np.searchsorted(z_sorted, z_nodes - cutoff, "left").astype(np.int64),
            np.searchsorted(z_sorted, z_nodes + cutoff, "right").astype(np.int64))


@njit(parallel=True, cache=True)
def _to_local_rz(pts, tens, x0, y0, pos, local):
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


# ----------------------------------------------------------------------------- grids

class CartesianGrid:
    """Regular grid of ``shape`` (nx, ny, nz) cells over [lo, hi] (m); fields at cell centres.

    ``slab=True`` (a quasi-2D slab silo, ny = 1, y from lo to hi its thickness): fields are
    averages through the slab, the kernel integrated over y divided by the thickness, so the
    whole mass is kept however thin the slab is against the kernel."""

    kind = "cartesian"

    def __init__(self, lo, hi, shape, slab: bool = False):
        self.lo = np.asarray(lo, float)
        self.hi = np.asarray(hi, float)
        self.shape = np.asarray(shape, np.int64)
        if self.lo.shape != (3,) or self.hi.shape != (3,) or self.shape.shape != (3,):
            raise ValueError("a Cartesian grid needs lo, hi and shape of length 3")
        if np.any(self.hi <= self.lo) or np.any(self.shape < 1):
            raise ValueError("grid: hi must exceed lo and every count be >= 1")
        if slab and self.shape[1] != 1:
            raise ValueError("a slab grid has one cell through the slab (ny = 1)")
        self.slab = bool(slab)
        self.spacing = (self.hi - self.lo) / self.shape

    def axes(self) -> dict:
        return {k: self.lo[a] + (np.arange(self.shape[a]) + 0.5) * self.spacing[a] for a, k in enumerate("xyz")}

    @property
    def cell_volume(self) -> float:
        return float(np.prod(self.spacing))

    def cell_volumes(self):
        return np.full(tuple(self.shape[::-1]), self.cell_volume)

    def accumulate(self, kernel: Kernel, pos, weights, dest, nfields, codes=None):
        order = np.argsort(pos[:, 2], kind="stable")
        z_nodes = self.axes()["z"]
        lo, hi = _z_ranges(pos[order, 2], z_nodes, kernel.cutoff)
        out = np.zeros((*self.shape[::-1], nfields))
        _accumulate_cartesian(self.lo, self.spacing, self.shape, np.ascontiguousarray(pos[order]),
                              np.ascontiguousarray(weights[order]), np.ascontiguousarray(dest[order]), lo, hi,
                              kernel.kind, kernel.norm, kernel.cutoff, kernel.width, self.slab, out)
        return out[..., None]

    def particle_frame(self, pos, vel):
        return pos, vel

    def contact_frame(self, pts, tens):
        return pts, tens.reshape(-1, 9)

    def combine(self, out, codes):
        return out[..., 0]


class AxisymmetricGrid:
    """(r, z) grid: ``nr`` cells over 0..r_max about the z axis through (x0, y0), ``nz`` cells
    over z_lo..z_hi; fields are azimuthal averages per unit volume at cell centres.

    ``method``: ``"exact"`` (every source against every node within reach, moments by
    quadrature: agrees with a brute-force sum to round-off) or ``"lattice"`` (sources spread
    onto a lattice ``refine`` times finer, tabulated moments, BLAS: many times faster for large
    frames, with a small interpolation error; see :mod:`postprocess.cg_lattice`)."""

    kind = "rz"
    METHODS = ("exact", "lattice")

    def __init__(self, r_max: float, z_lo: float, z_hi: float, nr: int, nz: int, x0: float = 0.0, y0: float = 0.0,
                 method: str = "exact", refine: int = 2):
        if not (r_max > 0 and z_hi > z_lo and nr >= 1 and nz >= 1):
            raise ValueError("RZ grid: r_max > 0, z_hi > z_lo, nr and nz >= 1")
        if method not in self.METHODS:
            raise ValueError(f"RZ grid: method must be one of {', '.join(self.METHODS)}")
        if method == "lattice" and (refine < 2 or refine % 2):
            raise ValueError("RZ grid: the lattice refinement must be an even number >= 2")
        self.r_max, self.z_lo, self.z_hi, self.nr, self.nz = float(r_max), float(z_lo), float(z_hi), int(nr), int(nz)
        self.x0, self.y0 = float(x0), float(y0)
        self.dr = self.r_max / self.nr
        self.dz = (self.z_hi - self.z_lo) / self.nz
        self.method, self.refine = method, int(refine)
        self._lattices = {}

    def axes(self) -> dict:
        return {"r": (np.arange(self.nr) + 0.5) * self.dr, "z": self.z_lo + (np.arange(self.nz) + 0.5) * self.dz}

    def cell_volumes(self):
        """Volume of each annular cell (nz, nr), m3: pi (r_out^2 - r_in^2) dz."""
        edges = np.arange(self.nr + 1) * self.dr
        ring = np.pi * (edges[1:] ** 2 - edges[:-1] ** 2) * self.dz
        return np.broadcast_to(ring, (self.nz, self.nr)).copy()

    def _shift(self, pos):
        p = np.asarray(pos, float).copy()
        p[:, 0] -= self.x0
        p[:, 1] -= self.y0
        return p

    def particle_frame(self, pos, vel):
        p = self._shift(pos)
        rho, v_cyl, _, _ = to_cylindrical(p, np.asarray(vel, float))
        return np.column_stack([rho, np.zeros_like(rho), p[:, 2]]), v_cyl

    def contact_frame(self, pts, tens):
        """Contact points as (rho, 0, z) and their tensors in the local (r, theta, z) basis (k, 9)."""
        pos = np.empty((len(pts), 3))
        local = np.empty((len(pts), 9))
        _to_local_rz(np.ascontiguousarray(pts, float), np.ascontiguousarray(tens, float).reshape(-1, 9),
                     self.x0, self.y0, pos, local)
        return pos, local

    def accumulate(self, kernel: Kernel, pos, weights, dest, nfields, codes):
        if self.method == "lattice":
            from .cg_lattice import RingMomentLattice

            if kernel not in self._lattices:             # tables: once per kernel, reused by every frame
                self._lattices[kernel] = RingMomentLattice(self, kernel, self.refine)
            return self._lattices[kernel].accumulate(pos, weights, dest, nfields, codes)
        order = np.argsort(pos[:, 2], kind="stable")
        z_nodes = self.axes()["z"]
        lo, hi = _z_ranges(pos[order, 2], z_nodes, kernel.cutoff)
        if kernel.kind == GAUSSIAN:
            import numba
            nchunks = max(1, min(numba.get_num_threads(), len(pos) // 1000 + 1))
            parts = np.zeros((nchunks, self.nz, self.nr, nfields, 2))
            _accumulate_rz_gaussian(self.dr, self.nr, self.z_lo, self.dz, self.nz,
                                    np.ascontiguousarray(pos[order, 0]), np.ascontiguousarray(pos[order, 2]),
                                    np.ascontiguousarray(weights[order]), np.asarray(codes, np.int64),
                                    np.ascontiguousarray(dest[order]), kernel.norm, kernel.cutoff, kernel.width,
                                    _GL_A_X, _GL_A_W, *_GL_U[GAUSSIAN], nchunks, parts)
            return parts.sum(axis=0)
        out = np.zeros((self.nz, self.nr, nfields, 2))
        _accumulate_rz(self.dr, self.nr, self.z_lo, self.dz, self.nz, np.ascontiguousarray(pos[order, 0]),
                       np.ascontiguousarray(pos[order, 2]), np.ascontiguousarray(weights[order]),
                       np.asarray(codes, np.int64), np.ascontiguousarray(dest[order]), lo, hi,
                       kernel.kind, kernel.norm, kernel.cutoff, kernel.width, _GL_A_X, _GL_A_W, *_GL_U[kernel.kind], out)
        return out

    def combine(self, out, codes):
        """Mix the two slots of code-2 columns into node-basis components (see module docstring)."""
        res = out[..., 0].copy()
        if len(codes) == len(PARTICLE_CODES) and np.array_equal(codes, PARTICLE_CODES):
            step = len(PARTICLE_CODES)
            for b in range(out.shape[-2] // step):             # rr, tt of each particle block
                rr, tt = b * step + 4, b * step + 5
                res[..., rr] = out[..., rr, 0] + out[..., tt, 1]
                res[..., tt] = out[..., rr, 1] + out[..., tt, 0]
        else:                                                  # contact tensor 00 01 02 10 11 12 20 21 22
            res[..., 0] = out[..., 0, 0] + out[..., 4, 1]
            res[..., 4] = out[..., 0, 1] + out[..., 4, 0]
            res[..., 1] = out[..., 1, 0] - out[..., 3, 1]
            res[..., 3] = out[..., 3, 0] - out[..., 1, 1]
        return res


# ----------------------------------------------------------------------------- one frame

def coarse_grain_frame(grid, kernel: Kernel, pos, vel, mass, species=None, n_species: int = 0,
                       contacts=None, n_s: int | None = None) -> dict:
    """Raw kernel sums of one frame: ``particles`` (grid..., 10 * (1 + n_species)) and, with
    ``contacts`` = (pos_i, pos_j, force_on_i), ``contact`` (grid..., 9)."""
    pos = np.asarray(pos, float)
    spos, svel = grid.particle_frame(pos, np.asarray(vel, float))
    weights = particle_weights(mass, svel)
    ncol = len(PARTICLE_COLUMNS)
    dest = np.zeros((len(pos), 2), np.int64)
    if species is not None and n_species:
        sp = np.asarray(species, np.int64)
        if sp.min(initial=0) < 0 or sp.max(initial=0) >= n_species:
            raise ValueError(f"species indices must lie in 0..{n_species - 1}")
        dest[:, 1] = ncol * (1 + sp)
    else:
        dest[:, 1] = -1
    nfields = ncol * (1 + (n_species if species is not None else 0))
    raw = grid.accumulate(kernel, spos, weights, dest, nfields, PARTICLE_CODES)
    out = {"particles": grid.combine(raw, PARTICLE_CODES)}
    if contacts is not None:
        pi, pj, f = contacts
        pts, tens = contact_points(pi, pj, f, n_s, kernel)
        cpos, cw = grid.contact_frame(pts, tens)
        cdest = np.zeros((len(cpos), 1), np.int64)
        raw = grid.accumulate(kernel, cpos, cw, cdest, 9, CONTACT_CODES)
        out["contact"] = grid.combine(raw, CONTACT_CODES)
    return out


def fields_from_sums(sums: dict, particle_density: float | None = None, n_species: int = 0,
                     species_density=None) -> dict:
    """Continuum fields from (time-averaged) kernel sums: rho, phi, P, V, kinetic stress and
    pressure, partial fields per species, contact stress and pressure. ``species_density``
    (kg/m3 per species): the partial solid fractions are rho_a / rho_a,p and the solid fraction
    their sum (species of different densities, e.g. scaled dust); else rho / ``particle_density``."""
    part = sums["particles"]
    ncol = len(PARTICLE_COLUMNS)
    rho = part[..., 0]
    P = part[..., 1:4]
    with np.errstate(invalid="ignore", divide="ignore"):
        V = np.where(rho[..., None] > 0, P / rho[..., None], 0.0)
    mvv = part[..., 4:10]
    vv = np.stack([V[..., 0] * V[..., 0], V[..., 1] * V[..., 1], V[..., 2] * V[..., 2],
                   V[..., 0] * V[..., 1], V[..., 0] * V[..., 2], V[..., 1] * V[..., 2]], axis=-1)
    kin = mvv - rho[..., None] * vv
    f = {"rho": rho, "momentum": P, "velocity": V, "kinetic_stress": kin,
         "kinetic_pressure": kin[..., :3].sum(axis=-1) / 3.0}
    if particle_density:
        f["solid_fraction"] = rho / particle_density
    if n_species:
        rho_a, kin_a = [], []
        idx = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
        for s in range(n_species):
            blk = part[..., ncol * (1 + s): ncol * (2 + s)]
            ra, Pa, mvva = blk[..., 0], blk[..., 1:4], blk[..., 4:10]
            comps = [mvva[..., k] - V[..., a] * Pa[..., b] - Pa[..., a] * V[..., b] + ra * V[..., a] * V[..., b]
                     for k, (a, b) in enumerate(idx)]
            rho_a.append(ra)
            kin_a.append(np.stack(comps, axis=-1))
        f["rho_species"] = np.stack(rho_a, axis=-1)
        f["kinetic_stress_species"] = np.stack(kin_a, axis=-2)
        f["kinetic_pressure_species"] = f["kinetic_stress_species"][..., :3].sum(axis=-1) / 3.0
        if species_density is not None:
            f["solid_fraction_species"] = f["rho_species"] / np.asarray(species_density, float)
            f["solid_fraction"] = f["solid_fraction_species"].sum(axis=-1)
        elif particle_density:
            f["solid_fraction_species"] = f["rho_species"] / particle_density
    if "contact" in sums:
        c = sums["contact"]
        f["contact_stress"] = c
        f["contact_pressure"] = (c[..., 0] + c[..., 4] + c[..., 8]) / 3.0
    return f


def gl_line_points(n_s: int):
    """Gauss-Legendre points and weights on [0, 1] for the contact line integral."""
    x, w = np.polynomial.legendre.leggauss(n_s)
    return 0.5 * (x + 1.0), 0.5 * w


# ----------------------------------------------------------------------------- over frames

def species_of(frame, by: str | None, classes=None):
    """Species index per particle and the class labels: by ``type``, by ``radius`` (distinct
    radii, rounded to 1e-9 m; or the given ``classes``), or None (no partial fields)."""
    if by is None:
        return None, []
    if by == "type":
        values = frame.column("type")
    elif by == "radius":
        values = np.round(frame.radii(), 9)
    else:
        raise ValueError("species must be 'type', 'radius' or None")
    labels = np.unique(values) if classes is None else np.asarray(classes)
    idx = np.searchsorted(labels, values)
    idx = np.clip(idx, 0, len(labels) - 1)
    if np.any(labels[idx] != values):
        raise ValueError(f"{frame.source}: a particle's {by} is not among the species classes {list(labels)}")
    return idx, list(labels)


def liggghts_contacts(contacts_frame, with_ids: bool = False):
    """(pos_i, pos_j, force on i) from a LIGGGHTS pair/gran/local frame (pos and force columns)
    or wall/gran/local frame (pos: wall point then particle; branch from the wall point).
    ``with_ids``: also (id_i, id_j), id_j None for a wall frame (needs the id columns).

    LIGGGHTS reports the force on the first particle of a pair (checked on a settled bed: the
    normal force points from particle 2 to particle 1 in 99 % of contacts, the rest being
    damping-dominated separating contacts) and, for walls, the force on the particle."""
    d = contacts_frame.data
    if "fx" not in d or not ("x1" in d):
        raise ValueError(f"{contacts_frame.source}: contact stress needs pos and force columns "
                         "(compute pair/gran/local pos id force)")
    wall = "xw" in d   # wall contact: the branch runs from the contact point on the wall to the centre
    keep = (d["periodic"].to_numpy() == 0) if "periodic" in d and not wall else np.ones(len(d), bool)
    rows = d.loc[keep]
    out = (rows[["x1", "y1", "z1"]].to_numpy(float), rows[["xw", "yw", "zw"] if wall else ["x2", "y2", "z2"]]
           .to_numpy(float), rows[["fx", "fy", "fz"]].to_numpy(float))
    if not with_ids:
        return out
    names = ["id1"] if wall else ["id1", "id2"]
    if any(n not in d for n in names):
        raise ValueError(f"{contacts_frame.source}: clump contact stress needs the {' and '.join(names)} column(s)")
    return out + (rows["id1"].to_numpy(np.int64), None if wall else rows["id2"].to_numpy(np.int64))


def _joined_contacts(*frames, atoms=None, centres=None):
    """Concatenate the (pos_i, pos_j, force) of several contact frames (pairs, walls); None if
    none. With ``atoms`` and its clumps' ``centres`` (:func:`clump_bodies.body_centres`), the
    branches run through the clumps' centroids."""
    if centres is not None and centres[1] is not None:
        parts = [body_contacts(atoms, *liggghts_contacts(f, with_ids=True), centres=centres)
                 for f in frames if f is not None]
    else:
        parts = [liggghts_contacts(f) for f in frames if f is not None]
    if not parts:
        return None
    return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))


class CoarseGraining:
    """Coarse-grain frames onto a grid; time-average (default) or keep per-frame fields.

        cg = CoarseGraining(grid, gaussian(w), particle_density=7520, species="radius")
        cg.run(read_frames(dumps), contacts=read_frames(local, columns=...))
        ds = cg.dataset()          # xarray.Dataset; ds.to_netcdf("fields.nc")

    Frames need positions, velocities, radius, and mass (or ``particle_density`` to compute
    it from the radius). Memory: one frame, plus the grid sums (times frames if per_frame).
    """

    def __init__(self, grid, kernel: Kernel, particle_density: float | None = None, species: str | None = None,
                 species_classes=None, per_frame: bool = False, n_s: int | None = None):
        self.grid, self.kernel, self.rho_p = grid, kernel, particle_density
        self.species, self.classes, self.per_frame, self.n_s = species, species_classes, per_frame, n_s
        self.sum = None
        self.class_density = None               # kg/m3 per species class, from the first frame
        self.frames: list[dict] = []
        self.steps: list[int] = []

    def _mass(self, frame):
        if "mass" in frame.data:
            return frame.column("mass").astype(float)
        if not self.rho_p:
            raise ValueError(f"{frame.source}: no mass column; give particle_density")
        return self.rho_p * 4.0 / 3.0 * np.pi * frame.radii() ** 3

    def add_frame(self, frame, contacts=None, wall_contacts=None):
        """Add one frame's sums; clumps (a ``mol`` column) are coarse-grained as rigid bodies
        (:mod:`postprocess.clump_bodies`)."""
        centres = body_centres(frame) if "mol" in frame.data else None
        joined = _joined_contacts(contacts, wall_contacts, atoms=frame, centres=centres)
        if centres is not None and centres[1] is not None:
            frame = body_frame(frame, self.rho_p, centres)
        sp, labels = species_of(frame, self.species, self.classes)
        if self.species is not None and self.classes is None:
            self.classes = labels              # the first frame fixes the classes
        if self.species is not None and self.class_density is None and "mass" in frame.data:
            volume = frame.column("volume").astype(float) if "volume" in frame.data else \
                4.0 / 3.0 * np.pi * frame.radii() ** 3
            mass = frame.column("mass").astype(float)
            k = len(self.classes)
            m, v = np.bincount(sp, mass, k), np.bincount(sp, volume, k)
            if np.all(v > 0):                  # each class's mass per solid volume
                self.class_density = m / v
        sums = coarse_grain_frame(self.grid, self.kernel, frame.positions(), frame.velocities(), self._mass(frame),
                                  sp, len(self.classes or []), joined, self.n_s)
        if self.per_frame:
            self.frames.append(sums)
        if self.sum is None:
            self.sum = {k: v.copy() for k, v in sums.items()}
        else:
            for k in self.sum:
                self.sum[k] += sums[k]
        self.steps.append(int(frame.timestep))

    def run(self, frames, contacts=None, wall_contacts=None):
        """Coarse-grain ``frames``; with ``contacts`` (and ``wall_contacts``), only the frames that
        have a contact frame of the same timestep (all streams in increasing step order)."""
        walls = StepCursor(wall_contacts) if wall_contacts is not None else None
        for frame, c in paired(frames, contacts):
            self.add_frame(frame, c, walls.at(frame.timestep) if walls else None)
        if not self.steps:
            raise ValueError("coarse graining: no frames")
        return self

    def fields(self, k: int | None = None) -> dict:
        """Time-averaged fields, or those of frame ``k`` (per_frame runs)."""
        if k is None:
            sums = {key: v / len(self.steps) for key, v in self.sum.items()}
        else:
            sums = self.frames[k]
        return fields_from_sums(sums, self.rho_p, len(self.classes or []), self.class_density)

    def dataset(self, k: int | None = None):
        """The fields as an xarray Dataset with coordinates and units (SI)."""
        import xarray as xr

        f = self.fields(k)
        axes = self.grid.axes()
        dims = ("z", "r") if self.grid.kind == "rz" else ("z", "y", "x")
        comps = "rtz" if self.grid.kind == "rz" else "xyz"
        coords = {d: axes[d] for d in dims}
        sym = [comps[a] + comps[b] for a, b in [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]]
        full = [comps[a] + comps[b] for a in range(3) for b in range(3)]
        data = {"rho": (dims, f["rho"], "kg m-3", "mass density"),
                "momentum": (dims + ("component",), f["momentum"], "kg m-2 s-1", "momentum density"),
                "velocity": (dims + ("component",), f["velocity"], "m s-1", "velocity P/rho"),
                "kinetic_stress": (dims + ("sym",), f["kinetic_stress"], "Pa", "kinetic stress"),
                "kinetic_pressure": (dims, f["kinetic_pressure"], "Pa", "trace of the kinetic stress / 3")}
        if "solid_fraction" in f:
            data["solid_fraction"] = (dims, f["solid_fraction"], "1", "rho / rho_p" if self.class_density is None
                                      else "sum over species of rho_a / rho_a,p")
        if "contact_stress" in f:
            data["contact_stress"] = (dims + ("tensor",), f["contact_stress"], "Pa", "contact stress")
            data["contact_pressure"] = (dims, f["contact_pressure"], "Pa", "trace of the contact stress / 3")
        if "rho_species" in f:
            data["rho_species"] = (dims + ("species",), f["rho_species"], "kg m-3", "partial density")
            data["kinetic_stress_species"] = (dims + ("species", "sym"), f["kinetic_stress_species"], "Pa",
                                              "partial kinetic stress")
            data["kinetic_pressure_species"] = (dims + ("species",), f["kinetic_pressure_species"], "Pa",
                                                "partial kinetic pressure")
            if "solid_fraction_species" in f:
                data["solid_fraction_species"] = (dims + ("species",), f["solid_fraction_species"], "1",
                                                  "partial solid fraction")
        ds = xr.Dataset({name: xr.DataArray(v, dims=d, attrs={"units": u, "long_name": ln})
                         for name, (d, v, u, ln) in data.items()},
                        coords={**coords, "component": list(comps), "sym": sym, "tensor": full})
        if "rho_species" in f:
            ds = ds.assign_coords(species=[float(c) for c in self.classes])
        ds.attrs.update({"grid": self.grid.kind, "frames": len(self.steps), "first_step": self.steps[0],
                         "last_step": self.steps[-1], "contact_line_points": "adaptive: 2 + ceil(2 L / s)" if self.n_s is None else self.n_s,
                         **{f"kernel_{k}": v for k, v in self.kernel.describe().items()}})
        if self.class_density is not None:
            ds.attrs["species_density_kg_m3"] = [float(v) for v in self.class_density]
        if getattr(self.grid, "slab", False):
            ds.attrs["slab_thickness_m"] = float(self.grid.spacing[1])
            ds.attrs["slab_average"] = "kernel integrated over y, divided by the slab thickness"
        if self.grid.kind == "rz":
            ds.attrs["rz_method"] = self.grid.method
            if self.grid.method == "lattice":
                ds.attrs["lattice_refine"] = self.grid.refine
        return ds
