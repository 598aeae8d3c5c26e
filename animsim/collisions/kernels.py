"""The numba kernel of impulse planes: the NumPy rule's operations, particle by particle.

Operation for operation as PlaneColliders.resolve and project_rows (the NumPy rule of
:mod:`animsim.collisions.numpy_rule`; the dot products summed x, y, z), so the backends
agree to rounding.

Laid out for the processor's vector units: the rows of a run that are on or behind a
plane are copied into one small buffer, a coordinate per line (structure of arrays),
and each plane's response is computed for every copied row without a branch, then
kept only where the row hit (a select, not a jump); the guarded divisions are done
unguarded (np.true_divide: an infinity or NaN where the guard fails, never kept). Each
row still sees its planes in order, every hit before every projection, and gets the
same numbers: only which rows are computed side by side has changed. The rare nudge of
a projected point that rounding left behind its plane runs row by row afterwards, from
the same point. Measured on 512 rows and a ground plane, one thread, per row and step:
23 -> 17 ns when every row rests on the plane, 12.8 -> 11.4 when a third does, 5.4 ->
6.4 when none does (2 ns of each is copying the rows for the measurement).

The rule of one row is written once (_hit_row, _settle_row) and the loops call it:
numba copies it into each loop (numba_inline_helper; a call would keep the loop off the
vector units). ``friction`` is False exactly when the plane's friction is 0 (the factor
is then 1, and t * 1.0 is t); where it is a constant at the call (the ground's loops,
_run_one_plane) the frictionless loop has no square root or division at all. A single
plane, the common case, hits and settles each row in one pass while its numbers are in
registers (with several planes every hit comes before every settling, as above).
Together with the padding below: 12 -> 9.5 ns a row and step with 55 % of the rows
resting (benchmarks/optimisation_log.md, "fourth round").
"""

from __future__ import annotations

import math

import numpy as np

from animsim.collisions.response import RESTING_STEPS, kept_bounce_speed, static_friction_holds
from animsim.elements import numba_helper, numba_inline_helper

#: rows copied into the vector buffer at a time (12 coordinates x 128 rows, 12 KB)
STAGE_RUN = 128
#: the rule runs over a multiple of this many buffer rows (the vector loop's width: four
#: float64 in the 256-bit registers the compiler uses), so no row is left to the loop's slow
#: one-row-at-a-time tail; the rows added are at x = NaN, so they never hit
VECTOR_ROWS = 4


@numba_inline_helper
def _friction_scale(t0, t1, t2, mu, dvn, friction):
    """Coulomb's factor max(|t| - mu dvn, 0) / |t| on the tangential velocity t (0 at rest),
    as selects; exactly 1 without friction (``friction`` False)."""
    if friction:
        speed = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        scaled = np.true_divide(max(speed - mu * dvn, 0.0), speed)
        return scaled if speed > 0 else 0.0
    return 1.0


@numba_inline_helper
def _hit_row(
    x0, x1, x2, v0, v1, v2, xo0, xo1, xo2, vo0, vo1, vo2, n0, n1, n2, off, e0, mu, dt, friction, kappa
):
    """One row's impulse on one plane: (hit, x, v) with x, v unchanged where it did not hit.
    ``kappa``: the method's energy shift (:func:`kept_bounce_speed`; 0: none)."""
    d1 = x0 * n0 + x1 * n1 + x2 * n2 - off
    # behind the plane, or on it and moving in (NaN: no); pinned and dead rows never come here
    hit = (d1 <= 0) & ((d1 < 0) | (v0 * n0 + v1 * n1 + v2 * n2 < 0))
    d0 = max(xo0 * n0 + xo1 * n1 + xo2 * n2 - off, 0.0)
    gap = d0 - d1
    q = np.true_divide(d0, gap)  # computed for every row, kept where the guard holds
    s = q if gap > 0 else 1.0
    a0 = np.true_divide(v0 - vo0, dt)
    a1 = np.true_divide(v1 - vo1, dt)
    a2 = np.true_divide(v2 - vo2, dt)
    xc0 = xo0 + s * (x0 - xo0)
    xc1 = xo1 + s * (x1 - xo1)
    xc2 = xo2 + s * (x2 - xo2)
    vc0 = vo0 + s * (v0 - vo0)
    vc1 = vo1 + s * (v1 - vo1)
    vc2 = vo2 + s * (v2 - vo2)
    vn = vc0 * n0 + vc1 * n1 + vc2 * n2
    approaching = vn < 0
    pressing = max(-(a0 * n0 + a1 * n1 + a2 * n2), 0.0)
    resting = approaching & (-vn <= RESTING_STEPS * pressing * dt)
    e = 0.0 if resting else e0
    vn_new = -e * vn if approaching else vn
    r = (1.0 - s) * dt
    if kappa != 0.0 and e > 0.0 and approaching:
        u0 = vo0 * n0 + vo1 * n1 + vo2 * n2
        an = a0 * n0 + a1 * n1 + a2 * n2
        w = kept_bounce_speed(u0, d0, an, r, e, kappa * dt)
        if w > 0.0:
            vn_new = w
    t0 = vc0 - vn * n0
    t1 = vc1 - vn * n1
    t2 = vc2 - vn * n2
    f = _friction_scale(t0, t1, t2, mu, abs(vn_new - vn), friction)
    vr0 = t0 * f + vn_new * n0
    vr1 = t1 * f + vn_new * n1
    vr2 = t2 * f + vn_new * n2
    if static_friction_holds(vr0, vr1, vr2, vn_new, a0, a1, a2, n0, n1, n2, mu, friction):
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
    return (
        hit,
        xc0 + r * vr0 + 0.5 * r * r * a0 if hit else x0,
        xc1 + r * vr1 + 0.5 * r * r * a1 if hit else x1,
        xc2 + r * vr2 + 0.5 * r * r * a2 if hit else x2,
        vr0 + r * a0 if hit else v0,
        vr1 + r * a1 if hit else v1,
        vr2 + r * a2 if hit else v2,
    )


@numba_inline_helper
def _settle_row(x0, x1, x2, v0, v1, v2, touched, n0, n1, n2, off, mu, friction):
    """Put a touched row behind one plane onto it and stop its inward motion:
    (x, v, rounding left it behind the plane)."""
    d = x0 * n0 + x1 * n1 + x2 * n2 - off
    behind = touched & (d < 0)
    b0 = x0 - d * n0
    b1 = x1 - d * n1
    b2 = x2 - d * n2
    again = behind & (b0 * n0 + b1 * n1 + b2 * n2 - off < 0)
    vn = v0 * n0 + v1 * n1 + v2 * n2
    inward = min(vn, 0.0)
    t0 = v0 - vn * n0
    t1 = v1 - vn * n1
    t2 = v2 - vn * n2
    f = _friction_scale(t0, t1, t2, mu, -inward, friction)  # the same factor with dvn = -inward
    return (
        b0 if behind else x0,
        b1 if behind else x1,
        b2 if behind else x2,
        t0 * f + (vn - inward) * n0 if behind else v0,
        t1 * f + (vn - inward) * n1 if behind else v1,
        t2 * f + (vn - inward) * n2 if behind else v2,
        again,
    )


@numba_helper
def _run_hits(buf, c, n0, n1, n2, off, e0, mu, dt, touched, friction, kappa):
    """One plane's impulse on the first ``c`` rows of ``buf`` (lines 0-2 x, 3-5 v, 6-8 the
    step's start x, 9-11 its v), in place where a row hit it; True if any did."""
    any_hit = False
    for j in range(c):
        hit, buf[0, j], buf[1, j], buf[2, j], buf[3, j], buf[4, j], buf[5, j] = _hit_row(
            buf[0, j], buf[1, j], buf[2, j], buf[3, j], buf[4, j], buf[5, j],
            buf[6, j], buf[7, j], buf[8, j], buf[9, j], buf[10, j], buf[11, j],
            n0, n1, n2, off, e0, mu, dt, friction, kappa,
        )  # fmt: skip
        touched[j] |= hit
        any_hit |= hit
    return any_hit


@numba_helper
def _run_projections(buf, c, n0, n1, n2, off, mu, touched, nudge, friction):
    """Settle the touched rows of ``buf`` on one plane (_settle_row); ``nudge`` marks those
    rounding left behind it (True if any)."""
    any_nudge = False
    for j in range(c):
        buf[0, j], buf[1, j], buf[2, j], buf[3, j], buf[4, j], buf[5, j], again = _settle_row(
            buf[0, j], buf[1, j], buf[2, j], buf[3, j], buf[4, j], buf[5, j],
            touched[j], n0, n1, n2, off, mu, friction,
        )  # fmt: skip
        nudge[j] = again
        any_nudge |= again
    return any_nudge


@numba_inline_helper
def _run_plane(buf, c, n0, n1, n2, off, e0, mu, dt, nudge, friction, kappa):
    """The only plane of a scene: each row hit (_hit_row) and settled (_settle_row) in one
    pass, the order the several-plane loops keep; returns (any hit, any to nudge)."""
    any_hit = False
    any_nudge = False
    for j in range(c):
        hit, x0, x1, x2, v0, v1, v2 = _hit_row(
            buf[0, j], buf[1, j], buf[2, j], buf[3, j], buf[4, j], buf[5, j],
            buf[6, j], buf[7, j], buf[8, j], buf[9, j], buf[10, j], buf[11, j],
            n0, n1, n2, off, e0, mu, dt, friction, kappa,
        )  # fmt: skip
        buf[0, j], buf[1, j], buf[2, j], buf[3, j], buf[4, j], buf[5, j], again = _settle_row(
            x0, x1, x2, v0, v1, v2, hit, n0, n1, n2, off, mu, friction
        )
        nudge[j] = again
        any_hit |= hit
        any_nudge |= again
    return any_hit, any_nudge


@numba_helper
def _run_one_plane(buf, c, n0, n1, n2, off, e0, mu, dt, nudge, kappa):
    """_run_plane, compiled apart for the ground of a y-up scene, with and without friction:
    its normal's components are constants there, so the compiler drops the products by 1.0
    (x * 1.0 is x to the bit; it rewrites nothing that could change a bit), and without
    friction the square roots and divisions. A component -0.0 is not +0.0 here (its
    products keep their signs). Each copy costs compile time (the kernel is compiled once
    and cached on disk), so other planes share one general loop."""
    unsigned = math.copysign(1.0, n0) > 0 and math.copysign(1.0, n2) > 0
    if unsigned and n0 == 0.0 and n1 == 1.0 and n2 == 0.0:
        if mu == 0.0:
            return _run_plane(buf, c, 0.0, 1.0, 0.0, off, e0, mu, dt, nudge, False, kappa)
        return _run_plane(buf, c, 0.0, 1.0, 0.0, off, e0, mu, dt, nudge, True, kappa)
    return _run_plane(buf, c, n0, n1, n2, off, e0, mu, dt, nudge, mu != 0.0, kappa)


@numba_helper
def _run_nudges(buf, c, n0, n1, n2, off, nudge):
    """Rounding can leave the projected point 1 ulp behind; nudge until it is not."""
    for j in range(c):
        if not nudge[j]:
            continue
        b0, b1, b2 = buf[0, j], buf[1, j], buf[2, j]
        for _ in range(4):
            db = b0 * n0 + b1 * n1 + b2 * n2 - off
            if not db < 0:
                break
            b0 -= 2.0 * db * n0 + np.spacing(abs(b0)) * np.sign(n0)
            b1 -= 2.0 * db * n1 + np.spacing(abs(b1)) * np.sign(n1)
            b2 -= 2.0 * db * n2 + np.spacing(abs(b2)) * np.sign(n2)
        buf[0, j], buf[1, j], buf[2, j] = b0, b1, b2


@numba_helper
def _planes_hit(buf, c, fp, dt, touched, nudge):
    """Several planes on the first ``c`` rows of ``buf``: every hit, then every settling
    (with its nudges); True if any row hit a plane."""
    count = int(fp[0])
    kappa = fp[1 + 6 * count]
    hit = False
    for j in range(c):
        touched[j] = False
    for k in range(count):
        p = fp[1 + 6 * k : 7 + 6 * k]  # normal, offset, restitution, friction
        hit |= _run_hits(buf, c, p[0], p[1], p[2], p[3], p[4], p[5], dt, touched, p[5] != 0.0, kappa)
    if not hit:
        return False
    for k in range(count):
        p = fp[1 + 6 * k : 7 + 6 * k]
        if _run_projections(buf, c, p[0], p[1], p[2], p[3], p[5], touched, nudge, p[5] != 0.0):
            _run_nudges(buf, c, p[0], p[1], p[2], p[3], nudge)
    return True


def stage_kernel(x_old, v_old, x, v, dt, inv_mass, fp, ip):
    count = int(fp[0])
    if count == 0:
        return False
    m = x.shape[0]
    buf = np.empty((12, STAGE_RUN))  # the rows' coordinates
    rows = np.empty(STAGE_RUN, dtype=np.int64)
    flags = np.empty((2, STAGE_RUN), dtype=np.bool_)
    touched = flags[0]
    nudge = flags[1]
    n0, n1, n2, off, e0, mu = fp[1], fp[2], fp[3], fp[4], fp[5], fp[6]  # the first plane
    kappa = fp[1 + 6 * count]  # the method's energy shift (kept_bounce_speed)
    changed = False
    for lo in range(0, m, STAGE_RUN):
        # The rows on or behind some plane (and movable) may hit one; no other row can:
        # only a hit moves a row, and a row that hits one plane is in this list already.
        c = 0
        hi = min(lo + STAGE_RUN, m)
        if count == 1:
            for i in range(lo, hi):
                near = x[i, 0] * n0 + x[i, 1] * n1 + x[i, 2] * n2 - off <= 0
                rows[c] = i
                c += near & (not inv_mass[i] <= 0)
        else:
            for i in range(lo, hi):
                near = False
                for k in range(count):
                    b = 1 + 6 * k
                    near |= x[i, 0] * fp[b] + x[i, 1] * fp[b + 1] + x[i, 2] * fp[b + 2] - fp[b + 3] <= 0
                rows[c] = i
                c += near & (not inv_mass[i] <= 0)
        if c == 0:
            continue
        for j in range(c):
            i = rows[j]
            for k in range(3):
                buf[k, j] = x[i, k]
                buf[3 + k, j] = v[i, k]
                buf[6 + k, j] = x_old[i, k]
                buf[9 + k, j] = v_old[i, k]
        width = min((c + VECTOR_ROWS - 1) // VECTOR_ROWS * VECTOR_ROWS, STAGE_RUN)
        for j in range(c, width):
            buf[0, j] = np.nan
        if count == 1:
            hit, again = _run_one_plane(buf, width, n0, n1, n2, off, e0, mu, dt, nudge, kappa)
            if again:
                _run_nudges(buf, width, n0, n1, n2, off, nudge)
        else:
            hit = _planes_hit(buf, width, fp, dt, touched, nudge)
        if not hit:
            continue
        changed = True
        for j in range(c):
            i = rows[j]
            for k in range(3):
                x[i, k] = buf[k, j]
                v[i, k] = buf[3 + k, j]
    return changed


def newborn_kernel(x_old, v_old, x, v, rest, fp, ip):
    """:meth:`PlaneColliders.collide_subset` compiled (the numba backend's birth step,
    :func:`animsim.emitters.kernels._pool_step`): the planes of ``fp`` on newborn rows (k, 3),
    all movable, each row over its own rest ``rest[j]`` of its birth step, in place; True if
    any row hit.

    The order of _planes_hit (every plane's hits, then every plane's settling with its
    nudges), which for one plane gives _run_plane's numbers; only the step length is the
    row's own. Every row is tested: a row neither on nor behind a plane is left as it is by
    the rule itself (a newborn step's few hundred rows need no prefilter)."""
    count = int(fp[0])
    k = x.shape[0]
    if count == 0 or k == 0:
        return False
    kappa = fp[1 + 6 * count]
    buf = np.empty((12, k))
    for j in range(k):
        for c in range(3):
            buf[c, j] = x[j, c]
            buf[3 + c, j] = v[j, c]
            buf[6 + c, j] = x_old[j, c]
            buf[9 + c, j] = v_old[j, c]
    flags = np.zeros((2, k), dtype=np.bool_)
    touched = flags[0]
    nudge = flags[1]
    hit = False
    for p in range(count):
        n0, n1, n2, off, e0, mu = (
            fp[1 + 6 * p],
            fp[2 + 6 * p],
            fp[3 + 6 * p],
            fp[4 + 6 * p],
            fp[5 + 6 * p],
            fp[6 + 6 * p],
        )
        friction = mu != 0.0
        for j in range(k):
            h, buf[0, j], buf[1, j], buf[2, j], buf[3, j], buf[4, j], buf[5, j] = _hit_row(
                buf[0, j], buf[1, j], buf[2, j], buf[3, j], buf[4, j], buf[5, j],
                buf[6, j], buf[7, j], buf[8, j], buf[9, j], buf[10, j], buf[11, j],
                n0, n1, n2, off, e0, mu, rest[j], friction, kappa,
            )  # fmt: skip
            touched[j] |= h
            hit |= h
    if not hit:
        return False
    for p in range(count):
        n0, n1, n2, off, mu = fp[1 + 6 * p], fp[2 + 6 * p], fp[3 + 6 * p], fp[4 + 6 * p], fp[6 + 6 * p]
        if _run_projections(buf, k, n0, n1, n2, off, mu, touched, nudge, mu != 0.0):
            _run_nudges(buf, k, n0, n1, n2, off, nudge)
    for j in range(k):
        for c in range(3):
            x[j, c] = buf[c, j]
            v[j, c] = buf[3 + c, j]
    return True
