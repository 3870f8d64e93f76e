"""A silo's vertical side walls as LIGGGHTS primitive walls, and their band and sector forces
binned inside the engine (issue 56).

Measured on the demo's settled bed (6,834 grains, LIGGGHTS 3.8, one rank, CPU seconds for the same
6,000 steps, 2026-12-07; ``docs/engines.md``): 52 sensor meshes in one ``wall/gran`` cost 49.4 s, the
same triangles as one side mesh 22.3 s, a primitive ``zcylinder`` 15.2 s, and the raw deck (the
primitive, no outputs) 15.9 s. A primitive's contacts are found without a triangle neighbour list,
and a grain has at most one contact with it, at its own height and azimuth: the contact point of a
grain at (x, y, z) on a vertical wall is the grain's projection on the wall.

So the side walls of generated silos (cylinders and cone hoppers: one ``zcylinder``; slabs: two
``xplane``; boxes: two ``xplane`` and two ``yplane``) are primitives that store each grain's wall
force (``store_force yes``: the per-atom ``f_force_<fix>[1..3]``, the force on the grain), and each
of the plan's side-wall pieces (sensor bands and sectors, and the unsensed rest) is a region
(a height block, for a cylinder's sector intersected with the two half-planes through the axis
that bound it) summed by ``compute reduce/region`` when the wall forces are sampled. Binning by the
grain's position is binning by the contact's, so the pieces' forces tile the wall's: the lowest
piece of a side reaches down and the highest up without bound, and a grain counts in one piece
(one on a boundary, a set of measure zero, in both). The sampled force is the force the grains
exert on the wall (the stored force, negated), as a mesh sensor's.

A case chooses it with ``engine.side_walls: primitive``; the default stays ``meshes`` (one sensor mesh
per band sector) until the equivalence campaign (``benchmarks/deck_equivalence.py``) has its seeds.
A user's STL silo (``kind: mesh``) keeps its walls as meshes: its sensor pieces are its own
triangles. ``compute wall/gran/local`` reports mesh walls only, so a deck that dumps contacts also
dumps each primitive's touching grains (``side_contacts``), which the dump reader turns into
wall contacts (:func:`postprocess.dumps.primitive_wall_contacts`).
"""
from __future__ import annotations

import math

from ...plan import RunPlan
from ...silos.registry import silo_kind

#: the roles of the side walls' pieces in the plan (sensor bands and the unsensed rest)
SIDE_ROLES = ("band", "wall")
#: sectors narrower than a full turn by less than this (rad) are the full turn
_FULL_TURN = 1e-9


def primitive_sides(plan: RunPlan) -> list[dict]:
    """The side walls as primitives, one dict each: ``fid`` (fix ID), ``style`` (``zcylinder``,
    ``xplane`` or ``yplane``), ``args`` (m: radius and axis, or the plane's position), ``sector``
    (the plan pieces' sector that lies on it; None for a cylinder: every sector), ``geometry``
    (what the dump reader needs to place a contact: ``{"style", "args"}``). Empty for a user's
    STL silo, whose walls stay meshes."""
    g = plan.geometry
    if not plan.engine.options.get("primitive_side_walls"):       # the case's engine.side_walls: meshes
        return []
    return silo_kind(g.kind).primitive_sides(g)


def on_primitive(plan: RunPlan, wall) -> bool:
    """Whether the plan wall ``wall`` is a piece of a primitive side wall (no mesh in the deck)."""
    return wall.role in SIDE_ROLES and bool(primitive_sides(plan))


def _sides_of(sides: list[dict], wall) -> list[dict]:
    """The primitive sides that carry the piece ``wall``: its sector's, or every side for a piece
    of no sector (the side walls merged into one plain wall when no result reads their bands)."""
    on = [s for s in sides if s["sector"] is None or wall.sector is None or s["sector"] == wall.sector]
    if not on:
        raise ValueError(f"wall piece {wall.name} (sector {wall.sector}) is on no primitive side wall")
    return on


def _sector_planes(theta0: float, theta1: float) -> list[tuple[float, float]]:
    """Inward normals (nx, ny) of the half-planes through the z axis that bound the sector
    theta0..theta1 (rad): none for the full turn; a sector wider than half a turn is refused
    (two half-planes cannot bound it)."""
    span = theta1 - theta0
    if span >= 2 * math.pi - _FULL_TURN:
        return []
    if span > math.pi + _FULL_TURN:
        raise ValueError(f"a sector of {math.degrees(span):.6g} deg: sectors wider than 180 deg are not binned")
    return [(-math.sin(theta0), math.cos(theta0)), (math.sin(theta1), -math.cos(theta1))]


def binned_pieces(plan: RunPlan) -> list[dict]:
    """Each side-wall piece on primitives, in the plan's wall order: ``name``; ``parts``, one per
    primitive it lies on (``fid``, its fix, and ``compute``, the ID of the sum over the piece's
    region of that fix's stored force); ``zlo``/``zhi`` (m; None: unbounded, the lowest and highest
    piece of its sides, or a piece without heights); ``planes`` (a cylinder sector's bounding
    half-planes' inward normals through the axis)."""
    sides = primitive_sides(plan)
    pieces = [w for w in plan.walls if w.role in SIDE_ROLES] if sides else []
    out = []
    for w in pieces:
        on = _sides_of(sides, w)
        same = [p for p in pieces if p.z0 is not None and any(s in _sides_of(sides, p) for s in on)]
        lowest = min((p.z0 for p in same), default=None)
        highest = max((p.z1 for p in same), default=None)
        planes = _sector_planes(w.theta0, w.theta1) if on[0]["style"] == "zcylinder" and w.theta0 is not None else []
        parts = [{"fid": s["fid"], "compute": f"{w.name}_force" if len(on) == 1 else f"{w.name}_{s['fid']}_force"}
                 for s in on]
        out.append({"name": w.name, "parts": parts,
                    "zlo": None if w.z0 is None or w.z0 <= lowest else w.z0,
                    "zhi": None if w.z1 is None or w.z1 >= highest else w.z1, "planes": planes})
    return out


def sampled_walls(plan: RunPlan, mesh_fix_id) -> list[dict]:
    """What the deck samples for each wall of the plan, in its order (three quantities each: fx,
    fy, fz, N, the force the grains exert on the wall): ``{"name", "binned": True}`` for a piece
    of a primitive (the variables that negate its binned sum), ``{"name", "binned": False, "fid"}``
    for a mesh (its ``f_<fid>[1..3]``; ``mesh_fix_id(wall)``: its fix ID)."""
    binned = {p["name"] for p in binned_pieces(plan)}
    return [{"name": w.name, "binned": True} if w.name in binned
            else {"name": w.name, "binned": False, "fid": mesh_fix_id(w)}
            for w in plan.walls if w.is_wall]
