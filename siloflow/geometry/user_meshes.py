"""Walls from the user's STL files (inserts, baffles): read, checked, placed inside the silo."""
from __future__ import annotations

import codecs
import re
from pathlib import Path

import numpy as np

from ..plan import Silo
from ..silos.registry import silo_kind
from .quality import LIGGGHTS_CURVATURE_DEG, as_written, min_angles
from .wall_mesh import WallMesh


class MeshError(ValueError):
    """A user mesh file that cannot be used (unreadable, not STL, non-finite, degenerate, outside)."""


#: user STL files larger than this are refused (a silo insert needs far fewer triangles)
MAX_USER_MESH_BYTES = 50_000_000


#: a binary STL: an 80-byte header, a little-endian uint32 triangle count, then 50 bytes per
#: triangle (normal, three vertices as float32, a uint16 attribute)
_BINARY_HEAD = 84
_BINARY_TRIANGLE = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])
#: bytes no text file holds (control characters other than tab, newlines, form feed, vertical tab)
_BINARY_BYTE = re.compile(rb"[\x00-\x08\x0e-\x1f\x7f]")


def _shown(line: bytes) -> str:
    text = line.strip().decode("utf-8", "replace")
    return repr(text if len(text) <= 60 else text[:60] + "...")


def _ascii_triangles(raw: bytes, path: Path) -> np.ndarray:
    """Triangles (n, 3, 3) of an ASCII STL (one or more ``solid ... endsolid`` blocks of
    ``facet normal / outer loop / vertex x3 / endloop / endfacet``), checked line by line;
    ``MeshError`` naming the line that breaks the grammar."""
    def fail(lineno: int, what: str, line: bytes | None = None):
        found = f", found {_shown(line)}" if line is not None else ""
        return MeshError(f"{path} is a malformed ASCII STL file (it starts with 'solid'): line {lineno}: "
                         f"expected {what}{found}; fix or re-export the file")

    def numbers(words: list, lineno: int, line: bytes, what: str) -> list[float]:
        try:
            if len(words) != 3:
                raise ValueError
            return [float(w) for w in words]
        except ValueError:
            raise fail(lineno, f"{what} followed by three numbers", line) from None

    # states: the keyword the next non-blank line must start with
    expect, vertices, last, in_facet = "solid", [], 0, 0
    for lineno, line in enumerate(raw.split(b"\n"), start=1):
        words = line.lower().split()
        if not words:
            continue
        last = lineno
        if expect == "solid":
            if words[0] != b"solid":
                raise fail(lineno, "'solid' (a new solid) or the end of the file", line)
            expect = "facet"
        elif expect == "facet":
            if words[0] == b"endsolid" or words[:2] == [b"end", b"solid"]:
                expect = "solid"
            elif words[:2] == [b"facet", b"normal"]:
                numbers(words[2:], lineno, line, "'facet normal'")
                expect = "outer loop"
            else:
                raise fail(lineno, "'facet normal nx ny nz' or 'endsolid'", line)
        elif expect == "outer loop":
            if words != [b"outer", b"loop"]:
                raise fail(lineno, "'outer loop'", line)
            expect, in_facet = "vertex", 0
        elif expect == "vertex":
            if words[0] != b"vertex":
                raise fail(lineno, f"'vertex x y z' (vertex {in_facet + 1} of 3)", line)
            vertices.append(numbers(words[1:], lineno, line, "'vertex'"))
            in_facet += 1
            if in_facet == 3:
                expect = "endloop"
        elif expect == "endloop":
            if words != [b"endloop"]:
                raise fail(lineno, "'endloop' after three vertices (a facet is a triangle)", line)
            expect = "endfacet"
        elif expect == "endfacet":
            if words != [b"endfacet"]:
                raise fail(lineno, "'endfacet'", line)
            expect = "facet"
    if expect != "solid":
        what = {"facet": "'endsolid'"}.get(expect, f"'{expect}'")
        raise MeshError(f"{path} is a malformed ASCII STL file (it starts with 'solid'): it ends after line {last} "
                        f"where {what} was expected (truncated file?)")
    return np.asarray(vertices, dtype=float).reshape(-1, 3, 3)


def stl_triangles(raw: bytes, path) -> np.ndarray:
    """Triangles (n, 3, 3) of the STL file ``path`` whose bytes are ``raw``, ASCII or binary told
    apart by their content, not by the first word alone: text starting with ``solid`` is ASCII
    (a parse error names its line; it is never re-read as binary); otherwise the file must be a
    binary STL whose size is 84 + 50 x its triangle count (binary files whose header starts with
    ``solid`` too). Raises ``MeshError`` naming the file and what is wrong."""
    path = Path(path)
    if raw.startswith(codecs.BOM_UTF8):            # a text editor's byte-order mark before 'solid'
        raw = raw[len(codecs.BOM_UTF8):]
    starts_solid = raw.lstrip()[:5].lower() == b"solid"
    binary = _BINARY_BYTE.search(raw) if starts_solid else None
    if starts_solid and binary is None:
        return _ascii_triangles(raw, path)
    if len(raw) < _BINARY_HEAD:
        raise MeshError(f"{path} is not an STL file: {len(raw)} bytes, too short for a binary STL (84-byte header "
                        "and triangle count) and not an ASCII STL (text starting with 'solid')")
    count = int(np.frombuffer(raw, "<u4", 1, 80)[0])
    expected = _BINARY_HEAD + _BINARY_TRIANGLE.itemsize * count
    if len(raw) != expected:
        ascii_note = (f"; it starts with 'solid' like an ASCII STL but holds a binary byte at offset {binary.start()}"
                      if starts_solid else "")
        raise MeshError(f"{path} is not an STL file: as a binary STL its header announces {count} triangles "
                        f"({expected} bytes), but the file has {len(raw)} bytes{ascii_note}; re-export it as STL")
    return np.frombuffer(raw, _BINARY_TRIANGLE, count, _BINARY_HEAD)["vertices"].astype(float)


def read_user_mesh(path, scale: float = 1.0) -> np.ndarray:
    """Triangles (n, 3, 3), m, of a user's ASCII or binary STL file, checked: finite vertices and
    no degenerate (zero-area) triangle. Raises ``MeshError`` saying what is wrong."""
    from ..atomic_files import read_regular_bytes
    path = Path(path)
    try:
        raw = read_regular_bytes(path, MAX_USER_MESH_BYTES, "a mesh")
    except ValueError as exc:
        raise MeshError(str(exc)) from None
    tris = stl_triangles(raw, path)
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
    inside = silo_kind(g.kind).inside(g, p)
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
