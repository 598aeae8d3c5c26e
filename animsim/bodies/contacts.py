"""Contacts of rigid bodies: against planes, against signed-distance colliders, and between bodies.

Model (after each integrator step, as a step stage):

1. **Detection.** Every shape is a few contact spheres fixed in its body
   (:mod:`animsim.bodies.shapes`): a box's corners, a sphere's centre, a
   capsule's end centres. A contact is a sphere whose surface is behind a plane
   or inside another body's shape (signed distance < 0).
2. **Impulses** (Baraff 1997, "Rigid Body Simulation", section 8, colliding
   contact; solved as sequential impulses, Catto 2005): at the contact point, with
   lever arms r_a, r_b from the centres of mass and unit normal n (from b to a),
   the normal impulse j changes the approach speed v_n = n . (v_a + w_a x r_a -
   v_b - w_b x r_b) by j K, K = 1/m_a + 1/m_b + n . (I_a^-1 (r_a x n)) x r_a + (same for b).
   Its target is -e v_n for an approaching contact, and 0 (resting contact) when
   the approach speed is no more than twice what the forces added in this step:
   that is what gravity alone gives a body lying on a floor, so a resting body
   gets no bounce and does not jitter. Accumulated normal impulses stay >= 0
   (contacts push, never pull); the tangential (Coulomb) impulse stops sliding,
   capped at mu times the normal impulse. The contacts are solved one after the
   other, ``iterations`` times: on NumPy in batches in which no body appears
   twice (a batch is one vectorised update, and the result is the sequential
   one), on numba by a kernel that walks the list. Both write every sum in the
   same order, so the backends agree to the bit.
3. **Projection.** Each body is moved out of each plane by its deepest
   penetration there, and out of other bodies along the normal (split between
   two free bodies by their inverse masses); a
   bouncing contact is moved out by (1 + e) times the depth, the distance the
   reflected motion would have covered after the impact inside the step. The
   projection changes positions only, never velocities.

Limits (also in the user docs): edges of boxes are not contact points, so
box-box contacts are corner-against-face only (an edge crossing an edge is not
found) and a capsule against a capsule is end-sphere-against-shape only.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

from animsim.bodies import box_box, projection
from animsim.bodies import quaternion as quat
from animsim.bodies.box_box import box_box as box_box_contacts
from animsim.bodies.quaternion import rotate_scalar
from animsim.bodies.shapes import BodyShape, Box, Capsule, Sphere, contact_table
from animsim.bodies.warm import WarmStart
from animsim.collisions import energy_shift, kept_end_speed
from animsim.elements import StepStage, compile_helpers

#: sequential-impulse sweeps over the contacts per step: at least this many ...
ITERATIONS = 10
#: ... then more until a sweep changes no contact's velocity by more than SWEEP_TOLERANCE (m/s),
#: at most MAX_SWEEPS. Sequential impulses converge linearly (Gauss-Seidel on the contact
#: problem; Catto 2005): a box resting on four corners gains about a factor 2 per sweep, so ten
#: sweeps leave a residual sliding of 1e-3 of the step's g dt, which a box on a slope held by
#: static friction turns into creep (6e-5 m/s at dt 1/60); the tolerance stops that.
SWEEP_TOLERANCE = 1e-10
MAX_SWEEPS = 100
#: ... or COLD_SWEEPS in a step where two bodies rest on each other with no impulse to start
#: from (warm starting, :mod:`animsim.bodies.warm`): a stack of ten boxes set down at rest
#: needs about 2000 sweeps from zero before its four contacts per box agree; cut short at 300,
#: the first step leaves its boxes turning by 1e-4 rad and the stack leans off within a minute
COLD_SWEEPS = 2000
#: a contact is resting (no bounce) below this multiple of the speed the forces added in the step
RESTING_FACTOR = 2.0
#: and below this absolute approach speed, m/s (rounding of a body already at rest)
RESTING_FLOOR = 1e-6
#: candidate pairs are kept while no body moved more than half of SKIN * the largest bound
SKIN = 0.5

SHAPE_BOX, SHAPE_SPHERE, SHAPE_CAPSULE = 0, 1, 2
#: the most contacts two boxes make (box_box)
MAX_BOX_POINTS = box_box.MAX_POINTS


@dataclass(frozen=True)
class PlaneTable:
    """Planes as arrays: point (P,3), unit normal (P,3), restitution (P,), friction (P,)."""

    point: np.ndarray
    normal: np.ndarray
    restitution: np.ndarray
    friction: np.ndarray

    @property
    def count(self) -> int:
        return int(self.point.shape[0])


@dataclass
class Contacts:
    """A list of contacts (C of them). b = -1: against something static."""

    a: np.ndarray  # (C,) body numbers
    b: np.ndarray  # (C,) body numbers or -1
    ra: np.ndarray  # (C,3) lever arm from a's centre of mass to the contact point
    rb: np.ndarray  # (C,3)
    n: np.ndarray  # (C,3) unit normal, pointing from b into a
    depth: np.ndarray  # (C,) penetration >= 0
    restitution: np.ndarray
    friction: np.ndarray
    plane: np.ndarray  # (C,) the plane a contact is behind, -1 for colliders and pairs

    @property
    def count(self) -> int:
        return int(self.a.shape[0])


def _empty_contacts() -> Contacts:
    z3 = np.zeros((0, 3))
    zi = np.zeros(0, dtype=np.int64)
    return Contacts(zi, zi, z3, z3, z3, np.zeros(0), np.zeros(0), np.zeros(0), zi)


def _concat(parts: list[Contacts]) -> Contacts:
    parts = [p for p in parts if p.count]
    if not parts:
        return _empty_contacts()
    if len(parts) == 1:
        return parts[0]
    return Contacts(*(np.concatenate([getattr(p, f) for p in parts]) for f in Contacts.__dataclass_fields__))


def world_spheres(x: np.ndarray, q: np.ndarray, points: np.ndarray) -> np.ndarray:
    """World centres of the contact spheres, (B, K, 3)."""
    return x[:, None, :] + quat.rotate(q[:, None, :], points)


def plane_contacts(
    x: np.ndarray, q: np.ndarray, points: np.ndarray, radii: np.ndarray, valid: np.ndarray, planes: PlaneTable
) -> Contacts:
    """Contact spheres behind each plane: ordered by plane, then body, then sphere. Vectorised over
    every body's spheres; the signed distance sums x, y, z in order (as the numba twin)."""
    centres = world_spheres(x, q, points)
    parts = []
    for p in range(planes.count):  # planes are a scene's few walls, not per-body work
        n, o = planes.normal[p], planes.point[p]
        dist = ((centres[..., 0] - o[0]) * n[0] + (centres[..., 1] - o[1]) * n[1]) + (
            centres[..., 2] - o[2]
        ) * n[2]
        dist = dist - radii
        body, k = np.nonzero((dist < 0.0) & valid)
        if body.size == 0:
            continue
        c = body.size
        ra = centres[body, k] - radii[body, k, None] * n - x[body]
        parts.append(
            Contacts(
                body,
                np.full(c, -1, dtype=np.int64),
                ra,
                np.zeros((c, 3)),
                np.broadcast_to(n, (c, 3)).copy(),
                -dist[body, k],
                np.full(c, planes.restitution[p]),
                np.full(c, planes.friction[p]),
                np.full(c, p, dtype=np.int64),
            )
        )
    return _concat(parts)


def sdf_contacts(
    x: np.ndarray,
    q: np.ndarray,
    points: np.ndarray,
    radii: np.ndarray,
    valid: np.ndarray,
    sdf: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    restitution: float,
    friction: float,
) -> Contacts:
    """Contact spheres inside a static solid given by ``sdf(points (M,3)) -> (distance (M,), outward
    unit normal (M,3))``: the hook for colliders (spheres, boxes, capsules, meshes)."""
    centres = world_spheres(x, q, points)
    body, k = np.nonzero(valid)
    d, n = sdf(centres[body, k])
    d = d - radii[body, k]
    hit = d < 0.0
    body, k, d, n = body[hit], k[hit], d[hit], n[hit]
    c = body.size
    ra = centres[body, k] - radii[body, k, None] * n - x[body]
    return Contacts(
        body,
        np.full(c, -1, dtype=np.int64),
        ra,
        np.zeros((c, 3)),
        n,
        -d,
        np.full(c, restitution),
        np.full(c, friction),
        np.full(c, -1, dtype=np.int64),
    )


# --- signed distances in a shape's own frame ---------------------------------------


def local_sdf(kind: np.ndarray, dims: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance and outward unit normal of points p (M,3) to shapes (kind (M,), dims (M,3):
    box half-extents | sphere (r, 0, 0) | capsule (r, half length, 0)), all in the shape's frame."""
    d = np.empty(p.shape[0])
    n = np.zeros_like(p)
    box = kind == SHAPE_BOX
    if box.any():
        pb, h = p[box], dims[box]
        qd = np.abs(pb) - h
        outside = np.maximum(qd, 0.0)
        # lengths sum x, y, z in order, as the numba twin (_pair_contacts_loop)
        out_len = np.sqrt(
            (outside[:, 0] * outside[:, 0] + outside[:, 1] * outside[:, 1]) + outside[:, 2] * outside[:, 2]
        )
        inside = np.minimum(qd.max(axis=1), 0.0)
        d[box] = out_len + inside
        axis = qd.argmax(axis=1)
        face = np.zeros_like(pb)
        face[np.arange(len(pb)), axis] = np.where(pb[np.arange(len(pb)), axis] >= 0, 1.0, -1.0)
        safe = np.where(out_len > 0, out_len, 1.0)[:, None]
        n[box] = np.where(out_len[:, None] > 0, np.sign(pb) * outside / safe, face)
    round_ = ~box
    if round_.any():
        pr, dm = p[round_], dims[round_]
        half = np.where(kind[round_] == SHAPE_CAPSULE, dm[:, 1], 0.0)
        closest = np.zeros_like(pr)
        closest[:, 1] = np.clip(pr[:, 1], -half, half)
        rel = pr - closest
        dist = np.sqrt((rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1]) + rel[:, 2] * rel[:, 2])
        d[round_] = dist - dm[:, 0]
        fallback = np.array([0.0, 1.0, 0.0])  # centre exactly on the axis: any normal will do
        n[round_] = np.where(dist[:, None] > 0, rel / np.where(dist > 0, dist, 1.0)[:, None], fallback)
    return d, n


def shape_arrays(shapes: tuple[BodyShape, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """kind (B,), dims (B,3) for :func:`local_sdf`, bounding radius (B,)."""
    kind = np.zeros(len(shapes), dtype=np.int64)
    dims = np.zeros((len(shapes), 3))
    bound = np.zeros(len(shapes))
    for i, s in enumerate(shapes):
        if isinstance(s, Box):
            kind[i], dims[i] = SHAPE_BOX, 0.5 * np.array(s.size)
        elif isinstance(s, Sphere):
            kind[i], dims[i, 0] = SHAPE_SPHERE, s.radius
        elif isinstance(s, Capsule):
            kind[i], dims[i, :2] = SHAPE_CAPSULE, (s.radius, 0.5 * s.length)
        bound[i] = s.bounding_radius
    return kind, dims, bound


#: the 13 neighbour cells "ahead" of a cell (the other 13 see it as ahead of them), plus itself
_HALF_SHELL = [
    (dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1) if (dx, dy, dz) > (0, 0, 0)
]


def candidate_pairs(x: np.ndarray, bound: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i < j) whose bounding spheres overlap, sorted: a uniform grid of cells twice the
    largest bounding radius, each body tested against its own cell and the 13 neighbour cells
    ahead of it (every overlapping pair shares a cell or sits in neighbouring ones). Vectorised."""
    b = x.shape[0]
    empty = np.zeros(0, dtype=np.int64)
    if b < 2 or not np.isfinite(x).all():
        return empty, empty
    cell = 2.0 * float(bound.max())
    ijk = np.floor((x - x.min(axis=0)) / cell).astype(np.int64) + 1
    dims = ijk.max(axis=0) + 2
    lin = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = np.argsort(lin, kind="stable")
    cells, start, count = np.unique(lin[order], return_index=True, return_counts=True)
    parts_i, parts_j = [], []
    # same cell: every pair within it
    rank = np.empty(b, dtype=np.int64)
    rank[order] = np.arange(b)
    slot = np.searchsorted(cells, lin)
    pos = rank  # position of each body in the sorted order
    n_after = start[slot] + count[slot] - pos - 1
    if n_after.sum():
        src = np.repeat(np.arange(b), n_after)
        offs = np.arange(n_after.sum()) - np.repeat(np.cumsum(n_after) - n_after, n_after)
        parts_i.append(src)
        parts_j.append(order[np.repeat(pos + 1, n_after) + offs])
    for dx, dy, dz in _HALF_SHELL:
        target = lin + (dx * dims[1] + dy) * dims[2] + dz
        k = np.searchsorted(cells, target)
        k = np.minimum(k, cells.size - 1)
        hit = cells[k] == target
        n = np.where(hit, count[k], 0)
        if not n.sum():
            continue
        src = np.repeat(np.arange(b), n)
        offs = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        parts_i.append(src)
        parts_j.append(order[np.repeat(start[k], n) + offs])
    if not parts_i:
        return empty, empty
    i = np.concatenate(parts_i)
    j = np.concatenate(parts_j)
    d = x[i] - x[j]
    reach = bound[i] + bound[j]
    # summed x, y, z in order, as the numba twin (_sweep_pairs_loop): both find the same pairs
    close = (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2] <= reach * reach
    i, j = i[close], j[close]
    i, j = np.minimum(i, j), np.maximum(i, j)
    keep = np.lexsort((j, i))
    return i[keep], j[keep]


def _sweep_pairs_loop(x: np.ndarray, bound: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Twin of :func:`candidate_pairs` for numba: sweep and prune along the axis of the widest
    spread (every overlapping pair overlaps along it), the same overlap test, the same sorted
    output."""
    b = x.shape[0]
    axis = 0
    widest = -1.0
    for k in range(3):
        spread = x[:, k].max() - x[:, k].min()
        if spread > widest:
            widest, axis = spread, k
    lo = x[:, axis] - bound
    order = np.argsort(lo)
    keys = []
    for s in range(b):
        i = order[s]
        hi = x[i, axis] + bound[i]
        for t in range(s + 1, b):
            j = order[t]
            if lo[j] > hi:
                break
            d0, d1, d2 = x[i, 0] - x[j, 0], x[i, 1] - x[j, 1], x[i, 2] - x[j, 2]
            reach = bound[i] + bound[j]
            if (d0 * d0 + d1 * d1) + d2 * d2 <= reach * reach:
                keys.append(min(i, j) * b + max(i, j))
    out = np.sort(np.array(keys, dtype=np.int64))
    return out // b, out % b


@cache
def numba_candidate_pairs() -> Any:
    """:func:`_sweep_pairs_loop` compiled by numba."""
    from numba import njit

    return njit(cache=True)(_sweep_pairs_loop)


def pair_contacts(
    x: np.ndarray,
    q: np.ndarray,
    points: np.ndarray,
    radii: np.ndarray,
    counts: np.ndarray,
    kind: np.ndarray,
    dims: np.ndarray,
    bound: np.ndarray,
    restitution: np.ndarray,
    friction: np.ndarray,
    candidates: tuple[np.ndarray, np.ndarray] | None = None,
) -> Contacts:
    """Contacts between bodies: the contact spheres of a round body (sphere, capsule) against the
    other's shape; two boxes face against face (:mod:`animsim.bodies.box_box`). ``candidates``: pairs
    (i, j) that may touch (default: all pairs whose bounding spheres overlap)."""
    i, j = candidate_pairs(x, bound) if candidates is None else candidates
    if i.size == 0:
        return _empty_contacts()
    round_i, round_j = kind[i] != SHAPE_BOX, kind[j] != SHAPE_BOX
    # (source of spheres, target shape) directions; two boxes meet face to face (box_box)
    src = np.concatenate([i[round_i], j[~round_i & round_j]])
    dst = np.concatenate([j[round_i], i[~round_i & round_j]])
    k_max = points.shape[1]
    s_idx = np.repeat(src, k_max)
    t_idx = np.repeat(dst, k_max)
    k_idx = np.tile(np.arange(k_max), src.size)
    ok = k_idx < counts[s_idx]
    s_idx, t_idx, k_idx = s_idx[ok], t_idx[ok], k_idx[ok]
    centre = x[s_idx] + quat.rotate(q[s_idx], points[s_idx, k_idx])
    local = quat.rotate_inverse(q[t_idx], centre - x[t_idx])
    d, n_local = local_sdf(kind[t_idx], dims[t_idx], local)
    d = d - radii[s_idx, k_idx]
    hit = d < 0.0
    s_idx, t_idx, k_idx, d = s_idx[hit], t_idx[hit], k_idx[hit], d[hit]
    n = quat.rotate(q[t_idx], n_local[hit])
    surface_a = centre[hit] - radii[s_idx, k_idx, None] * n  # on the sphere's surface
    point = surface_a + 0.5 * d[:, None] * n  # halfway between the two surfaces
    boxes = ~round_i & ~round_j
    if boxes.any():
        s_box, t_box, p_box, n_box, d_box = _box_pairs(x, q, dims, i[boxes], j[boxes])
        s_idx, t_idx = np.concatenate([s_idx, s_box]), np.concatenate([t_idx, t_box])
        point, n, d = np.concatenate([point, p_box]), np.concatenate([n, n_box]), np.concatenate([d, d_box])
    if s_idx.size == 0:
        return _empty_contacts()
    return Contacts(
        s_idx,
        t_idx,
        point - x[s_idx],
        point - x[t_idx],
        n,
        -d,
        0.5 * (restitution[s_idx] + restitution[t_idx]),
        np.sqrt(friction[s_idx] * friction[t_idx]),
        np.full(s_idx.size, -1, dtype=np.int64),
    )


def _box_pairs(
    x: np.ndarray, q: np.ndarray, dims: np.ndarray, i: np.ndarray, j: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Contacts of the box pairs (i, j), pair by pair (:func:`box_box.box_box`): source j,
    target i (the normal points from i to j), points, normals, signed distances (< 0)."""
    src, dst, pts, nrm, dist = [], [], [], [], []
    points = np.empty((box_box.MAX_POINTS, 3))
    depth = np.empty(box_box.MAX_POINTS)
    normal = np.empty(3)
    for a, b in zip(i.tolist(), j.tolist(), strict=True):
        k = box_box.box_box(x[a], q[a], dims[a], x[b], q[b], dims[b], points, depth, normal)
        if k:
            src.append(np.full(k, b, dtype=np.int64))
            dst.append(np.full(k, a, dtype=np.int64))
            pts.append(points[:k].copy())
            nrm.append(np.repeat(normal[None, :], k, axis=0))
            dist.append(-depth[:k])
    if not src:
        zi = np.zeros(0, dtype=np.int64)
        return zi, zi, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    return (
        np.concatenate(src),
        np.concatenate(dst),
        np.concatenate(pts),
        np.concatenate(nrm),
        np.concatenate(dist),
    )


def _pair_contacts_loop(
    x: np.ndarray,
    q: np.ndarray,
    points: np.ndarray,
    radii: np.ndarray,
    counts: np.ndarray,
    kind: np.ndarray,
    dims: np.ndarray,
    restitution: np.ndarray,
    friction: np.ndarray,
    ci: np.ndarray,
    cj: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """Twin of :func:`pair_contacts` (given its candidate pairs) for numba: the same tests in the
    same order (round sources first, then round targets, then box pairs; per pair its
    spheres in order) and the same arithmetic (:func:`quaternion.rotate`, :func:`local_sdf`)."""
    kmax = points.shape[1]
    cap = 2 * ci.shape[0] * kmax
    a_out = np.empty(cap, dtype=np.int64)
    b_out = np.empty(cap, dtype=np.int64)
    ra_out = np.empty((cap, 3))
    rb_out = np.empty((cap, 3))
    n_out = np.empty((cap, 3))
    depth_out = np.empty(cap)
    e_out = np.empty(cap)
    mu_out = np.empty(cap)
    c = 0
    box_points = np.empty((MAX_BOX_POINTS, 3))
    box_depth = np.empty(MAX_BOX_POINTS)
    box_normal = np.empty(3)
    for stage in range(3):
        for p in range(ci.shape[0]):
            i, j = ci[p], cj[p]
            round_i, round_j = kind[i] != SHAPE_BOX, kind[j] != SHAPE_BOX
            if stage == 0 and round_i:
                src, dst = i, j
            elif stage == 1 and not round_i and round_j:
                src, dst = j, i
            elif stage == 2 and not round_i and not round_j:
                # two boxes: face against face (box_box), source j, target i
                k = box_box_contacts(
                    x[i], q[i], dims[i], x[j], q[j], dims[j], box_points, box_depth, box_normal
                )
                for m in range(k):
                    px_, py_, pz_ = box_points[m, 0], box_points[m, 1], box_points[m, 2]
                    a_out[c], b_out[c] = j, i
                    ra_out[c, 0], ra_out[c, 1], ra_out[c, 2] = px_ - x[j, 0], py_ - x[j, 1], pz_ - x[j, 2]
                    rb_out[c, 0], rb_out[c, 1], rb_out[c, 2] = px_ - x[i, 0], py_ - x[i, 1], pz_ - x[i, 2]
                    n_out[c, 0], n_out[c, 1], n_out[c, 2] = box_normal[0], box_normal[1], box_normal[2]
                    depth_out[c] = box_depth[m]
                    e_out[c] = 0.5 * (restitution[j] + restitution[i])
                    mu_out[c] = np.sqrt(friction[j] * friction[i])
                    c += 1
                continue
            else:
                continue
            qw, qx, qy, qz = q[src, 0], q[src, 1], q[src, 2], q[src, 3]
            tw, tx_, ty_, tz_ = q[dst, 0], q[dst, 1], q[dst, 2], q[dst, 3]
            for k in range(counts[src]):
                # the sphere's centre in the world: x + R(q) p
                rx, ry, rz = rotate_scalar(
                    qw, qx, qy, qz, points[src, k, 0], points[src, k, 1], points[src, k, 2]
                )
                cx, cy, cz = x[src, 0] + rx, x[src, 1] + ry, x[src, 2] + rz
                # ... in the target's frame: R(q)^T v, the rotation by the conjugate
                lx, ly, lz = rotate_scalar(
                    tw, -tx_, -ty_, -tz_, cx - x[dst, 0], cy - x[dst, 1], cz - x[dst, 2]
                )
                # signed distance and outward normal in the target's frame (local_sdf)
                if kind[dst] == SHAPE_BOX:
                    q0 = abs(lx) - dims[dst, 0]
                    q1 = abs(ly) - dims[dst, 1]
                    q2 = abs(lz) - dims[dst, 2]
                    o0, o1, o2 = max(q0, 0.0), max(q1, 0.0), max(q2, 0.0)
                    out_len = np.sqrt((o0 * o0 + o1 * o1) + o2 * o2)
                    big = q0
                    axis = 0
                    if q1 > big:
                        big, axis = q1, 1
                    if q2 > big:
                        big, axis = q2, 2
                    d = out_len + min(big, 0.0)
                    if out_len > 0:
                        nx = (np.sign(lx) * o0) / out_len
                        ny = (np.sign(ly) * o1) / out_len
                        nz = (np.sign(lz) * o2) / out_len
                    else:
                        nx, ny, nz = 0.0, 0.0, 0.0
                        pa = lx if axis == 0 else (ly if axis == 1 else lz)
                        face = 1.0 if pa >= 0 else -1.0
                        if axis == 0:
                            nx = face
                        elif axis == 1:
                            ny = face
                        else:
                            nz = face
                else:
                    half = dims[dst, 1] if kind[dst] == SHAPE_CAPSULE else 0.0
                    r0 = lx - 0.0
                    r1 = ly - min(max(ly, -half), half)
                    r2 = lz - 0.0
                    dist = np.sqrt((r0 * r0 + r1 * r1) + r2 * r2)
                    d = dist - dims[dst, 0]
                    if dist > 0:
                        nx, ny, nz = r0 / dist, r1 / dist, r2 / dist
                    else:
                        nx, ny, nz = 0.0, 1.0, 0.0
                rr = radii[src, k]
                d = d - rr
                if not d < 0.0:
                    continue
                # the normal in the world: R(q_dst) n
                t0 = 2.0 * (ty_ * nz - tz_ * ny)
                t1 = 2.0 * (tz_ * nx - tx_ * nz)
                t2 = 2.0 * (tx_ * ny - ty_ * nx)
                wx = nx + tw * t0 + (ty_ * t2 - tz_ * t1)
                wy = ny + tw * t1 + (tz_ * t0 - tx_ * t2)
                wz = nz + tw * t2 + (tx_ * t1 - ty_ * t0)
                half_d = 0.5 * d
                px_ = (cx - rr * wx) + half_d * wx  # halfway between the two surfaces
                py_ = (cy - rr * wy) + half_d * wy
                pz_ = (cz - rr * wz) + half_d * wz
                a_out[c], b_out[c] = src, dst
                ra_out[c, 0], ra_out[c, 1], ra_out[c, 2] = px_ - x[src, 0], py_ - x[src, 1], pz_ - x[src, 2]
                rb_out[c, 0], rb_out[c, 1], rb_out[c, 2] = px_ - x[dst, 0], py_ - x[dst, 1], pz_ - x[dst, 2]
                n_out[c, 0], n_out[c, 1], n_out[c, 2] = wx, wy, wz
                depth_out[c] = -d
                e_out[c] = 0.5 * (restitution[src] + restitution[dst])
                mu_out[c] = np.sqrt(friction[src] * friction[dst])
                c += 1
    return (
        a_out[:c],
        b_out[:c],
        ra_out[:c],
        rb_out[:c],
        n_out[:c],
        depth_out[:c],
        e_out[:c],
        mu_out[:c],
    )


@cache
def numba_pair_contacts() -> Any:
    """:func:`_pair_contacts_loop` compiled by numba."""
    from numba import njit

    compile_helpers(vars(box_box))
    compile_helpers(globals())
    return njit(cache=True)(_pair_contacts_loop)


# --- the solver ---------------------------------------------------------------------


# --- fixed-order arithmetic shared by the NumPy solver and its numba twins ---------------
#
# Vectors of the NumPy solver are (3, k) arrays, one row per component, and every sum is
# written out in the order the numba kernels use (x, then y, then z; a matrix row as
# (m0 u0 + m1 u1) + m2 u2): the two backends then round alike, contact by contact.


def _cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of (3, k) arrays."""
    return np.stack((a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]))


def _dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a . b of (3, k) arrays, (k,): (a0 b0 + a1 b1) + a2 b2."""
    return (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]


def _sym_matvec(m: np.ndarray, u: np.ndarray) -> np.ndarray:
    """M u for symmetric M given as (6, k) rows (m00, m01, m02, m11, m12, m22) and u (3, k)."""
    return np.stack(
        (
            (m[0] * u[0] + m[1] * u[1]) + m[2] * u[2],
            (m[1] * u[0] + m[3] * u[1]) + m[4] * u[2],
            (m[2] * u[0] + m[4] * u[1]) + m[5] * u[2],
        )
    )


def _arm_inertia(m: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """(K, G) for symmetric M (6, k) and lever arms r (3, k): K = [r]x^T M [r]x as (6, k) rows
    (k00, k01, k02, k11, k12, k22), K_ij = c_i . M c_j with c_j the columns of [r]x; and
    G = M [r]x as its three columns M c_j, (3, k) each, so that M (r x f) = sum_j G_j f_j."""
    zero = np.zeros_like(r[0])
    cols = (np.stack((zero, r[2], -r[1])), np.stack((-r[2], zero, r[0])), np.stack((r[1], -r[0], zero)))
    mc = [_sym_matvec(m, c) for c in cols]
    return np.stack(
        (
            _dot3(cols[0], mc[0]),
            _dot3(cols[0], mc[1]),
            _dot3(cols[0], mc[2]),
            _dot3(cols[1], mc[1]),
            _dot3(cols[1], mc[2]),
            _dot3(cols[2], mc[2]),
        )
    ), mc


def inv_world_inertia(q: np.ndarray, inv_inertia: np.ndarray) -> np.ndarray:
    """R diag(I^-1) R^T of every body as (6, B) rows (m00, m01, m02, m11, m12, m22)."""
    qw, qx, qy, qz = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r00 = 1 - 2 * (qy * qy + qz * qz)
    r01 = 2 * (qx * qy - qw * qz)
    r02 = 2 * (qx * qz + qw * qy)
    r10 = 2 * (qx * qy + qw * qz)
    r11 = 1 - 2 * (qx * qx + qz * qz)
    r12 = 2 * (qy * qz - qw * qx)
    r20 = 2 * (qx * qz - qw * qy)
    r21 = 2 * (qy * qz + qw * qx)
    r22 = 1 - 2 * (qx * qx + qy * qy)
    i0, i1, i2 = inv_inertia[:, 0], inv_inertia[:, 1], inv_inertia[:, 2]
    return np.stack(
        (
            r00 * i0 * r00 + r01 * i1 * r01 + r02 * i2 * r02,
            r00 * i0 * r10 + r01 * i1 * r11 + r02 * i2 * r12,
            r00 * i0 * r20 + r01 * i1 * r21 + r02 * i2 * r22,
            r10 * i0 * r10 + r11 * i1 * r11 + r12 * i2 * r12,
            r10 * i0 * r20 + r11 * i1 * r21 + r12 * i2 * r22,
            r20 * i0 * r20 + r21 * i1 * r21 + r22 * i2 * r22,
        )
    )


def batches(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A batch number per contact such that no body appears twice in a batch and contacts keep their
    order within each body: greedy, in list order (vectorised per round)."""
    c = a.size
    batch = np.full(c, -1, dtype=np.int64)
    remaining = np.arange(c)
    level = 0
    while remaining.size:
        ra, rb = a[remaining], b[remaining]
        # static "bodies" (-1) never conflict: give each its own key
        rb_key = np.where(rb >= 0, rb, -1 - np.arange(rb.size))
        keys = np.stack([ra, rb_key], axis=1).ravel()
        _, first, inv = np.unique(keys, return_index=True, return_inverse=True)
        is_first = first[inv.reshape(-1)] == np.arange(keys.size)
        # a contact whose two ends are one body (a test's random pairs) conflicts with nothing else
        take = is_first[0::2] & (is_first[1::2] | (rb_key == ra))
        if not take.any():  # cannot happen with the rule above; never loop forever
            take[0] = True
        batch[remaining[take]] = level
        remaining = remaining[~take]
        level += 1
    return batch


def _slot_batches(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`batches` for lists in which no contact joins two bodies (planes, colliders): the
    batch of a contact is how many contacts of its body come before it (one sort, no rounds)."""
    order = np.argsort(a, kind="stable")
    sa = a[order]
    start = np.flatnonzero(np.r_[True, sa[1:] != sa[:-1]])
    rank = np.arange(a.size) - np.repeat(start, np.diff(np.r_[start, a.size]))
    batch = np.empty(a.size, dtype=np.int64)
    batch[order] = rank
    return batch


def solve(
    contacts: Contacts,
    v: np.ndarray,
    w: np.ndarray,
    q: np.ndarray,
    inv_mass: np.ndarray,
    inv_inertia: np.ndarray,
    resting_speed: np.ndarray,
    iterations: int = ITERATIONS,
    dv: np.ndarray | None = None,
    dx: np.ndarray | None = None,
    kh: float = 0.0,
    dt: float = 1.0,
    surface: np.ndarray | None = None,
    warm: tuple[np.ndarray, np.ndarray] | None = None,
    max_sweeps: int = MAX_SWEEPS,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sequential impulses on v (B,3), w (B,3) in place; returns the restitution applied per contact,
    which contacts were impacts (approaching faster than resting; they bounce with it), and the
    normal (C,) and friction (C, 3) impulses each contact ended with.
    ``warm``: impulses (C,), (C, 3) to start from (warm starting, :mod:`animsim.bodies.warm`);
    applied first, contact by contact, except on impacts.
    ``kh``: the method's energy shift times the step ``dt`` (:func:`_impact_target`).
    ``surface``: (C, 3) the velocity of the surface each contact touches (a keyframed collider;
    None: all still): every speed the contacts work with is relative to it.

    The contacts are solved one after the other in list order, ``iterations`` times
    (Catto 2005). Contacts that share no body commute, so the list is cut into
    batches in which no body appears twice and that keep each body's contacts in
    order (:func:`batches`); a batch is one vectorised update and the result is the
    sequential one, operation for operation (the numba twin, ``_solve_list``, walks
    the list itself).
    """
    c = contacts
    count = c.count
    e_out = np.zeros(count)
    if count == 0:
        return e_out, np.zeros(0, dtype=bool), np.zeros(0), np.zeros((0, 3))
    coupled = bool((c.b >= 0).any())
    batch = batches(c.a, c.b) if coupled else _slot_batches(c.a, c.b)
    order = np.argsort(batch, kind="stable")
    cuts = np.searchsorted(batch[order], np.arange(int(batch.max()) + 2))
    a, b = c.a[order], c.b[order]
    has_b = b >= 0
    bb = np.where(has_b, b, 0)
    n, ra, rb = c.n[order].T, c.ra[order].T, c.rb[order].T
    restitution, friction, depth = c.restitution[order], c.friction[order], c.depth[order]
    # per contact, once per step: the world inverse inertias, the angular response to a unit
    # normal impulse g = I^-1 (r x n), and the effective mass along n (Baraff 1997, sec. 8):
    # 1/K = 1/m_a + (r_a x n) . I_a^-1 (r_a x n) (+ the same for b)
    m_body = inv_world_inertia(q, inv_inertia)
    ma = inv_mass[a]
    mat_a = m_body[:, a]
    rna = _cross3(ra, n)
    gna = _sym_matvec(mat_a, rna)
    kn = ma + _dot3(rna, gna)
    mb = np.where(has_b, inv_mass[bb], 0.0)
    mat_b = np.where(has_b, m_body[:, bb], 0.0)
    rnb = _cross3(rb, n)
    gnb = _sym_matvec(mat_b, rnb)
    if coupled:
        kn = np.where(has_b, (ma + mb) + (_dot3(rna, gna) + _dot3(rnb, gnb)), kn)
    # two immovable things (a pinned body on a floor) exchange no impulse
    inv_kn = np.where(kn > 0, 1.0 / np.where(kn > 0, kn, 1.0), 0.0)
    # tangential response: along a unit direction e the effective mass is 1/(m_t + e . K e) with
    # K = [r]x^T I^-1 [r]x (the angular part, r x e = [r]x e), summed over both bodies
    k_t, ga = _arm_inertia(mat_a, ra)
    m_t = ma
    gb = ga
    if coupled:
        k_b, gb = _arm_inertia(mat_b, rb)
        k_t = np.where(has_b, k_t + k_b, k_t)
        m_t = np.where(has_b, ma + mb, ma)
    vT, wT = v.T.copy(), w.T.copy()
    sv = None if surface is None else surface[order].T  # (3, C), in the solver's order
    vel = vT[:, a] + _cross3(wT[:, a], ra)
    if coupled:
        vel = np.where(has_b, vel - (vT[:, bb] + _cross3(wT[:, bb], rb)), vel)
    if sv is not None:
        vel = vel - sv
    vn0 = _dot3(vel, n)
    rest_b = np.where(has_b, resting_speed[bb], 0.0)
    # a speculative contact (a gap, depth < 0) never bounces: it may close its gap in the step
    bounce = (vn0 < -(resting_speed[a] + rest_b + RESTING_FLOOR)) & (depth >= 0.0)
    e_used = np.where(bounce, restitution, 0.0)
    target = np.where(bounce, -restitution * vn0, np.minimum(depth, 0.0) / dt)
    if dv is not None and dx is not None and bounce.any():
        # against a moving surface the approach over the step is relative to its move too
        target = np.where(
            bounce,
            _impact_target(
                a, bb, has_b, n, depth, restitution, vn0, dv, dx, kh, dt, None if sv is None else sv * dt
            ),
            target,
        )
    jn = np.zeros(count)
    jt = np.zeros((3, count))
    vT_rows, wT_rows = vT.T, wT.T  # (B, 3) views
    if warm is not None:
        jn = np.where(bounce, 0.0, warm[0][order])
        jt = np.where(bounce, 0.0, warm[1][order].T)
        _apply_warm(a, bb, has_b, ma, mb, n, gna, gnb, ga, gb, jn, jt, vT_rows, wT_rows)
    groups = []
    for k in range(cuts.size - 1):
        s = slice(int(cuts[k]), int(cuts[k + 1]))
        hb = np.flatnonzero(has_b[s])
        groups.append((s, a[s], hb, b[s][hb], cuts[k] + hb))

    for sweep in range(max(iterations, max_sweeps)):
        change = 0.0
        for s, ai, hb, bi, sb in groups:
            ns, ras = n[:, s], ra[:, s]
            va, wa = vT[:, ai], wT[:, ai]
            # normal: push (never pull) toward the target approach speed
            vn = _dot3(va, ns) + _dot3(wa, rna[:, s])
            if hb.size:
                vb, wb = vT[:, bi], wT[:, bi]
                vn[hb] = vn[hb] - (_dot3(vb, n[:, sb]) + _dot3(wb, rnb[:, sb]))
            if sv is not None:
                vn = vn - _dot3(sv[:, s], ns)
            new = np.maximum(jn[s] + (target[s] - vn) * inv_kn[s], 0.0)
            dj = new - jn[s]
            jn[s] = new
            va += (ma[s] * dj) * ns
            wa += dj * gna[:, s]
            if hb.size:
                vb -= (mb[sb] * dj[hb]) * n[:, sb]
                wb -= dj[hb] * gnb[:, sb]
            # Coulomb friction: stop the sliding, within mu * (normal impulse so far)
            vel = va + _cross3(wa, ras)
            if hb.size:
                vel[:, hb] = vel[:, hb] - (vb + _cross3(wb, rb[:, sb]))
            if sv is not None:
                vel = vel - sv[:, s]
            vt = vel - _dot3(vel, ns) * ns
            # the impulse that stops the sliding: -vt / (m_t + e.K e), e = vt/|vt|, written
            # without the square root as -vt |vt|^2 / (m_t |vt|^2 + vt.K vt)
            s2 = _dot3(vt, vt)
            den = m_t[s] * s2 + _dot3(vt, _sym_matvec(k_t[:, s], vt))
            live = (s2 > 0.0) & (den > 0.0)
            f = np.where(live, s2 / np.where(live, den, 1.0), 0.0)
            jts = jt[:, s]
            want = jts - f * vt
            # ... within mu * (normal impulse so far)
            cap = friction[s] * jn[s]
            mag2 = _dot3(want, want)
            over = mag2 > cap * cap
            want = np.where(over, want * (cap / np.sqrt(np.where(over, mag2, 1.0))), want)
            imp = want - jts
            jt[:, s] = want
            change = max(change, float(np.max(m_t[s] * np.maximum(np.abs(dj), np.abs(imp).max(axis=0)))))
            va += ma[s] * imp
            wa += (ga[0][:, s] * imp[0] + ga[1][:, s] * imp[1]) + ga[2][:, s] * imp[2]
            vT[:, ai] = va
            wT[:, ai] = wa
            if hb.size:
                ib = imp[:, hb]
                vb -= mb[sb] * ib
                wb -= (gb[0][:, sb] * ib[0] + gb[1][:, sb] * ib[1]) + gb[2][:, sb] * ib[2]
                vT[:, bi] = vb
                wT[:, bi] = wb
        if sweep + 1 >= iterations and not change > SWEEP_TOLERANCE:
            break
    v[:] = vT.T
    w[:] = wT.T
    e_out[order] = e_used
    hit_out = np.zeros(count, dtype=bool)
    hit_out[order] = bounce
    jn_out = np.empty(count)
    jn_out[order] = jn
    jt_out = np.empty((count, 3))
    jt_out[order] = jt.T
    return e_out, hit_out, jn_out, jt_out


def _apply_warm(
    a: np.ndarray,
    bb: np.ndarray,
    has_b: np.ndarray,
    ma: np.ndarray,
    mb: np.ndarray,
    n: np.ndarray,
    gna: np.ndarray,
    gnb: np.ndarray,
    ga: list[np.ndarray],
    gb: list[np.ndarray],
    jn: np.ndarray,
    jt: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
) -> None:
    """Apply the starting impulses jn (C,), jt (3, C) to v, w (B, 3) in place: per contact (in the
    solver's order, which keeps each body's contacts in list order) its normal impulse on a,
    on b, then its friction impulse on a, on b; ``np.add.at`` adds in index order, so every body
    sums as the numba twin's loop does."""
    sn = ma * jn
    sbn = mb * jn
    rot_a = (ga[0] * jt[0] + ga[1] * jt[1]) + ga[2] * jt[2]
    rot_b = (gb[0] * jt[0] + gb[1] * jt[1]) + gb[2] * jt[2]
    # four updates per contact, interleaved: (a, normal), (b, normal), (a, friction), (b, friction)
    body = np.stack([a, bb, a, bb], axis=1).reshape(-1)
    live = np.stack([np.ones_like(has_b), has_b, np.ones_like(has_b), has_b], axis=1).reshape(-1)
    dvel = np.stack([(sn * n).T, -(sbn * n).T, (ma * jt).T, -(mb * jt).T], axis=1).reshape(-1, 3)
    dw = np.stack([(jn * gna).T, -(jn * gnb).T, rot_a.T, -rot_b.T], axis=1).reshape(-1, 3)
    np.add.at(v, body[live], dvel[live])
    np.add.at(w, body[live], dw[live])


def _impact_target(
    a: np.ndarray,
    bb: np.ndarray,
    has_b: np.ndarray,
    n: np.ndarray,
    depth: np.ndarray,
    restitution: np.ndarray,
    vn0: np.ndarray,
    dv: np.ndarray,
    dx: np.ndarray,
    kh: float = 0.0,
    dt: float = 1.0,
    moved: np.ndarray | None = None,
) -> np.ndarray:
    """Bounce targets corrected for the time of impact inside the step.

    The step ended with the contact d = depth inside; the centres approached by
    dx_n = n . (x - x_old) and the forces changed the normal speed by dv_n =
    n . (v - v_old). The impact happened at the fraction s = d0 / (d0 + d) of the
    step (d0 the distance at its start, d0 = -dx_n - d), with approach speed
    vn_imp = vn - (1 - s) dv_n; reflected there and carried on for the rest of the
    step, the normal speed ends at -e vn_imp + (1 - s) dv_n. (Without this the
    forces of the part of the step after the impact would be reflected too: a
    ball would gain height at every bounce.)

    A method not exact under a constant acceleration (``kh`` = kappa dt != 0, symplectic
    Euler's 1/2 dt) conserves a shifted energy; there the target is the speed that keeps e^2
    of it at the place the projection leaves the contact, e depth out of the surface
    (:func:`animsim.collisions.kept_end_speed`), so the apexes reach e^(2n) of the drop as
    with the exact methods.
    """
    rel_dv = dv[a].T - np.where(has_b, dv[bb].T, 0.0)
    rel_dx = dx[a].T - np.where(has_b, dx[bb].T, 0.0)
    if moved is not None:  # (3, C) how far the touched surface moved in the step
        rel_dx = rel_dx - moved
    dvn = _dot3(rel_dv, n)
    dxn = _dot3(rel_dx, n)
    d0 = -dxn - depth
    span = d0 + depth
    s = np.clip(np.divide(d0, span, out=np.zeros_like(d0), where=span > 0), 0.0, 1.0)
    vn_imp = vn0 - (1.0 - s) * dvn
    target = np.maximum(-restitution * vn_imp + (1.0 - s) * dvn, 0.0)
    if kh == 0.0:
        return target
    kept = kept_end_speed(vn0 - dvn, np.maximum(d0, 0.0), dvn / dt, restitution * depth, restitution, kh)
    return np.where((restitution > 0.0) & (kept > 0.0), kept, target)


def follow_impulses(
    contacts: Contacts,
    impact: np.ndarray,
    x: np.ndarray,
    q: np.ndarray,
    dvel: np.ndarray,
    domega: np.ndarray,
    h: float,
) -> np.ndarray:
    """Move bodies as the contact impulses of this step would have moved them; returns the depths
    that are left (C,). In place on x (B,3) and q (B,4).

    A resting or sliding contact's impulse stands for a force that acted during the whole
    step, so it moves the body as the step's forces did: a constant acceleration a over a
    step of dt moves a body by c dt^2 a (c = 1 for symplectic Euler, x1 = x0 + dt v1; 1/2 for
    Runge-Kutta and Verlet), so the velocity change dv of the impulses moves it by h dv,
    h = c dt, and turns it by h domega. Without this the step's own push down a slope
    (dt^2 g sin(theta) along it) stays in the position while friction takes it out of the
    velocity, and a box held by static friction creeps. A body with a bouncing contact
    is left alone: its impulse is an impact at one instant, placed by the time of impact
    (``_impact_target`` and the (1 + e) projection). What the move took out of each
    contact's penetration (the contact point's move along n, linear in the move) is taken
    off its depth; a depth that turns negative (the body started the step short of the
    surface and is moved back there) lets the projection bring it down onto the surface,
    so a body never hovers where its last step started.
    """
    c = contacts
    nb = x.shape[0]
    bounced = np.zeros(nb, dtype=bool)
    bounced[c.a[impact]] = True
    hb = c.b[impact]
    bounced[hb[hb >= 0]] = True
    sx = np.where(bounced[:, None], 0.0, h * dvel)
    sw = np.where(bounced[:, None], 0.0, h * domega)
    a, ra, rb, n = c.a, c.ra, c.rb, c.n
    has_b = c.b >= 0
    bb = np.where(has_b, c.b, 0)
    move = _point_move(sx[a], sw[a], ra, n)
    if has_b.any():
        move = np.where(has_b, move - _point_move(sx[bb], sw[bb], rb, n), move)
    depth = c.depth - move
    x += sx
    turn = np.flatnonzero(~bounced & (sw != 0.0).any(axis=1))
    if turn.size:
        qt = q[turn]
        q[turn] = quat.normalise(qt + quat.derivative(qt, sw[turn]))
    return depth


def _point_move(sx: np.ndarray, sw: np.ndarray, r: np.ndarray, n: np.ndarray) -> np.ndarray:
    """n . (sx + sw x r) per row, summed as the numba twin sums it."""
    px = sx[:, 0] + (sw[:, 1] * r[:, 2] - sw[:, 2] * r[:, 1])
    py = sx[:, 1] + (sw[:, 2] * r[:, 0] - sw[:, 0] * r[:, 2])
    pz = sx[:, 2] + (sw[:, 0] * r[:, 1] - sw[:, 1] * r[:, 0])
    return (px * n[:, 0] + py * n[:, 1]) + pz * n[:, 2]


# --- numba twins (compiled on first use; same operations in the same order) ---------------


@cache
def numba_kernels() -> tuple[Any, Any]:
    """(plane detection, list solver) compiled by numba."""
    from numba import njit

    compile_helpers(globals())
    detect = njit(cache=True)(_detect_planes_loop)
    solver = njit(cache=True)(_solve_list_loop)
    return detect, solver


def _detect_planes_loop(
    x: np.ndarray,
    q: np.ndarray,
    points: np.ndarray,
    radii: np.ndarray,
    counts: np.ndarray,
    plane_point: np.ndarray,
    plane_normal: np.ndarray,
    plane_e: np.ndarray,
    plane_mu: np.ndarray,
    a_out: np.ndarray,
    ra_out: np.ndarray,
    n_out: np.ndarray,
    depth_out: np.ndarray,
    e_out: np.ndarray,
    mu_out: np.ndarray,
    plane_out: np.ndarray,
) -> int:
    """Twin of :func:`plane_contacts`, body by body (each body's contacts in the same order:
    plane, then sphere). Writes the contacts into the outs; returns how many."""
    c = 0
    for bi in range(x.shape[0]):
        qw, qx, qy, qz = q[bi, 0], q[bi, 1], q[bi, 2], q[bi, 3]
        for p in range(plane_point.shape[0]):
            nx, ny, nz = plane_normal[p, 0], plane_normal[p, 1], plane_normal[p, 2]
            for k in range(counts[bi]):
                rx, ry, rz = rotate_scalar(
                    qw, qx, qy, qz, points[bi, k, 0], points[bi, k, 1], points[bi, k, 2]
                )
                cx, cy, cz = x[bi, 0] + rx, x[bi, 1] + ry, x[bi, 2] + rz
                rr = radii[bi, k]
                d = ((cx - plane_point[p, 0]) * nx + (cy - plane_point[p, 1]) * ny) + (
                    cz - plane_point[p, 2]
                ) * nz
                d = d - rr
                if d < 0.0:
                    a_out[c] = bi
                    ra_out[c, 0] = cx - rr * nx - x[bi, 0]
                    ra_out[c, 1] = cy - rr * ny - x[bi, 1]
                    ra_out[c, 2] = cz - rr * nz - x[bi, 2]
                    n_out[c, 0], n_out[c, 1], n_out[c, 2] = nx, ny, nz
                    depth_out[c] = -d
                    e_out[c] = plane_e[p]
                    mu_out[c] = plane_mu[p]
                    plane_out[c] = p
                    c += 1
    return c


def _solve_list_loop(
    count: int,
    a: np.ndarray,
    b: np.ndarray,
    ra: np.ndarray,
    rb: np.ndarray,
    n: np.ndarray,
    depth: np.ndarray,
    restitution: np.ndarray,
    friction: np.ndarray,
    plane: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
    q: np.ndarray,
    inv_mass: np.ndarray,
    inv_inertia: np.ndarray,
    resting_speed: np.ndarray,
    dv: np.ndarray,
    dx: np.ndarray,
    iterations: int,
    e_used: np.ndarray,
    impact: np.ndarray,
    h: float,
    depth_out: np.ndarray,
    kh: float,
    dt: float,
    jn: np.ndarray,
    jt: np.ndarray,
    max_sweeps: int,
) -> None:
    """Twin of :func:`solve` then :func:`follow_impulses` (when h > 0): the first ``count``
    contacts one after the other, ``iterations`` times; then the bodies moved as the impulses
    moved them (the depths left into ``depth_out``). ``jn`` (C,), ``jt`` (C, 3): the impulses to
    start from (warm starting; applied first, contact by contact, except on impacts), in place
    the impulses each contact ended with."""
    v0 = v.copy()
    w0 = w.copy()
    mat = np.empty((count, 12))  # per contact: I_a^-1 (6), I_b^-1 (6)
    g = np.empty((count, 12))  # r_a x n, I_a^-1 (r_a x n), r_b x n, I_b^-1 (r_b x n)
    inv_kn = np.empty(count)
    ma = np.empty(count)
    mb = np.empty(count)
    tgt = np.empty(count)
    kt6 = np.zeros((count, 6))  # K = [r]x^T I^-1 [r]x of both ends (solve's k_t)
    gm = np.zeros((count, 18))  # G = I^-1 [r]x of each end, column by column (solve's ga, gb)
    mt = np.empty(count)
    cols = np.empty((3, 3))
    mc = np.empty((3, 3))
    for i in range(count):
        for side in range(2):
            body = a[i] if side == 0 else b[i]
            o = 6 * side
            if body < 0:
                for k in range(6):
                    mat[i, o + k] = 0.0
                continue
            qw, qx, qy, qz = q[body, 0], q[body, 1], q[body, 2], q[body, 3]
            r00 = 1 - 2 * (qy * qy + qz * qz)
            r01 = 2 * (qx * qy - qw * qz)
            r02 = 2 * (qx * qz + qw * qy)
            r10 = 2 * (qx * qy + qw * qz)
            r11 = 1 - 2 * (qx * qx + qz * qz)
            r12 = 2 * (qy * qz - qw * qx)
            r20 = 2 * (qx * qz - qw * qy)
            r21 = 2 * (qy * qz + qw * qx)
            r22 = 1 - 2 * (qx * qx + qy * qy)
            i0, i1, i2 = inv_inertia[body, 0], inv_inertia[body, 1], inv_inertia[body, 2]
            mat[i, o + 0] = r00 * i0 * r00 + r01 * i1 * r01 + r02 * i2 * r02
            mat[i, o + 1] = r00 * i0 * r10 + r01 * i1 * r11 + r02 * i2 * r12
            mat[i, o + 2] = r00 * i0 * r20 + r01 * i1 * r21 + r02 * i2 * r22
            mat[i, o + 3] = r10 * i0 * r10 + r11 * i1 * r11 + r12 * i2 * r12
            mat[i, o + 4] = r10 * i0 * r20 + r11 * i1 * r21 + r12 * i2 * r22
            mat[i, o + 5] = r20 * i0 * r20 + r21 * i1 * r21 + r22 * i2 * r22
            # K_ij = c_i . M c_j, c_j the columns of [r]x (as _arm_inertia)
            if side == 0:
                rx, ry, rz = ra[i, 0], ra[i, 1], ra[i, 2]
            else:
                rx, ry, rz = rb[i, 0], rb[i, 1], rb[i, 2]
            cols[0, 0], cols[0, 1], cols[0, 2] = 0.0, rz, -ry
            cols[1, 0], cols[1, 1], cols[1, 2] = -rz, 0.0, rx
            cols[2, 0], cols[2, 1], cols[2, 2] = ry, -rx, 0.0
            m0, m1, m2 = mat[i, o + 0], mat[i, o + 1], mat[i, o + 2]
            m3, m4, m5 = mat[i, o + 3], mat[i, o + 4], mat[i, o + 5]
            for j in range(3):
                cx, cy, cz = cols[j, 0], cols[j, 1], cols[j, 2]
                mc[j, 0] = (m0 * cx + m1 * cy) + m2 * cz
                mc[j, 1] = (m1 * cx + m3 * cy) + m4 * cz
                mc[j, 2] = (m2 * cx + m4 * cy) + m5 * cz
                gm[i, 9 * side + 3 * j + 0] = mc[j, 0]
                gm[i, 9 * side + 3 * j + 1] = mc[j, 1]
                gm[i, 9 * side + 3 * j + 2] = mc[j, 2]
            kk = 0
            for ci in range(3):
                for cj in range(ci, 3):
                    val = (cols[ci, 0] * mc[cj, 0] + cols[ci, 1] * mc[cj, 1]) + cols[ci, 2] * mc[cj, 2]
                    if side == 0:
                        kt6[i, kk] = val
                    else:
                        kt6[i, kk] = kt6[i, kk] + val
                    kk += 1
        ai, bi = a[i], b[i]
        nx, ny, nz = n[i, 0], n[i, 1], n[i, 2]
        ax, ay, az = ra[i, 0], ra[i, 1], ra[i, 2]
        bx, by, bz = rb[i, 0], rb[i, 1], rb[i, 2]
        m0, m1, m2, m3, m4, m5 = mat[i, 0], mat[i, 1], mat[i, 2], mat[i, 3], mat[i, 4], mat[i, 5]
        ux, uy, uz = ay * nz - az * ny, az * nx - ax * nz, ax * ny - ay * nx
        gx = (m0 * ux + m1 * uy) + m2 * uz
        gy = (m1 * ux + m3 * uy) + m4 * uz
        gz = (m2 * ux + m4 * uy) + m5 * uz
        g[i, 0], g[i, 1], g[i, 2], g[i, 3], g[i, 4], g[i, 5] = ux, uy, uz, gx, gy, gz
        ma[i] = inv_mass[ai]
        da = (ux * gx + uy * gy) + uz * gz
        vx = v[ai, 0] + (w[ai, 1] * az - w[ai, 2] * ay)
        vy = v[ai, 1] + (w[ai, 2] * ax - w[ai, 0] * az)
        vz = v[ai, 2] + (w[ai, 0] * ay - w[ai, 1] * ax)
        rest = resting_speed[ai]
        dvx, dvy, dvz = dv[ai, 0], dv[ai, 1], dv[ai, 2]
        dxx, dxy, dxz = dx[ai, 0], dx[ai, 1], dx[ai, 2]
        if bi >= 0:
            m0, m1, m2, m3, m4, m5 = mat[i, 6], mat[i, 7], mat[i, 8], mat[i, 9], mat[i, 10], mat[i, 11]
            ux, uy, uz = by * nz - bz * ny, bz * nx - bx * nz, bx * ny - by * nx
            gx = (m0 * ux + m1 * uy) + m2 * uz
            gy = (m1 * ux + m3 * uy) + m4 * uz
            gz = (m2 * ux + m4 * uy) + m5 * uz
            g[i, 6], g[i, 7], g[i, 8], g[i, 9], g[i, 10], g[i, 11] = ux, uy, uz, gx, gy, gz
            mb[i] = inv_mass[bi]
            kn = (ma[i] + mb[i]) + (da + ((ux * gx + uy * gy) + uz * gz))
            mt[i] = ma[i] + mb[i]
            vx = vx - (v[bi, 0] + (w[bi, 1] * bz - w[bi, 2] * by))
            vy = vy - (v[bi, 1] + (w[bi, 2] * bx - w[bi, 0] * bz))
            vz = vz - (v[bi, 2] + (w[bi, 0] * by - w[bi, 1] * bx))
            rest = rest + resting_speed[bi]
            dvx, dvy, dvz = dvx - dv[bi, 0], dvy - dv[bi, 1], dvz - dv[bi, 2]
            dxx, dxy, dxz = dxx - dx[bi, 0], dxy - dx[bi, 1], dxz - dx[bi, 2]
        else:
            for k in range(6, 12):
                g[i, k] = 0.0
            mb[i] = 0.0
            kn = ma[i] + da
            mt[i] = ma[i]
            rest = rest + 0.0
        inv_kn[i] = 1.0 / kn if kn > 0.0 else 0.0
        vn0 = (vx * nx + vy * ny) + vz * nz
        if vn0 < -(rest + RESTING_FLOOR) and depth[i] >= 0.0:
            e = restitution[i]
            e_used[i] = e
            impact[i] = True
            # time of impact inside the step (as _impact_target)
            dvn = (dvx * nx + dvy * ny) + dvz * nz
            dxn = (dxx * nx + dxy * ny) + dxz * nz
            d0 = -dxn - depth[i]
            span = d0 + depth[i]
            s = d0 / span if span > 0 else 0.0
            s = min(max(s, 0.0), 1.0)
            vn_imp = vn0 - (1.0 - s) * dvn
            tgt[i] = max(-e * vn_imp + (1.0 - s) * dvn, 0.0)
            if kh != 0.0 and e > 0.0:
                kept = kept_end_speed(vn0 - dvn, max(d0, 0.0), dvn / dt, e * depth[i], e, kh)
                if kept > 0.0:
                    tgt[i] = kept
        else:
            e_used[i] = 0.0
            impact[i] = False
            tgt[i] = min(depth[i], 0.0) / dt  # a speculative contact may close its gap
    # warm start (solve's _apply_warm): normal impulse on a, on b, then friction on a, on b
    for i in range(count):
        if impact[i]:
            jn[i] = 0.0
            jt[i, 0], jt[i, 1], jt[i, 2] = 0.0, 0.0, 0.0
        ai, bi = a[i], b[i]
        dj = jn[i]
        ix, iy, iz = jt[i, 0], jt[i, 1], jt[i, 2]
        if dj == 0.0 and ix == 0.0 and iy == 0.0 and iz == 0.0:
            continue
        s = ma[i] * dj
        for k in range(3):
            v[ai, k] += s * n[i, k]
            w[ai, k] += dj * g[i, 3 + k]
        if bi >= 0:
            s = mb[i] * dj
            for k in range(3):
                v[bi, k] -= s * n[i, k]
                w[bi, k] -= dj * g[i, 9 + k]
        v[ai, 0] += ma[i] * ix
        v[ai, 1] += ma[i] * iy
        v[ai, 2] += ma[i] * iz
        for k in range(3):
            w[ai, k] += (gm[i, k] * ix + gm[i, 3 + k] * iy) + gm[i, 6 + k] * iz
        if bi >= 0:
            v[bi, 0] -= mb[i] * ix
            v[bi, 1] -= mb[i] * iy
            v[bi, 2] -= mb[i] * iz
            for k in range(3):
                w[bi, k] -= (gm[i, 9 + k] * ix + gm[i, 12 + k] * iy) + gm[i, 15 + k] * iz
    for sweep in range(max(iterations, max_sweeps)):
        change = 0.0
        for i in range(count):
            ai, bi = a[i], b[i]
            nx, ny, nz = n[i, 0], n[i, 1], n[i, 2]
            ax, ay, az = ra[i, 0], ra[i, 1], ra[i, 2]
            im_a, im_b = ma[i], mb[i]
            vn = (v[ai, 0] * nx + v[ai, 1] * ny) + v[ai, 2] * nz
            vn = vn + ((w[ai, 0] * g[i, 0] + w[ai, 1] * g[i, 1]) + w[ai, 2] * g[i, 2])
            if bi >= 0:
                vnb = (v[bi, 0] * nx + v[bi, 1] * ny) + v[bi, 2] * nz
                vnb = vnb + ((w[bi, 0] * g[i, 6] + w[bi, 1] * g[i, 7]) + w[bi, 2] * g[i, 8])
                vn = vn - vnb
            new = jn[i] + (tgt[i] - vn) * inv_kn[i]
            if new < 0.0:
                new = 0.0
            dj = new - jn[i]
            jn[i] = new
            s = im_a * dj
            v[ai, 0] += s * nx
            v[ai, 1] += s * ny
            v[ai, 2] += s * nz
            w[ai, 0] += dj * g[i, 3]
            w[ai, 1] += dj * g[i, 4]
            w[ai, 2] += dj * g[i, 5]
            if bi >= 0:
                s = im_b * dj
                v[bi, 0] -= s * nx
                v[bi, 1] -= s * ny
                v[bi, 2] -= s * nz
                w[bi, 0] -= dj * g[i, 9]
                w[bi, 1] -= dj * g[i, 10]
                w[bi, 2] -= dj * g[i, 11]
            # friction
            vx = v[ai, 0] + (w[ai, 1] * az - w[ai, 2] * ay)
            vy = v[ai, 1] + (w[ai, 2] * ax - w[ai, 0] * az)
            vz = v[ai, 2] + (w[ai, 0] * ay - w[ai, 1] * ax)
            if bi >= 0:
                bx, by, bz = rb[i, 0], rb[i, 1], rb[i, 2]
                vx = vx - (v[bi, 0] + (w[bi, 1] * bz - w[bi, 2] * by))
                vy = vy - (v[bi, 1] + (w[bi, 2] * bx - w[bi, 0] * bz))
                vz = vz - (v[bi, 2] + (w[bi, 0] * by - w[bi, 1] * bx))
            vn = (vx * nx + vy * ny) + vz * nz
            tx, ty, tz = vx - vn * nx, vy - vn * ny, vz - vn * nz
            s2 = (tx * tx + ty * ty) + tz * tz
            wx, wy, wz = jt[i, 0], jt[i, 1], jt[i, 2]
            if s2 > 0.0:
                k0, k1, k2, k3, k4, k5 = kt6[i, 0], kt6[i, 1], kt6[i, 2], kt6[i, 3], kt6[i, 4], kt6[i, 5]
                qf = (tx * ((k0 * tx + k1 * ty) + k2 * tz) + ty * ((k1 * tx + k3 * ty) + k4 * tz)) + tz * (
                    (k2 * tx + k4 * ty) + k5 * tz
                )
                den = mt[i] * s2 + qf
                if den > 0.0:
                    f = s2 / den
                    wx, wy, wz = wx - f * tx, wy - f * ty, wz - f * tz
            capj = friction[i] * jn[i]
            mag2 = (wx * wx + wy * wy) + wz * wz
            if mag2 > capj * capj:
                s = capj / np.sqrt(mag2)
                wx, wy, wz = wx * s, wy * s, wz * s
            ix, iy, iz = wx - jt[i, 0], wy - jt[i, 1], wz - jt[i, 2]
            jt[i, 0], jt[i, 1], jt[i, 2] = wx, wy, wz
            big = max(abs(dj), max(abs(ix), max(abs(iy), abs(iz))))
            change = max(change, mt[i] * big)
            v[ai, 0] += im_a * ix
            v[ai, 1] += im_a * iy
            v[ai, 2] += im_a * iz
            for k in range(3):  # w += I^-1 (r x imp) = sum_j G_j imp_j
                w[ai, k] += (gm[i, k] * ix + gm[i, 3 + k] * iy) + gm[i, 6 + k] * iz
            if bi >= 0:
                bx, by, bz = rb[i, 0], rb[i, 1], rb[i, 2]
                v[bi, 0] -= im_b * ix
                v[bi, 1] -= im_b * iy
                v[bi, 2] -= im_b * iz
                for k in range(3):
                    w[bi, k] -= (gm[i, 9 + k] * ix + gm[i, 12 + k] * iy) + gm[i, 15 + k] * iz
        if sweep + 1 >= iterations and not change > SWEEP_TOLERANCE:
            break
    # the bodies moved as the impulses moved them (follow_impulses)
    for i in range(count):
        depth_out[i] = depth[i]
    if h > 0.0:
        nb = x.shape[0]
        bounced = np.zeros(nb, dtype=np.bool_)
        for i in range(count):
            if impact[i]:
                bounced[a[i]] = True
                if b[i] >= 0:
                    bounced[b[i]] = True
        sx = np.zeros((nb, 3))
        sw = np.zeros((nb, 3))
        for bi in range(nb):
            if not bounced[bi]:
                for k in range(3):
                    sx[bi, k] = h * (v[bi, k] - v0[bi, k])
                    sw[bi, k] = h * (w[bi, k] - w0[bi, k])
        for i in range(count):
            ai = a[i]
            px = sx[ai, 0] + (sw[ai, 1] * ra[i, 2] - sw[ai, 2] * ra[i, 1])
            py = sx[ai, 1] + (sw[ai, 2] * ra[i, 0] - sw[ai, 0] * ra[i, 2])
            pz = sx[ai, 2] + (sw[ai, 0] * ra[i, 1] - sw[ai, 1] * ra[i, 0])
            mv = (px * n[i, 0] + py * n[i, 1]) + pz * n[i, 2]
            bi = b[i]
            if bi >= 0:
                px = sx[bi, 0] + (sw[bi, 1] * rb[i, 2] - sw[bi, 2] * rb[i, 1])
                py = sx[bi, 1] + (sw[bi, 2] * rb[i, 0] - sw[bi, 0] * rb[i, 2])
                pz = sx[bi, 2] + (sw[bi, 0] * rb[i, 1] - sw[bi, 1] * rb[i, 0])
                mv = mv - ((px * n[i, 0] + py * n[i, 1]) + pz * n[i, 2])
            depth_out[i] = depth[i] - mv
        for bi in range(nb):
            for k in range(3):
                x[bi, k] += sx[bi, k]
            if not bounced[bi] and (sw[bi, 0] != 0.0 or sw[bi, 1] != 0.0 or sw[bi, 2] != 0.0):
                wx, wy, wz = sw[bi, 0], sw[bi, 1], sw[bi, 2]
                qw, qx, qy, qz = q[bi, 0], q[bi, 1], q[bi, 2], q[bi, 3]
                q0 = qw + 0.5 * ((-wx * qx - wy * qy) - wz * qz)
                q1 = qx + 0.5 * ((wx * qw + wy * qz) - wz * qy)
                q2 = qy + 0.5 * ((-wx * qz + wy * qw) + wz * qx)
                q3 = qz + 0.5 * ((wx * qy - wy * qx) + wz * qw)
                norm = np.sqrt(((q0 * q0 + q1 * q1) + q2 * q2) + q3 * q3)
                q[bi, 0], q[bi, 1], q[bi, 2], q[bi, 3] = q0 / norm, q1 / norm, q2 / norm, q3 / norm


# --- the step stage -------------------------------------------------------------------


class BodyContacts(StepStage):
    """Step stage: bodies against planes, colliders (signed-distance callbacks) and each other."""

    injects = False
    dissipative = True
    no_closed_form = "its bodies touch planes or each other (contacts have no closed form here)"

    def __init__(
        self,
        first: int,
        inv_mass: np.ndarray,
        inv_inertia: np.ndarray,
        shapes: tuple[BodyShape, ...],
        planes: PlaneTable,
        restitution: np.ndarray,
        friction: np.ndarray,
        backend: str = "numpy",
        colliders: tuple[
            tuple[Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], float, float], ...
        ] = (),
        iterations: int = ITERATIONS,
        collider_thickness: float = math.inf,
        collider_offsets: Callable[[float], np.ndarray] | None = None,
    ) -> None:
        self.first = first
        #: t -> (C, 3) every collider's displacement from where it was given (keyframed ones
        #: move; None: all static): the bodies meet them where they are, at their velocity
        self.collider_offsets = collider_offsets
        #: the thinnest collider's thinnest extent (stability_note)
        self.collider_thickness = collider_thickness
        self.thinnest_body = min((s.thickness for s in shapes), default=math.inf)
        self.count = len(shapes)
        self.inv_mass = np.ascontiguousarray(inv_mass, dtype=np.float64)
        self.inv_inertia = np.ascontiguousarray(inv_inertia, dtype=np.float64)
        self.points, self.radii, self.counts = contact_table(shapes)
        self.valid = np.arange(self.points.shape[1])[None, :] < self.counts[:, None]
        self.kind, self.dims, self.bound = shape_arrays(shapes)
        self.planes = planes
        self.restitution = np.asarray(restitution, dtype=np.float64)
        self.friction = np.asarray(friction, dtype=np.float64)
        self.colliders = colliders
        self.iterations = iterations
        #: c in "the impulses of a step move a body by c dt dv" (follow_impulses); the compiler sets
        #: it from the integrator (animsim.contact_stages.follow_weight)
        self.follow_weight = 1.0
        self.between_bodies = self.count > 1
        # Verlet list of candidate pairs: bounding spheres grown by SKIN * the largest bound,
        # rebuilt once some body has moved half of that since the last build
        self._skin = SKIN * float(self.bound.max()) if self.count else 0.0
        self._built_at: np.ndarray | None = None
        self._candidates: tuple[np.ndarray, np.ndarray] | None = None
        # the numba kernel covers steps in which bodies touch only planes; a step with contacts
        # between bodies (or colliders) runs the NumPy path on both backends, so the two agree
        self.use_numba = backend == "numba" and not colliders
        self._buffers: tuple[np.ndarray, ...] | None = None
        self.numba_broadphase = backend == "numba"
        #: the last step's impulses, where each step's sweeps start (warm starting)
        self.warm = WarmStart(self.bound)
        kinds = sorted({s.kind for s in shapes})
        parts = []
        if planes.count:
            parts.append(f"{planes.count} plane(s)")
        if colliders:
            parts.append(f"{len(colliders)} collider(s)")
        if self.between_bodies:
            parts.append("each other (sphere-sphere, sphere-box, capsule ends; box-box faces, edges and corners)")
        self.label = (
            f"body contacts: {self.count} {'/'.join(kinds)} bodies against {', '.join(parts)}; "
            f"impulses with restitution and Coulomb friction, {iterations} to {MAX_SWEEPS} sweeps ({COLD_SWEEPS} from rest; until a sweep "
            f"changes no velocity by {SWEEP_TOLERANCE:g} m/s), resting below "
            f"{RESTING_FACTOR:g}x the speed forces add per step, positions projected out from the ground up (shock propagation)"
        )

    def stability_note(self, dt: float) -> str | None:
        """Contacts are found where the bodies are at the end of each step. A contact sphere of
        radius r (0 for a box's corners) is caught inside a thing of thickness t, and pushed
        back out on its own side, only if no step carries it more than r + t / 2: faster, it can
        skip over a collider or another body between two step ends, or be pushed out through
        the far side. Planes are half-spaces: a body behind one is always found and pushed out."""
        if not (self.colliders or self.between_bodies) or not self.valid.any():
            return None
        r = float(self.radii[self.valid].min())
        parts = []
        if self.colliders:
            parts.append(("a collider", self.collider_thickness))
        if self.between_bodies:
            parts.append(("another body", self.thinnest_body))
        t = min(thick for _, thick in parts)
        what = " or ".join(name for name, _ in parts)
        return (
            f"body contacts: found at step ends, so a body faster than (r + t/2) / dt = "
            f"{(r + 0.5 * t) / dt:.3g} m/s can pass through {what} (r = {r:.3g} m, the smallest "
            f"contact sphere of a body, 0 at a box's corners; t = {t:.3g} m, the thinnest one); "
            "planes stop bodies at any speed"
        )

    @property
    def left_out(self) -> list[str]:
        """What body contacts do not simulate (for explain)."""
        out = []
        if self.between_bodies and int((self.kind == SHAPE_CAPSULE).sum()) > 1:
            out.append("capsule-capsule side-on-side contact (only end spheres are detected)")
        return out

    def reset(self, state: Any) -> None:
        self._built_at = None
        self._candidates = None
        self.warm.forget()

    def apply(
        self, state: Any, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float, dt: float = 0.0
    ) -> bool:
        dt = dt or (t1 - t0)
        rows = slice(self.first, self.first + self.count)
        # views: the solver and the projection change the state in place
        x = state.particle_position[rows]
        v = state.particle_velocity[rows]
        q = state.body_orientation
        w = state.body_angular_velocity
        dv = v - v_old[rows]
        dx = x - x_old[rows]
        resting = RESTING_FACTOR * np.linalg.norm(dv, axis=1)
        pairs = self.find_pairs(x, q)
        if not self.use_numba:
            offsets = velocities = None
            if self.collider_offsets is not None:  # keyframed colliders: where they are now, how fast
                before, offsets = self.collider_offsets(t0), self.collider_offsets(t1)
                velocities = (offsets - before) / dt
            contacts, surface = self.find(x, q, pairs, offsets, velocities)
            if contacts.count == 0:
                return False
            c = contacts
            jn0, jt0, local = self.warm.guess(c.a, c.b, c.plane, c.n, c.ra, q)
            v_pre, w_pre = v.copy(), w.copy()
            e_used, impact, jn, jt = solve(
                contacts,
                v,
                w,
                q,
                self.inv_mass,
                self.inv_inertia,
                resting,
                self.iterations,
                dv,
                dx,
                energy_shift(self.follow_weight) * dt,
                dt,
                surface,
                (jn0, jt0),
                self._sweep_limit(c, jn0),
            )
            self.warm.keep(c.a, c.b, c.plane, c.n, local, jn, jt)
            h = self.follow_weight * dt
            left = follow_impulses(c, impact, x, q, v - v_pre, w - w_pre, h) if h > 0.0 else c.depth
            push = projection.pushes(c.depth, left, e_used)
            projection.project(c.a, c.b, c.n, push, c.plane, x, self.inv_mass)
            return True
        # numba: plane contacts found body by body, then the whole list (pairs after the planes,
        # as on the NumPy path) solved in list order by one kernel call
        detect, solver = numba_kernels()
        buf = self._plane_buffers()
        found = detect(
            x,
            q,
            self.points,
            self.radii,
            self.counts,
            self.planes.point,
            self.planes.normal,
            self.planes.restitution,
            self.planes.friction,
            *buf,
        )
        if found == 0 and pairs.count == 0:
            return False
        planes_found = Contacts(
            buf[0][:found],
            self._no_body[:found],
            buf[1][:found],
            self._zero3[:found],
            buf[2][:found],
            buf[3][:found],
            buf[4][:found],
            buf[5][:found],
            buf[6][:found],
        )
        c = _concat([planes_found, pairs])
        arrays = [np.ascontiguousarray(getattr(c, f)) for f in Contacts.__dataclass_fields__]
        count = c.count
        e_used = np.empty(count)
        impact = np.empty(count, dtype=np.bool_)
        depth_left = np.empty(count)
        jn, jt, local = self.warm.guess(c.a, c.b, c.plane, c.n, c.ra, q)
        solver(
            count,
            *arrays,
            x,
            v,
            w,
            q,
            self.inv_mass,
            self.inv_inertia,
            resting,
            dv,
            dx,
            self.iterations,
            e_used,
            impact,
            self.follow_weight * dt,
            depth_left,
            energy_shift(self.follow_weight) * dt,
            dt,
            jn,
            jt,
            self._sweep_limit(c, jn),
        )
        self.warm.keep(c.a, c.b, c.plane, c.n, local, jn, jt)
        push = projection.pushes(c.depth, depth_left, e_used)
        projection.project(c.a, c.b, c.n, push, c.plane, x, self.inv_mass, True)
        return True

    @staticmethod
    def _sweep_limit(c: Contacts, start: np.ndarray) -> int:
        """COLD_SWEEPS when bodies touch each other and none of their contacts has an impulse to
        start from (a stack set down), else MAX_SWEEPS. Not per contact: a corner that carries
        no load, or a speculative contact, starts from zero in every step of a standing stack."""
        between = c.b >= 0
        cold = bool(between.any()) and not bool((start[between] != 0.0).any())
        return COLD_SWEEPS if cold else MAX_SWEEPS

    def _plane_buffers(self) -> tuple[np.ndarray, ...]:
        """Output arrays of the numba plane detection (capacity: every sphere behind every plane)."""
        if self._buffers is None:
            cap = self.count * self.points.shape[1] * max(self.planes.count, 1)
            self._buffers = (
                np.zeros(cap, dtype=np.int64),
                np.zeros((cap, 3)),
                np.zeros((cap, 3)),
                np.zeros(cap),
                np.zeros(cap),
                np.zeros(cap),
                np.zeros(cap, dtype=np.int64),
            )
            self._no_body = np.full(cap, -1, dtype=np.int64)
            self._zero3 = np.zeros((cap, 3))
        return self._buffers

    def find(
        self,
        x: np.ndarray,
        q: np.ndarray,
        pairs: Contacts | None = None,
        offsets: np.ndarray | None = None,
        velocities: np.ndarray | None = None,
    ) -> tuple[Contacts, np.ndarray | None]:
        """Every contact of the bodies at x, q: planes, then colliders (displaced by ``offsets``
        (C, 3) where they move), then pairs; and with ``velocities`` (C, 3), the velocity (K, 3)
        of the surface each contact touches (None: every surface is still)."""
        parts = []
        if self.planes.count:
            parts.append(plane_contacts(x, q, self.points, self.radii, self.valid, self.planes))
        moving: list[tuple[int, int]] = []  # (collider, its contacts) in list order
        for c, (sdf, e, mu) in enumerate(self.colliders):
            where = None if offsets is None else offsets[c]
            found = sdf_contacts(
                x, q, self.points, self.radii, self.valid, lambda p, o=where, f=sdf: f(p, o), e, mu
            )
            parts.append(found)
            moving.append((c, found.count))
        parts.append(self.find_pairs(x, q) if pairs is None else pairs)
        contacts = _concat(parts)
        if velocities is None:
            return contacts, None
        surface = np.zeros((contacts.count, 3))
        at = parts[0].count if self.planes.count else 0
        for c, k in moving:
            surface[at : at + k] = velocities[c]
            at += k
        return contacts, surface

    def find_pairs(self, x: np.ndarray, q: np.ndarray) -> Contacts:
        """Contacts between bodies (none when the scene has one body)."""
        if not self.between_bodies:
            return _empty_contacts()
        moved = np.inf if self._built_at is None else float(np.abs(x - self._built_at).max(initial=0.0))
        if not moved <= 0.5 * self._skin / math.sqrt(3.0):  # a NaN position rebuilds too
            grown = self.bound + 0.5 * self._skin
            if self.numba_broadphase and self.count > 1 and np.isfinite(x).all():
                self._candidates = numba_candidate_pairs()(np.ascontiguousarray(x), grown)
            else:
                self._candidates = candidate_pairs(x, grown)
            self._built_at = x.copy()
        i, j = self._candidates
        if i.size == 0:
            return _empty_contacts()
        # the list holds pairs within a skin of touching; only pairs whose bounding spheres overlap
        # now can have a contact (every contact sphere lies inside its body's bounding sphere)
        gap = x[i] - x[j]
        reach = (self.bound[i] + self.bound[j]) * (1.0 + 1e-9)  # never lose a pair to rounding
        close = np.einsum("ij,ij->i", gap, gap) <= reach * reach
        if not close.any():
            return _empty_contacts()
        if self.numba_broadphase:
            found = numba_pair_contacts()(
                x,
                q,
                self.points,
                self.radii,
                self.counts,
                self.kind,
                self.dims,
                self.restitution,
                self.friction,
                i[close],
                j[close],
            )
            return Contacts(*found, np.full(found[0].size, -1, dtype=np.int64))
        return pair_contacts(
            x,
            q,
            self.points,
            self.radii,
            self.counts,
            self.kind,
            self.dims,
            self.bound,
            self.restitution,
            self.friction,
            (i[close], j[close]),
        )
