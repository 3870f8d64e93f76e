"""Mesh quality: the limits LIGGGHTS 3.8 puts on a wall mesh (smallest angle, shortest edge, triangle budget) and the measures checked against them."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: longest/shortest side of the cylinder facets
MAX_FACET_ASPECT = 10.0
#: LIGGGHTS' default ``curvature`` of fix mesh/surface, deg: acos(1 - 1e-5). A triangle with a smaller
#: angle stops the run ("Bad mesh, cannot continue").
LIGGGHTS_CURVATURE_DEG = math.degrees(math.acos(1.0 - 1e-5))
#: LIGGGHTS warns about triangles with an angle below this, deg ("highly skewed element")
LIGGGHTS_SKEWED_DEG = 0.5
#: LIGGGHTS' default mesh ``precision``, m: nodes closer than this are taken as one node
LIGGGHTS_PRECISION = 1e-8
#: smallest extent of a mesh LIGGGHTS accepts, m: a smaller one stops the run ("Mesh error - root
#: causes: (a) mesh empty or (b) dimensions too small"). Measured on LIGGGHTS 3.8: a 96 um square
#: refused, a 100 um square and a 2 mm x 48 um strip accepted (its largest extent counts)
LIGGGHTS_MIN_MESH_EXTENT = 1e-4
#: smallest angle of every triangle siloflow generates, deg (8 x LIGGGHTS' curvature, 4 x its warning)
MIN_ANGLE_DEG = 2.0
#: shortest edge of every triangle siloflow generates, m (10 x LIGGGHTS' precision)
MIN_EDGE = 10 * LIGGGHTS_PRECISION
#: most triangles of one generated wall (an ASCII STL of about 140 MB)
MAX_MESH_TRIANGLES = 500_000
#: re-triangulations: most cell aspect of the graded rings' end rows, growth of the ring spacing
#: per unit distance (m/m), fewest points of a ring, and the Delaunay refinement's target smallest
#: angle (deg)
ROW_ASPECT = 4.0
GRADING = 0.5
MIN_RING_POINTS = 6
REFINE_ANGLE_DEG = 25.0


class MeshQualityError(ValueError):
    """A generated wall that cannot be triangulated well: ``reason``, and the ``wall``'s name and role
    once known (:func:`silo_meshes` turns it into a ``CaseError``)."""

    def __init__(self, reason: str, wall: str = "", role: str = "", kind: str = "angle"):
        super().__init__(f"{wall}: {reason}" if wall else reason)
        self.reason, self.wall, self.role, self.kind = reason, wall, role, kind


def _edges(tris: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """Edge vectors (edge k from vertex k to k+1) and their lengths (n, 3) of triangles (n, 3, 3)."""
    t = np.asarray(tris, dtype=float)
    e = [t[:, 1] - t[:, 0], t[:, 2] - t[:, 1], t[:, 0] - t[:, 2]]
    return e, np.sqrt(np.stack([np.einsum("ij,ij->i", v, v) for v in e], axis=1))


def triangle_angles(tris: np.ndarray) -> np.ndarray:
    """Angles (n, 3) of triangles (n, 3, 3), deg, at each vertex; 0 for a degenerate triangle. As
    LIGGGHTS measures them (calcObtuseAngleIndex): from the unit edge vectors at each vertex."""
    e, length = _edges(tris)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.stack([-np.einsum("ij,ij->i", e[k], e[k - 1]) / (length[:, k] * length[:, k - 1])
                        for k in range(3)], axis=1)
    return np.degrees(np.arccos(np.clip(np.nan_to_num(cos, nan=1.0), -1.0, 1.0)))


def min_angles(tris: np.ndarray) -> np.ndarray:
    """Smallest angle of each triangle, deg."""
    return triangle_angles(tris).min(axis=1) if len(tris) else np.zeros(0)


def aspect_ratios(tris: np.ndarray) -> np.ndarray:
    """Longest edge over the shortest height of each triangle (1.15 for an equilateral one; inf when
    degenerate)."""
    e, length = _edges(tris)
    double_area = np.linalg.norm(np.cross(e[0], e[2]), axis=1)
    longest = length.max(axis=1)
    with np.errstate(divide="ignore"):
        return np.where(double_area > 0, longest * longest / np.maximum(double_area, 1e-300), np.inf)


@dataclass(frozen=True)
class MeshQuality:
    """Smallest angle (deg), largest aspect ratio, shortest edge (m) and size of a mesh."""

    min_angle: float
    max_aspect: float
    min_edge: float
    n_triangles: int
    worst: int              # index of the triangle with the smallest angle

    def problem(self, min_angle: float = MIN_ANGLE_DEG, min_edge: float = MIN_EDGE) -> str | None:
        """What makes the mesh unusable (None if nothing does)."""
        if self.n_triangles == 0:
            return "it has no triangles"
        if self.min_angle < min_angle:
            return (f"triangle {self.worst} has a smallest angle of {self.min_angle:.3g} deg (aspect ratio "
                    f"{self.max_aspect:.3g}); siloflow needs >= {min_angle:g} deg (LIGGGHTS refuses triangles "
                    f"below its curvature, {LIGGGHTS_CURVATURE_DEG:.3g} deg)")
        if self.min_edge < min_edge:
            return (f"it has an edge of {self.min_edge:.3g} m; LIGGGHTS merges mesh nodes closer than "
                    f"{LIGGGHTS_PRECISION:g} m, so siloflow needs edges >= {min_edge:g} m")
        return None


def mesh_quality(tris: np.ndarray) -> MeshQuality:
    """Quality figures of a triangle array (n, 3, 3) in m."""
    if len(tris) == 0:
        return MeshQuality(0.0, math.inf, 0.0, 0, -1)
    angles = min_angles(tris)
    _, length = _edges(tris)
    worst = int(np.argmin(angles))
    return MeshQuality(float(angles[worst]), float(aspect_ratios(tris).max()), float(length.min()), len(tris), worst)


def as_written(tris: np.ndarray) -> np.ndarray:
    """The triangles as LIGGGHTS reads them back: STL stores float32 coordinates."""
    return np.asarray(tris).astype(np.float32).astype(np.float64)


def _good(tris: np.ndarray) -> bool:
    return len(tris) > 0 and mesh_quality(as_written(tris)).problem() is None


def _budget(n_triangles: int, what: str) -> None:
    if n_triangles > MAX_MESH_TRIANGLES:
        raise MeshQualityError(f"{what} needs {n_triangles} triangles to keep every angle >= {MIN_ANGLE_DEG:g} "
                               f"deg, more than siloflow writes for one wall ({MAX_MESH_TRIANGLES})", kind="budget")
