"""Detection of rigid-body contacts: against planes, against signed-distance colliders, and
between bodies; the contact list (:class:`Contacts`) and the planes as arrays (:class:`PlaneTable`).

Every shape is a few contact spheres fixed in its body (:mod:`animsim.bodies.shapes`): a box's
corners, a sphere's centre, a capsule's end centres. A contact is a sphere whose surface is
behind a plane or inside another body's shape (signed distance < 0); two boxes meet face
against face (:mod:`animsim.bodies.box_box`). Candidate pairs come from a uniform grid of cells.

These are the NumPy versions; their numba twins (:mod:`animsim.bodies.contact_kernels`) do the
same tests in the same order with the same arithmetic. The model as a whole (detection,
impulses after Baraff 1997 and Catto 2005, projection) is described in
:mod:`animsim.bodies.contacts`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from animsim.bodies import box_box
from animsim.bodies import quaternion as quat
from animsim.bodies.contact_constants import SHAPE_BOX, SHAPE_CAPSULE, SHAPE_SPHERE
from animsim.bodies.contact_kernels import pair_coefficient
from animsim.bodies.shapes import BodyShape, Box, Capsule, Sphere


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


def contact_rolling(c: Contacts, rolling: np.ndarray, kind: np.ndarray) -> np.ndarray:
    """Each contact's rolling resistance (C,) from the bodies' ``rolling`` (B,) and shape kinds
    ``kind`` (B,): between two bodies combined as their friction is (:func:`pair_coefficient`);
    against a plane or a collider, which have none of their own, the body's. Only where a round
    body rolls: a contact whose body a is a sphere or a capsule (a round body is always a when it
    meets a box). A box does not roll on its corners, it tips over them, and there the corners
    already hold it: a rolling torque at each corner would only share out the load of the others
    (measured: a box sliding on a floor took another path, 1 % off, with rolling resistance
    at its corners), so a box's own key acts only where a round body rolls on it."""
    has_b = c.b >= 0
    own = rolling[c.a]
    pair = np.where(has_b, pair_coefficient(own, rolling[np.where(has_b, c.b, 0)]), own)
    return np.where(kind[c.a] != SHAPE_BOX, pair, 0.0)


def empty_contacts() -> Contacts:
    z3 = np.zeros((0, 3))
    zi = np.zeros(0, dtype=np.int64)
    return Contacts(zi, zi, z3, z3, z3, np.zeros(0), np.zeros(0), np.zeros(0), zi)


def concat(parts: list[Contacts]) -> Contacts:
    parts = [p for p in parts if p.count]
    if not parts:
        return empty_contacts()
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
    return concat(parts)


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
        return empty_contacts()
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
        return empty_contacts()
    return Contacts(
        s_idx,
        t_idx,
        point - x[s_idx],
        point - x[t_idx],
        n,
        -d,
        0.5 * (restitution[s_idx] + restitution[t_idx]),
        pair_coefficient(friction[s_idx], friction[t_idx]),
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
