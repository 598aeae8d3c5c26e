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
   other, ``iterations`` times, in batches in which no body appears twice (so a
   batch is one vectorised update).
3. **Projection.** Each body is moved out along the normal by its deepest
   penetration (split between two free bodies by their inverse masses); a
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

from animsim.bodies import quaternion as quat
from animsim.bodies.shapes import BodyShape, Box, Capsule, Sphere, contact_table
from animsim.elements import StepStage

#: sequential-impulse sweeps over the contacts per step
ITERATIONS = 10
#: a contact is resting (no bounce) below this multiple of the speed the forces added in the step
RESTING_FACTOR = 2.0
#: and below this absolute approach speed, m/s (rounding of a body already at rest)
RESTING_FLOOR = 1e-6
#: candidate pairs are kept while no body moved more than half of SKIN * the largest bound
SKIN = 0.5

SHAPE_BOX, SHAPE_SPHERE, SHAPE_CAPSULE = 0, 1, 2


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

    @property
    def count(self) -> int:
        return int(self.a.shape[0])


def _empty_contacts() -> Contacts:
    z3 = np.zeros((0, 3))
    zi = np.zeros(0, dtype=np.int64)
    return Contacts(zi, zi, z3, z3, z3, np.zeros(0), np.zeros(0), np.zeros(0))


def _select(c: Contacts, bodies: np.ndarray) -> Contacts:
    """The contacts whose first body is flagged in ``bodies`` (B,) bool."""
    keep = bodies[c.a]
    return Contacts(*(getattr(c, f)[keep] for f in Contacts.__dataclass_fields__))


def _concat(parts: list[Contacts]) -> Contacts:
    parts = [p for p in parts if p.count]
    if not parts:
        return _empty_contacts()
    if len(parts) == 1:
        return parts[0]
    return Contacts(*(np.concatenate([getattr(p, f) for p in parts]) for f in Contacts.__dataclass_fields__))


def world_spheres(x: np.ndarray, q: np.ndarray, points: np.ndarray) -> np.ndarray:
    """World centres of the contact spheres, (B, K, 3)."""
    k = points.shape[1]
    return x[:, None, :] + quat.rotate(np.repeat(q[:, None, :], k, axis=1), points)


def plane_contacts(
    x: np.ndarray, q: np.ndarray, points: np.ndarray, radii: np.ndarray, valid: np.ndarray, planes: PlaneTable
) -> Contacts:
    """Contact spheres behind each plane: ordered by plane, then body, then sphere."""
    centres = world_spheres(x, q, points)
    parts = []
    for p in range(planes.count):
        n = planes.normal[p]
        dist = (centres - planes.point[p]) @ n - radii
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
        out_len = np.linalg.norm(outside, axis=1)
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
        dist = np.linalg.norm(rel, axis=1)
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
    close = np.einsum("ij,ij->i", x[i] - x[j], x[i] - x[j]) <= (bound[i] + bound[j]) ** 2
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
    other's shape; for two boxes, each one's corners against the other. ``candidates``: pairs
    (i, j) that may touch (default: all pairs whose bounding spheres overlap)."""
    i, j = candidate_pairs(x, bound) if candidates is None else candidates
    if i.size == 0:
        return _empty_contacts()
    round_i, round_j = kind[i] != SHAPE_BOX, kind[j] != SHAPE_BOX
    # (source of spheres, target shape) directions
    src = np.concatenate([i[round_i], j[~round_i & round_j], i[~round_i & ~round_j], j[~round_i & ~round_j]])
    dst = np.concatenate([j[round_i], i[~round_i & round_j], j[~round_i & ~round_j], i[~round_i & ~round_j]])
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
    if not hit.any():
        return _empty_contacts()
    s_idx, t_idx, k_idx, d = s_idx[hit], t_idx[hit], k_idx[hit], d[hit]
    n = quat.rotate(q[t_idx], n_local[hit])
    surface_a = centre[hit] - radii[s_idx, k_idx, None] * n  # on the sphere's surface
    point = surface_a + 0.5 * d[:, None] * n  # halfway between the two surfaces
    return Contacts(
        s_idx,
        t_idx,
        point - x[s_idx],
        point - x[t_idx],
        n,
        -d,
        0.5 * (restitution[s_idx] + restitution[t_idx]),
        np.sqrt(friction[s_idx] * friction[t_idx]),
    )


# --- the solver ---------------------------------------------------------------------


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


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of (..., 3) arrays, written out (np.cross is slow on many short rows)."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


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
) -> np.ndarray:
    """Sequential impulses on v (B,3), w (B,3) in place; returns the restitution applied per contact."""
    c = contacts
    a, b = c.a, c.b
    has_b = b >= 0
    bb = np.where(has_b, b, 0)
    # world inverse inertia matrices, once per step (orientations do not change while solving)
    rot = quat.to_matrix(q)
    inv_iw = np.einsum("bij,bj,bkj->bik", rot, inv_inertia, rot)
    ia = inv_iw[a]
    ib = np.where(has_b[:, None, None], inv_iw[bb], 0.0)
    ma = inv_mass[a]
    mb = np.where(has_b, inv_mass[bb], 0.0)
    n, ra, rb = c.n, c.ra, c.rb

    def point_velocity() -> np.ndarray:
        va = v[a] + _cross(w[a], ra)
        vb = np.where(has_b[:, None], v[bb] + _cross(w[bb], rb), 0.0)
        return va - vb

    def eff_mass(d: np.ndarray) -> np.ndarray:
        ta = np.einsum("cij,cj->ci", ia, _cross(ra, d))
        tb = np.einsum("cij,cj->ci", ib, _cross(rb, d))
        return ma + mb + np.einsum("ci,ci->c", _cross(ta, ra) + _cross(tb, rb), d)

    kn = eff_mass(n)
    # two immovable things (a pinned body on a floor) exchange no impulse
    inv_kn = np.where(kn > 0, 1.0 / np.where(kn > 0, kn, 1.0), 0.0)
    vn0 = np.einsum("ci,ci->c", point_velocity(), n)
    rest_a = resting_speed[a]
    rest_b = np.where(has_b, resting_speed[bb], 0.0)
    bounce = vn0 < -(rest_a + rest_b + RESTING_FLOOR)
    e_used = np.where(bounce, c.restitution, 0.0)
    target = np.where(bounce, -c.restitution * vn0, 0.0)
    if dv is not None and dx is not None and bounce.any():
        target = np.where(bounce, _impact_target(c, vn0, dv, dx, has_b, bb), target)
    jn = np.zeros(c.count)
    jt = np.zeros((c.count, 3))
    batch = batches(a, b)
    groups = [np.nonzero(batch == k)[0] for k in range(int(batch.max()) + 1)] if c.count else []

    def apply(idx: np.ndarray, imp: np.ndarray) -> None:
        ai = a[idx]
        v[ai] += ma[idx, None] * imp
        w[ai] += np.einsum("cij,cj->ci", ia[idx], _cross(ra[idx], imp))
        withb = idx[has_b[idx]]
        if withb.size:
            imp_b = imp[has_b[idx]]
            bi = b[withb]
            v[bi] -= mb[withb, None] * imp_b
            w[bi] -= np.einsum("cij,cj->ci", ib[withb], _cross(rb[withb], imp_b))

    def rel_velocity(idx: np.ndarray) -> np.ndarray:
        ai = a[idx]
        vel = v[ai] + _cross(w[ai], ra[idx])
        hb = has_b[idx]
        bi = bb[idx]
        vel -= np.where(hb[:, None], v[bi] + _cross(w[bi], rb[idx]), 0.0)
        return vel

    for _ in range(iterations):
        for idx in groups:
            nn = n[idx]
            vel = rel_velocity(idx)
            vn = np.einsum("ci,ci->c", vel, nn)
            new = np.maximum(jn[idx] + (target[idx] - vn) * inv_kn[idx], 0.0)
            dj = new - jn[idx]
            jn[idx] = new
            apply(idx, dj[:, None] * nn)
            # Coulomb friction: stop the sliding, within mu * (normal impulse so far)
            vel = rel_velocity(idx)
            vt = vel - np.einsum("ci,ci->c", vel, nn)[:, None] * nn
            speed = np.linalg.norm(vt, axis=1)
            moving = speed > 0
            tdir = vt / np.where(moving, speed, 1.0)[:, None]
            kt = np.where(moving, eff_mass_sub(idx, tdir, ia, ib, ma, mb, ra, rb), 0.0)
            inv_kt = np.where(kt > 0, 1.0 / np.where(kt > 0, kt, 1.0), 0.0)
            want = jt[idx] - (speed * inv_kt)[:, None] * tdir
            cap = c.friction[idx] * jn[idx]
            mag = np.linalg.norm(want, axis=1)
            scale = np.where(mag > cap, cap / np.where(mag > 0, mag, 1.0), 1.0)
            want = want * scale[:, None]
            djt = want - jt[idx]
            jt[idx] = want
            apply(idx, djt)
    return e_used


def _impact_target(
    c: Contacts, vn0: np.ndarray, dv: np.ndarray, dx: np.ndarray, has_b: np.ndarray, bb: np.ndarray
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
    """
    rel_dv = dv[c.a] - np.where(has_b[:, None], dv[bb], 0.0)
    rel_dx = dx[c.a] - np.where(has_b[:, None], dx[bb], 0.0)
    dvn = np.einsum("ci,ci->c", rel_dv, c.n)
    dxn = np.einsum("ci,ci->c", rel_dx, c.n)
    d0 = -dxn - c.depth
    span = d0 + c.depth
    s = np.clip(np.divide(d0, span, out=np.zeros_like(d0), where=span > 0), 0.0, 1.0)
    vn_imp = vn0 - (1.0 - s) * dvn
    return np.maximum(-c.restitution * vn_imp + (1.0 - s) * dvn, 0.0)


def eff_mass_sub(
    idx: np.ndarray,
    d: np.ndarray,
    ia: np.ndarray,
    ib: np.ndarray,
    ma: np.ndarray,
    mb: np.ndarray,
    ra: np.ndarray,
    rb: np.ndarray,
) -> np.ndarray:
    """1 / (effective mass) along unit directions d for contacts idx."""
    ta = np.einsum("cij,cj->ci", ia[idx], _cross(ra[idx], d))
    tb = np.einsum("cij,cj->ci", ib[idx], _cross(rb[idx], d))
    return ma[idx] + mb[idx] + np.einsum("ci,ci->c", _cross(ta, ra[idx]) + _cross(tb, rb[idx]), d)


def project(contacts: Contacts, e_used: np.ndarray, x: np.ndarray, inv_mass: np.ndarray) -> None:
    """Move bodies out of what they penetrate (positions only), in place.

    Against static things: per body and normal direction the deepest contact
    wins (several corners of one box behind one plane need one push, not the sum).
    Between bodies: the push is shared by inverse mass.
    """
    c = contacts
    if c.count == 0:
        return
    push = c.depth * (1.0 + e_used)
    static = c.b < 0
    if static.any():
        a, n, d = c.a[static], c.n[static], push[static]
        # group contacts by (body, normal): the deepest of each group
        key = np.concatenate([a[:, None].astype(np.float64), np.round(n, 12)], axis=1)
        uniq, inv = np.unique(key, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        deepest = np.zeros(uniq.shape[0])
        np.maximum.at(deepest, inv, d)
        bodies = uniq[:, 0].astype(np.int64)
        movable = inv_mass[bodies] > 0
        np.add.at(x, bodies[movable], deepest[movable, None] * uniq[movable, 1:])
    pairs = ~static
    if pairs.any():
        a, b, n, d = c.a[pairs], c.b[pairs], c.n[pairs], push[pairs]
        wa, wb = inv_mass[a], inv_mass[b]
        total = wa + wb
        share = np.where(total > 0, 1.0 / np.where(total > 0, total, 1.0), 0.0)
        np.add.at(x, a, (d * wa * share)[:, None] * n)
        np.add.at(x, b, -(d * wb * share)[:, None] * n)


@cache
def numba_plane_solver() -> Any:
    """The numba kernel of plane contacts (detection, solve, projection) for scenes whose bodies
    touch nothing but planes; same operations and order as the NumPy path."""
    from numba import njit

    return njit(cache=True)(_plane_solver_loop)


def _plane_solver_loop(
    x: np.ndarray,
    v: np.ndarray,
    q: np.ndarray,
    w: np.ndarray,
    inv_mass: np.ndarray,
    inv_inertia: np.ndarray,
    points: np.ndarray,
    radii: np.ndarray,
    counts: np.ndarray,
    plane_point: np.ndarray,
    plane_normal: np.ndarray,
    plane_e: np.ndarray,
    plane_mu: np.ndarray,
    resting_speed: np.ndarray,
    iterations: int,
    dv: np.ndarray,
    dx: np.ndarray,
    skip: np.ndarray,
) -> int:
    """Each body on its own (bodies touching only planes are independent): its contacts in order
    plane, sphere; sequential impulses; then the push out of each plane. Returns the contact count."""
    total = 0
    kmax = points.shape[1]
    nplanes = plane_point.shape[0]
    cap = nplanes * kmax
    ra = np.empty((cap, 3))
    nrm = np.empty((cap, 3))
    dep = np.empty(cap)
    ee = np.empty(cap)
    mu = np.empty(cap)
    pid = np.empty(cap, dtype=np.int64)
    jn = np.empty(cap)
    jt = np.empty((cap, 3))
    kn = np.empty(cap)
    tgt = np.empty(cap)
    eu = np.empty(cap)
    for bi in range(x.shape[0]):
        if skip[bi]:  # touching another body this step: solved with it on the NumPy path
            continue
        qw, qx, qy, qz = q[bi, 0], q[bi, 1], q[bi, 2], q[bi, 3]
        # world inverse inertia R diag(I^-1) R^T
        r00 = 1 - 2 * (qy * qy + qz * qz)
        r01 = 2 * (qx * qy - qw * qz)
        r02 = 2 * (qx * qz + qw * qy)
        r10 = 2 * (qx * qy + qw * qz)
        r11 = 1 - 2 * (qx * qx + qz * qz)
        r12 = 2 * (qy * qz - qw * qx)
        r20 = 2 * (qx * qz - qw * qy)
        r21 = 2 * (qy * qz + qw * qx)
        r22 = 1 - 2 * (qx * qx + qy * qy)
        i0, i1, i2 = inv_inertia[bi, 0], inv_inertia[bi, 1], inv_inertia[bi, 2]
        m00 = r00 * i0 * r00 + r01 * i1 * r01 + r02 * i2 * r02
        m01 = r00 * i0 * r10 + r01 * i1 * r11 + r02 * i2 * r12
        m02 = r00 * i0 * r20 + r01 * i1 * r21 + r02 * i2 * r22
        m11 = r10 * i0 * r10 + r11 * i1 * r11 + r12 * i2 * r12
        m12 = r10 * i0 * r20 + r11 * i1 * r21 + r12 * i2 * r22
        m22 = r20 * i0 * r20 + r21 * i1 * r21 + r22 * i2 * r22
        im = inv_mass[bi]
        c = 0
        for p in range(nplanes):
            nx, ny, nz = plane_normal[p, 0], plane_normal[p, 1], plane_normal[p, 2]
            for k in range(counts[bi]):
                px, py, pz = points[bi, k, 0], points[bi, k, 1], points[bi, k, 2]
                tx = 2.0 * (qy * pz - qz * py)
                ty = 2.0 * (qz * px - qx * pz)
                tz = 2.0 * (qx * py - qy * px)
                wx_ = px + qw * tx + (qy * tz - qz * ty)
                wy_ = py + qw * ty + (qz * tx - qx * tz)
                wz_ = pz + qw * tz + (qx * ty - qy * tx)
                cx, cy, cz = x[bi, 0] + wx_, x[bi, 1] + wy_, x[bi, 2] + wz_
                d = (
                    (cx - plane_point[p, 0]) * nx
                    + (cy - plane_point[p, 1]) * ny
                    + (cz - plane_point[p, 2]) * nz
                ) - radii[bi, k]
                if d < 0.0:
                    rr = radii[bi, k]
                    ra[c, 0] = cx - rr * nx - x[bi, 0]
                    ra[c, 1] = cy - rr * ny - x[bi, 1]
                    ra[c, 2] = cz - rr * nz - x[bi, 2]
                    nrm[c, 0], nrm[c, 1], nrm[c, 2] = nx, ny, nz
                    dep[c] = -d
                    ee[c] = plane_e[p]
                    mu[c] = plane_mu[p]
                    pid[c] = p
                    c += 1
        if c == 0:
            continue
        total += c
        for i in range(c):
            ax, ay, az = ra[i, 0], ra[i, 1], ra[i, 2]
            nx, ny, nz = nrm[i, 0], nrm[i, 1], nrm[i, 2]
            # K along n: im + n . ((I^-1 (r x n)) x r)
            cxn, cyn, czn = ay * nz - az * ny, az * nx - ax * nz, ax * ny - ay * nx
            tx = m00 * cxn + m01 * cyn + m02 * czn
            ty = m01 * cxn + m11 * cyn + m12 * czn
            tz = m02 * cxn + m12 * cyn + m22 * czn
            kn[i] = im + ((ty * az - tz * ay) * nx + (tz * ax - tx * az) * ny + (tx * ay - ty * ax) * nz)
            vx = v[bi, 0] + (w[bi, 1] * az - w[bi, 2] * ay)
            vy = v[bi, 1] + (w[bi, 2] * ax - w[bi, 0] * az)
            vz = v[bi, 2] + (w[bi, 0] * ay - w[bi, 1] * ax)
            vn0 = vx * nx + vy * ny + vz * nz
            if vn0 < -(resting_speed[bi] + 0.0 + 1e-6):
                eu[i] = ee[i]
                # time of impact inside the step (as _impact_target)
                dvn = dv[bi, 0] * nx + dv[bi, 1] * ny + dv[bi, 2] * nz
                dxn = dx[bi, 0] * nx + dx[bi, 1] * ny + dx[bi, 2] * nz
                d0 = -dxn - dep[i]
                span = d0 + dep[i]
                s = d0 / span if span > 0 else 0.0
                s = min(max(s, 0.0), 1.0)
                vn_imp = vn0 - (1.0 - s) * dvn
                tgt[i] = max(-ee[i] * vn_imp + (1.0 - s) * dvn, 0.0)
            else:
                eu[i] = 0.0
                tgt[i] = 0.0
            jn[i] = 0.0
            jt[i, 0], jt[i, 1], jt[i, 2] = 0.0, 0.0, 0.0
        for _ in range(iterations):
            for i in range(c):
                ax, ay, az = ra[i, 0], ra[i, 1], ra[i, 2]
                nx, ny, nz = nrm[i, 0], nrm[i, 1], nrm[i, 2]
                vx = v[bi, 0] + (w[bi, 1] * az - w[bi, 2] * ay)
                vy = v[bi, 1] + (w[bi, 2] * ax - w[bi, 0] * az)
                vz = v[bi, 2] + (w[bi, 0] * ay - w[bi, 1] * ax)
                vn = vx * nx + vy * ny + vz * nz
                inv_kn = 1.0 / kn[i] if kn[i] > 0.0 else 0.0
                new = jn[i] + (tgt[i] - vn) * inv_kn
                if new < 0.0:
                    new = 0.0
                dj = new - jn[i]
                jn[i] = new
                ix, iy, iz = dj * nx, dj * ny, dj * nz
                v[bi, 0] += im * ix
                v[bi, 1] += im * iy
                v[bi, 2] += im * iz
                cx_, cy_, cz_ = ay * iz - az * iy, az * ix - ax * iz, ax * iy - ay * ix
                w[bi, 0] += m00 * cx_ + m01 * cy_ + m02 * cz_
                w[bi, 1] += m01 * cx_ + m11 * cy_ + m12 * cz_
                w[bi, 2] += m02 * cx_ + m12 * cy_ + m22 * cz_
                # friction
                vx = v[bi, 0] + (w[bi, 1] * az - w[bi, 2] * ay)
                vy = v[bi, 1] + (w[bi, 2] * ax - w[bi, 0] * az)
                vz = v[bi, 2] + (w[bi, 0] * ay - w[bi, 1] * ax)
                vn = vx * nx + vy * ny + vz * nz
                tx_, ty_, tz_ = vx - vn * nx, vy - vn * ny, vz - vn * nz
                speed = np.sqrt(tx_ * tx_ + ty_ * ty_ + tz_ * tz_)
                if speed > 0.0:
                    ex, ey, ez = tx_ / speed, ty_ / speed, tz_ / speed
                    cxd, cyd, czd = ay * ez - az * ey, az * ex - ax * ez, ax * ey - ay * ex
                    ux = m00 * cxd + m01 * cyd + m02 * czd
                    uy = m01 * cxd + m11 * cyd + m12 * czd
                    uz = m02 * cxd + m12 * cyd + m22 * czd
                    kt = im + ((uy * az - uz * ay) * ex + (uz * ax - ux * az) * ey + (ux * ay - uy * ax) * ez)
                    inv_kt = 1.0 / kt if kt > 0.0 else 0.0
                    wx_ = jt[i, 0] - (speed * inv_kt) * ex
                    wy_ = jt[i, 1] - (speed * inv_kt) * ey
                    wz_ = jt[i, 2] - (speed * inv_kt) * ez
                else:
                    wx_, wy_, wz_ = jt[i, 0], jt[i, 1], jt[i, 2]
                capj = mu[i] * jn[i]
                mag = np.sqrt(wx_ * wx_ + wy_ * wy_ + wz_ * wz_)
                if mag > capj:
                    s = capj / (mag if mag > 0 else 1.0)
                    wx_, wy_, wz_ = wx_ * s, wy_ * s, wz_ * s
                ix, iy, iz = wx_ - jt[i, 0], wy_ - jt[i, 1], wz_ - jt[i, 2]
                jt[i, 0], jt[i, 1], jt[i, 2] = wx_, wy_, wz_
                v[bi, 0] += im * ix
                v[bi, 1] += im * iy
                v[bi, 2] += im * iz
                cx_, cy_, cz_ = ay * iz - az * iy, az * ix - ax * iz, ax * iy - ay * ix
                w[bi, 0] += m00 * cx_ + m01 * cy_ + m02 * cz_
                w[bi, 1] += m01 * cx_ + m11 * cy_ + m12 * cz_
                w[bi, 2] += m02 * cx_ + m12 * cy_ + m22 * cz_
        if im > 0.0:
            for p in range(nplanes):
                deepest = 0.0
                for i in range(c):
                    if pid[i] == p:
                        push = dep[i] * (1.0 + eu[i])
                        if push > deepest:
                            deepest = push
                x[bi, 0] += deepest * plane_normal[p, 0]
                x[bi, 1] += deepest * plane_normal[p, 1]
                x[bi, 2] += deepest * plane_normal[p, 2]
    return total


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
    ) -> None:
        self.first = first
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
        self.between_bodies = self.count > 1
        # Verlet list of candidate pairs: bounding spheres grown by SKIN * the largest bound,
        # rebuilt once some body has moved half of that since the last build
        self._skin = SKIN * float(self.bound.max()) if self.count else 0.0
        self._built_at: np.ndarray | None = None
        self._candidates: tuple[np.ndarray, np.ndarray] | None = None
        # the numba kernel covers steps in which bodies touch only planes; a step with contacts
        # between bodies (or colliders) runs the NumPy path on both backends, so the two agree
        self.use_numba = backend == "numba" and not colliders
        kinds = sorted({s.kind for s in shapes})
        parts = []
        if planes.count:
            parts.append(f"{planes.count} plane(s)")
        if colliders:
            parts.append(f"{len(colliders)} collider(s)")
        if self.between_bodies:
            parts.append("each other (sphere-sphere, sphere-box, capsule ends; box-box corner-on-face only)")
        self.label = (
            f"body contacts: {self.count} {'/'.join(kinds)} bodies against {', '.join(parts)}; "
            f"impulses with restitution and Coulomb friction, {iterations} sweeps, resting below "
            f"{RESTING_FACTOR:g}x the speed forces add per step, positions projected out"
        )

    @property
    def left_out(self) -> list[str]:
        """What body contacts do not simulate (for explain)."""
        out = []
        if self.between_bodies and int((self.kind == SHAPE_BOX).sum()) > 1:
            out.append("box-box edge-on-edge contact (only corners against faces are detected)")
        if self.between_bodies and int((self.kind == SHAPE_CAPSULE).sum()) > 1:
            out.append("capsule-capsule side-on-side contact (only end spheres are detected)")
        return out

    def reset(self, state: Any) -> None:
        self._built_at = None
        self._candidates = None

    def apply(
        self, state: Any, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float, dt: float = 0.0
    ) -> bool:
        rows = slice(self.first, self.first + self.count)
        x = state.particle_position[rows]
        v = state.particle_velocity[rows]
        q = state.body_orientation
        w = state.body_angular_velocity
        dv = v - v_old[rows]
        dx = x - x_old[rows]
        resting = RESTING_FACTOR * np.linalg.norm(dv, axis=1)
        pairs = self.find_pairs(x, q)
        if self.use_numba:
            # bodies touching each other are solved together on the NumPy path (as on the NumPy
            # backend); every other body on its own in the numba kernel
            skip = np.zeros(self.count, dtype=bool)
            skip[pairs.a] = True
            skip[pairs.b] = True
            kernel = numba_plane_solver()
            xc, vc = np.ascontiguousarray(x), np.ascontiguousarray(v)
            n = kernel(
                xc,
                vc,
                q,
                w,
                self.inv_mass,
                self.inv_inertia,
                self.points,
                self.radii,
                self.counts,
                self.planes.point,
                self.planes.normal,
                self.planes.restitution,
                self.planes.friction,
                resting,
                self.iterations,
                np.ascontiguousarray(dv),
                np.ascontiguousarray(dx),
                skip,
            )
            if n:
                state.particle_position[rows] = xc
                state.particle_velocity[rows] = vc
            if pairs.count == 0:
                return bool(n)
            x, v = state.particle_position[rows], state.particle_velocity[rows]
            contacts = _select(self.find(x, q, pairs), skip)
            changed = bool(n)
        else:
            contacts = self.find(x, q, pairs)
            changed = False
        if contacts.count == 0:
            return changed
        e_used = solve(contacts, v, w, q, self.inv_mass, self.inv_inertia, resting, self.iterations, dv, dx)
        project(contacts, e_used, x, self.inv_mass)
        state.particle_position[rows] = x
        state.particle_velocity[rows] = v
        return True

    def find(self, x: np.ndarray, q: np.ndarray, pairs: Contacts | None = None) -> Contacts:
        """Every contact of the bodies at x, q: planes, then colliders, then pairs."""
        parts = []
        if self.planes.count:
            parts.append(plane_contacts(x, q, self.points, self.radii, self.valid, self.planes))
        for sdf, e, mu in self.colliders:
            parts.append(sdf_contacts(x, q, self.points, self.radii, self.valid, sdf, e, mu))
        parts.append(self.find_pairs(x, q) if pairs is None else pairs)
        return _concat(parts)

    def find_pairs(self, x: np.ndarray, q: np.ndarray) -> Contacts:
        """Contacts between bodies (none when the scene has one body)."""
        if not self.between_bodies:
            return _empty_contacts()
        moved = np.inf if self._built_at is None else float(np.abs(x - self._built_at).max(initial=0.0))
        if not moved <= 0.5 * self._skin / math.sqrt(3.0):  # a NaN position rebuilds too
            self._candidates = candidate_pairs(x, self.bound + 0.5 * self._skin)
            self._built_at = x.copy()
        if self._candidates[0].size == 0:
            return _empty_contacts()
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
            self._candidates,
        )
