"""Wall meshes of a silo, generated as triangle arrays and written as ASCII STL.

z = 0 is the outlet plane. Every cylinder band is split into ``sectors`` azimuthal
meshes, so that each (band, sector) is a force sensor whose net radial force is
not cancelled by the opposite side of the ring (docs/engine_facts.md).

Mesh quality: LIGGGHTS 3.8 refuses a mesh with a triangle whose smallest angle is below the
``curvature`` of ``fix mesh/surface`` (default 0.256 deg, ``SurfaceMesh::qualityCheck``: "The minumum
angle of mesh element ... is lower than the specified curvature ... Bad mesh") and merges nodes
closer than its ``precision`` (1e-8 m). Every generated wall is checked (:func:`check_wall`): its
smallest angle is at least ``MIN_ANGLE_DEG`` and its shortest edge at least ``MIN_EDGE``. The simple
structured grids are kept where they meet that; elsewhere (flat or steep hoppers, orifices much
smaller than the silo or nearly as wide, thin bands) the surface is triangulated anew with graded
rings (surfaces of revolution) or a Delaunay refinement (the slab's faces). A geometry that no
triangulation within ``MAX_MESH_TRIANGLES`` can mesh is refused with a ``CaseError`` naming the
geometry fields that shape the wall.

The package: ``quality`` (LIGGGHTS' limits and the measures), ``wall_mesh`` (one wall and its STL),
``triangulation`` (surfaces), ``silo_walls`` (the container's walls and sensors), ``user_meshes``
(the user's STL inserts), ``container`` (the user's own silo from STL: checked, measured, cut into
sensors). Every public name is importable from ``siloflow.geometry``.
"""
from __future__ import annotations

from .container import (  # noqa: F401
    Container,
    Outline,
    container_meshes,
    read_container,
)
from .quality import (  # noqa: F401
    GRADING,
    LIGGGHTS_CURVATURE_DEG,
    LIGGGHTS_MIN_MESH_EXTENT,
    LIGGGHTS_PRECISION,
    LIGGGHTS_SKEWED_DEG,
    MAX_FACET_ASPECT,
    MAX_MESH_TRIANGLES,
    MIN_ANGLE_DEG,
    MIN_EDGE,
    MIN_RING_POINTS,
    REFINE_ANGLE_DEG,
    ROW_ASPECT,
    MeshQuality,
    MeshQualityError,
    as_written,
    aspect_ratios,
    mesh_quality,
    min_angles,
    triangle_angles,
)
from .silo_walls import (  # noqa: F401
    band_boundaries,
    check_wall,
    cylinder_meshes,
    merge_side_walls,
    silo_meshes,
    slab_meshes,
)
from .triangulation import (  # noqa: F401
    disc,
    graded_disc,
    rectangle,
    revolution_rows,
    surface_of_revolution,
)
from .user_meshes import (  # noqa: F401
    MAX_USER_MESH_BYTES,
    MeshError,
    check_inside,
    read_user_mesh,
    user_wall,
)
from .wall_mesh import (  # noqa: F401
    WallMesh,
    write_stl,
)

__all__ = ['Container', 'GRADING', 'LIGGGHTS_CURVATURE_DEG', 'LIGGGHTS_MIN_MESH_EXTENT', 'LIGGGHTS_PRECISION', 'LIGGGHTS_SKEWED_DEG', 'MAX_FACET_ASPECT', 'MAX_MESH_TRIANGLES', 'MAX_USER_MESH_BYTES', 'MIN_ANGLE_DEG', 'MIN_EDGE', 'MIN_RING_POINTS', 'MeshError', 'MeshQuality', 'MeshQualityError', 'Outline', 'REFINE_ANGLE_DEG', 'ROW_ASPECT', 'WallMesh', 'as_written', 'aspect_ratios', 'band_boundaries', 'check_inside', 'check_wall', 'container_meshes', 'cylinder_meshes', 'disc', 'graded_disc', 'merge_side_walls', 'mesh_quality', 'min_angles', 'read_container', 'read_user_mesh', 'rectangle', 'revolution_rows', 'silo_meshes', 'slab_meshes', 'surface_of_revolution', 'triangle_angles', 'user_wall', 'write_stl']
