"""Structure generators: cloth, strand (hair, rope) and soft_box (jello).

Each expands to particles and families of springs whose rest length is the
initial distance. The spring layouts follow the course notes (the "Cloth" and
"Hair" slides of the computer-animation lectures, and Lander's "Building with
Sticks" jello cube): structural springs between grid neighbours, shear springs
on both diagonals of each cell, bend springs that skip one particle.

Ids are ``<id>[i,j]`` (cloth), ``<id>[i]`` (strand) and ``<id>[i,j,k]``
(soft_box), created in row-major order, so index = i*ny + j (cloth) and
(i*ny + j)*nz + k (soft_box). The regular layout is kept (``grid_shape``) so
later stages can use array slices instead of index lists.

A ``mesh`` structure (:mod:`animsim.scene.meshes`) has ids ``<id>[k]``, k the
vertex index in its file, and a one-dimensional "grid" of its vertex count.

Every expansion also says how its particles connect, for the exporters: the
surface faces of cloth (grid quads), soft boxes (the quads of the six outer
faces, outward) and meshes (triangles), and the particle order of a strand.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # numpy is imported where arrays are built, so validating a scene
    import numpy as np  # (and refusing a bad one) does not pay for importing it

from animsim.scene.meshes import geometry_of, inside_box, mesh_parts, mesh_spring_count, place
from animsim.scene.models import (
    Cloth,
    MeshStructure,
    PinInside,
    SoftBox,
    SpringFamily,
    Strand,
    Structure,
)

_PLANE_AXES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}


@dataclass(frozen=True)
class SpringGroup:
    """One family of generated springs, local particle indices."""

    family: str  # e.g. "cloth sheet: structural"
    index: np.ndarray  # (m, 2) int64, local indices
    ks: float
    kd: float
    max_strain: float = float("inf")  # tearing limit; inf: never breaks


@dataclass(frozen=True)
class Expanded:
    ids: list[str]
    position: np.ndarray  # (n, 3) m
    velocity: np.ndarray  # (n, 3) m/s
    mass: np.ndarray  # (n,) kg
    pinned: np.ndarray  # (n,) bool
    springs: list[SpringGroup]
    grid_shape: tuple[int, ...]
    # For export: (F, k) local vertex indices of the surface faces (quads or
    # triangles, counter-clockwise seen from outside where there is one), or
    # None; ``curves``: (C, L) local indices, one row per polyline, or None.
    faces: np.ndarray | None = None
    curves: np.ndarray | None = None


def grid_shape(s: Structure) -> tuple[int, ...]:
    if isinstance(s, MeshStructure):
        # Known once the loader has read the file; (0,) before that.
        geom = s._geometry
        return (0 if geom is None else geom.vertex_count,)
    if isinstance(s, Cloth):
        return (s.resolution[0], s.resolution[1])
    if isinstance(s, Strand):
        return (s.count,)
    return (s.resolution[0], s.resolution[1], s.resolution[2])


def particle_count(s: Structure) -> int:
    return math.prod(grid_shape(s))  # exact Python int: no overflow for absurd resolutions


def structure_spring_count(s: Structure) -> int:
    """Number of springs the structure generates, counted without generating them
    (the memory pre-flight calls this on lattices far too large to build)."""
    if isinstance(s, MeshStructure):
        return mesh_spring_count(s)
    shape = grid_shape(s)
    total = 0
    for _name, _fam, offsets in family_offsets(s):
        for offset in offsets:
            if all(abs(o) < n for n, o in zip(shape, offset, strict=True)):
                total += math.prod(n - abs(o) for n, o in zip(shape, offset, strict=True))
    return total


_ID_RE = re.compile(r"^(?P<base>.*)\[(?P<idx>-?\d+(?:,-?\d+)*)\]$")


def parse_structure_id(pid: str) -> tuple[str, tuple[int, ...]] | None:
    """Split ``sheet[3,4]`` into ("sheet", (3, 4)); None if not of that form."""
    m = _ID_RE.match(pid)
    if not m:
        return None
    return m.group("base"), tuple(int(x) for x in m.group("idx").split(","))


def local_index(s: Structure, pid: str) -> int | None:
    """Local index of ``pid`` in structure ``s``, or None if ``s`` has no such particle."""
    parsed = parse_structure_id(pid)
    if parsed is None or parsed[0] != s.id:
        return None
    shape = grid_shape(s)
    idx = parsed[1]
    if len(idx) != len(shape) or any(not 0 <= i < n for i, n in zip(idx, shape, strict=True)):
        return None
    flat = 0
    for i, n in zip(idx, shape, strict=True):  # row-major, as np.ravel_multi_index
        flat = flat * n + i
    return flat


def format_id(base: str, shape: tuple[int, ...]) -> list[str]:
    """All ids of a structure in creation order."""
    import numpy as np

    grids = np.indices(shape).reshape(len(shape), -1).T
    return [f"{base}[{','.join(map(str, row))}]" for row in grids.tolist()]


def _pairs(shape: tuple[int, ...], a: tuple[slice, ...], b: tuple[slice, ...]) -> np.ndarray:
    """Index pairs between two shifted sub-blocks of the grid."""
    import numpy as np

    flat = np.arange(int(np.prod(shape)), dtype=np.int64).reshape(shape)
    return np.stack([flat[a].ravel(), flat[b].ravel()], axis=1)


def _lo(k: int) -> slice:
    return slice(None, -k) if k else slice(None)


def _hi(k: int) -> slice:
    return slice(k, None)


def _offset_pairs(shape: tuple[int, ...], offset: tuple[int, ...]) -> np.ndarray:
    """Pairs (p, p + offset) for every p where both are on the grid.

    Negative offset components are handled by swapping which block is shifted.
    """
    import numpy as np

    a: list[slice] = []
    b: list[slice] = []
    for n, o in zip(shape, offset, strict=True):
        if abs(o) >= n:
            return np.zeros((0, 2), dtype=np.int64)
        if o >= 0:
            a.append(_lo(o))
            b.append(_hi(o))
        else:
            a.append(_hi(-o))
            b.append(_lo(-o))
    return _pairs(shape, tuple(a), tuple(b))


def family_max_strain(s: Structure, fam: SpringFamily) -> float:
    """The tearing limit of one spring family: its own max_strain, else the structure's
    (which tears every family that sets none), else +inf (never breaks)."""
    limit = fam.max_strain if fam.max_strain is not None else s.max_strain
    return float("inf") if limit is None else float(limit)


def tears(s: Structure) -> bool:
    """Whether any spring family of ``s`` has a tearing limit."""
    if s.max_strain is not None:
        return True
    return any(isinstance(f, SpringFamily) and f.max_strain is not None for f in vars(s).values())


def family_offsets(s: Structure) -> list[tuple[str, SpringFamily, list[tuple[int, ...]]]]:
    """The spring families a structure asks for, each with its grid offsets."""
    if isinstance(s, Cloth):
        spec = [
            ("structural", s.structural, [(1, 0), (0, 1)]),
            ("shear", s.shear, [(1, 1), (1, -1)]),
            ("bend", s.bend, [(2, 0), (0, 2)]),
        ]
    elif isinstance(s, Strand):
        spec = [("stretch", s.stretch, [(1,)]), ("bend", s.bend, [(2,)])]
    else:
        spec = [
            ("edge", s.edge, [(1, 0, 0), (0, 1, 0), (0, 0, 1)]),
            (
                "face_diagonal",
                s.face_diagonal,
                [(1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1), (0, 1, 1), (0, 1, -1)],
            ),
            ("body_diagonal", s.body_diagonal, [(1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1)]),
        ]
    return [(name, fam, offsets) for name, fam, offsets in spec if fam is not None]


def _families(s: Structure, shape: tuple[int, ...]) -> list[tuple[str, np.ndarray, SpringFamily]]:
    import numpy as np

    return [
        (name, np.concatenate([_offset_pairs(shape, o) for o in offsets]), fam)
        for name, fam, offsets in family_offsets(s)
    ]


def expand(s: Structure, scene_dir: Path | None = None) -> Expanded:
    """Particles, springs and connectivity of ``s`` (``scene_dir``: where a mesh
    file's relative path starts when the loader has not read it already)."""
    import numpy as np

    if isinstance(s, MeshStructure):
        return _expand_mesh(s, scene_dir)
    shape = grid_shape(s)
    n = int(np.prod(shape))
    pos = grid_positions(s)
    pinned = np.zeros(n, dtype=bool)
    pinned[pinned_rows(s)] = True
    groups = [
        SpringGroup(
            f"{s.type} {s.id}: {name}",
            pairs,
            fam.ks,
            fam.kd,
            family_max_strain(s, fam),
        )
        for name, pairs, fam in _families(s, shape)
    ]
    return Expanded(
        ids=format_id(s.id, shape),
        position=np.ascontiguousarray(pos, dtype=np.float64),
        velocity=np.tile(np.asarray(s.velocity, dtype=np.float64), (n, 1)),
        mass=np.full(n, s.mass),
        pinned=pinned,
        springs=groups,
        grid_shape=shape,
        faces=_grid_faces(s, shape),
        curves=np.arange(n, dtype=np.int64)[None, :] if isinstance(s, Strand) else None,
    )


def initial_positions(s: Structure, scene_dir: Path | None = None) -> np.ndarray:
    """The (n, 3) starting positions of ``s``'s particles, without its springs (the pre-flight's
    contact count needs only these)."""
    if isinstance(s, MeshStructure):
        return place(s, geometry_of(s, scene_dir).vertices)
    return grid_positions(s)


def grid_positions(s: Structure) -> np.ndarray:
    """(n, 3) positions of a cloth, strand or soft box, in creation order."""
    import numpy as np

    shape = grid_shape(s)
    n = int(np.prod(shape))
    if isinstance(s, Cloth):
        u_axis, v_axis = _PLANE_AXES[s.plane]
        i, j = np.indices(shape).reshape(2, -1).astype(np.float64)
        pos = np.tile(np.asarray(s.origin, dtype=np.float64), (n, 1))
        pos[:, u_axis] += s.size[0] * i / (shape[0] - 1)
        pos[:, v_axis] += s.size[1] * j / (shape[1] - 1)
    elif isinstance(s, Strand):
        f = np.linspace(0.0, 1.0, n)[:, None]
        pos = np.asarray(s.start) * (1 - f) + np.asarray(s.end) * f
    else:
        assert isinstance(s, SoftBox)
        frac = [np.linspace(-0.5, 0.5, k) for k in shape]
        grid = np.stack(np.meshgrid(*frac, indexing="ij"), axis=-1).reshape(-1, 3)
        pos = np.asarray(s.center) + grid * np.asarray(s.size)
    return np.ascontiguousarray(pos, dtype=np.float64)


def pinned_rows(s: Structure) -> np.ndarray:
    """Local indices of the pinned particles of a cloth, strand or soft box: the listed ids
    (one that names no particle is reported by the scene check), or those inside the box."""
    import numpy as np

    if isinstance(s.pin, PinInside):
        return np.flatnonzero(inside_box(grid_positions(s), s.pin.inside))
    rows = [local_index(s, pid) for pid in s.pin]
    return np.array(sorted({r for r in rows if r is not None}), dtype=np.int64)


def _grid_faces(s: Structure, shape: tuple[int, ...]) -> np.ndarray | None:
    """Quads of a cloth sheet, or of the outer surface of a soft box (outward)."""
    import numpy as np

    flat = np.arange(math.prod(shape), dtype=np.int64).reshape(shape)
    if isinstance(s, Cloth):
        return _quads(flat)
    if not isinstance(s, SoftBox):
        return None
    quads = []
    for axis in range(3):
        for side in (0, -1):
            sheet = np.moveaxis(flat, axis, 0)[side]  # the two other axes in cyclic order
            q = _quads(sheet)
            # _quads winds counter-clockwise about u x v, (u, v) the remaining
            # axes in order: u x v is +x, -y, +z for axis 0, 1, 2. Flip the faces
            # whose u x v points inward.
            if (axis == 1) != (side == 0):
                q = q[:, ::-1]
            quads.append(q)
    return np.concatenate(quads)


def _quads(sheet: np.ndarray) -> np.ndarray:
    """(i, j), (i+1, j), (i+1, j+1), (i, j+1) for every cell of a 2-D index grid."""
    import numpy as np

    return np.stack(
        [sheet[:-1, :-1].ravel(), sheet[1:, :-1].ravel(), sheet[1:, 1:].ravel(), sheet[:-1, 1:].ravel()],
        axis=1,
    )


def _expand_mesh(s: MeshStructure, scene_dir: Path | None) -> Expanded:
    import numpy as np

    parts = mesh_parts(s, scene_dir)
    n = len(parts.position)
    groups = [
        SpringGroup(
            f"mesh {s.id}: {name}",
            np.ascontiguousarray(pairs, dtype=np.int64),
            fam.ks,
            fam.kd,
            family_max_strain(s, fam),  # tearing
        )
        for name, pairs, fam in parts.families
    ]
    return Expanded(
        ids=format_id(s.id, (n,)),
        position=parts.position,
        velocity=np.tile(np.asarray(s.velocity, dtype=np.float64), (n, 1)),
        mass=parts.mass,
        pinned=parts.pinned,
        springs=groups,
        grid_shape=(n,),
        faces=parts.triangles,
    )


def connectivity(expanded: list[tuple[str, Expanded, int]]) -> tuple[Any, ...]:
    """:class:`animsim.record.Connectivity` of each expanded structure (id, expansion, first row)."""
    import numpy as np

    from animsim.record import Connectivity  # with numpy: validating a scene imports neither

    out = []
    for name, e, first in expanded:
        n = len(e.ids)
        for kind, table in (("mesh", e.faces), ("curves", e.curves)):
            if table is None or len(table) == 0:
                continue
            t = np.asarray(table, dtype=np.int64)
            counts = np.full(len(t), t.shape[1], dtype=np.int64)
            out.append(Connectivity(name, kind, first, n, counts, t.ravel()))
    return tuple(out)
