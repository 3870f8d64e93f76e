"""Coarse-graining kernels (3D, normalised, compact), m and m^-3.

* Gaussian (paper B, Eq. 1): phi(R) = A_w exp(-(|R| / 2w)^2) for |R| < 4w, else 0. ``w`` is
  NOT the standard deviation: the untruncated kernel exp(-R^2 / 4w^2) has standard deviation
  sigma = sqrt(2) w per coordinate. A_w normalises the truncated kernel:
  1 / A_w = 4 pi (2w)^3 (sqrt(pi)/4 erf(2) - exp(-4)).
* Lucy (compact polynomial): phi(R) = 105 / (16 pi c^3) (1 + 3q)(1 - q)^3, q = |R|/c < 1.

A slab silo's fields are averages through its thickness T: the 3D kernel integrated over all y,
divided by T (:func:`slab_kernel_value`, closed forms for both kernels), so a slab thinner than
the kernel keeps its whole mass and gives its own density, not the 3D kernel's value at y = 0.

Kernels are plain (kind, A, cutoff, width) tuples so that the numba loops can evaluate them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

GAUSSIAN = 0
LUCY = 1


@dataclass(frozen=True)
class Kernel:
    """``kind`` GAUSSIAN or LUCY; ``width`` w (Gaussian) or c (Lucy), m; ``cutoff`` m; ``norm`` m^-3."""

    kind: int
    width: float
    cutoff: float
    norm: float

    @property
    def name(self) -> str:
        return {GAUSSIAN: "gaussian", LUCY: "lucy"}[self.kind]

    def __call__(self, R):
        """Kernel value (m^-3) at distance(s) ``R`` (m)."""
        R = np.asarray(R, float)
        return np.vectorize(lambda x: kernel_value(self.kind, self.norm, self.cutoff, self.width, x * x))(R)

    def describe(self) -> dict:
        d = {"kernel": self.name, "cutoff_m": self.cutoff}
        if self.kind == GAUSSIAN:
            d.update(w_m=self.width, sigma_m=math.sqrt(2) * self.width,
                     definition="A_w exp(-(R/2w)^2), R < 4w; sigma = sqrt(2) w")
        else:
            d.update(c_m=self.width, definition="105/(16 pi c^3) (1+3q)(1-q)^3, q = R/c < 1")
        return d


def gaussian(w: float) -> Kernel:
    """Paper B's truncated Gaussian of width ``w`` (m), cut off at 4w."""
    if not (w > 0 and math.isfinite(w)):
        raise ValueError("coarse-graining width w must be a positive finite length (m)")
    inv_norm = 4.0 * math.pi * (2.0 * w) ** 3 * (math.sqrt(math.pi) / 4.0 * math.erf(2.0) - math.exp(-4.0))
    return Kernel(GAUSSIAN, w, 4.0 * w, 1.0 / inv_norm)


def lucy(c: float) -> Kernel:
    """Lucy's kernel with support radius ``c`` (m)."""
    if not (c > 0 and math.isfinite(c)):
        raise ValueError("Lucy kernel cutoff c must be a positive finite length (m)")
    return Kernel(LUCY, c, c, 105.0 / (16.0 * math.pi * c ** 3))


def make_kernel(name: str, width: float, unit: str = "m", radius: float | None = None) -> Kernel:
    """A kernel by name; ``width`` in metres or, with ``unit="radius"``, in particle radii (``radius`` m)."""
    if unit == "radius":
        if not radius or radius <= 0:
            raise ValueError("a width in particle radii needs the particle radius")
        width = width * radius
    elif unit != "m":
        raise ValueError("unit must be 'm' or 'radius'")
    if name == "gaussian":
        return gaussian(width)
    if name == "lucy":
        return lucy(width)
    raise ValueError("kernel must be 'gaussian' or 'lucy'")


@njit(cache=True, fastmath=False)
def kernel_value(kind, norm, cutoff, width, R2):
    """Kernel value at squared distance ``R2``."""
    if R2 >= cutoff * cutoff:
        return 0.0
    if kind == GAUSSIAN:
        return norm * math.exp(-R2 / (4.0 * width * width))
    q = math.sqrt(R2) / cutoff
    return norm * (1.0 + 3.0 * q) * (1.0 - q) ** 3


@njit(cache=True, fastmath=False)
def slab_kernel_value(kind, norm, cutoff, width, S2):
    """The kernel integrated over y, int phi(sqrt(S2 + y^2)) dy (m^-2), at squared in-plane
    distance ``S2``; integrates to 1 over the plane."""
    c2 = cutoff * cutoff
    if S2 >= c2:
        return 0.0
    L = math.sqrt(c2 - S2)                      # half the chord through the support
    if kind == GAUSSIAN:
        return norm * math.exp(-S2 / (4.0 * width * width)) * 2.0 * width * math.sqrt(math.pi) \
            * math.erf(L / (2.0 * width))
    # Lucy: (1 + 3q)(1 - q)^3 = 1 - 6 q^2 + 8 q^3 - 3 q^4, q^2 = (S2 + y^2) / c^2
    c = cutoff
    a2 = S2
    poly = L - 6.0 * (a2 * L + L ** 3 / 3.0) / c2 - 3.0 * (a2 * a2 * L + 2.0 * a2 * L ** 3 / 3.0 + L ** 5 / 5.0) / (c2 * c2)
    # int_0^L (a^2 + y^2)^(3/2) dy = L/8 (2 L^2 + 5 a^2) c + 3 a^4 / 8 ln((L + c) / a)
    cube = L / 8.0 * (2.0 * L * L + 5.0 * a2) * c
    if a2 > 0.0:
        cube += 3.0 * a2 * a2 / 8.0 * math.log((L + c) / math.sqrt(a2))
    return 2.0 * norm * (poly + 8.0 * cube / (c2 * c))
