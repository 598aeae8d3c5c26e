"""Soft-body struts: the neighbour search picks exactly what the rule over all pairs picks, and a
body at the vertex limit is braced in seconds (the search over all pairs took minutes)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from animsim.scene.meshes import (
    MAX_SOFT_BODY_VERTICES,
    STRUTS_PER_VERTEX,
    _topology,
    read_mesh,
    struts,
    vertex_normals,
)
from tests.conftest import SCENES


def struts_over_all_pairs(x: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """The rule of the module docstring, written out vertex by vertex over every other vertex."""
    normal = vertex_normals(x, tri)
    edges = _topology(tri, len(x)).edges
    h = float(np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1).max())
    pairs = []
    for i in range(len(x)):
        d = x - x[i]
        t = -d @ normal[i]
        perp2 = (d * d).sum(axis=1) - t * t
        ok = (t > 0) & (normal @ normal[i] < 0) & (perp2 < h * h)
        if not ok.any():
            continue
        ok &= t <= t[ok].min() + h
        js = np.flatnonzero(ok)
        js = js[np.lexsort((js, np.round(perp2[js] / (h * h) * 1e9)))][:STRUTS_PER_VERTEX]
        pairs += [sorted((i, int(j))) for j in js]
    return np.unique(np.array(pairs, dtype=np.int64).reshape(-1, 2), axis=0)


def uv_sphere(
    rings: int, segments: int, rng: np.random.Generator | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """A closed latitude-longitude sphere (two poles), optionally with its radius jittered."""
    theta = np.linspace(0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    ring_pts = np.stack([np.sin(tt) * np.cos(pp), np.cos(tt), np.sin(tt) * np.sin(pp)], -1).reshape(-1, 3)
    x = np.concatenate([[[0, 1, 0]], ring_pts, [[0, -1, 0]]])
    if rng is not None:
        x = x * rng.uniform(0.9, 1.1, size=(len(x), 1))
    tri = []
    ring = lambda r, s: 1 + r * segments + s % segments  # noqa: E731
    for s in range(segments):
        tri.append([0, ring(0, s + 1), ring(0, s)])
        for r in range(rings - 2):
            a, b, c, d = ring(r, s), ring(r, s + 1), ring(r + 1, s), ring(r + 1, s + 1)
            tri += [[a, b, d], [a, d, c]]
        tri.append([len(x) - 1, ring(rings - 2, s), ring(rings - 2, s + 1)])
    return x, np.array(tri, dtype=np.int64)


@pytest.mark.parametrize("name", ["icosphere.obj", "torus.obj"])
def test_the_shipped_meshes_get_the_struts_of_the_rule(name):
    g = read_mesh(SCENES / "meshes" / name)
    assert np.array_equal(struts(g.vertices, g.triangles), struts_over_all_pairs(g.vertices, g.triangles))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_an_uneven_body_gets_the_struts_of_the_rule(seed):
    x, tri = uv_sphere(14, 22, np.random.default_rng(seed))
    got = struts(x, tri)
    assert len(got) > len(x) / 2
    assert np.array_equal(got, struts_over_all_pairs(x, tri))


def test_a_body_at_the_vertex_limit_is_braced_in_seconds():
    x, tri = uv_sphere(100, 202)  # 99 rings of 202 vertices and two poles
    assert MAX_SOFT_BODY_VERTICES - 100 <= len(x) <= MAX_SOFT_BODY_VERTICES
    start = time.process_time()  # CPU time: the machine running the tests may be shared
    pairs = struts(x, tri)
    elapsed = time.process_time() - start
    assert elapsed < 30, f"{elapsed:.1f} s"  # the search over all pairs took minutes; about 3 s here
    assert np.all(np.isin(np.arange(len(x)), pairs))  # every vertex is braced
