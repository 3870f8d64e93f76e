"""Walls from the user's STL files (inserts, baffles): read, checked, placed inside the silo."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from stl import mesh as stl_mesh

from ..case import Case, PlanarGeometry
from ..errors import CaseError
from .quality import LIGGGHTS_CURVATURE_DEG, as_written, min_angles
from .wall_mesh import WallMesh


class MeshError(ValueError):
    """A user mesh file that cannot be used (unreadable, not STL, non-finite, degenerate, outside)."""


#: user STL files larger than this are refused (a silo insert needs far fewer triangles)
MAX_USER_MESH_BYTES = 50_000_000


def read_user_mesh(path, scale: float = 1.0) -> np.ndarray:
    """Triangles (n, 3, 3), m, of a user's ASCII or binary STL file, checked: finite vertices and
    no degenerate (zero-area) triangle. Raises ``MeshError`` saying what is wrong."""
    from ..atomic_files import read_regular_bytes
    path = Path(path)
    try:
        raw = read_regular_bytes(path, MAX_USER_MESH_BYTES, "a mesh")
    except ValueError as exc:
        raise MeshError(str(exc)) from None
    try:
        tris = np.array(stl_mesh.Mesh.from_file(str(path), fh=io.BytesIO(raw)).vectors, dtype=float)
    except Exception as exc:        # numpy-stl raises many kinds on foreign bytes
        raise MeshError(f"{path} is not an STL file ({type(exc).__name__}: {str(exc)[:120]})") from None
    if tris.ndim != 3 or len(tris) == 0:
        raise MeshError(f"{path} holds no triangles")
    tris = tris * scale
    if not np.all(np.isfinite(tris)):
        raise MeshError(f"{path} has non-finite vertex coordinates")
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    extent = float(np.ptp(tris.reshape(-1, 3), axis=0).max())
    bad = int((area <= 1e-12 * extent * extent).sum())
    if bad:
        raise MeshError(f"{path} has {bad} degenerate (zero-area) triangle(s) of {len(tris)}")
    angles = min_angles(tris)
    bad = int((angles < LIGGGHTS_CURVATURE_DEG).sum())
    if bad:
        raise MeshError(f"{path} has {bad} sliver triangle(s) of {len(tris)} (the smallest angle is "
                        f"{angles.min():.3g} deg, triangle {int(np.argmin(angles))}): LIGGGHTS refuses angles below "
                        f"{LIGGGHTS_CURVATURE_DEG:.3g} deg ('Bad mesh'); re-mesh the file with better triangles")
    return tris


def check_inside(case: Case, tris: np.ndarray) -> None:
    """Refuse a mesh that reaches outside the silo (LIGGGHTS needs walls inside its box)."""
    g = case.geometry
    p = tris.reshape(-1, 3)
    top = g.hopper_height + g.height
    if isinstance(g, PlanarGeometry):
        inside = (np.abs(p[:, 0]) <= g.half_width) & (np.abs(p[:, 1]) <= 0.5 * g.thickness)
    else:
        inside = np.hypot(p[:, 0], p[:, 1]) <= g.radius
    inside &= (p[:, 2] >= 0.0) & (p[:, 2] <= top)
    if not inside.all():
        lo, hi = p.min(axis=0), p.max(axis=0)
        raise MeshError(f"the mesh reaches outside the silo (it spans x {lo[0]:.4g}..{hi[0]:.4g}, y "
                        f"{lo[1]:.4g}..{hi[1]:.4g}, z {lo[2]:.4g}..{hi[2]:.4g} m; check 'scale')")


def insert_meshes(case: Case) -> list[WallMesh]:
    """The case's user walls, read from their files (relative paths from the working folder) and
    checked (:func:`read_user_mesh`, :func:`check_inside`). Raises ``CaseError`` naming each
    insert whose file cannot be used."""
    problems, meshes = [], []
    for k, ins in enumerate(case.inserts):
        try:
            tris = read_user_mesh(ins.file, ins.scale)
            check_inside(case, tris)
        except MeshError as exc:
            problems.append((f"inserts[{k}].file", str(exc)))
            continue
        # as the run folder's STL copy holds it (float32): a render from the copy is the same
        meshes.append(WallMesh(ins.mesh_name, "insert", as_written(tris)))
    if problems:
        raise CaseError(problems, case.name)
    return meshes
