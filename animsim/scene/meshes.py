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
  reader (:func:`animsim.export.ply.read_ply`); vertex order is file order.
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
  the same on every run. It costs O(n^2) distance evaluations once, at
  load, which is why soft bodies have the lower vertex limit.

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
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from animsim.scene.models import MeshStructure, Scene

MAX_MESH_VERTICES = 200_000
MAX_MESH_FACES = 1_000_000
MAX_SOFT_BODY_VERTICES = 20_000
MAX_MESH_FILE_BYTES = 200 * 1024 * 1024
STRUTS_PER_VERTEX = 3
# A triangle counts as zero-area below this fraction of the squared size of the mesh.
ZERO_AREA_RTOL = 1e-12
_CHUNK = 64  # rows of the strut distance matrix computed at once

MESH_FORMATS = (".obj", ".ply", ".stl")
_OBJ_SKIPPED = frozenset(
    {"vt", "vn", "vp", "g", "o", "s", "usemtl", "mtllib", "l", "p", "lod", "shadow_obj", "trace_obj"}
)


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
        return _topology(self.triangles, self.vertex_count)


@dataclass(frozen=True)
class Topology:
    edges: np.ndarray  # (E, 2) unique edges, a < b
    edge_faces: np.ndarray  # (E,) triangles per edge
    bend: np.ndarray  # (B, 2) opposite-corner pairs across interior edges


def _topology(tri: np.ndarray, n: int) -> Topology:
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


# --- reading -------------------------------------------------------------------------


def read_mesh(path: Path) -> MeshGeometry:
    """Read and check the mesh file at ``path`` (raises :class:`MeshError`)."""
    suffix = path.suffix.lower()
    if suffix not in MESH_FORMATS:
        raise MeshError(f"unknown mesh format {path.suffix or '(no suffix)'!r}: use .obj, .ply or .stl")
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise MeshError(f"no such file: {path}") from None
    except OSError as exc:
        raise MeshError(f"cannot read {path}: {exc.strerror}") from None
    if not path.is_file():
        raise MeshError(f"{path} is not a file")
    if size > MAX_MESH_FILE_BYTES:
        raise MeshError(f"{path} is larger than the {MAX_MESH_FILE_BYTES // 2**20} MB limit for meshes")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise MeshError(f"cannot read {path}: {exc.strerror}") from None
    digest = hashlib.sha256(raw).hexdigest()
    if suffix == ".obj":
        vertices, polygons = _parse_obj(raw, path.name)
    elif suffix == ".ply":
        vertices, polygons = _parse_ply(path)
    else:
        vertices, polygons = _parse_stl(path)
    return check_geometry(vertices, polygons, digest, path.name)


def _parse_obj(raw: bytes, name: str) -> tuple[np.ndarray, list[tuple[int, list[int]]]]:
    """Vertices and polygons (line number, 0-based corner indices) of an OBJ file."""
    import numpy as np

    if b"\0" in raw:
        raise MeshError(f"{name} is not a text OBJ file (it holds NUL bytes)")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise MeshError(f"{name} line {line}: not valid UTF-8 text (not an OBJ file?)") from None
    verts: list[list[float]] = []
    polygons: list[tuple[int, list[int]]] = []
    pending = ""
    for lineno, line in enumerate(text.splitlines(), start=1):
        line = pending + line.split("#", 1)[0]
        if line.endswith("\\"):
            pending = line[:-1] + " "
            continue
        pending = ""
        words = line.split()
        if not words:
            continue
        kw = words[0]
        if kw == "v":
            if not 3 <= len(words) - 1 <= 7:
                raise MeshError(f"{name} line {lineno}: a vertex needs x y z, got {len(words) - 1} numbers")
            try:
                xyz = [float(w) for w in words[1:4]]
            except ValueError:
                raise MeshError(
                    f"{name} line {lineno}: {' '.join(words[1:4])!r} is not three numbers"
                ) from None
            if not all(math.isfinite(c) for c in xyz):
                raise MeshError(f"{name} line {lineno}: vertex coordinates must be finite")
            verts.append(xyz)
        elif kw == "f":
            if len(words) < 4:
                raise MeshError(f"{name} line {lineno}: a face needs at least 3 corners")
            corners = []
            for w in words[1:]:
                head = w.split("/", 1)[0]
                try:
                    k = int(head)
                except ValueError:
                    raise MeshError(f"{name} line {lineno}: {w!r} is not a vertex index") from None
                if k == 0:
                    raise MeshError(f"{name} line {lineno}: vertex indices start at 1, not 0")
                if k < 0:
                    k = len(verts) + k + 1  # relative to the vertices read so far
                    if k < 1:
                        raise MeshError(
                            f"{name} line {lineno}: face index {w} is out of range "
                            f"(only {len(verts)} vertices before it)"
                        )
                corners.append(k - 1)
            polygons.append((lineno, corners))
        elif kw in _OBJ_SKIPPED:
            continue
        else:
            raise MeshError(f"{name} line {lineno}: unknown or unsupported OBJ statement {kw!r}")
    n = len(verts)
    for lineno, corners in polygons:
        bad = [c + 1 for c in corners if c >= n]
        if bad:
            raise MeshError(
                f"{name} line {lineno}: face index {bad[0]} is out of range (the file has {n} vertices)"
            )
    return np.array(verts, dtype=np.float64).reshape(-1, 3), polygons


def _parse_ply(path: Path) -> tuple[np.ndarray, list[tuple[int, list[int]]]]:
    import numpy as np

    from animsim.export.ply import PlyFormatError, read_ply

    try:
        v = read_ply(path, "vertex")
        names = {e.name for e in v.elements}
        if "face" not in names:
            raise MeshError(f"{path.name} has no face element: it is a point cloud, not a mesh")
        f = read_ply(path, "face")
    except PlyFormatError as exc:
        raise MeshError(f"{path.name}: {exc}") from None
    if not all(c in v for c in "xyz"):
        raise MeshError(f"{path.name}: the vertex element has no x, y, z")
    key = "vertex_indices" if "vertex_indices" in f else "vertex_index" if "vertex_index" in f else None
    if key is None:
        raise MeshError(f"{path.name}: the face element has no vertex_indices list")
    vertices = np.stack([np.asarray(v[c], dtype=np.float64) for c in "xyz"], axis=1)
    if not np.all(np.isfinite(vertices)):
        raise MeshError(f"{path.name}: vertex coordinates must be finite")
    n = len(vertices)
    polygons = []
    for i, corners in enumerate(f[key]):
        idx = [int(c) for c in np.atleast_1d(corners)]
        bad = [c for c in idx if not 0 <= c < n]
        if bad:
            raise MeshError(
                f"{path.name}: face {i}: index {bad[0]} is out of range (the file has {n} vertices)"
            )
        polygons.append((0, idx))
    return vertices, polygons


def _parse_stl(path: Path) -> tuple[np.ndarray, list[tuple[int, list[int]]]]:
    import numpy as np

    try:
        import trimesh
    except ImportError:
        raise MeshError(
            "reading STL needs trimesh: pip install 'animsim[mesh]' (or convert the file to OBJ or PLY)"
        ) from None
    try:
        mesh = trimesh.load_mesh(str(path), file_type="stl", process=True)
    except Exception as exc:  # trimesh raises many kinds; all mean "not a usable STL"
        raise MeshError(f"{path.name} is not a readable STL file ({type(exc).__name__}: {exc})") from None
    vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    return vertices, [(0, f) for f in faces.tolist()]


def check_geometry(
    vertices: np.ndarray, polygons: list[tuple[int, list[int]]], digest: str = "", name: str = ""
) -> MeshGeometry:
    """Triangulate and check a mesh (module docstring); raises :class:`MeshError`.

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
    tri = np.array(tris, dtype=np.int64)
    extent = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    tiny = ZERO_AREA_RTOL * extent**2

    def degenerate(t: np.ndarray) -> np.ndarray:
        p = vertices[t]
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
            p = vertices[corners]
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


# --- checks the loader runs ----------------------------------------------------------

Problem = tuple[tuple[str | int, ...], str, bool]


def check_meshes(scene: Scene, scene_dir: Path | None) -> list[Problem]:
    """Read every mesh structure's file, attach the geometry, and list the problems.

    ``scene_dir``: the folder relative paths start from (the scene file's);
    None means the current directory.
    """
    from animsim.scene.models import MeshStructure

    out: list[Problem] = []
    for i, s in enumerate(scene.structures):
        if not isinstance(s, MeshStructure):
            continue
        if s.volume is not None and s.mode != "soft_body":
            out.append((("structures", i, "volume"), "volume springs apply only to mode: soft_body", True))
        path = resolve(s.file, scene_dir)
        try:
            geom = read_mesh(path)
            _check_mode(s, geom)
        except MeshError as exc:
            out.append((("structures", i, "file"), str(exc), False))
            continue
        s._geometry = geom
        out.extend(((("structures", i, *p)), msg, key) for p, msg, key in _check_pins(s, geom))
    return out


def resolve(file: str, scene_dir: Path | None) -> Path:
    p = Path(file).expanduser()
    if p.is_absolute() or scene_dir is None:
        return p
    return scene_dir / p


def _check_mode(s: MeshStructure, geom: MeshGeometry) -> None:
    import numpy as np

    if s.mode != "soft_body":
        return
    if geom.vertex_count > MAX_SOFT_BODY_VERTICES:
        raise MeshError(
            f"a soft body may have at most {MAX_SOFT_BODY_VERTICES} vertices (choosing its interior "
            f"struts costs n^2), this mesh has {geom.vertex_count}; simplify it"
        )
    topo = geom.topology
    if not geom.closed:
        open_ = np.flatnonzero(topo.edge_faces == 1)
        many = np.flatnonzero(topo.edge_faces > 2)
        if open_.size:
            a, b = topo.edges[open_[0]]
            raise MeshError(
                f"mode soft_body needs a closed surface, but {open_.size} edges are on a hole or border "
                f"(the first between vertices {a} and {b}); close the mesh or use mode: cloth"
            )
        a, b = topo.edges[many[0]]
        raise MeshError(
            f"mode soft_body needs a closed surface, but the edge between vertices {a} and {b} "
            f"is shared by {topo.edge_faces[many[0]]} faces (non-manifold)"
        )


def _check_pins(s: MeshStructure, geom: MeshGeometry) -> list[Problem]:

    from animsim.scene.models import PinInside

    n = geom.vertex_count
    if isinstance(s.pin, PinInside):
        from animsim.scene.structures import inside_box

        if not inside_box(place(s, geom.vertices), s.pin.inside).any():
            return [
                (("pin", "inside"), "no vertex of the mesh is inside this box (world coordinates)", False)
            ]
        return []
    return [
        (("pin", k), f"vertex {v} does not exist (the mesh has {n} vertices, 0 to {n - 1})", False)
        for k, v in enumerate(s.pin)
        if v >= n
    ]


# --- expansion -----------------------------------------------------------------------


def rotation_matrix(axis: tuple[float, float, float], degrees: float) -> np.ndarray:
    """Rodrigues' formula: the right-handed rotation about ``axis`` by ``degrees``."""
    import numpy as np

    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    t = math.radians(degrees)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(t) * kx + (1 - math.cos(t)) * (kx @ kx)


def place(s: MeshStructure, vertices: np.ndarray) -> np.ndarray:
    """World positions of file vertices (module docstring, Placement)."""
    import numpy as np

    x = vertices * s.scale
    if s.rotation is not None:
        x = x @ rotation_matrix(s.rotation.axis, s.rotation.angle).T
    return np.ascontiguousarray(x + np.asarray(s.position), dtype=np.float64)


def geometry_of(s: MeshStructure, scene_dir: Path | None = None) -> MeshGeometry:
    """The structure's checked geometry: attached by the loader, else read now."""
    geom = s._geometry
    if geom is None:
        geom = read_mesh(resolve(s.file, scene_dir))
        _check_mode(s, geom)
        s._geometry = geom
    return geom


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


def struts(x: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Interior strut pairs of a closed surface (module docstring, "volume")."""
    import numpy as np

    n = len(x)
    normal = vertex_normals(x, tri)
    edges = _topology(tri, n).edges
    h = float(np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1).max())
    pairs = []
    for start in range(0, n, _CHUNK):
        rows = slice(start, min(start + _CHUNK, n))
        d = x[None, :, :] - x[rows, None, :]  # (r, n, 3): from i to every j
        t = -np.einsum("rnk,rk->rn", d, normal[rows])  # distance along the inward ray
        perp2 = np.einsum("rnk,rnk->rn", d, d) - t * t  # squared distance from the ray
        facing_away = (normal[rows] @ normal.T) < 0
        near_ray = (t > 0) & facing_away & (perp2 < h * h)
        first = np.where(near_ray, t, np.inf).min(axis=1, keepdims=True)  # the first surface hit
        ok = near_ray & (t <= first + h)
        score = np.where(ok, perp2, np.inf)
        k = min(STRUTS_PER_VERTEX, n - 1)
        best = np.argpartition(score, k - 1, axis=1)[:, :k]
        good = np.take_along_axis(score, best, axis=1) < np.inf
        i = np.broadcast_to(np.arange(rows.start, rows.stop)[:, None], best.shape)
        pairs.append(np.stack([i[good], best[good]], axis=1))
    if not pairs:
        return np.zeros((0, 2), dtype=np.int64)
    p = np.sort(np.concatenate(pairs), axis=1)
    return np.unique(p, axis=0).astype(np.int64)


@dataclass(frozen=True)
class MeshParts:
    position: np.ndarray
    mass: np.ndarray
    pinned: np.ndarray
    families: list[tuple[str, np.ndarray, Any]]  # (name, pairs, SpringFamily)
    triangles: np.ndarray


def mesh_parts(s: MeshStructure, scene_dir: Path | None = None) -> MeshParts:
    import numpy as np

    from animsim.scene.models import PinInside

    geom = geometry_of(s, scene_dir)
    x = place(s, geom.vertices)
    n = len(x)
    pinned = np.zeros(n, dtype=bool)
    if isinstance(s.pin, PinInside):
        from animsim.scene.structures import inside_box

        pinned = inside_box(x, s.pin.inside)
    else:
        pinned[[v for v in s.pin if v < n]] = True
    topo = geom.topology
    families: list[tuple[str, np.ndarray, Any]] = []
    if s.stretch is not None:
        families.append(("stretch", topo.edges, s.stretch))
    if s.bend is not None:
        families.append(("bend", topo.bend, s.bend))
    if s.volume is not None and s.mode == "soft_body":
        families.append(("volume", struts(x, geom.triangles), s.volume))
    return MeshParts(
        position=x,
        mass=vertex_masses(s.mass, x, geom.triangles),
        pinned=pinned,
        families=families,
        triangles=geom.triangles,
    )


def mesh_spring_count(s: MeshStructure) -> int:
    """Springs without building them where cheap (stretch, bend); struts are at most 3 per vertex."""
    geom = s._geometry
    if geom is None:
        return 0
    topo = geom.topology
    total = 0
    if s.stretch is not None:
        total += len(topo.edges)
    if s.bend is not None:
        total += len(topo.bend)
    if s.volume is not None and s.mode == "soft_body":
        total += STRUTS_PER_VERTEX * geom.vertex_count
    return total
