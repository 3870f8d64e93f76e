"""Synthetic frame for the coarse-graining benchmark: N spheres (radii uniform in r_min..r_max)
at a solid fraction phi in a cylinder of height/diameter = aspect, with Gaussian velocities
(mean downward flow), and contacts between spheres closer than a threshold chosen to give
the requested number of contacts, with random forces. Positions are random (grains overlap):
the frame has the size and statistics of a real one, not its mechanics."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def synthetic_frame(n=400_000, r_min=0.005, r_max=0.010, phi=0.5, aspect=2.0, contacts=477_085, seed=1):
    rng = np.random.default_rng(seed)
    radius = rng.uniform(r_min, r_max, n)
    volume = (4.0 / 3.0 * np.pi * radius ** 3).sum() / phi
    R = (volume / (2.0 * np.pi * aspect)) ** (1.0 / 3.0)       # V = pi R^2 (2 R aspect)
    H = 2.0 * R * aspect
    rho = R * np.sqrt(rng.random(n))
    th = rng.uniform(0, 2 * np.pi, n)
    pos = np.column_stack([rho * np.cos(th), rho * np.sin(th), rng.uniform(0, H, n)])
    vel = rng.normal(scale=0.05, size=(n, 3)) + [0.0, 0.0, -0.3]
    tree = cKDTree(pos)
    pairs = tree.query_pairs(2 * r_max, output_type="ndarray")
    d = np.linalg.norm(pos[pairs[:, 0]] - pos[pairs[:, 1]], axis=1)
    gap = d / (radius[pairs[:, 0]] + radius[pairs[:, 1]])
    keep = np.argsort(gap)[:contacts]
    i, j = pairs[keep, 0], pairs[keep, 1]
    branch = pos[i] - pos[j]
    force = branch / np.linalg.norm(branch, axis=1)[:, None] * rng.exponential(1.0, len(i))[:, None]
    return {"pos": pos, "vel": vel, "radius": radius, "mass": 7520.0 * 4 / 3 * np.pi * radius ** 3,
            "species": np.minimum(((radius - r_min) / (r_max - r_min) * 7).astype(int), 6),
            "contacts": (pos[i], pos[j], force), "R": R, "H": H}
