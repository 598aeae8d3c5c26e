"""Reading mesh files: :func:`read_mesh` takes an OBJ (animsim's own strict
reader, a line at a time), a PLY (:mod:`animsim.ply_reader`) or an STL
(through trimesh), refuses from the size, the header or the first bad line
what cannot be a mesh within the limits, and hands the vertices and polygons
to :func:`~animsim.scene.meshes.geometry.check_geometry`.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from animsim.scene.meshes.geometry import (
    MAX_MESH_FACES,
    MAX_MESH_VERTICES,
    MeshError,
    MeshGeometry,
    check_geometry,
)

if TYPE_CHECKING:
    import numpy as np

MAX_MESH_FILE_BYTES = 200 * 1024 * 1024

MESH_FORMATS = (".obj", ".ply", ".stl")
_OBJ_SKIPPED = frozenset(
    {"vt", "vn", "vp", "g", "o", "s", "usemtl", "mtllib", "l", "p", "lod", "shadow_obj", "trace_obj"}
)


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
