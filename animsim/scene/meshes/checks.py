"""The checks the loader runs on a scene's mesh structures: :func:`check_meshes`
reads each structure's file (only from the scene's folder or a ``--mesh-dir``,
:func:`resolve_allowed`), checks its mode (a soft body needs a closed surface
that encloses a volume), its placement (a scale the masses survive) and its
pins, and attaches the geometry to the structure.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from animsim.scene.meshes.geometry import MeshError, MeshGeometry, enclosed_volume, place, vertex_masses
from animsim.scene.meshes.reading import read_mesh
from animsim.scene.models import MeshStructure, PinBox, PinInside, Scene

if TYPE_CHECKING:
    import numpy as np

MAX_SOFT_BODY_VERTICES = 20_000

# A soft body's enclosed volume counts as zero below this fraction of its bounding box's volume.
ZERO_VOLUME_RTOL = 1e-9


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
            check_mode(s, geom)
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


def check_mode(s: MeshStructure, geom: MeshGeometry) -> None:
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
