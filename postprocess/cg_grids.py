"""Coarse-graining grids and the sources laid on them (lengths in m).

* :class:`CartesianGrid`: cell centres of a regular grid; with ``slab=True`` (one cell across a
  slab silo of thickness T, a planar (x, z) grid) averages through the thickness,
  sum_i ... phi2(x - r_i) / T with phi2 the kernel integrated over y
  (``cg_kernels.slab_kernel_value``), whatever T is against the kernel width w.
* :class:`AxisymmetricGrid`: (r, z) nodes; the field is the azimuthal average of the 3D field,
  (1/2 pi) int F(r, theta, z) dtheta, per unit volume, with vectors and tensors in the local
  (r, theta, z) basis. The average is taken analytically over the source's azimuth relative to
  the node: for a source at radius rho and a node at r, the kernel moments <phi>, <phi cos a>,
  <phi cos^2 a>, <phi cos 2a> over the relative azimuth a are integrated exactly over the
  kernel's support |a| < a_c by Gauss-Legendre (smooth integrand: < 1e-12 relative), or
  tabulated on a finer lattice (``method="lattice"``, :mod:`postprocess.cg_lattice`).

Sources: :func:`particle_weights` (m, m v, m v v of each particle: kg, kg m/s, kg m2/s2) and
:func:`contact_points` (the Gauss-Legendre points of each contact's branch line integral, with
tensor weights w_s f (x) b in N m). A grid's ``accumulate`` sums them with the kernel (per m3)
through the numba cores of :mod:`postprocess.cg_cores`.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .cg_cores import (GL_A_W, GL_A_X, GL_U, PARTICLE_CODES, accumulate_cartesian, accumulate_rz,
                       accumulate_rz_gaussian, line_sources, to_local_rz)
from .cg_kernels import GAUSSIAN, Kernel
from .cg_lattice import RingMomentLattice


# ----------------------------------------------------------------------------- sources

def particle_weights(mass, vel):
    """(n, 10) particle block: m, m v, m v v (xx yy zz xy xz yz) in the basis ``vel`` is given in."""
    m = np.asarray(mass, float)
    v = np.asarray(vel, float)
    return np.column_stack([m, m[:, None] * v,
                            m * v[:, 0] * v[:, 0], m * v[:, 1] * v[:, 1], m * v[:, 2] * v[:, 2],
                            m * v[:, 0] * v[:, 1], m * v[:, 0] * v[:, 2], m * v[:, 1] * v[:, 2]])


def to_cylindrical(pos, vectors):
    """rho (m), ``vectors`` (n, 3) in the local (r, theta, z) basis at each position, and
    cos theta, sin theta (on the axis: 1, 0)."""
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
    line_sources(pos_i, pos_j, force, need, start, nodes, weights, pts, tens)
    return pts, tens


def gl_line_points(n_s: int):
    """Gauss-Legendre points and weights on [0, 1] for the contact line integral."""
    x, w = np.polynomial.legendre.leggauss(n_s)
    return 0.5 * (x + 1.0), 0.5 * w


def _z_ranges(z_sorted, z_nodes, cutoff):
    """Index ranges [lo, hi) of the sources (sorted by z) within ``cutoff`` of each node plane."""
    return (np.searchsorted(z_sorted, z_nodes - cutoff, "left").astype(np.int64),
            np.searchsorted(z_sorted, z_nodes + cutoff, "right").astype(np.int64))


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
    def cells(self) -> int:
        """How many cells (a Python int: no overflow however absurd the counts)."""
        return math.prod(int(n) for n in self.shape)

    def describe(self) -> str:
        nx, ny, nz = (int(n) for n in self.shape)
        if self.slab:
            return f"a slab's planar grid of {nx} x {nz} (x, z) cells"
        return f"a Cartesian grid of {nx} x {ny} x {nz} (x, y, z) cells"

    def sums_bytes(self, kernel: Kernel, nfields: int, nsources: int) -> int:
        """Bytes one :meth:`accumulate` of ``nfields`` columns from ``nsources`` sources holds at
        once (float64): the sums on every cell, the node planes' source ranges, the sorted sources."""
        return 8 * (self.cells * nfields + 3 * int(self.shape[2]) + nsources * (2 * nfields + 8))

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
        accumulate_cartesian(self.lo, self.spacing, self.shape, np.ascontiguousarray(pos[order]),
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

    @property
    def cells(self) -> int:
        return self.nr * self.nz

    def describe(self) -> str:
        return f"an (r, z) grid of {self.nr} x {self.nz} cells" + (
            f" (lattice method, refine {self.refine})" if self.method == "lattice" else "")

    def sums_bytes(self, kernel: Kernel, nfields: int, nsources: int) -> int:
        """Bytes one :meth:`accumulate` of ``nfields`` columns from ``nsources`` sources holds at
        once (float64): the two slots of every column on every node, per thread for the Gaussian,
        their sum and the combined sums; the lattice's tables and lattice
        (``RingMomentLattice.estimate_bytes``)."""
        sources = 8 * nsources * (2 * nfields + 8)
        if self.method == "lattice":
            return RingMomentLattice.estimate_bytes(self, kernel, self.refine, nfields, nsources) + sources
        nchunks = max(1, min(numba.get_num_threads(), nsources // 1000 + 1)) if kernel.kind == GAUSSIAN else 0
        return 8 * (((nchunks + 1) * 2 + 1) * self.cells * nfields + self.nr + 3 * self.nz) + sources

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
        to_local_rz(np.ascontiguousarray(pts, float), np.ascontiguousarray(tens, float).reshape(-1, 9),
                    self.x0, self.y0, pos, local)
        return pos, local

    def accumulate(self, kernel: Kernel, pos, weights, dest, nfields, codes):
        if self.method == "lattice":
            if kernel not in self._lattices:             # tables: once per kernel, reused by every frame
                self._lattices[kernel] = RingMomentLattice(self, kernel, self.refine)
            return self._lattices[kernel].accumulate(pos, weights, dest, nfields, codes)
        order = np.argsort(pos[:, 2], kind="stable")
        z_nodes = self.axes()["z"]
        lo, hi = _z_ranges(pos[order, 2], z_nodes, kernel.cutoff)
        if kernel.kind == GAUSSIAN:
            nchunks = max(1, min(numba.get_num_threads(), len(pos) // 1000 + 1))
            parts = np.zeros((nchunks, self.nz, self.nr, nfields, 2))
            accumulate_rz_gaussian(self.dr, self.nr, self.z_lo, self.dz, self.nz,
                                   np.ascontiguousarray(pos[order, 0]), np.ascontiguousarray(pos[order, 2]),
                                   np.ascontiguousarray(weights[order]), np.asarray(codes, np.int64),
                                   np.ascontiguousarray(dest[order]), kernel.norm, kernel.cutoff, kernel.width,
                                   GL_A_X, GL_A_W, *GL_U[GAUSSIAN], nchunks, parts)
            return parts.sum(axis=0)
        out = np.zeros((self.nz, self.nr, nfields, 2))
        accumulate_rz(self.dr, self.nr, self.z_lo, self.dz, self.nz, np.ascontiguousarray(pos[order, 0]),
                      np.ascontiguousarray(pos[order, 2]), np.ascontiguousarray(weights[order]),
                      np.asarray(codes, np.int64), np.ascontiguousarray(dest[order]), lo, hi,
                      kernel.kind, kernel.norm, kernel.cutoff, kernel.width, GL_A_X, GL_A_W, *GL_U[kernel.kind], out)
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

