"""Meshes from files: reading, checking, and turning a mesh into particles and springs.

Reading
-------
* OBJ: our own strict reader (below). ``v x y z [w]`` (extra numbers such as
  vertex colours are ignored), ``f`` with ``i``, ``i/j``, ``i//k`` or
  ``i/j/k`` corners, 1-based, negative indices counted back from the last
  vertex read so far. Texture coordinates, normals, groups, objects,
  smoothing groups and materials are skipped; anything else (free-form
  curves, a misspelt statement) is refused with its line number, as is a
  number that is not finite. Vertex ``k`` of the file (0-based, in file
  order) is particle ``<id>[k]``.
* PLY: the ``vertex`` (x, y, z) and ``face`` (``vertex_indices`` or
  ``vertex_index``) elements, ASCII or binary, read by animsim's own PLY
  reader (:func:`animsim.ply_reader.read_ply`); vertex order is file order.
* STL: through trimesh (``pip install animsim[mesh]``), with identical
  corners merged, so ``k`` is trimesh's merged vertex order.

Polygons with more than three corners are split into a fan of triangles
from their first corner (so a quad gains one diagonal edge).

Refused, at the ``file`` key: a missing file, a file that is not a mesh (no
vertices or no faces, an unparseable line), a face index out of range, a
face that repeats a corner or has zero area, a vertex no face uses (it would
be a loose particle), more than :data:`MAX_MESH_VERTICES` vertices (or more
than :data:`MAX_SOFT_BODY_VERTICES` for a soft body), and for
``mode: soft_body`` a surface that is not closed (every edge must be shared
by exactly two triangles).

Springs
-------
* stretch: one spring per unique triangle edge.
* bend: for each edge shared by exactly two triangles, a spring between the
  two corners opposite that edge (the classic "bend across the edge" spring
  of mass-spring cloth); pairs that are already an edge, or repeat, are
  dropped.
* volume (soft bodies): interior struts, joining each vertex to the far
  side of the body seen straight through it. Each vertex gets a normal
  (area-weighted sum of its triangles' normals, made outward by the sign
  of the enclosed volume) and casts a ray inward, along ``-n_i``. The
  candidates are the vertices ``j`` within ``h`` of that ray (``h`` the
  longest edge of the mesh, so a ray that crosses a triangle always has a
  candidate) whose own normal faces the other way (``n_i . n_j < 0``). Of
  those, only the first surface the ray meets counts (distance along the
  ray at most ``h`` beyond the nearest candidate), and vertex ``i`` is joined
  to the :data:`STRUTS_PER_VERTEX` candidates closest to the ray; duplicate
  pairs are merged. On a sphere this joins each vertex to the vertices
  around its antipode; on a torus it joins the two sides of the tube, not
  the two sides of the hole. No random numbers are involved, so the choice is
  the same on every run. The candidates come from a neighbour search
  along each ray (:func:`_ray_neighbours`): about n^1.5 cheap grid look-ups
  and O(n log n) tree queries for an evenly meshed body instead of n^2
  distances (20,000 vertices take seconds).

Mass
----
``mass`` is the total. Each vertex gets a third of the area of every triangle
around it (the lumped mass of a uniform sheet or shell), so a finely meshed
region does not get heavier than a coarse one.

Placement
---------
World position = rotation(scale * file position) + position, with the
rotation right-handed about its axis by its angle in degrees (Rodrigues'
formula). ``pin: {inside: {min, max}}`` tests world positions.

The package keeps one module per step: :mod:`~.reading` (the files),
:mod:`~.geometry` (the checked mesh and its geometry), :mod:`~.checks` (what
the loader checks) and :mod:`~.expansion` (particles and springs). Every name
is importable from this package, as it was when it was one module.
"""

from __future__ import annotations

# Every name the one-module meshes had, and _topology (tests reach it) under its old name.
from animsim.scene.meshes.checks import (
    MAX_SOFT_BODY_VERTICES,
    ZERO_VOLUME_RTOL,
    Problem,
    check_meshes,
    check_mode,
    inside_box,
    resolve,
    resolve_allowed,
)
from animsim.scene.meshes.expansion import (
    STRUTS_PER_VERTEX,
    MeshParts,
    geometry_of,
    mesh_parts,
    mesh_spring_count,
    struts,
)
from animsim.scene.meshes.geometry import (
    MAX_MESH_FACES,
    MAX_MESH_VERTICES,
    ZERO_AREA_RTOL,
    MeshError,
    MeshGeometry,
    Topology,
    check_geometry,
    enclosed_volume,
    place,
    rotation_matrix,
    topology_of,
    vertex_masses,
    vertex_normals,
)
from animsim.scene.meshes.geometry import topology_of as _topology  # noqa: F401
from animsim.scene.meshes.reading import MAX_MESH_FILE_BYTES, MESH_FORMATS, read_mesh

__all__ = [
    "MAX_MESH_FACES",
    "MAX_MESH_FILE_BYTES",
    "MAX_MESH_VERTICES",
    "MAX_SOFT_BODY_VERTICES",
    "MESH_FORMATS",
    "STRUTS_PER_VERTEX",
    "ZERO_AREA_RTOL",
    "ZERO_VOLUME_RTOL",
    "MeshError",
    "MeshGeometry",
    "MeshParts",
    "Problem",
    "Topology",
    "check_geometry",
    "check_meshes",
    "check_mode",
    "enclosed_volume",
    "geometry_of",
    "inside_box",
    "mesh_parts",
    "mesh_spring_count",
    "place",
    "read_mesh",
    "resolve",
    "resolve_allowed",
    "rotation_matrix",
    "struts",
    "topology_of",
    "vertex_masses",
    "vertex_normals",
]
