"""Coarse-graining speed on a synthetic 400,000-sphere frame (benchmarks/cg_frame.py; radii
5-10 mm, phi 0.5, 477,085 contacts) with a Gaussian of standard deviation 15.6 mm
(w = 15.6 / sqrt 2 mm): every field (density, 7 partial densities, momentum, kinetic and
7 partial kinetic stresses, contact stress) on a 100 x 300 (r, z) grid and on a
60 x 60 x 120 Cartesian grid, against a straightforward NumPy density-only loop on the
same RZ grid. The RZ grid is timed with both methods: ``exact`` (every source against every
node, moments by quadrature) and ``lattice`` (sources on a 2x finer lattice, tabulated moments,
BLAS; its tables are built on the first frame and reused, so its first and later frames are
timed apart), with the lattice's largest deviation from the exact fields. Prints times of one
run each and ratios (read the ratios: this machine is noisy).

    python benchmarks/coarse_graining_speed.py [n_particles]
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from cg_frame import synthetic_frame  # noqa: E402
from postprocess.cg_grids import AxisymmetricGrid, CartesianGrid  # noqa: E402
from postprocess.cg_kernels import gaussian  # noqa: E402
from postprocess.coarse_grain import coarse_grain_frame, fields_from_sums  # noqa: E402

GL_X, GL_W = np.polynomial.legendre.leggauss(16)


def numpy_rz_density(grid, kernel, pos, mass):
    """Straightforward NumPy: per grid row in z, every particle within reach against every r
    node, azimuthal average by the same 16-point Gauss-Legendre rule."""
    ax = grid.axes()
    rho_s = np.hypot(pos[:, 0], pos[:, 1])
    out = np.zeros((grid.nz, grid.nr))
    c2 = kernel.cutoff ** 2
    for iz, z in enumerate(ax["z"]):
        near = np.abs(pos[:, 2] - z) < kernel.cutoff
        rs, dz, m = rho_s[near], z - pos[near, 2], mass[near]
        r = ax["r"][None, :]
        d0 = (r - rs[:, None]) ** 2 + dz[:, None] ** 2
        two = 2 * r * rs[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            cosc = 1 - (c2 - d0) / two
        amax = np.where((two <= 0) | (cosc <= -1), math.pi, np.arccos(np.clip(cosc, -1, 1)))
        amax = np.where(d0 >= c2, 0.0, amax)
        acc = np.zeros_like(d0)
        for x, w in zip(GL_X, GL_W):
            a = 0.5 * amax * (x + 1)
            R2 = d0 + two * (1 - np.cos(a))
            acc += w * np.where(R2 < c2, kernel.norm * np.exp(-R2 / (4 * kernel.width ** 2)), 0.0)
        out[iz] = (m[:, None] * acc * 0.5 * amax / math.pi).sum(axis=0)
    return out


def timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return time.perf_counter() - t0, out


def main(n=400_000):
    t_gen, f = timed(synthetic_frame, n, contacts=int(477_085 * n / 400_000))
    kernel = gaussian(0.0156 / math.sqrt(2))
    R, H = f["R"], f["H"]
    rz = AxisymmetricGrid(R, 0.0, H, 100, 300)
    cart = CartesianGrid([-R, -R, 0.0], [R, R, H], (60, 60, 120))
    print(f"frame: {n} spheres, {len(f['contacts'][0])} contacts, silo R = {R:.3f} m, H = {H:.3f} m "
          f"(generated in {t_gen:.1f} s)")
    small = slice(0, 2000)      # compile the numba kernels first, so times are run times
    coarse_grain_frame(rz, kernel, f["pos"][small], f["vel"][small], f["mass"][small], f["species"][small], 7,
                       tuple(c[small] for c in f["contacts"]))
    coarse_grain_frame(cart, kernel, f["pos"][small], f["vel"][small], f["mass"][small], f["species"][small], 7,
                       tuple(c[small] for c in f["contacts"]))
    fast = AxisymmetricGrid(R, 0.0, H, 100, 300, method="lattice")
    coarse_grain_frame(AxisymmetricGrid(R / 10, 0.0, H / 10, 10, 30, method="lattice"), kernel,
                       f["pos"][small] / 10, f["vel"][small], f["mass"][small], f["species"][small], 7,
                       tuple(c[small] / 10 for c in f["contacts"]))
    args = (f["pos"], f["vel"], f["mass"], f["species"], 7)
    t_lat_first, fast_sums = timed(coarse_grain_frame, fast, kernel, *args, contacts=f["contacts"])
    t_lat, fast_sums = timed(coarse_grain_frame, fast, kernel, *args, contacts=f["contacts"])
    t_lat_p, _ = timed(coarse_grain_frame, fast, kernel, *args)
    t_rz_p, _ = timed(coarse_grain_frame, rz, kernel, *args)
    t_rz, sums = timed(coarse_grain_frame, rz, kernel, *args, contacts=f["contacts"])
    t_c_p, _ = timed(coarse_grain_frame, cart, kernel, *args)
    t_c, _ = timed(coarse_grain_frame, cart, kernel, *args, contacts=f["contacts"])
    t_np, rho_np = timed(numpy_rz_density, rz, kernel, f["pos"], f["mass"])
    err = np.abs(rho_np - sums["particles"][..., 0]).max() / rho_np.max()
    print(f"RZ 100 x 300, all fields + contacts      {t_rz:7.2f} s   (without contacts {t_rz_p:.2f} s)  exact")
    print(f"RZ 100 x 300, all fields + contacts      {t_lat:7.2f} s   (without contacts {t_lat_p:.2f} s; first "
          f"frame with the tables {t_lat_first:.2f} s)  lattice")
    fa, fb = fields_from_sums(sums, 7520.0, 7), fields_from_sums(fast_sums, 7520.0, 7)
    for name in ("rho", "velocity", "kinetic_pressure", "kinetic_pressure_species", "contact_pressure",
                 "contact_stress"):
        a, b = fa[name], fb[name]
        if name == "velocity":                     # V = P / rho: compare where there is mass
            keep = fa["rho"] > 0.05 * fa["rho"].max()
            a, b = a[keep], b[keep]
        print(f"    lattice vs exact {name:26s} max |diff| / max |exact| = {np.abs(a - b).max() / np.abs(a).max():.1e}")
    print(f"ratio exact / lattice (RZ, all fields + contacts): {t_rz / t_lat:.1f}x")
    print(f"Cartesian 60x60x120, all fields + contacts {t_c:7.2f} s   (without contacts {t_c_p:.2f} s)")
    print(f"NumPy RZ density only                    {t_np:7.2f} s   (max difference {err:.1e} of max density)")
    print(f"ratio NumPy density-only / siloflow all fields (RZ): {t_np / t_rz:.1f}x exact, {t_np / t_lat:.1f}x lattice; "
          f"goal: all fields on RZ < 2 s (measured {t_rz:.2f} s exact, {t_lat:.2f} s lattice)")
    print("MercuryCG reference (issue, same machine kind): RZ 376 s (146 s without contacts), "
          f"Cartesian 22 s (10 s): ratios {376 / t_rz:.0f}x RZ exact, {376 / t_lat:.0f}x RZ lattice, "
          f"{22 / t_c:.0f}x Cartesian")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:2]))
