"""Porosity (and solid fraction) in measurement regions, from exact overlap volumes.

Regions (all lengths m, coordinates absolute):

* ``sphere``: a measurement sphere (3D);
* ``cylinder``: a measurement cylinder along ``axis`` from ``t0`` to ``t1`` (a 2D "measure
  circle" of a slab silo extruded through the slab's thickness, or a bulk core of a bed);
* ``circle``: a 2D measure circle in the plane ``coordinate[axis] == plane``; its porosity is
  the area porosity of the section, which :func:`porosity_2d_to_3d` converts as paper A does.

Grains are spheres (``radius`` column). Soft-contact overlaps between grains (a few 1e-3 of a
radius) are counted twice; the error is of the order of the mean overlap over the radius.

Clumps (a ``mol`` column: LIGGGHTS multisphere body ids, -1 or 0 for plain spheres) have
overlapping sub-spheres. Each sub-sphere's clipped volume is weighted with its clump's
V_union / sum V_sphere (exact union volumes, :mod:`siloflow.clumps`); in a circle (2D)
region with the clump's union area / sum of areas of its circles in that plane. This is
exact for clumps wholly inside a region and an approximation for clumps cut by its edge.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from siloflow.clumps import union_area, union_volume

from .analysis_base import FrameAnalysis
from .overlap_volume import solid_area_in_circle, solid_volume_in_cylinder, solid_volume_in_sphere

#: 2 / sqrt(pi sqrt 3) and sqrt 2 / sqrt(pi sqrt 3), the constants of paper A's Eq. 37
XI_A = 2.0 / math.sqrt(math.pi * math.sqrt(3.0))
XI_B = math.sqrt(2.0) / math.sqrt(math.pi * math.sqrt(3.0))


@dataclass(frozen=True)
class MeasureRegion:
    """A measurement region; see the module docstring for the shapes."""

    name: str
    shape: str
    center: tuple[float, float, float]
    radius: float
    axis: int = 1
    t0: float = 0.0
    t1: float = 0.0
    plane: float = 0.0

    def __post_init__(self):
        if self.shape not in ("sphere", "cylinder", "circle"):
            raise ValueError(f"region {self.name}: shape must be sphere, cylinder or circle")
        if not (self.radius > 0 and all(math.isfinite(c) for c in self.center)):
            raise ValueError(f"region {self.name}: radius must be > 0 and the centre finite")
        if self.shape == "cylinder" and not self.t1 > self.t0:
            raise ValueError(f"region {self.name}: cylinder needs t1 > t0")
        if self.axis not in (0, 1, 2):
            raise ValueError(f"region {self.name}: axis must be 0, 1 or 2")

    @property
    def measure(self) -> float:
        """Volume (m3) or, for a circle, area (m2)."""
        if self.shape == "sphere":
            return 4.0 / 3.0 * math.pi * self.radius ** 3
        if self.shape == "cylinder":
            return math.pi * self.radius ** 2 * (self.t1 - self.t0)
        return math.pi * self.radius ** 2

    def solid(self, positions, radii, tree=None, weights=None) -> float:
        """Solid volume (m3) or, for a circle, solid area (m2) inside the region; ``weights``: see
        :func:`grain_weights` (volumes) and :func:`section_weights` (circle sections)."""
        if self.shape == "sphere":
            return solid_volume_in_sphere(self.center, self.radius, positions, radii, tree, weights)
        if self.shape == "cylinder":
            return solid_volume_in_cylinder(self.center, self.radius, self.axis, self.t0, self.t1,
                                            positions, radii, tree, weights)
        return solid_area_in_circle(self.center, self.radius, self.axis, self.plane, positions, radii, tree,
                                    weights)


def porosity_2d_to_3d(eps2d, relative_density: float, reading: str = "as_printed"):
    """Convert a 2D (area) porosity to a 3D (volume) porosity.

    ``as_printed`` (paper A, Eqs. 36-37 as printed): eps3d = 1 - xi (1 - eps2d) with
    xi = a + Dr (a - b), a = 2/sqrt(pi sqrt 3) = 0.857, b = sqrt 2/sqrt(pi sqrt 3) = 0.606,
    Dr = (e_max - e)/(e_max - e_min) in [0, 1]. Limits: xi runs from 0.857 (Dr = 0) to
    1.109 (Dr = 1); for Dr > 0.57 a dense 2D packing gives eps3d < 0, and even at Dr = 0 a
    hexagonal disc packing (eps2d = 0.093) maps to 0.222, not FCC's 0.260. Results outside
    [0, 1] are refused.

    ``hexagonal``: eps3d = 1 - a (1 - eps2d)^(3/2), which maps the hexagonal disc packing
    exactly onto FCC (the lattice the constant a comes from) and ignores Dr.
    """
    eps2d = np.asarray(eps2d, float)
    if np.any((eps2d < 0) | (eps2d > 1)):
        raise ValueError("2D porosity must be within [0, 1]")
    if reading == "as_printed":
        if not 0.0 <= relative_density <= 1.0:
            raise ValueError("relative density Dr must be within [0, 1]")
        xi = XI_A + relative_density * (XI_A - XI_B)
        eps3d = 1.0 - xi * (1.0 - eps2d)
    elif reading == "hexagonal":
        eps3d = 1.0 - XI_A * (1.0 - eps2d) ** 1.5
    else:
        raise ValueError("reading must be 'as_printed' or 'hexagonal'")
    if np.any(eps3d < 0):
        raise ValueError(f"2D -> 3D conversion ({reading}, Dr = {relative_density}) gives a negative "
                         f"3D porosity for 2D porosity {eps2d.min():.4f}: outside the formula's range")
    return eps3d


def relative_density(e: float, e_min: float, e_max: float) -> float:
    """Dr = (e_max - e)/(e_max - e_min) from void ratios (paper A, Eq. 37)."""
    if not e_max > e_min:
        raise ValueError("e_max must exceed e_min")
    return (e_max - e) / (e_max - e_min)


def clump_bodies(frame):
    """(body index per row or -1, number of bodies) of a frame's clumps (``mol`` > 0 shared by
    two or more rows); None when the frame has no clumps."""
    if "mol" not in frame.data or frame.n == 0:
        return None
    mol = frame.column("mol").astype(np.int64)
    keys, inverse, counts = np.unique(mol, return_inverse=True, return_counts=True)
    multi = (keys > 0) & (counts > 1)
    if not multi.any():
        return None
    index = np.cumsum(multi) - 1
    body = np.where(multi[inverse], index[inverse], -1)
    return body, int(multi.sum())


def _rows_by_body(body: np.ndarray, rows: np.ndarray):
    """The given rows grouped by their body index (>= 0), one array per body, by one sort."""
    rows = rows[body[rows] >= 0]
    rows = rows[np.argsort(body[rows], kind="stable")]
    cuts = np.flatnonzero(np.diff(body[rows])) + 1
    return np.split(rows, cuts) if len(rows) else []


_UNION_CACHE: dict = {}


def _clump_key(pos, rad) -> tuple:
    """Shape of a clump up to rigid motion, rounded to 1e-4 of its largest radius (dumps carry about
    six digits; shapes that close share one union volume, good to about 1e-4)."""
    scale = 1e-4 * rad.max()
    d = np.sqrt(((pos[:, None, :] - pos[None, :, :]) ** 2).sum(-1))
    return (tuple(np.round(np.sort(rad) / scale).astype(int)),
            tuple(np.round(np.sort(d[np.triu_indices(len(rad), 1)]) / scale).astype(int)))


def grain_weights(frame) -> np.ndarray | None:
    """Per row, the share of the sphere's volume that is its grain's alone: None for plain spheres;
    for clump sub-spheres V_union / sum V_sphere of their clump (exact union, cached per shape)."""
    found = clump_bodies(frame)
    if found is None:
        return None
    body, _ = found
    pos, rad = frame.positions(), frame.radii()
    weights = np.ones(frame.n)
    for rows in _rows_by_body(body, np.arange(frame.n)):
        key = _clump_key(pos[rows], rad[rows])
        if key not in _UNION_CACHE:
            _UNION_CACHE[key] = union_volume(pos[rows], rad[rows]) / float((4.0 / 3.0 * np.pi * rad[rows] ** 3).sum())
        weights[rows] = _UNION_CACHE[key]
    return weights


def section_weights(frame, axis: int, plane: float) -> np.ndarray | None:
    """Like :func:`grain_weights` for the sections of the grains by the plane
    ``coordinate[axis] == plane``: a clump's union area of its circles there over their summed area."""
    found = clump_bodies(frame)
    if found is None:
        return None
    body, _ = found
    pos, rad = frame.positions(), frame.radii()
    h = np.abs(pos[:, axis] - plane)
    cut = (h < rad) & (body >= 0)
    weights = np.ones(frame.n)
    keep = [k for k in range(3) if k != axis]
    for rows in _rows_by_body(body, np.flatnonzero(cut)):
        if len(rows) < 2:
            continue
        circle = np.sqrt(rad[rows] ** 2 - h[rows] ** 2)
        weights[rows] = union_area(pos[rows][:, keep], circle) / float((np.pi * circle ** 2).sum())
    return weights


def periodic_images(positions: np.ndarray, radii: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """The rows of a box periodic along y over [-period/2, period/2) (m) with the images of the
    grains within their radius of either end, moved by -+ ``period``: (row index into the
    originals, positions (m, 3))."""
    half = 0.5 * period
    y = positions[:, 1]
    near_hi, near_lo = np.flatnonzero(y + radii > half), np.flatnonzero(y - radii < -half)
    rows = np.concatenate([np.arange(len(y)), near_hi, near_lo])
    shift = np.zeros((len(rows), 3))
    shift[len(y):len(y) + len(near_hi), 1] = -period
    shift[len(y) + len(near_hi):, 1] = period
    return rows, positions[rows] + shift


class Porosity(FrameAnalysis):
    """Porosity and solid fraction per region and frame.

    ``conversion``: optional dict(relative_density=..., reading=...) applied to ``circle``
    regions, adding a ``porosity_3d`` column.

    ``bulk_density`` column (kg/m3, sphere and cylinder regions) = sum of density x solid
    volume / volume, with each row's density from ``densities`` (kg/m3 per atom type) or, for
    plain spheres, from a ``mass`` column (mass / sphere volume; LIGGGHTS gives each sphere of a
    clump the whole clump's mass, so clumps need ``densities``). With one density it is density
    x solid fraction; with species of different densities (dust whose density is scaled) only
    this gives the bed's mass per volume.
    """

    name = "porosity"

    def __init__(self, regions: list[MeasureRegion], conversion: dict | None = None,
                 densities: dict[int, float] | None = None, period_y: float | None = None):
        super().__init__()
        self.period_y = period_y             # m: a slab periodic along y, centred on y = 0
        if not regions:
            raise ValueError("porosity needs at least one measurement region")
        self.regions = list(regions)
        self.conversion = conversion
        self.densities = dict(densities) if densities else None
        if self.densities and not all(math.isfinite(v) and v > 0 for v in self.densities.values()):
            raise ValueError("particle densities must be finite and > 0")

    def _row_densities(self, frame, clumps: bool) -> np.ndarray | None:
        """Density (kg/m3) of every row, from its type (or its mass; None if neither is known)."""
        if not self.densities:
            if clumps or "mass" not in frame.data:
                return None
            return frame.column("mass").astype(float) / (4.0 / 3.0 * np.pi * frame.radii() ** 3)
        types = frame.column("type").astype(int)
        known = np.array(sorted(self.densities))
        missing = np.setdiff1d(np.unique(types), known)
        if len(missing):
            raise ValueError(f"step {frame.timestep}: no particle density for atom type(s) "
                             f"{', '.join(map(str, missing))}")
        return np.array([self.densities[k] for k in known])[np.searchsorted(known, types)]

    def _single_frame(self, frame, contacts):
        pos, rad = frame.positions(), frame.radii()
        volume_weights = grain_weights(frame)
        rho = self._row_densities(frame, clumps=volume_weights is not None)
        mass_weights = rho if rho is None or volume_weights is None else rho * volume_weights
        if self.period_y is not None and len(pos):
            # the periodic images of the grains across y = -+ L/2 hold the volume they carry across it
            rows, pos = periodic_images(pos, rad, self.period_y)
            rad = rad[rows]
            volume_weights, rho, mass_weights = (None if w is None else w[rows] for w in
                                                 (volume_weights, rho, mass_weights))
        tree = cKDTree(pos) if len(pos) else None
        sections = {}                        # circle regions often share a plane (paper A: nine)
        rows = []
        for region in self.regions:
            if region.shape == "circle":
                plane = (region.axis, region.plane)
                if plane not in sections:
                    sections[plane] = section_weights(frame, *plane)
                weights = sections[plane]
            else:
                weights = volume_weights
            solid = region.solid(pos, rad, tree, weights) if tree is not None else 0.0
            phi = solid / region.measure
            row = {"region": region.name, "shape": region.shape, "solid_fraction": phi, "porosity": 1.0 - phi}
            if mass_weights is not None:
                row["bulk_density"] = (region.solid(pos, rad, tree, mass_weights) / region.measure
                                       if region.shape != "circle" and tree is not None else float("nan"))
            if self.conversion and region.shape == "circle":
                try:
                    row["porosity_3d"] = float(porosity_2d_to_3d(1.0 - phi, **self.conversion))
                except ValueError as exc:   # outside the formula's range: say so in the table
                    row["porosity_3d"] = float("nan")
                    row["note"] = str(exc)
            rows.append(row)
        return rows

    def _conclude(self):
        cols = [c for c in ("solid_fraction", "porosity", "bulk_density") if c in self.table]
        self.results.summary = self.table.groupby("region")[cols].mean()
