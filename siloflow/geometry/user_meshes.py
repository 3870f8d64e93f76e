"""Walls from the user's STL files (inserts, baffles): read, checked, placed inside the silo."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from stl import mesh as stl_mesh

from ..plan import Silo
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
    finite = np.isfinite(tris).all(axis=(1, 2))
    if not finite.all():
        raise MeshError(f"{path} has non-finite vertex coordinates (NaN or infinite) in {int((~finite).sum())} "
                        f"triangle(s), the first triangle {int(np.argmin(finite))} (from 0): re-export the file")
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    extent = float(np.ptp(tris.reshape(-1, 3), axis=0).max())
    degenerate = area <= 1e-12 * extent * extent
    if degenerate.any():
        raise MeshError(f"{path} has {int(degenerate.sum())} degenerate (zero-area) triangle(s) of {len(tris)}, the "
                        f"first triangle {int(np.argmax(degenerate))} (from 0): remove them")
    angles = min_angles(tris)
    bad = int((angles < LIGGGHTS_CURVATURE_DEG).sum())
    if bad:
        raise MeshError(f"{path} has {bad} sliver triangle(s) of {len(tris)} (the smallest angle is "
                        f"{angles.min():.3g} deg, triangle {int(np.argmin(angles))}): LIGGGHTS refuses angles below "
                        f"{LIGGGHTS_CURVATURE_DEG:.3g} deg ('Bad mesh'); re-mesh the file with better triangles")
    return tris


def check_inside(silo: Silo, tris: np.ndarray) -> None:
    """Refuse a mesh that reaches outside the silo (the run plan's ``geometry``): LIGGGHTS needs walls
    inside its box. Raises ``MeshError``."""
    g = silo
    p = tris.reshape(-1, 3)
    if g.kind in ("planar", "box"):
        inside = (np.abs(p[:, 0]) <= g.half_width) & (np.abs(p[:, 1]) <= g.half_depth)
    else:
        inside = np.hypot(p[:, 0], p[:, 1]) <= g.radius
    inside &= (p[:, 2] >= 0.0) & (p[:, 2] <= g.top)
    if not inside.all():
        lo, hi = p.min(axis=0), p.max(axis=0)
        raise MeshError(f"the mesh reaches outside the silo (it spans x {lo[0]:.4g}..{hi[0]:.4g}, y "
                        f"{lo[1]:.4g}..{hi[1]:.4g}, z {lo[2]:.4g}..{hi[2]:.4g} m; check 'scale')")


def user_wall(name: str, path, scale: float, silo: Silo) -> WallMesh:
    """The user's wall ``name`` (role ``insert``) from the STL file ``path`` (relative paths from the
    working folder) times ``scale``, checked (:func:`read_user_mesh`, :func:`check_inside`) and as
    the run folder's STL copy holds it (float32), so that a render from the copy is the same.
    Raises ``MeshError`` saying what is wrong."""
    tris = read_user_mesh(path, scale)
    check_inside(silo, tris)
    return WallMesh(name, "insert", as_written(tris))
