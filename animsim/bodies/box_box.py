"""The contact between two boxes: a separating-axis test and a clipped contact face.

Two boxes touch where no axis separates them. Of the 15 candidate axes (the three face
normals of each box and the nine cross products of an edge of one with an edge of the
other; Gottschalk, Lin and Manocha, "OBBTree", SIGGRAPH 1996) the one along which they
overlap least is the contact normal, and the contact points follow from which kind of axis
it is (Gregorius, "Robust Contact Creation for Physics Simulations", GDC 2015):

* **A face axis**: the face of that box (the *reference* face) against the face of the other
  box that points most against it (the *incident* face). The incident face's four corners are
  clipped to the reference face's four side planes (Sutherland and Hodgman, "Reentrant polygon
  clipping", CACM 1974); every clipped point below the reference face is a contact, with its
  depth below it. A box lying on a box of the same size gets its four corners, one normal for
  all of them, whatever the rounding of its position: testing each corner against the other
  box's signed distance (as for the round shapes) gives a corner exactly over an edge the
  normal of the side face half of the time, and a stack walks sideways and topples.
* **An edge axis**: one contact, halfway between the closest points of the two edges.

Faces are preferred: an edge axis wins only when it overlaps clearly less (``EDGE_RELATIVE``,
``EDGE_ABSOLUTE``), and the second box's face only when it overlaps less than the first's by
``FACE_ABSOLUTE``, so that a resting contact keeps one normal from step to step.

Written on scalars, for both backends: NumPy calls it as Python, pair by pair; numba compiles
it into the pair kernel (:func:`animsim.bodies.contact_kernels.numba_pair_contacts`).
"""

from __future__ import annotations

import math

import numpy as np

from animsim.bodies.quaternion import rotate_scalar
from animsim.elements import numba_helper

#: an edge axis is the normal only if its overlap is below EDGE_RELATIVE times the best face's ...
EDGE_RELATIVE = 0.95
#: ... by EDGE_ABSOLUTE times the smaller box's smallest half extent
EDGE_ABSOLUTE = 0.01
#: the second box's face is the reference only if it overlaps less by this times that half extent
FACE_ABSOLUTE = 1e-3
#: cross products of edges shorter than this are (nearly) parallel edges: not an axis
PARALLEL = 1e-6
#: the reference face's side planes are moved out by this times the smaller box's smallest half
#: extent before clipping: a box lying on a box of the same size has its incident face's edges
#: on those planes to a rounding error, and an edge straddling a plane by 1e-17 m was cut at a
#: point anywhere along it (0 / 0), so the contact gained points that moved from step to step
#: and could not start warm from the last step's impulses (a ten-box stack walked)
CLIP_SLACK = 1e-9
#: the most contacts of one pair (a square clipped by four lines has at most eight corners)
MAX_POINTS = 8
#: points of the contact face up to this times the smaller box's smallest half extent apart are
#: contacts too, *speculative* ones (Catto, "Contact creation", GDC 2013 / Box2D): the solver
#: lets them close that gap in the step but no more. A box set down on another with a tilt of
#: a rounding error touches with two corners and the other two a nanometre above; without
#: them the whole landing is taken on one edge, and the box starts to turn
MARGIN = 0.01


@numba_helper
def box_axes(q: np.ndarray, out: np.ndarray) -> None:
    """out[k] = R(q) e_k: the box's k-th axis in the world (3, 3)."""
    for k in range(3):
        ex = 1.0 if k == 0 else 0.0
        ey = 1.0 if k == 1 else 0.0
        ez = 1.0 if k == 2 else 0.0
        out[k, 0], out[k, 1], out[k, 2] = rotate_scalar(q[0], q[1], q[2], q[3], ex, ey, ez)


@numba_helper
def _dot(a: np.ndarray, b: np.ndarray) -> float:
    return (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]


@numba_helper
def _radius(axes: np.ndarray, half: np.ndarray, lx: float, ly: float, lz: float) -> float:
    """The box's half width along the unit direction l: sum_k h_k |A_k . l|."""
    total = 0.0
    for k in range(3):
        total += half[k] * abs((axes[k, 0] * lx + axes[k, 1] * ly) + axes[k, 2] * lz)
    return total


@numba_helper
def _clip(
    poly: np.ndarray, count: int, nx: float, ny: float, nz: float, limit: float, out: np.ndarray
) -> int:
    """Keep the part of the polygon poly[:count] where n . p <= limit (Sutherland-Hodgman);
    writes it to out and returns its corner count."""
    kept = 0
    for k in range(count):
        p = poly[k]
        r = poly[(k + 1) % count]
        dp = (p[0] * nx + p[1] * ny) + p[2] * nz - limit
        dr = (r[0] * nx + r[1] * ny) + r[2] * nz - limit
        if dp <= 0.0:
            out[kept, 0], out[kept, 1], out[kept, 2] = p[0], p[1], p[2]
            kept += 1
        if (dp < 0.0 < dr) or (dr < 0.0 < dp):
            s = dp / (dp - dr)
            out[kept, 0] = p[0] + s * (r[0] - p[0])
            out[kept, 1] = p[1] + s * (r[1] - p[1])
            out[kept, 2] = p[2] + s * (r[2] - p[2])
            kept += 1
    return kept


@numba_helper
def box_box(
    xa: np.ndarray,
    qa: np.ndarray,
    ha: np.ndarray,
    xb: np.ndarray,
    qb: np.ndarray,
    hb: np.ndarray,
    points: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
) -> int:
    """Contacts of box a (centre xa, orientation qa, half extents ha) and box b.

    Writes the contact points (halfway between the two surfaces) to points[:k], their
    penetration depths to depth[:k] (negative: a gap, below ``MARGIN``) and the unit normal,
    pointing from a to b, to normal; returns k (0: they are further apart)."""
    axes_a = np.empty((3, 3))
    axes_b = np.empty((3, 3))
    box_axes(qa, axes_a)
    box_axes(qb, axes_b)
    dx, dy, dz = xb[0] - xa[0], xb[1] - xa[1], xb[2] - xa[2]
    scale = min(min(ha[0], ha[1]), min(min(ha[2], hb[0]), min(hb[1], hb[2])))
    margin = MARGIN * scale
    # the face axes: separation along each (negative: overlap)
    best_a, axis_a = -math.inf, -1
    best_b, axis_b = -math.inf, -1
    for k in range(3):
        ax, ay, az = axes_a[k, 0], axes_a[k, 1], axes_a[k, 2]
        sep = abs((dx * ax + dy * ay) + dz * az) - (ha[k] + _radius(axes_b, hb, ax, ay, az))
        if sep > margin:
            return 0
        if sep > best_a:
            best_a, axis_a = sep, k
    for k in range(3):
        bx, by, bz = axes_b[k, 0], axes_b[k, 1], axes_b[k, 2]
        sep = abs((dx * bx + dy * by) + dz * bz) - (_radius(axes_a, ha, bx, by, bz) + hb[k])
        if sep > margin:
            return 0
        if sep > best_b:
            best_b, axis_b = sep, k
    # the edge axes
    best_e, edge_i, edge_j = -math.inf, -1, -1
    ex, ey, ez = 0.0, 0.0, 0.0
    for i in range(3):
        for j in range(3):
            cx = axes_a[i, 1] * axes_b[j, 2] - axes_a[i, 2] * axes_b[j, 1]
            cy = axes_a[i, 2] * axes_b[j, 0] - axes_a[i, 0] * axes_b[j, 2]
            cz = axes_a[i, 0] * axes_b[j, 1] - axes_a[i, 1] * axes_b[j, 0]
            length = math.sqrt((cx * cx + cy * cy) + cz * cz)
            if length < PARALLEL:
                continue
            cx, cy, cz = cx / length, cy / length, cz / length
            sep = abs((dx * cx + dy * cy) + dz * cz) - (
                _radius(axes_a, ha, cx, cy, cz) + _radius(axes_b, hb, cx, cy, cz)
            )
            if sep > margin:
                return 0
            if sep > best_e:
                best_e, edge_i, edge_j = sep, i, j
                ex, ey, ez = cx, cy, cz
    best_face = max(best_a, best_b)
    if edge_i >= 0 and best_e > EDGE_RELATIVE * best_face + EDGE_ABSOLUTE * scale:
        return _edge_contact(
            xa, axes_a, ha, xb, axes_b, hb, edge_i, edge_j, ex, ey, ez, best_e, points, depth, normal
        )
    if best_b > best_a + FACE_ABSOLUTE * scale:
        # b's face is the reference: the normal from b to a, turned around at the end
        k = _face_contacts(xb, axes_b, hb, axis_b, xa, axes_a, ha, margin, points, depth, normal)
        normal[0], normal[1], normal[2] = -normal[0], -normal[1], -normal[2]
        return k
    return _face_contacts(xa, axes_a, ha, axis_a, xb, axes_b, hb, margin, points, depth, normal)


@numba_helper
def _face_contacts(
    xr: np.ndarray,
    axes_r: np.ndarray,
    hr: np.ndarray,
    i: int,
    xi: np.ndarray,
    axes_i: np.ndarray,
    hi: np.ndarray,
    margin: float,
    points: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
) -> int:
    """Reference face of box r on axis i against the incident box: the incident face clipped to
    the reference face's sides; the normal (written to normal) points from r to the other box."""
    dx, dy, dz = xi[0] - xr[0], xi[1] - xr[1], xi[2] - xr[2]
    sign = 1.0 if (dx * axes_r[i, 0] + dy * axes_r[i, 1]) + dz * axes_r[i, 2] >= 0.0 else -1.0
    nx, ny, nz = sign * axes_r[i, 0], sign * axes_r[i, 1], sign * axes_r[i, 2]
    # the incident face: the other box's face whose normal points most against n
    j, most = 0, -1.0
    for k in range(3):
        c = abs((axes_i[k, 0] * nx + axes_i[k, 1] * ny) + axes_i[k, 2] * nz)
        if c > most:
            j, most = k, c
    toward = (axes_i[j, 0] * nx + axes_i[j, 1] * ny) + axes_i[j, 2] * nz
    f = -1.0 if toward >= 0.0 else 1.0  # the face normal f A_j points against n
    u, v = (j + 1) % 3, (j + 2) % 3
    poly = np.empty((MAX_POINTS, 3))
    work = np.empty((MAX_POINTS, 3))
    for c in range(4):
        su = 1.0 if c == 0 or c == 3 else -1.0
        sv = 1.0 if c < 2 else -1.0
        for m in range(3):
            poly[c, m] = (xi[m] + f * hi[j] * axes_i[j, m]) + (
                su * hi[u] * axes_i[u, m] + sv * hi[v] * axes_i[v, m]
            )
    count = 4
    slack = CLIP_SLACK * min(min(min(hr[0], hr[1]), hr[2]), min(min(hi[0], hi[1]), hi[2]))
    # the reference face's four side planes (moved out by the slack)
    for side in range(2):
        k = (i + 1 + side) % 3
        ax, ay, az = axes_r[k, 0], axes_r[k, 1], axes_r[k, 2]
        centre = (xr[0] * ax + xr[1] * ay) + xr[2] * az
        count = _clip(poly, count, ax, ay, az, (centre + hr[k]) + slack, work)
        count = _clip(work, count, -ax, -ay, -az, (-centre + hr[k]) + slack, poly)
        if count == 0:
            return 0
    face = (xr[0] * nx + xr[1] * ny) + xr[2] * nz + hr[i]
    kept = 0
    for c in range(count):
        d = face - ((poly[c, 0] * nx + poly[c, 1] * ny) + poly[c, 2] * nz)
        if d > -margin:
            half = 0.5 * d
            points[kept, 0] = poly[c, 0] + half * nx
            points[kept, 1] = poly[c, 1] + half * ny
            points[kept, 2] = poly[c, 2] + half * nz
            depth[kept] = d
            kept += 1
    normal[0], normal[1], normal[2] = nx, ny, nz
    return kept


@numba_helper
def _edge_contact(
    xa: np.ndarray,
    axes_a: np.ndarray,
    ha: np.ndarray,
    xb: np.ndarray,
    axes_b: np.ndarray,
    hb: np.ndarray,
    i: int,
    j: int,
    lx: float,
    ly: float,
    lz: float,
    sep: float,
    points: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
) -> int:
    """Edge i of a against edge j of b along the unit axis l: one contact halfway between the
    closest points of the two edges (the edge of a furthest along l, of b furthest against it)."""
    if ((xb[0] - xa[0]) * lx + (xb[1] - xa[1]) * ly) + (xb[2] - xa[2]) * lz < 0.0:
        lx, ly, lz = -lx, -ly, -lz
    pa = np.empty(3)
    pb = np.empty(3)
    for m in range(3):
        pa[m] = xa[m]
        pb[m] = xb[m]
    for k in range(3):
        if k != i:
            s = 1.0 if (axes_a[k, 0] * lx + axes_a[k, 1] * ly) + axes_a[k, 2] * lz >= 0.0 else -1.0
            for m in range(3):
                pa[m] += s * ha[k] * axes_a[k, m]
        if k != j:
            s = -1.0 if (axes_b[k, 0] * lx + axes_b[k, 1] * ly) + axes_b[k, 2] * lz >= 0.0 else 1.0
            for m in range(3):
                pb[m] += s * hb[k] * axes_b[k, m]
    # closest points of the lines pa + s u and pb + t w (u, w unit): s = (b f - c) / (1 - b^2),
    # t = f + s b, with b = u . w, c = u . (pa - pb), f = w . (pa - pb)
    u, w = axes_a[i], axes_b[j]
    r0, r1, r2 = pa[0] - pb[0], pa[1] - pb[1], pa[2] - pb[2]
    b = _dot(u, w)
    c = (u[0] * r0 + u[1] * r1) + u[2] * r2
    f = (w[0] * r0 + w[1] * r1) + w[2] * r2
    s = (b * f - c) / (1.0 - b * b)
    s = min(max(s, -ha[i]), ha[i])
    t = min(max(f + s * b, -hb[j]), hb[j])
    for m in range(3):
        points[0, m] = 0.5 * ((pa[m] + s * u[m]) + (pb[m] + t * w[m]))
    depth[0] = -sep
    normal[0], normal[1], normal[2] = lx, ly, lz
    return 1
