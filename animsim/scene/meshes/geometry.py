"""A mesh as animsim holds it, and the geometry computed on it.

:class:`MeshGeometry` (vertices in file units and order, triangles) with its
:class:`Topology` (edges, triangles per edge, bend pairs); :func:`check_geometry`,
which triangulates the polygons a reader found and refuses what cannot be a
mesh (:class:`MeshError`, the vertex and triangle limits, degenerate faces,
loose vertices); and the geometry of a placed mesh: rotation and placement in
the world, lumped vertex masses, vertex normals and enclosed volume.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

from animsim.scene.models import MeshStructure

if TYPE_CHECKING:
    import numpy as np

MAX_MESH_VERTICES = 200_000
MAX_MESH_FACES = 1_000_000

# A triangle counts as zero-area below this fraction of the squared size of the mesh.
ZERO_AREA_RTOL = 1e-12


class MeshError(ValueError):
    """A mesh file that cannot be used; the message says why (no file name in front)."""


@dataclass(frozen=True, eq=False)
class MeshGeometry:
    """A checked mesh as read: vertices in file units and order, triangles (0-based)."""

    vertices: np.ndarray  # (n, 3) float64
    triangles: np.ndarray  # (F, 3) int64
    sha256: str
    closed: bool = field(default=False)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, MeshGeometry) and other.sha256 == self.sha256

    def __hash__(self) -> int:
        return hash(self.sha256)

    @property
    def vertex_count(self) -> int:
        return int(self.vertices.shape[0])

    @cached_property
    def topology(self) -> Topology:
        return topology_of(self.triangles, self.vertex_count)


@dataclass(frozen=True)
class Topology:
    edges: np.ndarray  # (E, 2) unique edges, a < b
    edge_faces: np.ndarray  # (E,) triangles per edge
    bend: np.ndarray  # (B, 2) opposite-corner pairs across interior edges


def topology_of(tri: np.ndarray, n: int) -> Topology:
    import numpy as np

    a = tri[:, [0, 1, 2]].reshape(-1)
    b = tri[:, [1, 2, 0]].reshape(-1)
    opposite = tri[:, [2, 0, 1]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * n + hi
    order = np.argsort(key, kind="stable")
    key_s = key[order]
    uniq, start, counts = np.unique(key_s, return_index=True, return_counts=True)
    edges = np.stack([uniq // n, uniq % n], axis=1).astype(np.int64)
    two = counts == 2
    o = opposite[order]
    pairs = np.stack([o[start[two]], o[start[two] + 1]], axis=1)
    pairs = np.sort(pairs, axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    pkey = np.unique(pairs[:, 0] * n + pairs[:, 1])
    pkey = pkey[~np.isin(pkey, uniq)]  # an opposite pair that is already an edge adds nothing
    bend = np.stack([pkey // n, pkey % n], axis=1).astype(np.int64)
    return Topology(edges=edges, edge_faces=counts.astype(np.int64), bend=bend)


def check_geometry(
    vertices: np.ndarray, polygons: list[tuple[int, list[int]]], digest: str = "", name: str = ""
) -> MeshGeometry:
    """Triangulate and check a mesh (package docstring); raises :class:`MeshError`.

    ``name``: the file's name, which every message starts with.
    """
    import numpy as np

    n = len(vertices)
    if n == 0:
        raise MeshError("not a mesh: the file has no vertices")
    if not polygons:
        raise MeshError("not a mesh: the file has no faces")
    if n > MAX_MESH_VERTICES:
        raise MeshError(f"the mesh has {n} vertices, more than the limit of {MAX_MESH_VERTICES}")
    tris: list[list[int]] = []
    where: list[int] = []
    for k, (lineno, corners) in enumerate(polygons):
        if len(set(corners)) != len(corners):
            raise MeshError(f"{_face_at(name, k, lineno, corners)} repeats a vertex (a degenerate face)")
        for j in range(1, len(corners) - 1):
            tris.append([corners[0], corners[j], corners[j + 1]])
            where.append(k)
    if len(tris) > MAX_MESH_FACES:
        raise MeshError(f"the mesh has {len(tris)} triangles, more than the limit of {MAX_MESH_FACES}")
    if not tris:
        raise MeshError("not a mesh: no face has 3 corners")
    tri = np.array(tris, dtype=np.int64)
    lo = vertices.min(axis=0)
    with np.errstate(over="ignore"):
        span = vertices.max(axis=0) - lo
    if not np.all(np.isfinite(span)):
        raise MeshError("the vertex coordinates span more than a float64 can hold (about 1.8e308); rescale")
    # Areas relative to the size of the mesh, in coordinates scaled to it: the same test at
    # 1e-300 and 1e300 without underflow or overflow (the squared size of 1e300 is inf).
    size = float(span.max()) or 1.0
    scaled = (vertices - lo) / size
    extent = float(np.linalg.norm(span / size))
    tiny = ZERO_AREA_RTOL * extent**2

    def degenerate(t: np.ndarray) -> np.ndarray:
        p = scaled[t]
        return np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1) <= tiny

    flat = np.flatnonzero(degenerate(tri))
    if flat.size:
        # A polygon with three corners on one line (a corner on an edge) is a good face whose
        # fan from its first corner has a sliver: fan it from another corner instead.
        first_tri = np.searchsorted(np.asarray(where), np.arange(len(polygons)))
        bad_faces: list[int] = []
        for k in dict.fromkeys(where[int(i)] for i in flat):
            corners = polygons[k][1]
            m = len(corners)
            for r in range(1, m):
                c = corners[r:] + corners[:r]
                fan = np.array([[c[0], c[j], c[j + 1]] for j in range(1, m - 1)], dtype=np.int64)
                if m > 3 and not degenerate(fan).any():
                    tri[first_tri[k] : first_tri[k] + m - 2] = fan
                    break
            else:
                bad_faces.append(k)
        if bad_faces:
            k = bad_faces[0]
            lineno, corners = polygons[k]
            p = scaled[corners]
            # Newell's normal: twice the polygon's vector area (zero when the face is flat)
            area = 0.5 * np.linalg.norm(np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0))
            what = (
                "has zero area"
                if area <= tiny
                else "cannot be split into triangles of nonzero area from any corner (split it in the file)"
            )
            more = f"; {len(bad_faces)} such faces in all" if len(bad_faces) > 1 else ""
            raise MeshError(f"{_face_at(name, k, lineno, corners)} {what} (a degenerate face{more})")
    used = np.zeros(n, dtype=bool)
    used[tri.ravel()] = True
    if not used.all():
        loose = np.flatnonzero(~used)
        raise MeshError(
            f"vertex {int(loose[0])} (0-based) is used by no face ({loose.size} such vertices): "
            "it would be a loose particle; remove it from the file"
        )
    geom = MeshGeometry(vertices=vertices, triangles=tri, sha256=digest)
    closed = bool(np.all(geom.topology.edge_faces == 2))
    object.__setattr__(geom, "closed", closed)
    return geom


def _face_at(name: str, k: int, lineno: int, corners: list[int]) -> str:
    """A face as the file wrote it: ``m.obj line 12: the face f 1 2 3 4`` (OBJ indices start
    at 1), or ``m.ply: face 7 (vertices 0 1 2)`` (PLY and STL faces, 0-based)."""
    prefix = f"{name} " if name else ""
    if lineno:
        return f"{prefix}line {lineno}: the face f {' '.join(str(c + 1) for c in corners)}"
    return f"{prefix.rstrip()}{': ' if name else ''}face {k} (vertices {' '.join(map(str, corners))})"


def rotation_matrix(axis: tuple[float, float, float], degrees: float) -> np.ndarray:
    """Rodrigues' formula: the right-handed rotation about ``axis`` by ``degrees``."""
    import numpy as np

    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    t = math.radians(degrees)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(t) * kx + (1 - math.cos(t)) * (kx @ kx)


def place(s: MeshStructure, vertices: np.ndarray) -> np.ndarray:
    """World positions of file vertices (package docstring, Placement)."""
    import numpy as np

    x = vertices * s.scale
    if s.rotation is not None:
        x = x @ rotation_matrix(s.rotation.axis, s.rotation.angle).T
    return np.ascontiguousarray(x + np.asarray(s.position), dtype=np.float64)


def vertex_masses(total: float, x: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Lumped masses: a third of each incident triangle's area, scaled to ``total``."""
    import numpy as np

    p = x[tri]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    share = np.bincount(tri.ravel(), weights=np.repeat(area / 3.0, 3), minlength=len(x))
    return total * share / share.sum()


def vertex_normals(x: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals, outward for a closed surface (positive volume)."""
    import numpy as np

    p = x[tri]
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # 2 * area * unit normal
    signed_volume = float(np.einsum("ij,ij->", p[:, 0], fn)) / 6.0
    if signed_volume < 0:
        fn = -fn
    vn = np.zeros_like(x)
    for c in range(3):
        np.add.at(vn, tri[:, c], fn)
    length = np.linalg.norm(vn, axis=1, keepdims=True)
    return vn / np.where(length > 0, length, 1.0)


def enclosed_volume(x: np.ndarray, tri: np.ndarray) -> float:
    """|sum over triangles of p0 . (p1 x p2) / 6|: the volume of a closed surface (divergence theorem)."""
    import numpy as np

    p = x[tri]
    return abs(float(np.einsum("ij,ij->", p[:, 0], np.cross(p[:, 1], p[:, 2]))) / 6.0)
