"""The numba twin of the solid colliders' NumPy kernel
(:func:`animsim.colliders.numpy_rule.resolve_numpy`): its algorithm, one particle at a time,
with the same operations in the same order, so the backends agree to the bit.

Module-level helpers (compiled with the kernels that call them, animsim.elements.numba_helper):
the step-by-step kernel (:func:`numba_kernel`, for keyframed colliders) and the fused stage
kernel (:func:`stage_kernel`, static ones) run the same code.

The per-particle loop, ``_collide``, reads in named pieces, the twins of the NumPy kernel's
(the colliders' grown boxes, a step's box, its path, the march, the bounce, the projection).
numba copies them into the loop (numba_inline_helper): the compiled kernel stays one loop over
particles and colliders, with no call that passes its arrays for every candidate.
"""

from __future__ import annotations

import numpy as np

from animsim.colliders.impact import BISECT_STEPS, GOLDEN_STEPS, INV_PHI, MARCH_STEPS
from animsim.colliders.shapes import BOX, PARAMS
from animsim.collisions.response import RESTING_STEPS, kept_bounce_speed, static_friction_holds
from animsim.elements import jit_kernel, numba_helper, numba_inline_helper


@numba_helper
def _edge_face1(pr, px, py, pz, wx, wy, wz, tol, n):  # pragma: no cover - compiled
    """:func:`animsim.colliders.impact.edge_face` for one point, into ``n``: the same operations."""
    q0 = pr[8] * px + pr[11] * py + pr[14] * pz
    q1 = pr[9] * px + pr[12] * py + pr[15] * pz
    q2 = pr[10] * px + pr[13] * py + pr[16] * pz
    count = 0
    top = -np.inf
    best = np.inf
    face = -1
    sign = 1.0
    for j in range(3):
        qj = q0 if j == 0 else (q1 if j == 1 else q2)
        ej = abs(qj) - pr[5 + j]
        top = max(top, ej)
        if ej >= -tol:
            count += 1
            sj = -1.0 if qj < 0 else 1.0
            into = sj * ((pr[8 + j] * wx + pr[11 + j] * wy) + pr[14 + j] * wz)
            if into < best:
                best = into
                face = j
                sign = sj
    if count >= 2 and top <= tol and face >= 0:
        n[0] = sign * pr[8 + face]
        n[1] = sign * pr[11 + face]
        n[2] = sign * pr[14 + face]


@numba_helper
def _first_touch1(pr, p0x, p0y, p0z, sgx, sgy, sgz, cx, cy, cz, r, tol, s0, n):  # pragma: no cover
    """:func:`animsim.colliders.impact.first_touch` for one path: (hit, s), the same steps."""
    touch = np.nan
    if _sdf1(pr, p0x + sgx - cx, p0y + sgy - cy, p0z + sgz - cz, n) - r <= tol:
        touch = 1.0
    a, b = s0, 1.0
    for _ in range(GOLDEN_STEPS):
        if not np.isnan(touch):
            break
        c = b - INV_PHI * (b - a)
        d = a + INV_PHI * (b - a)
        fc = _sdf1(pr, p0x + c * sgx - cx, p0y + c * sgy - cy, p0z + c * sgz - cz, n) - r
        fd = _sdf1(pr, p0x + d * sgx - cx, p0y + d * sgy - cy, p0z + d * sgz - cz, n) - r
        if fc <= tol:
            touch = c
        elif fd <= tol:
            touch = d
        if fc <= fd:
            b = d
        else:
            a = c
    if np.isnan(touch):
        return False, s0
    lo, hi = s0, touch
    for _ in range(BISECT_STEPS):
        mid = 0.5 * (lo + hi)
        if _sdf1(pr, p0x + mid * sgx - cx, p0y + mid * sgy - cy, p0z + mid * sgz - cz, n) - r <= tol:
            hi = mid
        else:
            lo = mid
    return True, hi


@numba_helper
def _sdf1(pr, px, py, pz, out_n):  # pragma: no cover - compiled
    """Signed distance of one point p (relative to the centre) and its normal (into ``out_n``)."""
    kind = int(pr[0])
    if kind == 0:
        ln = np.sqrt(px * px + py * py + pz * pz)
        if ln > 0:
            out_n[0] = px / ln
            out_n[1] = py / ln
            out_n[2] = pz / ln
        else:
            out_n[0] = 0.0
            out_n[1] = 1.0
            out_n[2] = 0.0
        return ln - pr[4]
    if kind == 2:
        sx, sy, sz = pr[17], pr[18], pr[19]
        ss = sx * sx + sy * sy + sz * sz
        t = 0.0
        if ss > 0:
            t = (px * sx + py * sy + pz * sz) / ss
            if t < -1.0:
                t = -1.0
            elif t > 1.0:
                t = 1.0
        wx, wy, wz = px - t * sx, py - t * sy, pz - t * sz
        ln = np.sqrt(wx * wx + wy * wy + wz * wz)
        if ln > 0:
            out_n[0] = wx / ln
            out_n[1] = wy / ln
            out_n[2] = wz / ln
        else:
            sn = np.sqrt(ss)
            if abs(sx) < 0.9 * sn:  # cross(s, x-axis)
                cx, cy, cz = 0.0, sz, -sy
            else:  # cross(s, y-axis)
                cx, cy, cz = -sz, 0.0, sx
            cn = np.sqrt(cx * cx + cy * cy + cz * cz)
            if cn > 0:
                out_n[0] = cx / cn
                out_n[1] = cy / cn
                out_n[2] = cz / cn
            else:
                out_n[0] = 0.0
                out_n[1] = 1.0
                out_n[2] = 0.0
        return ln - pr[4]
    # box: q = R^T p, R row major at pr[8:17]
    q0 = pr[8] * px + pr[11] * py + pr[14] * pz
    q1 = pr[9] * px + pr[12] * py + pr[15] * pz
    q2 = pr[10] * px + pr[13] * py + pr[16] * pz
    e0 = abs(q0) - pr[5]
    e1 = abs(q1) - pr[6]
    e2 = abs(q2) - pr[7]
    s0 = -1.0 if q0 < 0 else 1.0
    s1 = -1.0 if q1 < 0 else 1.0
    s2 = -1.0 if q2 < 0 else 1.0
    o0 = max(e0, 0.0)
    o1 = max(e1, 0.0)
    o2 = max(e2, 0.0)
    ol = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
    if ol > 0:
        n0, n1, n2 = s0 * o0 / ol, s1 * o1 / ol, s2 * o2 / ol
        d = ol
    else:
        n0 = n1 = n2 = 0.0
        if e0 >= e1 and e0 >= e2:
            n0 = s0
            d = e0
        elif e1 >= e2:
            n1 = s1
            d = e1
        else:
            n2 = s2
            d = e2
    out_n[0] = pr[8] * n0 + pr[9] * n1 + pr[10] * n2
    out_n[1] = pr[11] * n0 + pr[12] * n1 + pr[13] * n2
    out_n[2] = pr[14] * n0 + pr[15] * n1 + pr[16] * n2
    return d


@numba_helper
def _friction1(vt, dvn, mu):  # pragma: no cover - compiled
    if mu == 0.0:
        return
    sp = np.sqrt(vt[0] * vt[0] + vt[1] * vt[1] + vt[2] * vt[2])
    keep = 0.0
    if sp > 0:
        keep = max(sp - mu * dvn, 0.0) / sp
    for a in range(3):
        vt[a] *= keep


@numba_helper
def _collide(
    params,
    friction,
    bounds,
    off0,
    off1,
    x_old,
    v_old,
    x,
    v,
    dt,
    radius,
    movable,
    inv_mass,
    project_only,
    kappa,
):  # pragma: no cover - compiled
    """The numba kernel: :func:`resolve_numpy`'s algorithm, one particle at a time.

    Particles are independent here, so each runs through every collider in turn
    (the NumPy kernel's order for that particle), with the same broad phase.
    """
    n_col = params.shape[0]
    lo, hi, cen, sh, uu = _grown_boxes1(params, bounds, off0, off1, dt)
    changed = False
    n = np.zeros(3)
    vt = np.zeros(3)
    acc = np.zeros(3)
    for i in range(x.shape[0]):
        if not movable[i] or not inv_mass[i] > 0:
            continue
        r = radius[i]
        stale = True
        lx = ly = lz = hx = hy = hz = 0.0
        for c in range(n_col):
            if stale:  # the box of _boxes
                lx, ly, lz, hx, hy, hz = _step_box1(x_old, x, i, r, project_only)
                stale = False
            if not (
                hx >= lo[c, 0]
                and hy >= lo[c, 1]
                and hz >= lo[c, 2]
                and lx <= hi[c, 0]
                and ly <= hi[c, 1]
                and lz <= hi[c, 2]
            ):
                continue
            pr = params[c]
            mu = friction[c]
            cx, cy, cz = cen[c, 0], cen[c, 1], cen[c, 2]
            ux, uy, uz = uu[c, 0], uu[c, 1], uu[c, 2]
            p0x, p0y, p0z, sgx, sgy, sgz, length, dm = _path1(
                pr, x_old, x, i, sh[c, 0], sh[c, 1], sh[c, 2], cx, cy, cz, r, project_only, n
            )
            if not (dm <= 0.5 * length * (1 + 1e-12) + 1e-12):
                continue
            stale = True  # looked at: it may move
            tol = 1e-9 * (1.0 + length)
            hit, s, d_start = _march1(
                pr, p0x, p0y, p0z, sgx, sgy, sgz, cx, cy, cz, r, tol, length, project_only, n
            )
            if hit:
                changed = True
                _bounce1(
                    pr, x, v, v_old, i, s, p0x, p0y, p0z, sgx, sgy, sgz, cx, cy, cz,
                    ux, uy, uz, tol, d_start, mu, dt, kappa, n, vt, acc,
                )  # fmt: skip
            # projection (every candidate, as the NumPy kernel)
            if _project1(pr, x, v, i, cx, cy, cz, r, ux, uy, uz, mu, n, vt):
                changed = True
    return changed


@numba_inline_helper
def _grown_boxes1(params, bounds, off0, off1, dt):  # pragma: no cover - compiled
    """(lo, hi, centre, shift, velocity) (C, 3) of every collider over the step: its box where
    it ends the step, grown by how far it moved and a margin, and where and how fast it goes."""
    n_col = params.shape[0]
    lo = np.empty((n_col, 3))
    hi = np.empty((n_col, 3))
    cen = np.empty((n_col, 3))
    sh = np.empty((n_col, 3))
    uu = np.empty((n_col, 3))
    for c in range(n_col):
        # _grown_box and the centre and velocity of resolve_numpy, operation for operation
        big = 0.0
        for a in range(6):
            big = max(big, abs(bounds[c, a]))
        d0 = off1[c, 0] - off0[c, 0]
        d1 = off1[c, 1] - off0[c, 1]
        d2 = off1[c, 2] - off0[c, 2]
        grow = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) + 1e-6 * (1.0 + big) + 1e-8
        for a in range(3):
            lo[c, a] = bounds[c, a] + off1[c, a] - grow
            hi[c, a] = bounds[c, 3 + a] + off1[c, a] + grow
            cen[c, a] = params[c, 1 + a] + off1[c, a]
            sh[c, a] = off1[c, a] - off0[c, a]
            uu[c, a] = sh[c, a] / dt
    return lo, hi, cen, sh, uu


@numba_inline_helper
def _step_box1(x_old, x, i, r, project_only):  # pragma: no cover - compiled
    """The box of row i's step grown by its radius (_boxes): (lx, ly, lz, hx, hy, hz)."""
    rr = r * (1.0 + 1e-6) + 1e-12
    if project_only:
        lx, ly, lz = x[i, 0], x[i, 1], x[i, 2]
        hx, hy, hz = lx, ly, lz
    else:
        lx, hx = min(x_old[i, 0], x[i, 0]), max(x_old[i, 0], x[i, 0])
        ly, hy = min(x_old[i, 1], x[i, 1]), max(x_old[i, 1], x[i, 1])
        lz, hz = min(x_old[i, 2], x[i, 2]), max(x_old[i, 2], x[i, 2])
        # the tracing's tolerance grows with the step's length
        rr += 1e-8 * max(hx - lx, max(hy - ly, hz - lz))
    lx -= rr
    ly -= rr
    lz -= rr
    hx += rr
    hy += rr
    hz += rr
    return lx, ly, lz, hx, hy, hz


@numba_inline_helper
def _path1(pr, x_old, x, i, shx, shy, shz, cx, cy, cz, r, project_only, n):  # pragma: no cover
    """Row i's step relative to a collider that moved by sh and ends it at c: its start p0, its
    segment sg, its length and its midpoint's distance from the shape (resolve_numpy's exact
    filter; -1 when ``project_only``, which has no path)."""
    if project_only:
        sgx = sgy = sgz = 0.0
        p0x, p0y, p0z = x[i, 0], x[i, 1], x[i, 2]
        length = 0.0
        dm = -1.0
    else:
        p0x, p0y, p0z = x_old[i, 0] + shx, x_old[i, 1] + shy, x_old[i, 2] + shz
        sgx, sgy, sgz = x[i, 0] - p0x, x[i, 1] - p0y, x[i, 2] - p0z
        length = np.sqrt(sgx * sgx + sgy * sgy + sgz * sgz)
        dm = _sdf1(pr, p0x + 0.5 * sgx - cx, p0y + 0.5 * sgy - cy, p0z + 0.5 * sgz - cz, n) - r
    return p0x, p0y, p0z, sgx, sgy, sgz, length, dm


@numba_inline_helper
def _march1(
    pr, p0x, p0y, p0z, sgx, sgy, sgz, cx, cy, cz, r, tol, length, project_only, n
):  # pragma: no cover
    """(hit, s, d_start) of one path p0 + s sg (resolve_numpy's _march): sphere tracing, then
    _first_touch1 where it gave up on a grazing path."""
    s = 0.0
    hit = False
    d_start = 0.0
    for it in range(0 if project_only else MARCH_STEPS):
        d = _sdf1(pr, p0x + s * sgx - cx, p0y + s * sgy - cy, p0z + s * sgz - cz, n) - r
        if it == 0:
            d_start = d
        if d <= tol:
            hit = True
            break
        s += d / length if length > 0 else 2.0
        if s > 1.0:
            break
    if not hit and not project_only and s <= 1.0:  # the march gave up: a grazing path
        hit, s = _first_touch1(pr, p0x, p0y, p0z, sgx, sgy, sgz, cx, cy, cz, r, tol, s, n)
    return hit, s, d_start


@numba_inline_helper
def _bounce1(
    pr, x, v, v_old, i, s, p0x, p0y, p0z, sgx, sgy, sgz, cx, cy, cz,
    ux, uy, uz, tol, d_start, mu, dt, kappa, n, vt, acc,
):  # fmt: skip  # pragma: no cover - compiled
    """Row i's response where its path hit the collider at s (resolve_numpy's _bounce):
    reflected with friction, then flown on for the rest of the step, into x[i] and v[i]."""
    if s > 1.0:
        s = 1.0
    xcx, xcy, xcz = p0x + s * sgx, p0y + s * sgy, p0z + s * sgz
    _sdf1(pr, xcx - cx, xcy - cy, xcz - cz, n)
    if int(pr[0]) == BOX:  # at an edge: the face it runs into (edge_face)
        _edge_face1(pr, xcx - cx, xcy - cy, xcz - cz, v[i, 0] - ux, v[i, 1] - uy, v[i, 2] - uz, tol, n)
    for a in range(3):
        acc[a] = (v[i, a] - v_old[i, a]) / dt
    vcx = v_old[i, 0] + s * (v[i, 0] - v_old[i, 0]) - ux
    vcy = v_old[i, 1] + s * (v[i, 1] - v_old[i, 1]) - uy
    vcz = v_old[i, 2] + s * (v[i, 2] - v_old[i, 2]) - uz
    vn = vcx * n[0] + vcy * n[1] + vcz * n[2]
    an = acc[0] * n[0] + acc[1] * n[1] + acc[2] * n[2]
    pressing = max(-an, 0.0)
    vn_new = _reflected1(vn, an, pressing, pr[20], s, d_start, dt, kappa, v_old, i, ux, uy, uz, n)
    rest = (1.0 - s) * dt
    settled = an < 0.0 and vn_new + an * rest <= 0.0  # resting (resolve_numpy)
    reaction = 0.0
    if settled:
        reaction = -an * rest
        vn_new = 0.0
    vt[0] = vcx - vn * n[0]
    vt[1] = vcy - vn * n[1]
    vt[2] = vcz - vn * n[2]
    _friction1(vt, abs(vn_new - vn) + reaction, mu)
    vrx = vt[0] + vn_new * n[0]
    vry = vt[1] + vn_new * n[1]
    vrz = vt[2] + vn_new * n[2]
    if static_friction_holds(vrx, vry, vrz, vn_new, acc[0], acc[1], acc[2], n[0], n[1], n[2], mu, mu != 0.0):
        acc[0] = 0.0
        acc[1] = 0.0
        acc[2] = 0.0
    ap = acc[0] * n[0] + acc[1] * n[1] + acc[2] * n[2]
    if settled and ap < 0.0:
        acc[0] -= ap * n[0]
        acc[1] -= ap * n[1]
        acc[2] -= ap * n[2]
    x[i, 0] = xcx + rest * vrx + 0.5 * rest * rest * acc[0]
    x[i, 1] = xcy + rest * vry + 0.5 * rest * rest * acc[1]
    x[i, 2] = xcz + rest * vrz + 0.5 * rest * rest * acc[2]
    v[i, 0] = vrx + ux + rest * acc[0]
    v[i, 1] = vry + uy + rest * acc[1]
    v[i, 2] = vrz + uz + rest * acc[2]


@numba_inline_helper
def _reflected1(vn, an, pressing, e_rest, s, d_start, dt, kappa, v_old, i, ux, uy, uz, n):  # pragma: no cover
    """The normal speed after the impact of a row arriving at ``vn`` (resolve_numpy's rule):
    an approaching row bounces with restitution e_rest, keeping e^2 of the method's energy,
    unless it is resting."""
    vn_new = vn
    if vn < 0:
        e = e_rest
        if -vn <= RESTING_STEPS * pressing * dt:
            e = 0.0
        vn_new = -e * vn
        if kappa != 0.0 and e > 0.0:
            u0 = (v_old[i, 0] - ux) * n[0] + (v_old[i, 1] - uy) * n[1] + (v_old[i, 2] - uz) * n[2]
            w = kept_bounce_speed(u0, max(d_start, 0.0), an, (1.0 - s) * dt, e, kappa * dt)
            if w > 0.0:
                vn_new = w
    return vn_new


@numba_inline_helper
def _project1(pr, x, v, i, cx, cy, cz, r, ux, uy, uz, mu, n, vt):  # pragma: no cover - compiled
    """Put row i on the collider's surface if it ends inside, and stop its inward motion
    relative to the collider (resolve_numpy's _project); True if it was inside."""
    d = _sdf1(pr, x[i, 0] - cx, x[i, 1] - cy, x[i, 2] - cz, n) - r
    if not d < 0:
        return False
    bx, by, bz = x[i, 0] - d * n[0], x[i, 1] - d * n[1], x[i, 2] - d * n[2]
    nx, ny, nz = n[0], n[1], n[2]
    for _ in range(4):
        db = _sdf1(pr, bx - cx, by - cy, bz - cz, n) - r
        if db >= 0:
            break
        big = max(abs(bx), max(abs(by), abs(bz))) + 1.0
        push = np.spacing(big) * 4 - db
        bx += push * nx
        by += push * ny
        bz += push * nz
    x[i, 0], x[i, 1], x[i, 2] = bx, by, bz
    rvx, rvy, rvz = v[i, 0] - ux, v[i, 1] - uy, v[i, 2] - uz
    vn = rvx * nx + rvy * ny + rvz * nz
    inward = min(vn, 0.0)
    vt[0] = rvx - vn * nx
    vt[1] = rvy - vn * ny
    vt[2] = rvz - vn * nz
    _friction1(vt, -inward, mu)
    v[i, 0] = vt[0] + (vn - inward) * nx + ux
    v[i, 1] = vt[1] + (vn - inward) * ny + uy
    v[i, 2] = vt[2] + (vn - inward) * nz + uz
    return True


def stage_kernel(x_old, v_old, x, v, dt, inv_mass, fp, ip):  # pragma: no cover - compiled
    """Static colliders as a fused stage (stage_signature): fp = [C, params, friction, bounds, kappa, radius],
    ip = the rows colliders act on (1) or not (0)."""
    n_col = int(fp[0])
    o = 1
    params = np.ascontiguousarray(fp[o : o + PARAMS * n_col]).reshape((n_col, PARAMS))
    o += PARAMS * n_col
    friction = fp[o : o + n_col]
    o += n_col
    bounds = np.ascontiguousarray(fp[o : o + 6 * n_col]).reshape((n_col, 6))
    o += 6 * n_col
    kappa = fp[o]
    radius = fp[o + 1 : o + 1 + x.shape[0]]
    still = np.zeros((n_col, 3))
    return _collide(
        params, friction, bounds, still, still, x_old, v_old, x, v, dt, radius, ip, inv_mass, False, kappa
    )


def numba_kernel():
    """The step-by-step numba kernel (:func:`_collide`), compiled or loaded on first use."""
    jit_kernel(stage_kernel, stage=True)  # compiles this module's helpers (_collide among them)
    return globals()["_collide"]
