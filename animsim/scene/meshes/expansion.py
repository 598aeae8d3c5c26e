"""Turning a checked mesh structure into particles and springs:
:func:`mesh_parts` gives the placed vertices, their masses and pins, and the
spring families (stretch along the edges, bend across them, and a soft body's
interior struts, :func:`struts`); :func:`mesh_spring_count` counts the springs
without building them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from animsim.scene.meshes.checks import check_mode, inside_box, resolve
from animsim.scene.meshes.geometry import MeshGeometry, place, topology_of, vertex_masses, vertex_normals
from animsim.scene.meshes.reading import read_mesh
from animsim.scene.models import MeshStructure, PinInside

if TYPE_CHECKING:
    import numpy as np

STRUTS_PER_VERTEX = 3

_SAMPLES_PER_BLOCK = 1 << 20  # ray samples placed at once when choosing struts (about 24 MiB)


def geometry_of(s: MeshStructure, scene_dir: Path | None = None) -> MeshGeometry:
    """The structure's checked geometry: attached by the loader, else read now."""
    geom = s._geometry
    if geom is None:
        geom = read_mesh(resolve(s.file, scene_dir))
        check_mode(s, geom)
        s._geometry = geom
    return geom


def struts(x: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Interior strut pairs of a closed surface (package docstring, "volume").

    The candidates of each ray come from a neighbour search instead of all n
    vertices (:func:`_ray_neighbours`), then the rule is applied to them
    exactly. Near ties (squared distances from the ray equal to within 1e-9 of
    h^2) go to the lower vertex index, so rounding cannot change the choice.
    """
    import numpy as np

    n = len(x)
    normal = vertex_normals(x, tri)
    edges = topology_of(tri, n).edges
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
