"""Where a particle's step first touches a shape: the march's and the search's constants,
the search along a grazing path, and the face an edge contact runs into (NumPy).

Along a step's path the first contact is found by sphere tracing (march by the distance,
which can never overshoot a surface); a path that skims a surface, which the march cannot
finish, is searched by golden section and bisection (:func:`first_touch`). The numba kernels
(:mod:`animsim.colliders.kernels`) take the same steps.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from animsim.colliders.shapes import Shape, sdf

#: sphere-tracing iterations; a grazing path that needs more is searched (first_touch)
MARCH_STEPS = 48
#: after the march: golden-section steps towards a grazing path's closest approach, then
#: bisection steps to its first touch (brackets shrink by 0.618^80 and 0.5^60 of the step)
GOLDEN_STEPS = 80
BISECT_STEPS = 60
INV_PHI = (math.sqrt(5.0) - 1.0) / 2.0


def edge_face(shape: Shape, p: np.ndarray, w: np.ndarray, tol: np.ndarray, n: np.ndarray) -> None:
    """At a box's edge or corner, the face the particle runs into: in place on the normals n.

    A contact point on an edge is on two faces' planes at once (within ``tol``), and which one
    the distance function names was left to rounding: a grain on the floor lies on the plane
    of the bottom face of a box sliding flush with the floor, and half the time the box's
    front face, which pushes it, lost to the bottom one, which does not, and the box slid over
    the grain. Where two or more faces are within tol (and the point is not further outside),
    the face is the one whose outward normal the particle's velocity relative to the box at
    the step's end, ``w`` (k, 3), runs into most; the first of equals (x, y, z) otherwise."""
    r, half = shape.rotation, shape.half
    q0 = p[:, 0] * r[0, 0] + p[:, 1] * r[1, 0] + p[:, 2] * r[2, 0]  # q = R^T p, as sdf
    q1 = p[:, 0] * r[0, 1] + p[:, 1] * r[1, 1] + p[:, 2] * r[2, 1]
    q2 = p[:, 0] * r[0, 2] + p[:, 1] * r[1, 2] + p[:, 2] * r[2, 2]
    e = np.stack([np.abs(q0) - half[0], np.abs(q1) - half[1], np.abs(q2) - half[2]], axis=1)
    sign = np.where(np.stack([q0, q1, q2], axis=1) < 0, -1.0, 1.0)
    near = e >= -tol[:, None]
    edge = np.flatnonzero((near.sum(axis=1) >= 2) & (e.max(axis=1) <= tol))
    if edge.size == 0:
        return
    score = np.full((edge.size, 3), np.inf)
    for j in range(3):  # the world normal of face j: sign_j R[:, j]
        into = sign[edge, j] * ((r[0, j] * w[edge, 0] + r[1, j] * w[edge, 1]) + r[2, j] * w[edge, 2])
        score[:, j] = np.where(near[edge, j], into, np.inf)
    face = np.argmin(score, axis=1)
    n[edge] = sign[edge, face][:, None] * r[:, face].T


def path_distance(
    shape: Shape, center: np.ndarray, p0: np.ndarray, sg: np.ndarray, r: np.ndarray, rows: np.ndarray
) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """f(s, sel) of :func:`first_touch`: the distance from ``shape`` (at ``center``) of the
    paths p0 + s sg of ``rows[sel]``, minus their radii."""

    def dist(sv: np.ndarray, sel: np.ndarray) -> np.ndarray:
        at = rows[sel]
        d, _ = sdf(
            shape.kind,
            p0[at] + sv[:, None] * sg[at] - center,
            shape.radius,
            shape.half,
            shape.rotation,
            shape.segment,
        )
        return d - r[at]

    return dist


def first_touch(
    dist: Callable[[np.ndarray, np.ndarray], np.ndarray], s0: np.ndarray, tol: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where paths the march gave up on first touch the shape: (hit (k,), s (k,)).

    Sphere tracing steps by the distance to the shape; along a path that skims a surface at a
    small angle theta each step closes only sin(theta) of the gap, so a particle at 1,000 m/s
    passing a 1 cm box at 2 degrees ran out of steps and went through. The distance to a convex
    shape along a line, f(s) = dist(s) (``dist(s, sel)``: the rows ``sel`` at fractions ``s``,
    minus their radius), is a convex function, so from s0 (where f > tol) a golden-section
    search (Kiefer 1953) closes in on its minimum over [s0, 1]; the first point found with
    f <= tol brackets the first touch, which bisection then finds. A path whose minimum stays
    above tol misses the shape. The numba twin (``_first_touch1`` of :mod:`animsim.colliders.kernels`) does the same steps."""
    k = s0.size
    every = np.arange(k)
    touch = np.where(dist(np.ones(k), every) <= tol, 1.0, np.nan)  # ends on or inside
    a, b = s0.copy(), np.ones(k)
    for _ in range(GOLDEN_STEPS):
        sel = np.flatnonzero(np.isnan(touch))
        if sel.size == 0:
            break
        c = b[sel] - INV_PHI * (b[sel] - a[sel])
        d = a[sel] + INV_PHI * (b[sel] - a[sel])
        fc, fd = dist(c, sel), dist(d, sel)
        touch[sel] = np.where(fc <= tol[sel], c, np.where(fd <= tol[sel], d, np.nan))
        left = fc <= fd  # convex: the minimum is in [a, d], else in [c, b]
        b[sel] = np.where(left, d, b[sel])
        a[sel] = np.where(left, a[sel], c)
    hit = ~np.isnan(touch)
    sel = np.flatnonzero(hit)
    lo, hi = s0[sel], touch[sel]
    for _ in range(BISECT_STEPS if sel.size else 0):
        mid = 0.5 * (lo + hi)
        inside = dist(mid, sel) <= tol[sel]
        hi = np.where(inside, mid, hi)
        lo = np.where(inside, lo, mid)
    s = s0.copy()
    s[sel] = hi
    return hit, s
