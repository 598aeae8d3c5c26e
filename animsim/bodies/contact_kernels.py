"""The numba twins of rigid-body contacts (compiled on first use; same operations in the same
order as the NumPy versions, so the backends agree to the bit): the candidate pairs by sweep
and prune, the contacts between bodies, the plane contacts body by body, and the list solver
(sequential impulses after Baraff 1997, section 8, and Catto 2005, then the bodies moved by
the impulses). Each ``_..._loop`` is plain Python over arrays; a ``numba_*`` factory compiles it.
The list solver's pieces are ``@numba_helper`` functions of this module, compiled before it
(they live here: numba's disk cache checks only the file of the function it cached, so a
helper in another file could be left stale in the cache after an edit). That is why this
module is longer than the house's 600 lines: every kernel of the rigid-body contacts and
every piece they call share it.

Their NumPy versions: :mod:`animsim.bodies.contact_detection` (:func:`candidate_pairs`,
:func:`pair_contacts`, :func:`plane_contacts`) and :mod:`animsim.bodies.contact_solve`
(:func:`solve`) and :mod:`animsim.bodies.contact_follow` (:func:`follow_impulses`). The model
as a whole is described in :mod:`animsim.bodies.contacts`.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

from animsim.bodies import box_box
from animsim.bodies.box_box import box_box as box_box_contacts
from animsim.bodies.contact_constants import (
    IMPACT_SWEEPS,
    MAX_BOX_POINTS,
    RESTING_FLOOR,
    SHAPE_BOX,
    SHAPE_CAPSULE,
    SHOCK_SWEEPS,
    SWEEP_TOLERANCE,
)
from animsim.bodies.quaternion import rotate_scalar
from animsim.collisions import kept_end_speed
from animsim.elements import compile_helpers, numba_helper, numba_inline_helper


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


@numba_inline_helper
def _target_sdf(
    kind: int, d0: float, d1: float, d2: float, lx: float, ly: float, lz: float
) -> tuple[float, float, float, float]:
    """Signed distance and outward normal at (lx, ly, lz) in a body's own frame, from its shape
    (``kind``) and dimensions (half sizes of a box; radius and half length of a capsule;
    radius of a sphere): :func:`animsim.bodies.contact_detection.local_sdf`, one point."""
    if kind == SHAPE_BOX:
        q0 = abs(lx) - d0
        q1 = abs(ly) - d1
        q2 = abs(lz) - d2
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
        half = d1 if kind == SHAPE_CAPSULE else 0.0
        r0 = lx - 0.0
        r1 = ly - min(max(ly, -half), half)
        r2 = lz - 0.0
        dist = np.sqrt((r0 * r0 + r1 * r1) + r2 * r2)
        d = dist - d0
        if dist > 0:
            nx, ny, nz = r0 / dist, r1 / dist, r2 / dist
        else:
            nx, ny, nz = 0.0, 1.0, 0.0
    return d, nx, ny, nz


@numba_inline_helper
def _emit(
    c: int,
    a: int,
    b: int,
    px: float,
    py: float,
    pz: float,
    nx: float,
    ny: float,
    nz: float,
    depth: float,
    x: np.ndarray,
    restitution: np.ndarray,
    friction: np.ndarray,
    out_i: np.ndarray,
    out_v: np.ndarray,
    out_s: np.ndarray,
) -> None:
    """Write contact ``c`` of :func:`_pair_contacts_loop`: bodies a and b, the point p (its
    arms from both centres), the normal n, the depth, the mean restitution and the geometric
    mean of the frictions (pair_contacts' rules)."""
    out_i[0, c], out_i[1, c] = a, b
    out_v[0, c, 0], out_v[0, c, 1], out_v[0, c, 2] = px - x[a, 0], py - x[a, 1], pz - x[a, 2]
    out_v[1, c, 0], out_v[1, c, 1], out_v[1, c, 2] = px - x[b, 0], py - x[b, 1], pz - x[b, 2]
    out_v[2, c, 0], out_v[2, c, 1], out_v[2, c, 2] = nx, ny, nz
    out_s[0, c] = depth
    out_s[1, c] = 0.5 * (restitution[a] + restitution[b])
    out_s[2, c] = pair_coefficient(friction[a], friction[b])


@numba_inline_helper
def pair_coefficient(mu_a: Any, mu_b: Any) -> Any:
    """The coefficient of a contact between two bodies from theirs, the geometric mean
    sqrt(mu_a mu_b) (Coulomb friction and rolling resistance alike): one body with 0 makes the
    pair's 0. One number each in the kernels, or arrays of them on NumPy."""
    return np.sqrt(mu_a * mu_b)


@numba_inline_helper
def rolling_total(
    w0: Any,
    w1: Any,
    w2: Any,
    n0: Any,
    n1: Any,
    n2: Any,
    k0: Any,
    k1: Any,
    k2: Any,
    k3: Any,
    k4: Any,
    k5: Any,
    j0: Any,
    j1: Any,
    j2: Any,
    cap: Any,
) -> tuple[Any, Any, Any]:
    """A contact's new total rolling impulse (an angular impulse, N m s): its old one (j0, j1,
    j2) plus the one that stops the relative turning tangential to the normal n (w minus its
    part along n), held inside ``cap`` = mu_r times the normal impulse.

    Rolling resistance as Bullet's sequential-impulse solver has it
    (``btSequentialImpulseConstraintSolver``: angular-only rows per contact, each limited to
    +-mu_r times the contact's normal impulse) and MuJoCo's condim 6 (the rolling rows of the
    contact's friction cone), solved as the Coulomb friction here is (Catto 2005): the angular
    impulse that stops the tangential relative angular velocity t is -t |t|^2 / (t . K t),
    K = I_a^-1 + I_b^-1 in world axes (``k0..k5``, the rows (k00, k01, k02, k11, k12, k22));
    the total is kept in the disc |L| <= mu_r j_n, as the tangential impulse is kept in
    mu j_n (Bullet clamps its two rolling rows one by one, a square, so its resistance depends
    on the direction of rolling; the disc does not). Only the turning about axes in the
    contact's plane is resisted (rolling); the spin about n is left free.

    The one rule of both backends: each kernel calls it with one contact's numbers, the NumPy
    solver with arrays of a batch's; written without branches (comparisons as 0 or 1) so that
    the two do the same operations. Here rather than in the NumPy module, for numba's disk cache
    (module docstring)."""
    wn = (w0 * n0 + w1 * n1) + w2 * n2
    t0, t1, t2 = w0 - wn * n0, w1 - wn * n1, w2 - wn * n2
    s2 = (t0 * t0 + t1 * t1) + t2 * t2
    kq = (t0 * ((k0 * t0 + k1 * t1) + k2 * t2) + t1 * ((k1 * t0 + k3 * t1) + k4 * t2)) + t2 * (
        (k2 * t0 + k4 * t1) + k5 * t2
    )
    # s2 / kq where kq > 0 (no turning, or two immovable ends: nothing to stop)
    f = (s2 * (kq > 0.0)) / (kq + (kq <= 0.0))
    u0, u1, u2 = j0 - f * t0, j1 - f * t1, j2 - f * t2
    mag2 = (u0 * u0 + u1 * u1) + u2 * u2
    # scaled back onto the disc |L| <= cap (cap / |u| >= 1 inside it: left as it is)
    scale = np.minimum(1.0, cap / np.sqrt(mag2 + (mag2 <= 0.0)))
    return u0 * scale, u1 * scale, u2 * scale


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
    out_i = np.empty((2, cap), dtype=np.int64)  # a, b
    out_v = np.empty((3, cap, 3))  # ra, rb, n
    out_s = np.empty((3, cap))  # depth, e, mu
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
                    _emit(
                        c, j, i, box_points[m, 0], box_points[m, 1], box_points[m, 2],
                        box_normal[0], box_normal[1], box_normal[2], box_depth[m],
                        x, restitution, friction, out_i, out_v, out_s,
                    )  # fmt: skip
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
                d, nx, ny, nz = _target_sdf(kind[dst], dims[dst, 0], dims[dst, 1], dims[dst, 2], lx, ly, lz)
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
                _emit(
                    c, src, dst, px_, py_, pz_, wx, wy, wz, -d, x, restitution, friction, out_i, out_v, out_s
                )
                c += 1
    return (
        out_i[0, :c],
        out_i[1, :c],
        out_v[0, :c],
        out_v[1, :c],
        out_v[2, :c],
        out_s[0, :c],
        out_s[1, :c],
        out_s[2, :c],
    )


@cache
def numba_pair_contacts() -> Any:
    """:func:`_pair_contacts_loop` compiled by numba."""
    from numba import njit

    compile_helpers(vars(box_box))
    compile_helpers(globals())
    return njit(cache=True)(_pair_contacts_loop)


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


@numba_inline_helper
def _world_inverse_inertia(
    q: np.ndarray, inv_inertia: np.ndarray, body: int, mat: np.ndarray, i: int, o: int
) -> None:
    """I^-1 in world axes, R diag(I^-1) R^T of ``body``: its 6 entries into ``mat[i, o:o + 6]``."""
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


@numba_inline_helper
def _arm_inertia(
    i: int,
    side: int,
    rx: float,
    ry: float,
    rz: float,
    mat: np.ndarray,
    gm: np.ndarray,
    kt6: np.ndarray,
    cols: np.ndarray,
    mc: np.ndarray,
) -> None:
    """G = I^-1 [r]x of one end column by column into ``gm``, K = [r]x^T I^-1 [r]x into ``kt6``
    (the first end sets it, the second adds to it). K_ij = c_i . M c_j, c_j the columns of [r]x
    (as contact_algebra.arm_inertia)."""
    o = 6 * side
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


@numba_helper
def _contact_inertia(
    i: int,
    a: np.ndarray,
    b: np.ndarray,
    ra: np.ndarray,
    rb: np.ndarray,
    q: np.ndarray,
    inv_inertia: np.ndarray,
    mat: np.ndarray,
    gm: np.ndarray,
    kt6: np.ndarray,
    cols: np.ndarray,
    mc: np.ndarray,
) -> None:
    """Contact ``i``'s world inverse inertias (``mat``) and arm inertias (``gm``, ``kt6``), end a
    then end b (zeros for a plane's missing end)."""
    for side in range(2):
        body = a[i] if side == 0 else b[i]
        o = 6 * side
        if body < 0:
            for k in range(6):
                mat[i, o + k] = 0.0
            continue
        _world_inverse_inertia(q, inv_inertia, body, mat, i, o)
        if side == 0:
            rx, ry, rz = ra[i, 0], ra[i, 1], ra[i, 2]
        else:
            rx, ry, rz = rb[i, 0], rb[i, 1], rb[i, 2]
        _arm_inertia(i, side, rx, ry, rz, mat, gm, kt6, cols, mc)


@numba_inline_helper
def _arm_normal(
    i: int, o: int, rx: float, ry: float, rz: float, n: np.ndarray, mat: np.ndarray, g: np.ndarray
) -> float:
    """u = r x n and I^-1 u of one end into ``g[i, o:o + 6]``; returns u . I^-1 u."""
    nx, ny, nz = n[i, 0], n[i, 1], n[i, 2]
    m0, m1, m2, m3, m4, m5 = (
        mat[i, o],
        mat[i, o + 1],
        mat[i, o + 2],
        mat[i, o + 3],
        mat[i, o + 4],
        mat[i, o + 5],
    )
    ux, uy, uz = ry * nz - rz * ny, rz * nx - rx * nz, rx * ny - ry * nx
    gx = (m0 * ux + m1 * uy) + m2 * uz
    gy = (m1 * ux + m3 * uy) + m4 * uz
    gz = (m2 * ux + m4 * uy) + m5 * uz
    g[i, o], g[i, o + 1], g[i, o + 2], g[i, o + 3], g[i, o + 4], g[i, o + 5] = ux, uy, uz, gx, gy, gz
    return (ux * gx + uy * gy) + uz * gz


@numba_helper
def _contact_masses(
    i: int,
    a: np.ndarray,
    b: np.ndarray,
    ra: np.ndarray,
    rb: np.ndarray,
    n: np.ndarray,
    inv_mass: np.ndarray,
    resting_speed: np.ndarray,
    dv: np.ndarray,
    dx: np.ndarray,
    mat: np.ndarray,
    g: np.ndarray,
    inv_kn: np.ndarray,
    ma: np.ndarray,
    mb: np.ndarray,
    mt: np.ndarray,
    limit: np.ndarray,
    dvn_all: np.ndarray,
    dxn_all: np.ndarray,
) -> None:
    """Contact ``i``'s effective masses (``inv_kn``, ``ma``, ``mb``, ``mt``), its resting speed
    (``limit``) and what the step's forces added along n and moved along n (``dvn_all``,
    ``dxn_all``)."""
    ai, bi = a[i], b[i]
    nx, ny, nz = n[i, 0], n[i, 1], n[i, 2]
    da = _arm_normal(i, 0, ra[i, 0], ra[i, 1], ra[i, 2], n, mat, g)
    ma[i] = inv_mass[ai]
    rest = resting_speed[ai]
    dvx, dvy, dvz = dv[ai, 0], dv[ai, 1], dv[ai, 2]
    dxx, dxy, dxz = dx[ai, 0], dx[ai, 1], dx[ai, 2]
    if bi >= 0:
        db = _arm_normal(i, 6, rb[i, 0], rb[i, 1], rb[i, 2], n, mat, g)
        mb[i] = inv_mass[bi]
        kn = (ma[i] + mb[i]) + (da + db)
        mt[i] = ma[i] + mb[i]
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
    limit[i] = rest + RESTING_FLOOR
    dvn_all[i] = (dvx * nx + dvy * ny) + dvz * nz
    dxn_all[i] = (dxx * nx + dxy * ny) + dxz * nz


@numba_inline_helper
def _normal_speed(
    i: int, ai: int, bi: int, n: np.ndarray, g: np.ndarray, v: np.ndarray, w: np.ndarray
) -> float:
    """Contact ``i``'s approach speed along n, a's minus b's (b < 0: a plane, at rest)."""
    nx, ny, nz = n[i, 0], n[i, 1], n[i, 2]
    vn = (v[ai, 0] * nx + v[ai, 1] * ny) + v[ai, 2] * nz
    vn = vn + ((w[ai, 0] * g[i, 0] + w[ai, 1] * g[i, 1]) + w[ai, 2] * g[i, 2])
    if bi >= 0:
        vnb = (v[bi, 0] * nx + v[bi, 1] * ny) + v[bi, 2] * nz
        vnb = vnb + ((w[bi, 0] * g[i, 6] + w[bi, 1] * g[i, 7]) + w[bi, 2] * g[i, 8])
        vn = vn - vnb
    return vn


@numba_inline_helper
def _relative_velocity(
    i: int, ai: int, bi: int, ra: np.ndarray, rb: np.ndarray, v: np.ndarray, w: np.ndarray
) -> tuple[float, float, float]:
    """Contact ``i``'s velocity at the contact point, a's minus b's (b < 0: a plane, at rest)."""
    ax, ay, az = ra[i, 0], ra[i, 1], ra[i, 2]
    vx = v[ai, 0] + (w[ai, 1] * az - w[ai, 2] * ay)
    vy = v[ai, 1] + (w[ai, 2] * ax - w[ai, 0] * az)
    vz = v[ai, 2] + (w[ai, 0] * ay - w[ai, 1] * ax)
    if bi >= 0:
        bx, by, bz = rb[i, 0], rb[i, 1], rb[i, 2]
        vx = vx - (v[bi, 0] + (w[bi, 1] * bz - w[bi, 2] * by))
        vy = vy - (v[bi, 1] + (w[bi, 2] * bx - w[bi, 0] * bz))
        vz = vz - (v[bi, 2] + (w[bi, 0] * by - w[bi, 1] * bx))
    return vx, vy, vz


@numba_inline_helper
def _push_normal(
    i: int,
    ai: int,
    bi: int,
    dj: float,
    ma: np.ndarray,
    mb: np.ndarray,
    n: np.ndarray,
    g: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
) -> None:
    """The normal impulse ``dj`` of contact ``i`` applied to a, its opposite to b."""
    s = ma[i] * dj
    v[ai, 0] += s * n[i, 0]
    v[ai, 1] += s * n[i, 1]
    v[ai, 2] += s * n[i, 2]
    w[ai, 0] += dj * g[i, 3]
    w[ai, 1] += dj * g[i, 4]
    w[ai, 2] += dj * g[i, 5]
    if bi >= 0:
        s = mb[i] * dj
        v[bi, 0] -= s * n[i, 0]
        v[bi, 1] -= s * n[i, 1]
        v[bi, 2] -= s * n[i, 2]
        w[bi, 0] -= dj * g[i, 9]
        w[bi, 1] -= dj * g[i, 10]
        w[bi, 2] -= dj * g[i, 11]


@numba_inline_helper
def _push_friction(
    i: int,
    ai: int,
    bi: int,
    ix: float,
    iy: float,
    iz: float,
    ma: np.ndarray,
    mb: np.ndarray,
    gm: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
) -> None:
    """The friction impulse (ix, iy, iz) of contact ``i`` applied to a, its opposite to b:
    w += I^-1 (r x imp) = sum_j G_j imp_j."""
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


@numba_helper
def _single_points(count: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per contact: its two bodies touch at no other point of the list (keys as solve's
    _impact_pass: a (max b + 1) + b, a distinct negative for a contact with no second body)."""
    top = 0
    for i in range(count):
        top = max(top, b[i])
    keys = np.empty(count, dtype=np.int64)
    for i in range(count):
        keys[i] = a[i] * (top + 1) + b[i] if b[i] >= 0 else -1 - i
    srt = np.argsort(keys)
    single = np.ones(count, dtype=np.bool_)
    for m in range(1, count):
        if keys[srt[m]] == keys[srt[m - 1]]:
            single[srt[m]] = False
            single[srt[m - 1]] = False
    return single


@numba_helper
def _impact_pass(
    count: int,
    a: np.ndarray,
    b: np.ndarray,
    n: np.ndarray,
    depth: np.ndarray,
    restitution: np.ndarray,
    dt: float,
    v: np.ndarray,
    w: np.ndarray,
    g: np.ndarray,
    ma: np.ndarray,
    mb: np.ndarray,
    inv_kn: np.ndarray,
    limit: np.ndarray,
    struck: np.ndarray,
) -> None:
    """Impacts between bodies first, one contact at a time, sweeping back and forth until none
    is left (solve's _impact_pass); marks the contacts struck in ``struck``. Only a contact
    that is its two bodies' one point of contact takes part (a face or an edge held at several
    points is left to the simultaneous solve)."""
    for i in range(count):
        struck[i] = False
    single = _single_points(count, a, b)
    for sweep in range(IMPACT_SWEEPS):
        hit = False
        for m in range(count):
            i = m if sweep % 2 == 0 else count - 1 - m
            ai, bi = a[i], b[i]
            if bi < 0 or not single[i] or not restitution[i] > 0.0 or not inv_kn[i] > 0.0:
                continue
            vn = _normal_speed(i, ai, bi, n, g, v, w)
            if not (vn < -limit[i] and (depth[i] >= 0.0 or depth[i] - vn * dt >= 0.0)):
                continue
            hit = True
            struck[i] = True
            dj = -(1.0 + restitution[i]) * vn * inv_kn[i]
            _push_normal(i, ai, bi, dj, ma, mb, n, g, v, w)
        if not hit:
            break


@numba_inline_helper
def _impact_target(vn0: float, depth: float, dvn: float, dxn: float, e: float, kh: float, dt: float) -> float:
    """The speed along n an impact leaves with, from the time of impact inside the step (as
    _impact_target)."""
    d0 = -dxn - depth
    span = d0 + depth
    s = d0 / span if span > 0 else 0.0
    s = min(max(s, 0.0), 1.0)
    vn_imp = vn0 - (1.0 - s) * dvn
    tgt = max(-e * vn_imp + (1.0 - s) * dvn, 0.0)
    if kh != 0.0 and e > 0.0:
        kept = kept_end_speed(vn0 - dvn, max(d0, 0.0), dvn / dt, e * depth, e, kh)
        if kept > 0.0:
            tgt = kept
    return tgt


@numba_helper
def _bounce_targets(
    count: int,
    a: np.ndarray,
    b: np.ndarray,
    ra: np.ndarray,
    rb: np.ndarray,
    n: np.ndarray,
    depth: np.ndarray,
    restitution: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
    limit: np.ndarray,
    struck: np.ndarray,
    dvn_all: np.ndarray,
    dxn_all: np.ndarray,
    kh: float,
    dt: float,
    e_used: np.ndarray,
    impact: np.ndarray,
    tgt: np.ndarray,
) -> None:
    """Each contact's target speed along n (``tgt``), the restitution it used (``e_used``) and
    whether it is an impact (``impact``)."""
    for i in range(count):
        nx, ny, nz = n[i, 0], n[i, 1], n[i, 2]
        vx, vy, vz = _relative_velocity(i, a[i], b[i], ra, rb, v, w)
        vn0 = (vx * nx + vy * ny) + vz * nz
        if vn0 < -limit[i] and depth[i] >= 0.0:
            e = restitution[i]
            e_used[i] = e
            impact[i] = True
            tgt[i] = _impact_target(vn0, depth[i], dvn_all[i], dxn_all[i], e, kh, dt)
        else:
            e_used[i] = restitution[i] if struck[i] else 0.0
            impact[i] = struck[i]
            tgt[i] = min(depth[i], 0.0) / dt  # a speculative contact may close its gap


@numba_helper
def _warm_start(
    count: int,
    a: np.ndarray,
    b: np.ndarray,
    n: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
    g: np.ndarray,
    gm: np.ndarray,
    ma: np.ndarray,
    mb: np.ndarray,
    impact: np.ndarray,
    jn: np.ndarray,
    jt: np.ndarray,
    jr: np.ndarray,
    mat: np.ndarray,
) -> None:
    """Warm start (solve's _apply_warm): the impulses each contact starts from (none on an
    impact), normal impulse on a, on b, then friction on a, on b, then rolling on a, on b."""
    for i in range(count):
        if impact[i]:
            jn[i] = 0.0
            jt[i, 0], jt[i, 1], jt[i, 2] = 0.0, 0.0, 0.0
            jr[i, 0], jr[i, 1], jr[i, 2] = 0.0, 0.0, 0.0
        dj = jn[i]
        ix, iy, iz = jt[i, 0], jt[i, 1], jt[i, 2]
        if dj == 0.0 and ix == 0.0 and iy == 0.0 and iz == 0.0:
            continue
        _push_normal(i, a[i], b[i], dj, ma, mb, n, g, v, w)
        _push_friction(i, a[i], b[i], ix, iy, iz, ma, mb, gm, v, w)
        if jr[i, 0] != 0.0 or jr[i, 1] != 0.0 or jr[i, 2] != 0.0:
            _push_rolling(i, a[i], b[i], jr[i, 0], jr[i, 1], jr[i, 2], mat, w)


@numba_inline_helper
def _friction_total(
    i: int,
    vx: float,
    vy: float,
    vz: float,
    n: np.ndarray,
    kt6: np.ndarray,
    mt: np.ndarray,
    friction: np.ndarray,
    jn: np.ndarray,
    jt: np.ndarray,
) -> tuple[float, float, float]:
    """Contact ``i``'s new total friction impulse: its old one plus what stops the sliding
    velocity (vx, vy, vz minus its part along n), held inside the cone of ``friction`` times the
    normal impulse."""
    nx, ny, nz = n[i, 0], n[i, 1], n[i, 2]
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
    return wx, wy, wz


@numba_inline_helper
def _push_rolling(
    i: int, ai: int, bi: int, ix: float, iy: float, iz: float, mat: np.ndarray, w: np.ndarray
) -> None:
    """The rolling impulse (ix, iy, iz) of contact ``i`` applied to a, its opposite to b:
    w += I^-1 L (``mat[i]``: I_a^-1 then I_b^-1, rows (m00, m01, m02, m11, m12, m22))."""
    w[ai, 0] += (mat[i, 0] * ix + mat[i, 1] * iy) + mat[i, 2] * iz
    w[ai, 1] += (mat[i, 1] * ix + mat[i, 3] * iy) + mat[i, 4] * iz
    w[ai, 2] += (mat[i, 2] * ix + mat[i, 4] * iy) + mat[i, 5] * iz
    if bi >= 0:
        w[bi, 0] -= (mat[i, 6] * ix + mat[i, 7] * iy) + mat[i, 8] * iz
        w[bi, 1] -= (mat[i, 7] * ix + mat[i, 9] * iy) + mat[i, 10] * iz
        w[bi, 2] -= (mat[i, 8] * ix + mat[i, 10] * iy) + mat[i, 11] * iz


@numba_inline_helper
def _rolling_row(
    i: int,
    ai: int,
    bi: int,
    n: np.ndarray,
    ra: np.ndarray,
    rolling: np.ndarray,
    jr: np.ndarray,
    mat: np.ndarray,
    jn: np.ndarray,
    w: np.ndarray,
) -> float:
    """Contact ``i``'s rolling impulse (:func:`rolling_total`, solve's _rolling_impulse) from
    the angular velocities now, applied; returns its change as a velocity at the contact point,
    tr(K) |r_a| times the change's largest component."""
    w0, w1, w2 = w[ai, 0], w[ai, 1], w[ai, 2]
    if bi >= 0:
        w0, w1, w2 = w0 - w[bi, 0], w1 - w[bi, 1], w2 - w[bi, 2]
    k0, k1, k2 = mat[i, 0] + mat[i, 6], mat[i, 1] + mat[i, 7], mat[i, 2] + mat[i, 8]
    k3, k4, k5 = mat[i, 3] + mat[i, 9], mat[i, 4] + mat[i, 10], mat[i, 5] + mat[i, 11]
    u0, u1, u2 = rolling_total(
        w0, w1, w2, n[i, 0], n[i, 1], n[i, 2], k0, k1, k2, k3, k4, k5,
        jr[i, 0], jr[i, 1], jr[i, 2], rolling[i] * jn[i],
    )  # fmt: skip
    ix, iy, iz = u0 - jr[i, 0], u1 - jr[i, 1], u2 - jr[i, 2]
    jr[i, 0], jr[i, 1], jr[i, 2] = u0, u1, u2
    _push_rolling(i, ai, bi, ix, iy, iz, mat, w)
    arm = np.sqrt((ra[i, 0] * ra[i, 0] + ra[i, 1] * ra[i, 1]) + ra[i, 2] * ra[i, 2])
    rate = ((k0 + k3) + k5) * arm
    return rate * max(abs(ix), max(abs(iy), abs(iz)))


@numba_helper
def _sweep(
    count: int,
    a: np.ndarray,
    b: np.ndarray,
    ra: np.ndarray,
    rb: np.ndarray,
    n: np.ndarray,
    friction: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
    g: np.ndarray,
    gm: np.ndarray,
    kt6: np.ndarray,
    inv_kn: np.ndarray,
    ma: np.ndarray,
    mb: np.ndarray,
    mt: np.ndarray,
    tgt: np.ndarray,
    jn: np.ndarray,
    jt: np.ndarray,
    island: np.ndarray,
    live: np.ndarray,
    change: np.ndarray,
    roll: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> None:
    """One sweep of the sequential impulses: each contact's normal impulse toward its target,
    then its friction, then its rolling impulse (``roll``: mu_r (C,), the rolling impulses
    (C, 3), the inverse inertias (C, 12); where mu_r > 0); contacts of an island no longer
    ``live`` are passed over. Each island's largest change (mass times impulse) of the sweep
    goes into ``change``."""
    rolling, jr, mat = roll
    for i in range(count):
        k = island[i]
        if not live[k]:
            continue
        ai, bi = a[i], b[i]
        vn = _normal_speed(i, ai, bi, n, g, v, w)
        new = jn[i] + (tgt[i] - vn) * inv_kn[i]
        if new < 0.0:
            new = 0.0
        dj = new - jn[i]
        jn[i] = new
        _push_normal(i, ai, bi, dj, ma, mb, n, g, v, w)
        # friction
        vx, vy, vz = _relative_velocity(i, ai, bi, ra, rb, v, w)
        wx, wy, wz = _friction_total(i, vx, vy, vz, n, kt6, mt, friction, jn, jt)
        ix, iy, iz = wx - jt[i, 0], wy - jt[i, 1], wz - jt[i, 2]
        jt[i, 0], jt[i, 1], jt[i, 2] = wx, wy, wz
        big = max(abs(dj), max(abs(ix), max(abs(iy), abs(iz))))
        change[k] = max(change[k], mt[i] * big)
        _push_friction(i, ai, bi, ix, iy, iz, ma, mb, gm, v, w)
        if rolling[i] > 0.0:
            change[k] = max(change[k], _rolling_row(i, ai, bi, n, ra, rolling, jr, mat, jn, w))


@numba_helper
def _sweeps(
    count: int,
    a: np.ndarray,
    b: np.ndarray,
    ra: np.ndarray,
    rb: np.ndarray,
    n: np.ndarray,
    friction: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
    g: np.ndarray,
    gm: np.ndarray,
    kt6: np.ndarray,
    inv_kn: np.ndarray,
    ma: np.ndarray,
    mb: np.ndarray,
    mt: np.ndarray,
    tgt: np.ndarray,
    jn: np.ndarray,
    jt: np.ndarray,
    least: int,
    most: int,
    island: np.ndarray,
    roll: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> None:
    """Sweeps, at least ``least``, then until one changes no velocity by more than
    SWEEP_TOLERANCE, at most ``most``, island by island (``island`` (C,); solve's _sweeps);
    ``roll`` as :func:`_sweep`'s."""
    size = 0
    for i in range(count):
        size = max(size, island[i] + 1)
    live = np.ones(size, dtype=np.bool_)
    change = np.empty(size)
    for sweep in range(max(least, most)):
        change[:] = 0.0
        _sweep(
            count, a, b, ra, rb, n, friction, v, w, g, gm, kt6, inv_kn, ma, mb, mt, tgt, jn, jt, island, live, change,
            roll,
        )  # fmt: skip
        if sweep + 1 >= least:
            left = False
            for k in range(size):
                live[k] = live[k] and change[k] > SWEEP_TOLERANCE
                left = left or live[k]
            if not left:
                break


@numba_helper
def _shock_pass(
    count: int,
    a: np.ndarray,
    b: np.ndarray,
    ra: np.ndarray,
    rb: np.ndarray,
    n: np.ndarray,
    depth: np.ndarray,
    friction: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
    body: tuple[np.ndarray, np.ndarray, np.ndarray],
    forces: tuple[np.ndarray, np.ndarray, np.ndarray],
    dt: float,
    impact: np.ndarray,
    level: np.ndarray,
    island: np.ndarray,
    jn: np.ndarray,
    jt: np.ndarray,
    rolling: np.ndarray,
    jr: np.ndarray,
) -> None:
    """Twin of :func:`animsim.bodies.contact_shock.shock_pass`: level by level from level 1 up,
    that level's contacts (no impacts; in list order) swept with the bodies below held still.
    ``body``: (q, inverse masses, inverse inertias); ``forces``: (resting speeds, dv, dx) as
    the solve's; ``rolling`` (C,), ``jr`` (C, 3): rolling resistances and impulses."""
    q, inv_mass, inv_inertia = body
    rest, dv, dx = forces
    nb = inv_mass.shape[0]
    up = np.empty(count, dtype=np.int64)
    top = -1
    for i in range(count):
        up[i] = level[a[i]] if b[i] < 0 else max(level[a[i]], level[b[i]])
        if impact[i] or up[i] == 0 or up[i] >= nb:
            up[i] = -1
        top = max(top, up[i])
    im = np.empty(nb)
    ii = np.empty((nb, 3))
    for lv in range(top + 1):
        sel = np.flatnonzero(up == lv)
        k = sel.size
        if k == 0:
            continue
        for bi in range(nb):
            still = level[bi] < lv
            im[bi] = 0.0 if still else inv_mass[bi]
            for m in range(3):
                ii[bi, m] = 0.0 if still else inv_inertia[bi, m]
        sa, sb, sra, srb, sn = a[sel], b[sel], ra[sel], rb[sel], n[sel]
        sjn, sjt, sjr = jn[sel], jt[sel], jr[sel]
        mat, g, gm, kt6 = np.empty((k, 12)), np.empty((k, 12)), np.zeros((k, 18)), np.zeros((k, 6))
        inv_kn, ma, mb, mt, tgt = np.empty(k), np.empty(k), np.empty(k), np.empty(k), np.empty(k)
        limit, dvn, dxn = np.empty(k), np.empty(k), np.empty(k)
        cols, mc = np.empty((3, 3)), np.empty((3, 3))
        for i in range(k):
            _contact_inertia(i, sa, sb, sra, srb, q, ii, mat, gm, kt6, cols, mc)
            _contact_masses(
                i, sa, sb, sra, srb, sn, im, rest, dv, dx, mat, g, inv_kn, ma, mb, mt, limit, dvn, dxn
            )
            tgt[i] = min(depth[sel[i]], 0.0) / dt  # resting or speculative (as _bounce_targets)
        fr = friction[sel]
        _sweeps(
            k, sa, sb, sra, srb, sn, fr, v, w, g, gm, kt6, inv_kn, ma, mb, mt, tgt, sjn, sjt, 1, SHOCK_SWEEPS,
            island[sel], (rolling[sel], sjr, mat),
        )  # fmt: skip
        for i in range(k):
            jn[sel[i]] = sjn[i]
            for m in range(3):
                jt[sel[i], m] = sjt[i, m]
                jr[sel[i], m] = sjr[i, m]


@numba_inline_helper
def _arm_move(i: int, body: int, r: np.ndarray, n: np.ndarray, sx: np.ndarray, sw: np.ndarray) -> float:
    """How far the point ``r[i]`` of ``body`` moved along contact ``i``'s n (sx + sw x r)."""
    px = sx[body, 0] + (sw[body, 1] * r[i, 2] - sw[body, 2] * r[i, 1])
    py = sx[body, 1] + (sw[body, 2] * r[i, 0] - sw[body, 0] * r[i, 2])
    pz = sx[body, 2] + (sw[body, 0] * r[i, 1] - sw[body, 1] * r[i, 0])
    return (px * n[i, 0] + py * n[i, 1]) + pz * n[i, 2]


@numba_inline_helper
def _turn(q: np.ndarray, bi: int, wx: float, wy: float, wz: float) -> None:
    """``q[bi]`` turned by the small rotation (wx, wy, wz), renormalised."""
    qw, qx, qy, qz = q[bi, 0], q[bi, 1], q[bi, 2], q[bi, 3]
    q0 = qw + 0.5 * ((-wx * qx - wy * qy) - wz * qz)
    q1 = qx + 0.5 * ((wx * qw + wy * qz) - wz * qy)
    q2 = qy + 0.5 * ((-wx * qz + wy * qw) + wz * qx)
    q3 = qz + 0.5 * ((wx * qy - wy * qx) + wz * qw)
    norm = np.sqrt(((q0 * q0 + q1 * q1) + q2 * q2) + q3 * q3)
    q[bi, 0], q[bi, 1], q[bi, 2], q[bi, 3] = q0 / norm, q1 / norm, q2 / norm, q3 / norm


@numba_helper
def _follow_impulses(
    count: int,
    a: np.ndarray,
    b: np.ndarray,
    ra: np.ndarray,
    rb: np.ndarray,
    n: np.ndarray,
    depth: np.ndarray,
    impact: np.ndarray,
    x: np.ndarray,
    q: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
    v0: np.ndarray,
    w0: np.ndarray,
    h: float,
    depth_out: np.ndarray,
) -> None:
    """The bodies moved as the impulses moved them (follow_impulses; when h > 0): each body not
    in an impact by h times its change of velocity, the depths left into ``depth_out``."""
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
            mv = _arm_move(i, a[i], ra, n, sx, sw)
            if b[i] >= 0:
                mv = mv - _arm_move(i, b[i], rb, n, sx, sw)
            depth_out[i] = depth[i] - mv
        for bi in range(nb):
            for k in range(3):
                x[bi, k] += sx[bi, k]
            if not bounced[bi] and (sw[bi, 0] != 0.0 or sw[bi, 1] != 0.0 or sw[bi, 2] != 0.0):
                _turn(q, bi, sw[bi, 0], sw[bi, 1], sw[bi, 2])


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
    cold: bool,
    level: np.ndarray,
    island: np.ndarray,
    rolling: np.ndarray,
    jr: np.ndarray,
) -> None:
    """Twin of :func:`solve`, :func:`shock_pass` then :func:`follow_impulses` (when h > 0): the
    first ``count`` contacts one after the other, ``iterations`` times (first without friction
    when ``cold``); the levels of a stack settled from the ground up (``level`` the bodies');
    then the bodies moved as the impulses moved them (the depths left into ``depth_out``).
    ``island`` (C,): each contact's island (contact_batches.islands), swept until it converged.
    ``jn`` (C,), ``jt`` (C, 3): the impulses to start from (warm starting; applied first,
    contact by contact, except on impacts), in place the impulses each contact ended with;
    ``rolling`` (C,), ``jr`` (C, 3): each contact's rolling resistance and rolling impulse (the
    same)."""
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
    limit = np.empty(count)  # the resting speed: slower approaches never bounce
    dvn = np.empty(count)  # what the step's forces added along n, and its move along n
    dxn = np.empty(count)
    struck = np.empty(count, dtype=np.bool_)  # impacts of the impact pass
    cols = np.empty((3, 3))
    mc = np.empty((3, 3))
    for i in range(count):
        _contact_inertia(i, a, b, ra, rb, q, inv_inertia, mat, gm, kt6, cols, mc)
        _contact_masses(
            i, a, b, ra, rb, n, inv_mass, resting_speed, dv, dx, mat, g, inv_kn, ma, mb, mt, limit, dvn, dxn
        )
    _impact_pass(count, a, b, n, depth, restitution, dt, v, w, g, ma, mb, inv_kn, limit, struck)
    _bounce_targets(
        count, a, b, ra, rb, n, depth, restitution, v, w, limit, struck, dvn, dxn, kh, dt, e_used, impact, tgt
    )
    _warm_start(count, a, b, n, v, w, g, gm, ma, mb, impact, jn, jt, jr, mat)
    least, most = iterations, max_sweeps
    if cold:  # as solve: the normal impulses first, without friction (or rolling resistance)
        fr = np.zeros(count)
        _sweeps(
            count, a, b, ra, rb, n, fr, v, w, g, gm, kt6, inv_kn, ma, mb, mt, tgt, jn, jt, least, most, island,
            (fr, jr, mat),
        )  # fmt: skip
    _sweeps(
        count, a, b, ra, rb, n, friction, v, w, g, gm, kt6, inv_kn, ma, mb, mt, tgt, jn, jt, least, most, island,
        (rolling, jr, mat),
    )  # fmt: skip
    body, forces = (q, inv_mass, inv_inertia), (resting_speed, dv, dx)
    _shock_pass(
        count, a, b, ra, rb, n, depth, friction, v, w, body, forces, dt, impact, level, island, jn, jt,
        rolling, jr,
    )  # fmt: skip
    _follow_impulses(count, a, b, ra, rb, n, depth, impact, x, q, v, w, v0, w0, h, depth_out)
