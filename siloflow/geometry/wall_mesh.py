"""One wall as triangles (WallMesh: its role, band and sector, area) and its ASCII STL file."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from stl import Mode
from stl import mesh as stl_mesh

from ..errors import SetupError
from .quality import (
    LIGGGHTS_CURVATURE_DEG,
    LIGGGHTS_PRECISION,
    as_written,
    mesh_quality,
)


@dataclass
class WallMesh:
    """One STL wall.

    ``role`` is ``band`` (a wall sensor), ``wall`` (cylinder wall not sensed),
    ``bottom``, ``cone``, ``plate`` (the orifice plate) or ``outlet`` (the counting disc,
    not a wall). Bands carry their height range z0..z1 (m, absolute) and angular range
    theta0..theta1 (rad) on a cylinder of ``radius`` (m).
    """

    name: str
    role: str
    triangles: np.ndarray = field(repr=False)
    band: int | None = None
    sector: int | None = None
    z0: float | None = None
    z1: float | None = None
    theta0: float | None = None
    theta1: float | None = None
    radius: float | None = None
    normal: tuple[float, float] | None = None     # sensors: horizontal direction the grains push
    projected_area: float | None = None           # sensors: |vector area| along ``normal``, m2

    @property
    def area(self) -> float:
        """Sum of triangle areas, m2."""
        t = self.triangles
        return float(0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum())

    def info(self) -> dict:
        """JSON-ready description (no triangles)."""
        keys = ("name", "role", "band", "sector", "z0", "z1", "theta0", "theta1", "radius", "normal",
                "projected_area")
        out = {k: getattr(self, k) for k in keys}
        out["area"] = self.area
        out["file"] = f"meshes/{self.name}.stl"
        out["n_triangles"] = int(len(self.triangles))
        return out
def write_stl(wall: WallMesh, path) -> None:
    """Write ``wall`` as ASCII STL (LIGGGHTS 3.8 reads ASCII), atomically. A mesh LIGGGHTS would
    refuse (an angle below its curvature, an edge below its precision) is never written: ``SetupError``."""
    problem = mesh_quality(as_written(wall.triangles)).problem(LIGGGHTS_CURVATURE_DEG, LIGGGHTS_PRECISION)
    if problem:
        raise SetupError(f"mesh {wall.name} would be refused by LIGGGHTS ('Bad mesh'): {problem}")
    m = stl_mesh.Mesh(np.zeros(len(wall.triangles), dtype=stl_mesh.Mesh.dtype))
    m.vectors[:] = wall.triangles
    m.update_normals()
    from ..atomic_files import atomic_path
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        m.save(wall.name, fh=fh, mode=Mode.ASCII, update_normals=False)
