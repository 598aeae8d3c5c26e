"""The NumPy kernel of the solid colliders: a broad phase, the march to the time of impact,
the response at the contact and the projection of what ends inside (:func:`resolve_numpy`).
"""

from __future__ import annotations

import numpy as np

from animsim.colliders.impact import MARCH_STEPS, edge_face, first_touch, path_distance
from animsim.colliders.shapes import BOX, Shape, sdf, shape_bounds, shape_of
from animsim.collisions.response import (
    RESTING_STEPS,
    apply_friction,
    hold_by_static_friction,
    kept_bounce_speed,
)
from animsim.vec import dot3

#: slack of the broad phase: relative, on a particle's radius and a collider's box
#: (far more than rounding in the exact tests that follow it)
BROAD_RELATIVE = 1e-6


def _grown_box(
    bounds: np.ndarray, off0: np.ndarray, off1: np.ndarray, longest: float
) -> tuple[np.ndarray, np.ndarray]:
    """A collider's box where it ends the step, grown by how far it moved and a margin
    (``longest``: the longest extent of a particle's step, for the tracing's tolerance)."""
    shift = off1 - off0
    grow = (
        float(np.sqrt(dot3(shift, shift)))
        + BROAD_RELATIVE * (1.0 + float(np.abs(bounds).max()))
        + 1e-8 * (1.0 + longest)
    )
    return bounds[:3] + off1 - grow, bounds[3:] + off1 + grow


def _boxes(
    x_old: np.ndarray, x: np.ndarray, radius: np.ndarray, rows: np.ndarray, project_only: bool
) -> tuple[np.ndarray, np.ndarray, float]:
    """Boxes (3, k) lo and hi around each row's step (its end alone when ``project_only``), grown by
    its radius, and the longest extent of a step.

    A particle that touches a shape during its step has its segment within its
    radius of the shape, so within its radius of the shape's box: one that
    misses the box is left alone by the exact tests too (they only change
    particles whose segment reaches the shape).
    """
    xs, r = x[rows], radius[rows] * (1.0 + BROAD_RELATIVE) + 1e-12
    if project_only:
        lo, hi, longest = xs - r[:, None], xs + r[:, None], 0.0
    else:
        xo = x_old[rows]
        lo, hi = np.minimum(xo, xs), np.maximum(xo, xs)
        longest = float((hi - lo).max(initial=0.0))
        lo -= r[:, None]
        hi += r[:, None]
    return np.ascontiguousarray(lo.T), np.ascontiguousarray(hi.T), longest


def _overlap(lo: np.ndarray, hi: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray) -> np.ndarray:
    """Indices of the boxes (3, k) that overlap the box [box_lo, box_hi]."""
    m = hi[0] >= box_lo[0]
    for a in range(3):
        if a:
            m &= hi[a] >= box_lo[a]
        m &= lo[a] <= box_hi[a]
    return np.flatnonzero(m)


def resolve_numpy(
    params: np.ndarray,
    friction: np.ndarray,
    off0: np.ndarray,
    off1: np.ndarray,
    x_old: np.ndarray,
    v_old: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    dt: float,
    radius: np.ndarray,
    movable: np.ndarray,
    project_only: bool = False,
    bounds: np.ndarray | None = None,
    kappa: float = 0.5,
) -> bool:
    """Resolve the step x_old -> x against every collider, in place (NumPy kernel).

    ``project_only``: no time of impact, only push out whatever is inside
    (after particle contacts moved particles). ``bounds``: :func:`shape_bounds`
    of ``params`` (computed when not given). ``kappa``: the method's energy shift
    (:func:`animsim.collisions.response.kept_bounce_speed`).
    """
    if bounds is None:
        bounds = shape_bounds(params)
    mov = np.flatnonzero(movable)
    if mov.size == 0:
        return False
    lo_p, hi_p, longest = _boxes(x_old, x, radius, mov, project_only)
    changed = False
    for c in range(params.shape[0]):  # colliders, not particles
        shape = shape_of(params[c], float(friction[c]))
        center = shape.center + off1[c]
        u = (off1[c] - off0[c]) / dt  # the collider's velocity over the step
        near = _overlap(lo_p, hi_p, *_grown_box(bounds[c], off0[c], off1[c], longest))
        if near.size == 0:
            continue
        rows = mov[near]
        if project_only:
            if _project(shape, center, u, x, v, rows, radius):
                changed = True
                lo_p[:, near], hi_p[:, near], _ = _boxes(x_old, x, radius, rows, True)
            continue
        cand, p0 = _reaching(shape, off1[c] - off0[c], off1[c], x_old, x, rows, radius)
        if cand.size == 0:
            continue
        r = radius[cand]
        p1 = x[cand]
        sg = p1 - p0
        length = np.sqrt(dot3(sg, sg))
        tol = 1e-9 * (1.0 + length)
        hit, s, d_start = _march(shape, center, p0, sg, r, length, tol)
        h = np.flatnonzero(hit)
        if h.size:
            changed = True
            _bounce(shape, center, u, cand, h, p0, sg, s, d_start, tol, v_old, x, v, dt, kappa)
        if _project(shape, center, u, x, v, cand, radius):
            changed = True
        # the rows looked at may have moved: their boxes follow them
        lo_p[:, near], hi_p[:, near], moved = _boxes(x_old, x, radius, rows, False)
        longest = max(longest, moved)
    return changed


def _reaching(
    shape: Shape,
    shift: np.ndarray,
    offset: np.ndarray,
    x_old: np.ndarray,
    x: np.ndarray,
    rows: np.ndarray,
    radius: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(the rows whose step, relative to the shape, may reach it; where those steps start).

    The shape moved by ``shift`` in the step and ends it at ``offset``.
    """
    # Exact filter: the relative segment lies in the ball around its midpoint
    # of radius half its length; if that ball misses the shape, so does the segment.
    p0_all = x_old[rows] + shift
    seg = x[rows] - p0_all
    mid = p0_all + 0.5 * seg  # the numba kernel's midpoint, to the bit
    half_len = 0.5 * np.sqrt(dot3(seg, seg))
    d_mid, _ = shape.signed_distance(mid, offset)
    keep = d_mid - radius[rows] <= half_len * (1 + 1e-12) + 1e-12
    return rows[keep], p0_all[keep]


def _march(
    shape: Shape,
    center: np.ndarray,
    p0: np.ndarray,
    sg: np.ndarray,
    r: np.ndarray,
    length: np.ndarray,
    tol: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(hit, s, d_start) of the paths p0 + s sg of radii ``r`` against ``shape`` (at ``center``):
    whether each touches it, the fraction of the path where it first does, and its distance at
    the path's start. Sphere tracing, then :func:`first_touch` for the paths it gave up on."""
    s = np.zeros(len(p0))
    hit = np.zeros(len(p0), dtype=bool)
    alive = np.ones(len(p0), dtype=bool)
    d_start = np.zeros(len(p0))  # each row's distance at the step's start (the first march)
    for it in range(MARCH_STEPS):  # sphere tracing, vectorised over candidates
        idx = np.flatnonzero(alive)
        if idx.size == 0:
            break
        d, _ = sdf(
            shape.kind,
            p0[idx] + s[idx, None] * sg[idx] - center,
            shape.radius,
            shape.half,
            shape.rotation,
            shape.segment,
        )
        d = d - r[idx]
        if it == 0:
            d_start[idx] = d
        touched = d <= tol[idx]
        hit[idx[touched]] = True
        step = np.divide(d, length[idx], out=np.full(idx.size, 2.0), where=length[idx] > 0)
        s[idx] = np.where(touched, s[idx], s[idx] + step)
        alive[idx[touched | (s[idx] > 1.0)]] = False
    grazing = np.flatnonzero(alive)  # the march gave up: neither touching nor past the end
    if grazing.size:
        along = path_distance(shape, center, p0, sg, r, grazing)
        touched, s_touch = first_touch(along, s[grazing], tol[grazing])
        hit[grazing] = touched
        s[grazing] = s_touch
    return hit, s, d_start


def _bounce(
    shape: Shape,
    center: np.ndarray,
    u: np.ndarray,
    cand: np.ndarray,
    h: np.ndarray,
    p0: np.ndarray,
    sg: np.ndarray,
    s: np.ndarray,
    d_start: np.ndarray,
    tol: np.ndarray,
    v_old: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    dt: float,
    kappa: float,
) -> None:
    """The response of the candidates ``h`` (of ``cand``, whose paths are p0 + s sg) that hit the
    shape moving at ``u``: reflected at the contact with friction, then flown on for the rest of
    the step; written into x and v."""
    rows_hit = cand[h]
    sh = np.minimum(s[h], 1.0)[:, None]
    xc = p0[h] + sh * sg[h]
    vo, vh = v_old[rows_hit], v[rows_hit]
    mean_acc = (vh - vo) / dt
    vc = vo + sh * (vh - vo) - u  # relative velocity at the contact
    _, n = sdf(shape.kind, xc - center, shape.radius, shape.half, shape.rotation, shape.segment)
    if shape.kind == BOX:
        edge_face(shape, xc - center, vh - u, tol[h], n)
    vn = dot3(vc, n)
    approaching = vn < 0
    an = dot3(mean_acc, n)
    pressing = np.maximum(-an, 0.0)
    resting = approaching & (-vn <= RESTING_STEPS * pressing * dt)
    e = np.where(resting, 0.0, shape.restitution)
    vn_new = np.where(approaching, -e * vn, vn)
    rest = (1.0 - sh) * dt
    if kappa != 0.0 and shape.restitution > 0.0:
        bounce = approaching & ~resting
        u0 = dot3(vo - u, n)
        w = kept_bounce_speed(u0, np.maximum(d_start[h], 0.0), an, rest[:, 0], e, kappa * dt)
        vn_new = np.where(bounce & (w > 0.0), w, vn_new)
    # A contact that the step's acceleration presses back onto the surface before the
    # step ends rests on it: the surface's reaction takes the normal speed left and
    # cancels the press for the rest of the step (and friction takes its share of that
    # reaction, -an rest). Flown on with the press, the particle went into the shape
    # and relied on the projection, which cannot see a point on the plane of a box's
    # face (a box sliding flush with the floor then lost the grains it pushed).
    settled = (an < 0.0) & (vn_new + an * rest[:, 0] <= 0.0)
    reaction = np.where(settled, -an * rest[:, 0], 0.0)
    vn_new = np.where(settled, 0.0, vn_new)
    vt = vc - vn[:, None] * n
    vt = apply_friction(vt, np.abs(vn_new - vn) + reaction, shape.friction)
    vr = vt + vn_new[:, None] * n
    if shape.friction != 0.0:  # held still on the surface: no flight after the impact
        hold_by_static_friction(vr, vn_new, mean_acc, n, shape.friction)
    pressed = dot3(mean_acc, n)
    mean_acc = mean_acc - np.where(settled & (pressed < 0.0), pressed, 0.0)[:, None] * n
    x[rows_hit] = xc + rest * vr + 0.5 * rest * rest * mean_acc
    v[rows_hit] = vr + u + rest * mean_acc


def _project(
    shape: Shape,
    center: np.ndarray,
    u: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    idx: np.ndarray,
    radius: np.ndarray,
) -> bool:
    """Put any of ``idx`` still inside the shape on its surface; stop its inward relative motion."""
    d, n = sdf(shape.kind, x[idx] - center, shape.radius, shape.half, shape.rotation, shape.segment)
    d = d - radius[idx]
    sel = d < 0
    if not sel.any():
        return False
    rows = idx[sel]
    n = n[sel]
    xb = x[rows] - d[sel, None] * n
    # Rounding can leave the projected point a hair inside; push until it is not.
    for _ in range(4):
        db, _ = sdf(shape.kind, xb - center, shape.radius, shape.half, shape.rotation, shape.segment)
        db = db - radius[rows]
        still = db < 0
        if not still.any():
            break
        xb[still] += (np.spacing(np.abs(xb[still]).max(axis=1) + 1.0) * 4 - db[still])[:, None] * n[still]
    x[rows] = xb
    vr = v[rows] - u
    vn = dot3(vr, n)
    inward = np.minimum(vn, 0.0)
    vt = vr - vn[:, None] * n
    vt = apply_friction(vt, -inward, shape.friction)
    v[rows] = vt + (vn - inward)[:, None] * n + u
    return True
