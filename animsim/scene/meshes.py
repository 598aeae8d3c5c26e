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
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from animsim.scene.models import MeshStructure, PinBox, PinInside, Scene

if TYPE_CHECKING:
    import numpy as np

MAX_MESH_VERTICES = 200_000
MAX_MESH_FACES = 1_000_000
MAX_SOFT_BODY_VERTICES = 20_000
MAX_MESH_FILE_BYTES = 200 * 1024 * 1024
STRUTS_PER_VERTEX = 3
# A triangle counts as zero-area below this fraction of the squared size of the mesh.
ZERO_AREA_RTOL = 1e-12
# A soft body's enclosed volume counts as zero below this fraction of its bounding box's volume.
ZERO_VOLUME_RTOL = 1e-9
_SAMPLES_PER_BLOCK = 1 << 20  # ray samples placed at once when choosing struts (about 24 MiB)

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
    except (OSError, ValueError) as exc:  # ValueError: a NUL character in the name
        raise MeshError(f"cannot read {path}: {getattr(exc, 'strerror', None) or exc}") from None
    if not path.is_file():
        raise MeshError(f"{path} is not a file")
    if size > MAX_MESH_FILE_BYTES:
        raise MeshError(f"{path} is larger than the {MAX_MESH_FILE_BYTES // 2**20} MB limit for meshes")
    if suffix == ".obj":
        return _read_obj(path)
    digest = _file_digest(path)
    if suffix == ".ply":
        vertices, polygons = _parse_ply(path)
    else:
        vertices, polygons = _parse_stl(path)
    return check_geometry(vertices, polygons, digest, path.name)


def _file_digest(path: Path) -> str:
    try:
        with open(path, "rb") as fh:
            return hashlib.file_digest(fh, "sha256").hexdigest()
    except OSError as exc:
        raise MeshError(f"cannot read {path}: {exc.strerror}") from None


def _obj_lines(path: Path, digest: Any) -> Any:
    """(line number, text) of an OBJ file, read a line at a time (the whole file is never held).

    ``digest`` is fed every byte. Lines end at LF, CRLF or a lone CR (as
    str.splitlines would split them); a UTF-8 byte order mark at the start
    is dropped (some Windows tools write one).
    """
    name = path.name
    lineno = 0
    try:
        fh = open(path, "rb", buffering=1 << 16)  # noqa: SIM115 - closed by the with below; this try names the error
    except OSError as exc:
        raise MeshError(f"cannot read {path}: {exc.strerror}") from None
    with fh:
        if b"\0" in fh.peek(1 << 16)[: 1 << 16]:  # a binary file says so before its first bad line
            raise MeshError(f"{name} is not a text OBJ file (it holds NUL bytes)")
        for raw in fh:
            digest.update(raw)
            if b"\0" in raw:
                raise MeshError(f"{name} is not a text OBJ file (it holds NUL bytes)")
            if lineno == 0 and raw.startswith(b"\xef\xbb\xbf"):
                raw = raw[3:]
            text = raw[:-1] if raw.endswith(b"\n") else raw
            text = text[:-1] if text.endswith(b"\r") else text
            for part in text.split(b"\r") if b"\r" in text else (text,):
                lineno += 1
                try:
                    yield lineno, part.decode("utf-8")
                except UnicodeDecodeError:
                    raise MeshError(
                        f"{name} line {lineno}: not valid UTF-8 text (not an OBJ file?)"
                    ) from None


def _read_obj(path: Path) -> MeshGeometry:
    digest = hashlib.sha256()
    vertices, polygons = _parse_obj(_obj_lines(path, digest), path.name)
    return check_geometry(vertices, polygons, digest.hexdigest(), path.name)


def _shown(word: str) -> str:
    """A word of a mesh file fit to quote: short and made of what OBJ keywords are made of.

    A file that is not a mesh at all (a symlink to a password file named
    x.obj) must not have its contents shown in an error message.
    """
    return repr(word) if len(word) <= 16 and word.replace("_", "").isalnum() and word.isascii() else ""


def _parse_obj(lines: Any, name: str) -> tuple[np.ndarray, list[tuple[int, list[int]]]]:
    """Vertices and polygons (line number, 0-based corner indices) of an OBJ file's lines.

    Stops as soon as the vertex or triangle limit is passed, so a huge file
    costs what the limit allows, not what the file holds.
    """
    import numpy as np

    verts: list[list[float]] = []
    polygons: list[tuple[int, list[int]]] = []
    pending = ""
    triangles = 0
    for lineno, line in lines:
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
                raise MeshError(f"{name} line {lineno}: a vertex needs three numbers x y z") from None
            if not all(math.isfinite(c) for c in xyz):
                raise MeshError(f"{name} line {lineno}: vertex coordinates must be finite")
            verts.append(xyz)
            if len(verts) > MAX_MESH_VERTICES:
                raise MeshError(
                    f"the mesh has more than {MAX_MESH_VERTICES} vertices, the limit "
                    f"(stopped reading at line {lineno})"
                )
        elif kw == "f":
            if len(words) < 4:
                raise MeshError(f"{name} line {lineno}: a face needs at least 3 corners")
            corners = []
            for w in words[1:]:
                head = w.split("/", 1)[0]
                try:
                    k = int(head)
                except ValueError:
                    raise MeshError(
                        f"{name} line {lineno}: {_shown(w) or 'a corner'} is not a vertex index"
                    ) from None
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
            triangles += len(corners) - 2
            if triangles > MAX_MESH_FACES:
                raise MeshError(
                    f"the mesh has more than {MAX_MESH_FACES} triangles, the limit "
                    f"(stopped reading at line {lineno})"
                )
        elif kw in _OBJ_SKIPPED:
            continue
        else:
            shown = _shown(kw)
            raise MeshError(
                f"{name} line {lineno}: unknown or unsupported OBJ statement"
                + (f" {shown}" if shown else " (is it an OBJ file?)")
            )
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

    # lazy as numpy is here: loading a scene without a mesh does not pay for it
    from animsim.ply_reader import PlyFormatError, read_ply, read_ply_header

    try:
        elements = read_ply_header(path)
    except PlyFormatError as exc:
        raise MeshError(f"{path.name}: {exc}") from None
    _check_ply_header(path.name, {e.name: e for e in elements})
    try:
        v = read_ply(path, "vertex")
        f = read_ply(path, "face")
    except PlyFormatError as exc:
        raise MeshError(f"{path.name}: {exc}") from None
    key = "vertex_indices" if "vertex_indices" in f else "vertex_index"
    vertices = np.stack([np.asarray(v[c], dtype=np.float64) for c in "xyz"], axis=1)
    if not np.all(np.isfinite(vertices)):
        raise MeshError(f"{path.name}: vertex coordinates must be finite")
    n = len(vertices)
    polygons = []
    for i, corners in enumerate(f[key]):
        if len(corners) < 3:
            raise MeshError(f"{path.name}: face {i} has {len(corners)} corners; a face needs at least 3")
        idx = [int(c) for c in corners]
        bad = [c for c in idx if not 0 <= c < n]
        if bad:
            raise MeshError(
                f"{path.name}: face {i}: index {bad[0]} is out of range (the file has {n} vertices)"
            )
        polygons.append((0, idx))
    return vertices, polygons


def _check_ply_header(name: str, elements: dict[str, Any]) -> None:
    """Refuse from the header alone what cannot be a mesh within the limits, before any row is read."""
    # lazy as numpy is here: loading a scene without a mesh does not pay for it
    from animsim.ply_reader import PLY_SCALAR_TYPES

    if "vertex" not in elements:
        raise MeshError(f"{name}: no vertex element")
    if "face" not in elements:
        raise MeshError(f"{name} has no face element: it is a point cloud, not a mesh")
    vertex, face = elements["vertex"], elements["face"]
    if vertex.count > MAX_MESH_VERTICES:
        raise MeshError(f"the mesh has {vertex.count} vertices, more than the limit of {MAX_MESH_VERTICES}")
    if face.count > MAX_MESH_FACES:  # every face is at least one triangle
        raise MeshError(f"the mesh has {face.count} faces, more than the limit of {MAX_MESH_FACES} triangles")
    props = {p.name: p for p in vertex.properties}
    for c in "xyz":
        if c not in props:
            raise MeshError(f"{name}: the vertex element has no x, y, z")
        if props[c].list_count_type is not None:
            raise MeshError(f"{name}: vertex property {c!r} is a list; x, y and z must be single numbers")
    fprops = {p.name: p for p in face.properties}
    prop = fprops.get("vertex_indices", fprops.get("vertex_index"))
    if prop is None:
        raise MeshError(f"{name}: the face element has no vertex_indices list")
    if prop.list_count_type is None:
        raise MeshError(f"{name}: the face property {prop.name!r} must be a list of vertex indices")
    if PLY_SCALAR_TYPES[prop.type].startswith("f"):
        raise MeshError(
            f"{name}: the face indices have the type {prop.type!r}; vertex indices must be integers"
        )


def _parse_stl(path: Path) -> tuple[np.ndarray, list[tuple[int, list[int]]]]:
    import numpy as np

    try:
        import trimesh
    except ImportError:
        raise MeshError(
            "reading STL needs trimesh: pip install 'animsim[mesh]' (or convert the file to OBJ or PLY)"
        ) from None
    _sniff_stl(path)
    try:
        mesh = trimesh.load_mesh(str(path), file_type="stl", process=True)
    except Exception as exc:  # trimesh raises many kinds; all mean "not a usable STL"
        # its message may quote the file or name a module it lacks: neither helps the user
        raise MeshError(f"{path.name} is not a readable STL file ({type(exc).__name__})") from None
    vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    return vertices, [(0, f) for f in faces.tolist()]


def _sniff_stl(path: Path) -> None:
    """Refuse what is neither STL form before trimesh parses it, and too many triangles from the header.

    Binary STL: an 80-byte header, a little-endian uint32 triangle count n,
    then 50 bytes per triangle, so the size is exactly 84 + 50 n. ASCII STL
    starts with ``solid``.
    """
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(84)
    if len(head) == 84:
        n = int.from_bytes(head[80:84], "little")
        if size == 84 + 50 * n:
            if n > MAX_MESH_FACES:
                raise MeshError(f"the mesh has {n} triangles, more than the limit of {MAX_MESH_FACES}")
            return
    if head.lstrip().startswith(b"solid"):
        return
    raise MeshError(
        f"{path.name} is not an STL file (neither binary STL, whose size is 84 + 50 bytes per "
        "triangle, nor ASCII STL, which starts with 'solid')"
    )


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


# --- checks the loader runs ----------------------------------------------------------

Problem = tuple[tuple[str | int, ...], str, bool]


def check_meshes(scene: Scene, scene_dir: Path | None, mesh_dirs: tuple[str, ...] = ()) -> list[Problem]:
    """Read every mesh structure's file, attach the geometry, and list the problems.

    ``scene_dir``: the folder relative paths start from (the scene file's);
    None means the current directory. A mesh file must lie under that folder
    or under one of ``mesh_dirs`` (``--mesh-dir``), see :func:`resolve_allowed`.
    """
    out: list[Problem] = []
    for i, s in enumerate(scene.structures):
        if not isinstance(s, MeshStructure):
            continue
        if s.volume is not None and s.mode != "soft_body":
            out.append((("structures", i, "volume"), "volume springs apply only to mode: soft_body", True))
        try:
            path = resolve_allowed(s.file, scene_dir, mesh_dirs)
            geom = read_mesh(path)
            _check_mode(s, geom)
        except MeshError as exc:
            out.append((("structures", i, "file"), str(exc), False))
            continue
        placed = _check_placed(s, geom)
        if placed is not None:
            out.append((("structures", i, "scale"), placed, False))
            continue
        s._geometry = geom
        out.extend(((("structures", i, *p)), msg, key) for p, msg, key in _check_pins(s, geom))
    return out


def _check_placed(s: MeshStructure, geom: MeshGeometry) -> str | None:
    """Why the placed mesh cannot carry its mass (None when it can).

    Masses are shares of the triangles' areas in world units (vertex_masses): a
    scale of 1e-300 makes every area underflow to 0 and every mass 0/0, one of
    1e300 makes positions or areas overflow.
    """
    import numpy as np

    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        x = place(s, geom.vertices)
        if not np.all(np.isfinite(x)):
            return f"scale {s.scale:g} puts vertices beyond what a float64 can hold; use a smaller scale"
        mass = vertex_masses(s.mass, x, geom.triangles)
    if not np.all(np.isfinite(mass) & (mass > 0)):
        return (
            f"scale {s.scale:g} makes the triangles' areas underflow or overflow, so the mass cannot be "
            "shared among the vertices; use a scale that gives the mesh a size between about 1e-100 "
            "and 1e100 m"
        )
    return None


def resolve_allowed(file: str, scene_dir: Path | None, mesh_dirs: tuple[str, ...] = ()) -> Path:
    """The mesh file a scene names, if it may read it (else :class:`MeshError`).

    A scene may come from someone else, so by default it reads meshes only
    from its own folder and below: the path is taken relative to the scene's
    folder (the current one for a scene given as text), ``~`` is not expanded,
    and after symlinks are resolved the file must still lie under that folder.
    Each ``--mesh-dir DIR`` allows the files under DIR too (absolute paths
    included). The message names the path as written, never what the file holds.
    """
    if "\0" in file:
        raise MeshError("the path holds a NUL character, which no file name can contain")
    if file.startswith("~"):
        raise MeshError(
            f"{file!r}: '~' is not expanded in scenes; give the path relative to the scene file "
            "(or allow the mesh's folder with --mesh-dir)"
        )
    base = Path.cwd() if scene_dir is None else scene_dir
    candidate = base / file  # an absolute ``file`` replaces base
    try:
        real = candidate.resolve()
        roots = [base.resolve(), *(Path(d).expanduser().resolve() for d in mesh_dirs)]
    except (OSError, RuntimeError) as exc:  # a symlink loop
        raise MeshError(f"cannot resolve {file!r}: {exc}") from None
    if not any(real.is_relative_to(root) for root in roots):
        where = "the scene's folder" if scene_dir is not None else "the current folder"
        raise MeshError(
            f"{file!r} lies outside {where} ({base}); scenes read meshes only from their own folder "
            "and below: move the mesh there, or allow its folder with --mesh-dir DIR"
        )
    return candidate


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
            f"struts grows faster than n), this mesh has {geom.vertex_count}; simplify it"
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
    # Volume relative to the mesh's size (scaled as in check_geometry, so no overflow): a closed
    # surface folded flat (a sheet and its copy, wound both ways) encloses nothing to hold.
    x = geom.vertices - geom.vertices.min(axis=0)
    size = float(x.max()) or 1.0
    if enclosed_volume(x / size, geom.triangles) <= ZERO_VOLUME_RTOL:
        raise MeshError(
            "mode soft_body needs a surface that encloses a volume, but this closed surface encloses "
            "none (it is folded flat); use mode: cloth"
        )


def inside_box(x: np.ndarray, box: PinBox) -> np.ndarray:
    """(n,) True where a point of ``x`` (n, 3) lies in ``box``, faces included
    (``pin: {inside: {min, max}}`` of every structure and mesh)."""
    import numpy as np

    return np.all((x >= np.asarray(box.min)) & (x <= np.asarray(box.max)), axis=1)


def _check_pins(s: MeshStructure, geom: MeshGeometry) -> list[Problem]:

    n = geom.vertex_count
    if isinstance(s.pin, PinInside):
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
    """Interior strut pairs of a closed surface (module docstring, "volume").

    The candidates of each ray come from a neighbour search instead of all n
    vertices (:func:`_ray_neighbours`), then the rule is applied to them
    exactly. Near ties (squared distances from the ray equal to within 1e-9 of
    h^2) go to the lower vertex index, so rounding cannot change the choice.
    """
    import numpy as np

    n = len(x)
    normal = vertex_normals(x, tri)
    edges = _topology(tri, n).edges
    h = float(np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1).max())
    i, j = _ray_neighbours(x, normal, h)
    key = np.unique(i * n + j)
    i, j = key // n, key % n
    d = x[j] - x[i]
    t = -np.einsum("ij,ij->i", d, normal[i])  # distance along the inward ray
    perp2 = np.einsum("ij,ij->i", d, d) - t * t  # squared distance from the ray
    near_ray = (t > 0) & (perp2 < h * h) & (np.einsum("ij,ij->i", normal[i], normal[j]) < 0)
    i, j, t, perp2 = i[near_ray], j[near_ray], t[near_ray], perp2[near_ray]
    first = np.full(n, np.inf)
    np.minimum.at(first, i, t)  # the first surface hit
    ok = t <= first[i] + h
    i, j, perp2 = i[ok], j[ok], perp2[ok]
    order = np.lexsort((j, np.round(perp2 / (h * h) * 1e9), i))
    i, j = i[order], j[order]
    rank = np.arange(len(i)) - np.searchsorted(i, i, side="left")
    best = rank < STRUTS_PER_VERTEX
    if not best.any():
        return np.zeros((0, 2), dtype=np.int64)
    p = np.sort(np.stack([i[best], j[best]], axis=1), axis=1)
    return np.unique(p, axis=0).astype(np.int64)


def _ray_neighbours(x: np.ndarray, normal: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(i, j): a superset of the vertices j within h of vertex i's inward ray.

    Each ray is sampled every h up to the mesh's diameter L. A vertex within
    h of the ray lies within r = sqrt(h^2 + (h/2)^2) of the nearest sample, so
    the balls of radius r around the samples hold every candidate. Most
    samples lie in the empty inside: a sample is looked up in a grid of
    cells of size r, and only one whose cell or a neighbouring cell holds a
    vertex gets a ball query (a k-d tree). Cost: n L/h grid look-ups (about
    n^1.5 for an evenly meshed body) plus O(log n) per ball query near the
    surface, against n^2 distances for the search over all pairs; memory is
    bounded by doing the samples in blocks.
    """
    import numpy as np
    from scipy.spatial import cKDTree

    n = len(x)
    reach = float(np.hypot(h, 0.5 * h))
    lo = x.min(axis=0)
    span = float(np.linalg.norm(x.max(axis=0) - lo))
    cells = np.floor((x - lo) / reach).astype(np.int64) + 1  # from 1, so the -1 neighbours stay >= 0
    dims = cells.max(axis=0) + 2
    around = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1], indexing="ij"), -1).reshape(-1, 3)
    near = (cells[:, None, :] + around[None, :, :]).reshape(-1, 3)
    occupied = np.unique((near[:, 0] * dims[1] + near[:, 1]) * dims[2] + near[:, 2])
    steps = np.arange(math.ceil(span / h) + 2) * h
    rows_per_block = max(1, _SAMPLES_PER_BLOCK // len(steps))
    tree = cKDTree(x)
    out_i, out_j = [], []
    for start in range(0, n, rows_per_block):
        rows = np.arange(start, min(start + rows_per_block, n))
        pts = x[rows, None, :] - steps[None, :, None] * normal[rows, None, :]
        c = np.floor((pts - lo) / reach).astype(np.int64) + 1
        inside = np.all((c >= 0) & (c < dims), axis=-1)
        key = (c[..., 0] * dims[1] + c[..., 1]) * dims[2] + c[..., 2]
        at = np.minimum(np.searchsorted(occupied, key), len(occupied) - 1)
        r, k = np.nonzero(inside & (occupied[at] == key))
        if not r.size:
            continue
        found = tree.query_ball_point(pts[r, k], reach, return_sorted=False)
        counts = np.fromiter(map(len, found), dtype=np.int64, count=len(found))
        out_j.append(np.fromiter((v for f in found for v in f), dtype=np.int64, count=int(counts.sum())))
        out_i.append(np.repeat(rows[r], counts))
    if not out_i:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return np.concatenate(out_i), np.concatenate(out_j)


@dataclass(frozen=True)
class MeshParts:
    position: np.ndarray
    mass: np.ndarray
    pinned: np.ndarray
    families: list[tuple[str, np.ndarray, Any]]  # (name, pairs, SpringFamily)
    triangles: np.ndarray


def mesh_parts(s: MeshStructure, scene_dir: Path | None = None) -> MeshParts:
    import numpy as np

    geom = geometry_of(s, scene_dir)
    x = place(s, geom.vertices)
    n = len(x)
    pinned = np.zeros(n, dtype=bool)
    if isinstance(s.pin, PinInside):
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
