"""Fast axisymmetric coarse-graining: sources spread onto a fine (rho, z) lattice, ring moments tabulated.

The exact (r, z) sum (:class:`cg_grids.AxisymmetricGrid` with ``method="exact"``) evaluates
the kernel's azimuthal moments by quadrature for every (source, node) pair: for paper B-sized
frames, most of the time goes there, and contacts (several line-integral points each) are
most of the sources. Here instead:

1. every source (particle or contact point, weights already in the local (r, theta, z) basis)
   is spread onto a lattice of spacing (h_r, h_z) = (dr, dz) / k with 4-point (cubic) Lagrange
   weights in rho and in z. They sum to 1 and reproduce cubic functions of the source
   position, so a smooth kernel sum is reproduced to O(h^4) and mass and momentum are conserved;
2. lattice nodes sit at rho = j h_r (j >= -1) and z = z_lo + j h_z, so the z offset between a
   grid node and a lattice node is a whole number of h_z (k even). The node at rho = -h_r is
   the mirror image through the axis (the signed continuation: <phi cos a> changes sign, the
   other moments do not, as the local basis flips);
3. the moments <phi>, <phi cos a>, <phi cos^2 a> for every (z offset, grid radius, lattice
   radius) come from a table computed once per grid and kernel, by the exact method's own
   quadrature;
4. the deposit is then, for each z offset and each band of grid radii, a dense matrix product
   (BLAS) of the table slice with the lattice's columns.

The truncation of the kernel at its cutoff (the Gaussian is e^-4 of its peak there) is not
smooth, so the error is largest where a node sits near a source's cutoff sphere. It is
measured against the exact method in tests/test_coarse_grain.py and printed by
benchmarks/coarse_graining_speed.py. Memory: the lattice holds every field column on
(k nz) x (k nr) nodes (about 100 MB for 89 columns on a 100 x 300 grid with k = 2).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .cg_cores import GL_A_W, GL_A_X, GL_U, moment_table

# lattice nodes beyond the cutoff that a source's 4-point stencil can reach
_STENCIL = 2


@njit(cache=True)
def _lagrange4(u, out):
    """Cubic Lagrange weights of nodes -1, 0, 1, 2 at u in [0, 1)."""
    out[0] = -u * (u - 1.0) * (u - 2.0) / 6.0
    out[1] = (u + 1.0) * (u - 1.0) * (u - 2.0) / 2.0
    out[2] = -(u + 1.0) * u * (u - 2.0) / 2.0
    out[3] = (u + 1.0) * u * (u - 1.0) / 6.0


@njit(parallel=True, cache=True)
def _spread(rho_s, z_s, weights, dest, inv_hr, inv_hz, zl0, nchunks, out):
    """out[chunk, J, I, dest + c] += Lagrange weights x weights[i, c]; lattice I = 0 is rho = -h_r."""
    n = rho_s.shape[0]
    nlz, nlr = out.shape[1], out.shape[2]
    per = (n + nchunks - 1) // nchunks
    for ch in prange(nchunks):
        lat = out[ch]
        wr = np.empty(4)
        wz = np.empty(4)
        for i in range(ch * per, min(n, (ch + 1) * per)):
            tr = rho_s[i] * inv_hr + 1.0
            tz = (z_s[i] - zl0) * inv_hz
            br = int(math.floor(tr))
            bz = int(math.floor(tz))
            if br - 1 < 0 or br + 2 >= nlr or bz - 1 < 0 or bz + 2 >= nlz:
                continue                 # every stencil node is beyond the cutoff of every grid node
            _lagrange4(tr - br, wr)
            _lagrange4(tz - bz, wz)
            for a in range(4):
                for b in range(4):
                    wab = wz[a] * wr[b]
                    cell = lat[bz - 1 + a, br - 1 + b]
                    for d in range(dest.shape[1]):
                        base = dest[i, d]
                        if base < 0:
                            continue
                        for c in range(weights.shape[1]):
                            cell[base + c] += wab * weights[i, c]


class RingMomentLattice:
    """The lattice and moment tables of one (r, z) grid and kernel; ``refine`` k (even) lattice
    nodes per grid cell and direction. Build once, :meth:`accumulate` any number of frames."""

    def __init__(self, grid, kernel, refine: int = 2, block: int = 16):
        if refine < 2 or refine % 2:
            raise ValueError("lattice refinement must be an even number >= 2")
        self.grid, self.kernel, self.k, self.block = grid, kernel, int(refine), int(block)
        self.hr, self.hz = grid.dr / self.k, grid.dz / self.k
        c = kernel.cutoff
        self.Q, self.padz, self.nlz, self.nlr = self.dimensions(grid, kernel, refine)
        self.zl0 = grid.z_lo - self.padz * self.hz
        r_nodes = (np.arange(grid.nr) + 0.5) * grid.dr
        rho_lat = (np.arange(self.nlr) - 1.0) * self.hr
        dz_vals = np.arange(self.Q + 1) * self.hz
        self.table = np.zeros((3, self.Q + 1, grid.nr, self.nlr))
        moment_table(kernel.kind, kernel.norm, c, kernel.width, r_nodes, rho_lat, dz_vals,
                     GL_A_X, GL_A_W, *GL_U[kernel.kind], self.table)
        # per (|offset|, block of grid radii): the band of lattice radii with a non-zero moment
        self.bands = {}
        for q in range(self.Q + 1):
            for i0 in range(0, grid.nr, self.block):
                i1 = min(grid.nr, i0 + self.block)
                cols = np.nonzero(np.any(self.table[:, q, i0:i1, :] != 0.0, axis=(0, 1)))[0]
                if len(cols):
                    self.bands[q, i0] = (int(cols[0]), int(cols[-1]) + 1)

    @staticmethod
    def dimensions(grid, kernel, refine: int) -> tuple[int, int, int, int]:
        """The z offsets Q (-Q..Q lattice rows within the cutoff), the lattice's padding rows in z,
        and its rows nlz (z) and columns nlr (radius) for ``grid`` and ``kernel``."""
        k = int(refine)
        Q = int(math.ceil(kernel.cutoff / (grid.dz / k)))
        padz = Q + _STENCIL
        nlz = 2 * padz + k * grid.nz + 1
        nlr = int(math.ceil((grid.r_max + kernel.cutoff) / (grid.dr / k))) + 1 + _STENCIL + 1
        return Q, padz, nlz + (-nlz) % k, nlr

    @classmethod
    def estimate_bytes(cls, grid, kernel, refine: int, nfields: int, nsources: int) -> int:
        """Bytes the tables and one :meth:`accumulate` of ``nfields`` columns from ``nsources``
        sources hold at once (float64): the moment table 3 (Q + 1) nr nlr, the lattice per thread
        and its phase copy nlz nlr nfields, and the sums on the grid (six nz nr nfields)."""
        import numba
        Q, _, nlz, nlr = cls.dimensions(grid, kernel, refine)
        nchunks = max(1, min(numba.get_num_threads(), nsources // 20000 + 1))
        cells = grid.nr * grid.nz
        return 8 * (3 * (Q + 1) * grid.nr * nlr + (nchunks + 1) * nlz * nlr * nfields + 6 * cells * nfields)

    def accumulate(self, pos, weights, dest, nfields, codes):
        """Kernel sums in the exact method's layout (nz, nr, nfields, 2) for sources at ``pos``
        (rho, 0, z), whose ``weights`` go to the column blocks ``dest``; ``codes``: each column's
        moment (0 <phi>, 1 <phi cos a>, 2 <phi cos^2 a> and <phi sin^2 a>, 3 <phi cos 2a>)."""
        import numba

        g = self.grid
        nchunks = max(1, min(numba.get_num_threads(), len(pos) // 20000 + 1))
        lat = np.zeros((nchunks, self.nlz, self.nlr, nfields))
        _spread(np.ascontiguousarray(pos[:, 0]), np.ascontiguousarray(pos[:, 2]), np.ascontiguousarray(weights),
                np.ascontiguousarray(dest), 1.0 / self.hr, 1.0 / self.hz, self.zl0, nchunks, lat)
        for ch in range(1, nchunks):
            lat[0] += lat[ch]
        lat = lat[0]
        full = np.resize(np.asarray(codes, np.int64), nfields)
        groups = {0: np.nonzero(np.isin(full, (0, 2, 3)))[0],     # <phi>: codes 0, 2 (sin^2 = 1 - cos^2), 3
                  1: np.nonzero(full == 1)[0],
                  2: np.nonzero(np.isin(full, (2, 3)))[0]}
        res = {m: self._deposit(lat, idx, m) for m, idx in groups.items()}
        out = np.zeros((g.nz, g.nr, nfields, 2))

        def put(m, sel, slot, factor=1.0):
            cols = np.nonzero(np.isin(groups[m], sel))[0]
            out[:, :, groups[m][cols], slot] += factor * res[m][:, :, cols]

        code0, code1, code2, code3 = (np.nonzero(full == c)[0] for c in range(4))
        put(0, code0, 0)
        put(1, code1, 0)
        put(2, code2, 0)
        put(0, code2, 1)
        put(2, code2, 1, -1.0)
        put(2, code3, 0, 2.0)
        put(0, code3, 0, -1.0)
        return out

    def _deposit(self, lat, idx, m):
        """(nz, nr, len(idx)) sums of moment ``m`` over the lattice columns ``idx``."""
        g, k = self.grid, self.k
        ncol = len(idx)
        if ncol == 0:
            return np.zeros((g.nz, g.nr, 0))
        # phases: P[p, I, a, c] = lat[k a + p, I, idx[c]], so that grid row iz meets lattice row
        # k iz + const along a contiguous axis
        P = np.ascontiguousarray(lat[:, :, idx].reshape(self.nlz // k, k, self.nlr, ncol).transpose(1, 2, 0, 3))
        G = np.zeros((g.nr, g.nz * ncol))
        T = self.table[m]
        for s in range(-self.Q, self.Q + 1):
            c0 = self.padz + k // 2 - s                         # lattice row of grid row 0
            p, a = c0 % k, c0 // k
            src = P[p, :, a:a + g.nz, :]
            for i0 in range(0, g.nr, self.block):
                band = self.bands.get((abs(s), i0))
                if band is None:
                    continue
                i1 = min(g.nr, i0 + self.block)
                lo, hi = band
                G[i0:i1] += T[abs(s), i0:i1, lo:hi] @ src[lo:hi].reshape(hi - lo, g.nz * ncol)
        return G.reshape(g.nr, g.nz, ncol).transpose(1, 0, 2)
