"""The silo's walls as meshes: cylinder, cone hopper and slab, the side walls cut into sensor bands and sectors (z = 0 at the outlet, m)."""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..plan import Silo
from ..silos.registry import silo_kind
from .quality import (
    LIGGGHTS_CURVATURE_DEG,
    LIGGGHTS_MIN_MESH_EXTENT,
    LIGGGHTS_PRECISION,
    MAX_FACET_ASPECT,
    MAX_MESH_TRIANGLES,
    MIN_ANGLE_DEG,
    MIN_EDGE,
    MeshQualityError,
    _budget,
    _good,
    as_written,
    mesh_quality,
)
from .triangulation import (
    _balanced_rectangle,
    _chord,
    _divisions,
    _grid_triangles,
    _refine_polygon,
    disc,
    graded_disc,
    revolution_rows,
    surface_of_revolution,
)
from .wall_mesh import WallMesh


#: the most rings tried for a flat disc's fewest-triangle mesh before the near-equilateral rings
FEWEST_RINGS_TRIED = 4
#: flat floors, plates and counting discs with the fewest good rings (6 % of the demo's loop, issue 56);
#: off until the deck equivalence campaign covers them (a floor's facets change its bed's contacts)
FEWEST_TRIANGLE_FLOORS = False


def band_boundaries(height: float, bands: int, heights: Sequence[float] | None = None) -> list[float]:
    """Band boundaries in m above the side wall's base (the top of the hopper, if any): the given
    ``heights``, else ``bands`` equal bands over the side wall's ``height`` (m)."""
    if heights is not None:
        return list(heights)
    return [height * i / bands for i in range(bands + 1)]


def silo_meshes(silo: Silo, band_bounds: Sequence[float], sectors: int, outlet_z: float, outlet_radius: float,
                sensors: bool = True, container=None) -> list[WallMesh]:
    """The generated meshes of a silo (cylinder, hopper or slab, the run plan's ``geometry``), in the
    order the deck lists them, the counting mesh last.

    ``band_bounds``: the sensor bands' boundaries (m above the side wall's base,
    :func:`band_boundaries`); ``sectors``: sectors per band of a cylinder; ``outlet_z``,
    ``outlet_radius``: position and size of the counting disc below the orifice (m). Without
    ``sensors`` the side walls' pieces (bands and the rest) are one mesh ``wall`` of the same
    facets: no result reads their pressure. Every wall is checked (:func:`check_wall`); one that
    cannot be triangulated well raises ``MeshQualityError`` naming the wall, its role and the kind
    of defect (the plan's maker names the case fields that shape it). A user's silo (kind ``mesh``)
    is cut from its ``container`` (``siloflow.geometry.container``); its pieces keep the user's
    triangles, so they are held to LIGGGHTS' own limits instead of siloflow's.
    """
    kind = silo_kind(silo.kind)
    meshes = kind.wall_meshes(silo, band_bounds, sectors, outlet_z, outlet_radius, container)
    min_angle, min_edge = (LIGGGHTS_CURVATURE_DEG, LIGGGHTS_PRECISION) if kind.user_triangles else (MIN_ANGLE_DEG,
                                                                                                    MIN_EDGE)
    if not sensors:
        meshes = merge_side_walls(meshes)
    for w in meshes:
        check_wall(w, min_angle, min_edge)
    return meshes


def merge_side_walls(meshes: list[WallMesh]) -> list[WallMesh]:
    """The meshes with every side-wall piece (roles ``band`` and ``wall``) merged into one plain
    wall ``wall`` of the same triangles, where the first piece was."""
    side = [m for m in meshes if m.role in ("band", "wall")]
    if not side:
        return meshes
    merged = WallMesh("wall", "wall", np.concatenate([m.triangles for m in side]))
    first = meshes.index(side[0])
    rest = [m for m in meshes if m.role not in ("band", "wall")]
    return rest[:first] + [merged] + rest[first:]


def check_wall(wall: WallMesh, min_angle: float = MIN_ANGLE_DEG, min_edge: float = MIN_EDGE) -> None:
    """Raise ``MeshQualityError`` if a wall, as written (float32), has a triangle with an angle
    below ``min_angle`` (deg) or an edge shorter than ``min_edge`` (m)."""
    quality = mesh_quality(as_written(wall.triangles))
    problem = quality.problem(min_angle, min_edge)
    if problem:
        kind = "edge" if quality.n_triangles and quality.min_angle >= min_angle else "angle"
        raise MeshQualityError(problem, wall.name, wall.role, kind)
    points = np.asarray(wall.triangles).reshape(-1, 3)
    extent = float((points.max(axis=0) - points.min(axis=0)).max())
    if extent < 1.05 * LIGGGHTS_MIN_MESH_EXTENT:      # 5 % margin over the measured limit
        raise MeshQualityError(f"the mesh is {extent:.3g} m across; LIGGGHTS refuses meshes smaller than about "
                               f"{LIGGGHTS_MIN_MESH_EXTENT:g} m ('Mesh error ... dimensions too small')",
                               wall.name, wall.role, "edge")


def _wall(name: str, role: str, build, **kw) -> WallMesh:
    """``WallMesh(name, role, build(), **kw)``, with a triangulation failure named after the wall."""
    try:
        return WallMesh(name, role, build(), **kw)
    except MeshQualityError as exc:
        raise MeshQualityError(exc.reason, name, role, exc.kind) from None


def _structured_or_graded(count: int, structured, graded) -> np.ndarray:
    """The structured triangles (``count`` of them) where they are good, else the graded ones."""
    if count <= MAX_MESH_TRIANGLES:
        tris = structured()
        if _good(tris):
            return tris
    return graded()


def cylinder_meshes(silo: Silo, band_bounds: Sequence[float], sectors: int, outlet_z: float,
                    outlet_radius: float) -> list[WallMesh]:
    """Meshes of a cylindrical silo or hopper (see :func:`silo_meshes`)."""
    g = silo
    R = g.radius
    base = g.hopper_height
    n_seg = g.mesh_segments
    per_sector = max(1, math.ceil(n_seg / sectors))
    n_ring = per_sector * sectors
    h_facet = 2 * math.pi * R / n_ring
    meshes: list[WallMesh] = []
    side = _chord(g.outlet_radius, n_ring)
    if side < MIN_EDGE:                  # the orifice's polygon itself: no need to mesh the rest first
        raise MeshQualityError(f"its {n_ring}-gon of radius {g.outlet_radius:.3g} m has sides of {side:.3g} m; "
                               f"LIGGGHTS merges mesh nodes closer than {LIGGGHTS_PRECISION:g} m, so siloflow "
                               f"needs edges >= {MIN_EDGE:g} m", "plate", "plate", "edge")

    def cylinder_tris(z_lo, z_hi, th0, th1, n_th):
        dz = z_hi - z_lo
        if not dz > 0:
            raise MeshQualityError(f"it spans no height (z {z_lo:.9g} to {z_hi:.9g} m)")
        # the wall is straight along z: tall facets are exact and keep the triangle count
        # (which dominates LIGGGHTS' mesh-wall cost) low
        n_ax = max(1, math.ceil(dz / (MAX_FACET_ASPECT * h_facet)))
        if 2 * n_th * n_ax <= MAX_MESH_TRIANGLES:
            tris = surface_of_revolution(R, z_lo, R, z_hi, th0, th1, n_th, n_ax)
            if _good(tris):
                return tris
        # a piece much lower than its facets are wide: split each facet along its chord (flat, so the
        # wall stays the same polygon) into pieces at most MAX_FACET_ASPECT times wider than high
        m = max(1, math.ceil(h_facet / (MAX_FACET_ASPECT * dz) - 1e-9))
        _budget(2 * n_th * m * n_ax, f"a piece {dz:.3g} m high of facets {h_facet:.3g} m wide")
        theta = np.linspace(th0, th1, n_th + 1)
        corners = np.stack([R * np.cos(theta), R * np.sin(theta)], axis=-1)
        f = np.arange(m) / m
        xy = (corners[:-1, None, :] + f[None, :, None] * (corners[1:] - corners[:-1])[:, None, :]).reshape(-1, 2)
        xy = np.concatenate([xy, corners[-1:]])
        z = np.linspace(z_lo, z_hi, n_ax + 1)
        pts = np.concatenate([np.broadcast_to(xy[None], (len(z),) + xy.shape),
                              np.broadcast_to(z[:, None, None], (len(z), len(xy), 1))], axis=-1)
        return _grid_triangles(pts)

    def cylinder_piece(name, role, z_lo, z_hi, th0, th1, n_th, **kw):
        sensor = {}
        if role == "band":   # a sector's net force is along its mid direction (postprocess.wall_pressure)
            tc = 0.5 * (th0 + th1)
            sensor = {"normal": (math.cos(tc), math.sin(tc)),
                      "projected_area": 2.0 * R * (z_hi - z_lo) * math.sin(0.5 * (th1 - th0))}
        meshes.append(_wall(name, role, lambda: cylinder_tris(z_lo, z_hi, th0, th1, n_th), z0=z_lo, z1=z_hi,
                            theta0=th0, theta1=th1, radius=R, **sensor, **kw))

    bounds = list(band_bounds)
    if bounds[0] > 0:
        cylinder_piece("wall_below", "wall", base, base + bounds[0], 0.0, 2 * math.pi, n_ring)
    for b, (lo, hi) in enumerate(zip(bounds, bounds[1:])):
        for s in range(sectors):
            th0, th1 = 2 * math.pi * s / sectors, 2 * math.pi * (s + 1) / sectors
            cylinder_piece(f"band{b:02d}_s{s:02d}", "band", base + lo, base + hi, th0, th1,
                           per_sector, band=b, sector=s)
    if bounds[-1] < g.height:
        cylinder_piece("wall_above", "wall", base + bounds[-1], base + g.height, 0.0, 2 * math.pi, n_ring)

    def disc_tris(radius, z, inner=0.0, fewest=True):
        # flat: the fewest rings whose triangles are good (a fan, one ring of long triangles), as a
        # mesh wall's cost grows with its triangles (issue 56: the demo's floor, plate and counting
        # disc went from 1,680 triangles to 192, 6 % of its loop); else (and for an eccentric floor,
        # whose annulus is then sheared: ``fewest`` False) rings of near-equilateral triangles, else
        # graded rings
        h = 2 * math.pi * radius / n_ring
        n_r = max(1, math.ceil((radius - inner) / h))
        for rows in range(1, min(n_r, FEWEST_RINGS_TRIED) + 1 if fewest and FEWEST_TRIANGLE_FLOORS else 1):
            tris = disc(radius, z, n_ring, inner_radius=inner, rows=rows)
            if _good(tris):
                return tris
        count = 2 * n_ring * n_r if inner > 0 else n_ring * (2 * n_r - 1)
        return _structured_or_graded(count, lambda: disc(radius, z, n_ring, inner_radius=inner),
                                     lambda: graded_disc(inner, radius, z, n_ring))

    r_out = g.outlet_radius
    if base > 0:                        # a hopper's cone, else a flat floor
        slant = math.hypot(R - r_out, base)
        n_ax = max(1, math.ceil(slant / h_facet))
        meshes.append(_wall("cone", "cone", lambda: _structured_or_graded(
            2 * n_ring * n_ax, lambda: surface_of_revolution(r_out, 0.0, R, base, 0.0, 2 * math.pi, n_ring, n_ax),
            lambda: revolution_rows(r_out, 0.0, R, base, n_ring))))
    else:
        meshes.append(_wall("bottom", "bottom", lambda: disc_tris(R, 0.0, r_out, fewest=not g.outlet_offset)))
    meshes.append(_wall("plate", "plate", lambda: disc_tris(r_out, 0.0)))
    meshes.append(_wall("outlet", "outlet", lambda: disc_tris(outlet_radius, outlet_z)))
    if g.outlet_offset:
        eccentric(meshes, g, sectors, n_ring)
    return meshes


def eccentric(meshes: list[WallMesh], silo: Silo, sectors: int, n_ring: int) -> None:
    """Make a centred cylinder's or hopper's meshes (in place) eccentric, the outlet's centre at
    x = e = ``silo.outlet_offset``: everything turned
    about z by half a sector, so that sector 0 is centred on +x (the outlet's azimuth: the near and
    far walls are sensors of their own); then the plate and the counting disc moved by e along x; the
    cone sheared (x + e (1 - z / h): its outlet ring moves by e, its top stays the cylinder's, every
    facet stays flat); the flat floor's annulus mapped point by point by p + (1 - t) e x, t its
    polygonal radius' place between the orifice's n-gon (t = 0, moved with it) and the wall's (t = 1,
    in place), which keeps every facet in the plane z = 0 and on the same side up while e < R - r."""
    e, R, r = silo.outlet_offset, silo.radius, silo.outlet_radius
    phase = -math.pi / sectors
    rot = np.array([[math.cos(phase), -math.sin(phase), 0.0], [math.sin(phase), math.cos(phase), 0.0], [0, 0, 1.0]])
    half = math.pi / n_ring
    for m in meshes:
        p = np.asarray(m.triangles, float) @ rot.T
        if m.role in ("plate", "outlet"):
            p[..., 0] += e
        elif m.role == "cone":
            p[..., 0] += e * (1.0 - p[..., 2] / silo.hopper_height)
        elif m.role == "bottom":
            # the polygonal radius: |p| cos(angle to the middle of its n-gon side) / cos(pi / n), the
            # n-gons' vertices now at 2 pi k / n + phase
            theta = np.arctan2(p[..., 1], p[..., 0]) - phase
            to_mid = np.mod(theta, 2 * half) - half
            q = np.hypot(p[..., 0], p[..., 1]) * np.cos(to_mid) / math.cos(half)
            t = np.clip((q - r) / (R - r), 0.0, 1.0)
            p[..., 0] += (1.0 - t) * e
        m.triangles = p
        if m.theta0 is not None:
            m.theta0, m.theta1 = m.theta0 + phase, m.theta1 + phase
        if m.normal is not None:
            tc = 0.5 * (m.theta0 + m.theta1)
            m.normal = (math.cos(tc), math.sin(tc))
def side_pieces(piece, sides, band_bounds: Sequence[float], base: float, height: float) -> None:
    """Cut flat side walls (a slab's or a box's) into their sensor bands and the unsensed rest:
    ``piece(name, role, side, z_lo, z_hi, **fields)`` makes one, for each of ``sides``, the walls
    standing on z = ``base`` (m) ``height`` (m) high, ``band_bounds`` above their base (m); in the
    order the deck lists them (the pieces below the bands, the bands band by band, those above)."""
    bounds = list(band_bounds)
    if bounds[0] > 0:
        for side in sides:
            piece(f"wall_below_s{side:02d}", "wall", side, base, base + bounds[0])
    for k, (lo, hi) in enumerate(zip(bounds, bounds[1:])):
        for side in sides:
            piece(f"band{k:02d}_s{side:02d}", "band", side, base + lo, base + hi, band=k)
    if bounds[-1] < height:
        for side in sides:
            piece(f"wall_above_s{side:02d}", "wall", side, base + bounds[-1], base + height)


def slab_meshes(silo: Silo, band_bounds: Sequence[float], outlet_z: float, outlet_half: float) -> list[WallMesh]:
    """Meshes of a quasi-2D slab silo (x across, y through the slab, z up; z = 0 the outlet):
    side walls cut into sensor sections (sector 0 at x = -width/2, sector 1 at +width/2),
    the wedge hopper's two walls (a flat floor's two pieces either side of the slot, role
    ``bottom``, when the silo has no hopper), the front and back faces (role ``face``), the plate
    and the counting rectangle ``outlet_half`` wide at ``outlet_z`` (m), the slot centred at
    x = ``silo.outlet_offset``. A slab periodic along y (``silo.periodic_depth``) has no faces, and
    its walls span the periodic length exactly."""
    g = silo
    a, b, hh, top = g.half_width, 0.5 * g.thickness, g.hopper_height, g.hopper_height + g.height
    w0, e = g.outlet_radius, g.outlet_offset
    # faces: few large facets (every grain touches the faces: their facet count is what costs);
    # thin walls: one facet across, at most MAX_FACET_ASPECT times longer
    facet = max(g.width / 2.0, g.thickness)
    long = MAX_FACET_ASPECT * g.thickness                # thin walls' facets along their length
    meshes: list[WallMesh] = []

    def side_piece(name, role, side, z_lo, z_hi, **kw):
        x = -a if side == 0 else a
        sensor = {"normal": (-1.0 if side == 0 else 1.0, 0.0), "projected_area": 2 * b * (z_hi - z_lo)} \
            if role == "band" else {}
        meshes.append(_wall(name, role, lambda: _balanced_rectangle(
            (x, -b, z_lo), (0.0, 2 * b, 0.0), (0.0, 0.0, z_hi - z_lo), 1, _divisions(z_hi - z_lo, long)),
            z0=z_lo, z1=z_hi, sector=side, **sensor, **kw))

    side_pieces(side_piece, (0, 1), band_bounds, hh, g.height)
    for side, sign in ((0, -1.0), (1, 1.0)):
        edge = e + sign * w0                        # the slot's edge on this side, x
        run = sign * a - edge                       # to the side wall's foot, along x
        name, role = (f"hopper_s{side:02d}", "hopper") if hh > 0 else (f"bottom_s{side:02d}", "bottom")
        meshes.append(_wall(name, role, lambda edge=edge, run=run: _balanced_rectangle(
            (edge, -b, 0.0), (0.0, 2 * b, 0.0), (run, 0.0, hh), 1, _divisions(math.hypot(run, hh), long)),
            sector=side))
    # faces: the silo's outline in x-z (wedge, then the full width), on a grid of trapezoid rows where
    # that grid is good, else triangulated anew (a nearly flat or very steep wedge, a narrow slot)
    nz_h, nz_v = _divisions(hh, facet), _divisions(g.height, facet)
    nx = _divisions(g.width, facet)

    def face_grid(y):
        z = np.concatenate([np.linspace(0.0, hh, nz_h + 1), np.linspace(hh, top, nz_v + 1)[1:]]) if hh > 0 \
            else np.linspace(0.0, top, nz_v + 1)
        if e == 0:                                   # symmetric about x = 0
            half = np.where(z < hh, w0 + (a - w0) * z / max(hh, 1e-300), a)
            x = half[:, None] * np.linspace(-1.0, 1.0, nx + 1)[None, :]
        else:                                        # the wedge sheared to the slot's centre
            f = np.where(z < hh, z / max(hh, 1e-300), 1.0)      # 0 at the slot, 1 from the hopper's top
            left, right = (e - w0) + (-a - e + w0) * f, (e + w0) + (a - e - w0) * f
            x = left[:, None] + (right - left)[:, None] * np.linspace(0.0, 1.0, nx + 1)[None, :]
        pts = np.stack([x, np.full((len(z), nx + 1), y), np.broadcast_to(z[:, None], (len(z), nx + 1))], axis=-1)
        return _grid_triangles(pts)

    outline = None

    def face_refined(y):
        nonlocal outline
        if outline is None:
            corners = [(e - w0, 0.0), (e + w0, 0.0), (a, hh), (a, top), (-a, top), (-a, hh)] if hh > 0 else \
                [(-a, 0.0), (a, 0.0), (a, top), (-a, top)]
            outline = _refine_polygon(np.array(corners), facet)
        p, tri = outline
        xyz = np.column_stack([p[:, 0], np.full(len(p), y), p[:, 1]])
        return xyz[tri[:, [0, 2, 1]]]            # counter-clockwise in x-z: normal +y, like the grid's

    for side, y in ((0, -b), (1, b)) if not g.periodic_depth else ():       # periodic along y: no faces
        meshes.append(_wall(f"face_s{side:02d}", "face", lambda y=y: _structured_or_graded(
            2 * nx * (nz_h + nz_v), lambda: face_grid(y), lambda: face_refined(y)), sector=side))
    meshes.append(_wall("plate", "plate", lambda: _balanced_rectangle(
        (e - w0, -b, 0.0), (2 * w0, 0.0, 0.0), (0.0, 2 * b, 0.0), _divisions(2 * w0, facet), 1)))
    y0, dy = (-b, 2 * b) if g.periodic_depth else (-1.5 * b, 3 * b)     # inside a periodic box, beyond faces
    meshes.append(_wall("outlet", "outlet", lambda: _balanced_rectangle(
        (e - outlet_half, y0, outlet_z), (2 * outlet_half, 0.0, 0.0), (0.0, dy, 0.0),
        _divisions(2 * outlet_half, facet), 1)))
    return meshes


def _trapezoid(bottom0, bottom1, top0, top1, n_u: int, n_v: int) -> np.ndarray:
    """Triangles of the planar quadrilateral with the parallel edges bottom0-bottom1 and top0-top1
    (m), on an n_u (along the edges) x n_v grid of straight rows (``MeshQualityError`` beyond
    ``MAX_MESH_TRIANGLES``, before any is made)."""
    _budget(2 * n_u * n_v, f"a trapezoid of {n_u} x {n_v} facets")
    u = np.linspace(0.0, 1.0, n_u + 1)[:, None]
    lo = np.asarray(bottom0, float) + u * (np.asarray(bottom1, float) - bottom0)
    hi = np.asarray(top0, float) + u * (np.asarray(top1, float) - top0)
    v = np.linspace(0.0, 1.0, n_v + 1)[None, :, None]
    return _grid_triangles(lo[:, None, :] + v * (hi - lo)[:, None, :])


def box_meshes(silo: Silo, band_bounds: Sequence[float], outlet_z: float, outlet_half: float) -> list[WallMesh]:
    """Meshes of a rectangular silo (x across its width, y its depth, z up; z = 0 the outlet): the
    four vertical walls cut into sensor bands (sector 0 at x = -width/2, 1 at +width/2, 2 at
    y = -depth/2, 3 at +depth/2), the hopper's four faces (a pyramid's for a rectangular outlet; a
    wedge's two inclined faces and two vertical end walls for a slot) or the flat floor around the
    outlet (strips around a rectangle or slot; around a circle, rings from the circle's polygon to
    the rectangle), the plate and the counting surface (the outlet grown by ``outlet_half`` - its
    half width, m, at ``outlet_z``)."""
    g = silo
    a, b, hh = g.half_width, 0.5 * g.depth, g.hopper_height
    ex, ey, hx, hy = g.outlet_offset, g.outlet_offset_y, g.outlet_radius, g.outlet_half_y
    x0, x1, y0, y1 = ex - hx, ex + hx, ey - hy, ey + hy          # the outlet's extent (a circle's box)
    facet = max(min(a, b) / 2.0, 1e-9)                           # the walls' facets: few and large
    meshes: list[WallMesh] = []
    # the walls: (sector, origin at z = 0 of the vertical part, its horizontal side, outward normal)
    sides = [(0, (-a, -b), (0.0, 2 * b), (-1.0, 0.0)), (1, (a, -b), (0.0, 2 * b), (1.0, 0.0)),
             (2, (-a, -b), (2 * a, 0.0), (0.0, -1.0)), (3, (-a, b), (2 * a, 0.0), (0.0, 1.0))]

    def piece(name, role, side, z_lo, z_hi, **kw):
        sector, (ox, oy), (ux, uy), normal = sides[side]
        length = math.hypot(ux, uy)
        sensor = {"normal": normal, "projected_area": length * (z_hi - z_lo)} if role == "band" else {}
        meshes.append(_wall(name, role, lambda: _balanced_rectangle(
            (ox, oy, z_lo), (ux, uy, 0.0), (0.0, 0.0, z_hi - z_lo), _divisions(length, facet),
            _divisions(z_hi - z_lo, facet)), z0=z_lo, z1=z_hi, sector=sector, **sensor, **kw))

    side_pieces(piece, range(4), band_bounds, hh, g.height)

    # a circle's polygon: the plate's, the counting disc's and the inner ring of the floor around it
    theta = _circle_angles(a, b, ex, ey, _circle_sides(a, b, hx, facet)) if g.outlet == "circle" else None
    if hh > 0:
        # the hopper's faces from the outlet's edges (z = 0) to the walls' feet (z = hh); a slot's end
        # faces are vertical, in the end walls' planes
        corners = {"lo": [(x0, y0), (x1, y0), (x1, y1), (x0, y1)], "hi": [(-a, -b), (a, -b), (a, b), (-a, b)]}
        for side, (i, j) in enumerate([(3, 0), (1, 2), (0, 1), (2, 3)]):       # faces facing -x, +x, -y, +y
            p0, p1 = corners["lo"][i], corners["lo"][j]
            q0, q1 = corners["hi"][i], corners["hi"][j]
            along = max(math.dist(p0, p1), math.dist(q0, q1))
            slant = math.dist((*p0, 0.0), (*q0, hh))
            meshes.append(_wall(f"hopper_s{side:02d}", "hopper", lambda p0=p0, p1=p1, q0=q0, q1=q1, along=along,
                                slant=slant: _trapezoid((*p0, 0.0), (*p1, 0.0), (*q0, hh), (*q1, hh),
                                                        _divisions(along, facet), _divisions(slant, facet)),
                                sector=side))
    elif g.outlet == "circle":
        meshes.append(_wall("bottom", "bottom", lambda: _floor_around_circle(a, b, ex, ey, hx, theta, facet)))
    else:
        strips = [("bottom_s00", (-a, -b), (x0 + a, 2 * b)), ("bottom_s01", (x1, -b), (a - x1, 2 * b)),
                  ("bottom_s02", (x0, -b), (x1 - x0, y0 + b)), ("bottom_s03", (x0, y1), (x1 - x0, b - y1))]
        for name, (ox, oy), (lx, ly) in strips:
            if lx > 1e-12 * a and ly > 1e-12 * b:        # a slot leaves no strip before or behind it
                meshes.append(_wall(name, "bottom", lambda ox=ox, oy=oy, lx=lx, ly=ly: _balanced_rectangle(
                    (ox, oy, 0.0), (lx, 0.0, 0.0), (0.0, ly, 0.0), _divisions(lx, facet), _divisions(ly, facet))))
    if g.outlet == "slot":
        # the slot's end walls go on below the floor to the counting plane: a grain leaving at an end of
        # the slot falls between them, as it fell between the walls above
        for side, y in ((2, -b), (3, b)):
            meshes.append(_wall(f"slot_end_s{side:02d}", "hopper", lambda y=y: _balanced_rectangle(
                (x0, y, outlet_z), (x1 - x0, 0.0, 0.0), (0.0, 0.0, -outlet_z), _divisions(x1 - x0, facet),
                _divisions(-outlet_z, facet)), sector=side))
    if g.outlet == "circle":
        meshes.append(_wall("plate", "plate", lambda: _circle_fan(ex, ey, hx, 0.0, theta)))
        meshes.append(_wall("outlet", "outlet", lambda: _circle_fan(ex, ey, outlet_half, outlet_z, theta)))
    else:
        meshes.append(_wall("plate", "plate", lambda: _balanced_rectangle(
            (x0, y0, 0.0), (x1 - x0, 0.0, 0.0), (0.0, y1 - y0, 0.0), _divisions(x1 - x0, facet),
            _divisions(y1 - y0, facet))))
        grow = outlet_half - hx                          # the counting surface reaches past the outlet
        cy0, cy1 = (y0 - grow, y1 + grow) if g.outlet != "slot" else (-b, b)
        meshes.append(_wall("outlet", "outlet", lambda: _balanced_rectangle(
            (x0 - grow, cy0, outlet_z), (x1 - x0 + 2 * grow, 0.0, 0.0), (0.0, cy1 - cy0, 0.0), 1, 1)))
    return meshes


def _circle_sides(a: float, b: float, radius: float, facet: float) -> int:
    """Sides of a box floor's circular outlet polygon: about ``facet`` long on the box's scale,
    at least 32, and a multiple of 4."""
    return 4 * max(8, math.ceil(2 * math.pi * max(radius, 0.25 * min(a, b)) / facet / 4))


def _circle_angles(a: float, b: float, ex: float, ey: float, n: int) -> np.ndarray:
    """The polar angles about the circle's centre (ex, ey) of its polygon's vertices: n even ones
    and the directions of the rectangle's four corners (so that the floor's outer ring has them)."""
    corners = np.array([math.atan2(cy - ey, cx - ex) for cx, cy in ((a, b), (-a, b), (-a, -b), (a, -b))])
    even = np.linspace(-math.pi, math.pi, n, endpoint=False)
    gap = np.abs(np.mod(even[:, None] - corners[None, :] + math.pi, 2 * math.pi) - math.pi).min(axis=1)
    return np.sort(np.concatenate([even[gap > 0.25 * (2 * math.pi / n)], corners]))


def _circle_fan(ex: float, ey: float, radius: float, z: float, theta: np.ndarray) -> np.ndarray:
    """A circle's polygon (vertices at ``theta`` about (ex, ey)) as a fan of triangles facing up."""
    ring = np.column_stack([ex + radius * np.cos(theta), ey + radius * np.sin(theta), np.full(len(theta), z)])
    centre = np.array([ex, ey, z])
    return np.stack([np.broadcast_to(centre, ring.shape), ring, np.roll(ring, -1, axis=0)], axis=1)


def _floor_around_circle(a: float, b: float, ex: float, ey: float, radius: float, theta: np.ndarray,
                         facet: float) -> np.ndarray:
    """The flat floor [-a, a] x [-b, b] (z = 0) around the circle of ``radius`` at (ex, ey) whose
    polygon has its vertices at ``theta`` (:func:`_circle_angles`, the rectangle's corners among
    them): rings out to the rectangle along the same rays, as many as keep the facets near square
    (no wider than ``facet``, m)."""
    c, s_ = np.cos(theta), np.sin(theta)
    with np.errstate(divide="ignore"):         # distance along each ray to the rectangle's side
        tx = np.where(c > 0, (a - ex) / c, np.where(c < 0, (-a - ex) / c, np.inf))
        ty = np.where(s_ > 0, (b - ey) / s_, np.where(s_ < 0, (-b - ey) / s_, np.inf))
    far = np.minimum(tx, ty)
    side = 2 * math.pi * radius / len(theta)
    n_r = max(1, math.ceil(float((far - radius).max()) / max(side, 0.5 * facet)))
    t = np.linspace(0.0, 1.0, n_r + 1)
    rho = radius + t[:, None] * (far - radius)[None, :]                   # (rings, rays)
    pts = np.stack([ex + rho * c, ey + rho * s_, np.zeros_like(rho)], axis=-1)
    pts = np.concatenate([pts, pts[:, :1]], axis=1)                       # close the rings
    return _grid_triangles(pts)
