"""The contact solver of rigid bodies: sequential impulses on the contact list, with
restitution, resting contacts, Coulomb friction and rolling resistance, warm starting, the time
of impact inside the step; the move of the bodies by the impulses is
:func:`animsim.bodies.contact_follow.follow_impulses`.

Baraff 1997, "Rigid Body Simulation", section 8 (colliding contact; the effective mass along
the normal), solved as sequential impulses (Catto 2005): the contacts one after the other,
``iterations`` times, on NumPy in batches in which no body appears twice
(:func:`animsim.bodies.contact_batches.batches`), a
batch being one vectorised update whose result is the sequential one. Every sum is written in
the order of the numba twin (:mod:`animsim.bodies.contact_kernels`; the arithmetic in
:mod:`animsim.bodies.contact_algebra`), so the backends agree to the bit; the rolling
resistance is one rule both call (:func:`animsim.bodies.contact_kernels.rolling_total`).
The model as a whole is described in :mod:`animsim.bodies.contacts`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from animsim.bodies.contact_algebra import arm_inertia, cross3, dot3, inv_world_inertia, sym_matvec
from animsim.bodies.contact_batches import batches, islands, slot_batches
from animsim.bodies.contact_constants import (
    IMPACT_SWEEPS,
    ITERATIONS,
    MAX_SWEEPS,
    RESTING_FLOOR,
    SWEEP_TOLERANCE,
)
from animsim.bodies.contact_detection import Contacts
from animsim.bodies.contact_kernels import rolling_total
from animsim.collisions import kept_end_speed


@dataclass(frozen=True)
class ContactRows:
    """The contacts in the solver's order (batch after batch, :func:`batches`) with what the
    solve needs of each, computed once per step. Vectors are (3, C), inertias (6, C) rows."""

    coupled: bool  # some contact joins two bodies
    order: np.ndarray  # the solver's order: position -> index in the contact list
    level: np.ndarray  # the batch of each contact, in the solver's order
    cuts: np.ndarray  # batch k is rows cuts[k]:cuts[k + 1]
    a: np.ndarray
    b: np.ndarray
    has_b: np.ndarray
    bb: np.ndarray  # b, with 0 where there is none
    n: np.ndarray
    ra: np.ndarray
    rb: np.ndarray
    restitution: np.ndarray
    friction: np.ndarray
    depth: np.ndarray
    ma: np.ndarray
    mb: np.ndarray
    rna: np.ndarray
    rnb: np.ndarray
    gna: np.ndarray
    gnb: np.ndarray
    inv_kn: np.ndarray
    k_t: np.ndarray
    m_t: np.ndarray
    ga: list[np.ndarray]
    gb: list[np.ndarray]
    # rolling resistance (rolling_total): mu_r per contact, whether any contact has one, the
    # world inverse inertias of a and b (b's zero without one), their sum K, and the rate that
    # turns a change of rolling impulse into a velocity at the contact point, tr(K) |r_a|
    rolling: np.ndarray
    rolls: bool
    ia: np.ndarray
    ib: np.ndarray
    k_r: np.ndarray
    r_rate: np.ndarray


# one batch of the sweep: its rows, their bodies a, which rows have a body b (within the
# batch), those bodies b, and those rows' positions in the solver's order
_Group = tuple[slice, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def contact_rows(
    c: Contacts,
    q: np.ndarray,
    inv_mass: np.ndarray,
    inv_inertia: np.ndarray,
    rolling: np.ndarray | None = None,
) -> ContactRows:
    """Sort the contacts into batches and compute their effective masses (see :class:`ContactRows`);
    ``rolling`` (C,): each contact's rolling resistance (None: none has any)."""
    coupled = bool((c.b >= 0).any())
    batch = batches(c.a, c.b) if coupled else slot_batches(c.a, c.b)
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
    rna = cross3(ra, n)
    gna = sym_matvec(mat_a, rna)
    kn = ma + dot3(rna, gna)
    mb = np.where(has_b, inv_mass[bb], 0.0)
    mat_b = np.where(has_b, m_body[:, bb], 0.0)
    rnb = cross3(rb, n)
    gnb = sym_matvec(mat_b, rnb)
    if coupled:
        kn = np.where(has_b, (ma + mb) + (dot3(rna, gna) + dot3(rnb, gnb)), kn)
    # two immovable things (a pinned body on a floor) exchange no impulse
    inv_kn = np.where(kn > 0, 1.0 / np.where(kn > 0, kn, 1.0), 0.0)
    # tangential response: along a unit direction e the effective mass is 1/(m_t + e . K e) with
    # K = [r]x^T I^-1 [r]x (the angular part, r x e = [r]x e), summed over both bodies
    k_t, ga = arm_inertia(mat_a, ra)
    m_t = ma
    gb = ga
    if coupled:
        k_b, gb = arm_inertia(mat_b, rb)
        k_t = np.where(has_b, k_t + k_b, k_t)
        m_t = np.where(has_b, ma + mb, ma)
    mu_r = np.zeros(a.size) if rolling is None else rolling[order]
    rolls = bool((mu_r > 0.0).any())
    k_r = r_rate = mu_r
    if rolls:
        k_r = mat_a + mat_b
        r_rate = ((k_r[0] + k_r[3]) + k_r[5]) * np.sqrt(dot3(ra, ra))
    return ContactRows(
        coupled, order, batch[order], cuts, a, b, has_b, bb, n, ra, rb, restitution, friction, depth,
        ma, mb, rna, rnb, gna, gnb, inv_kn, k_t, m_t, ga, gb, mu_r, rolls, mat_a, mat_b, k_r, r_rate,
    )  # fmt: skip


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
    warm: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    max_sweeps: int = MAX_SWEEPS,
    cold: bool = False,
    island: np.ndarray | None = None,
    rolling: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sequential impulses on v (B,3), w (B,3) in place; returns the restitution applied per contact,
    which contacts were impacts (approaching faster than resting; they bounce with it), and the
    normal (C,), friction (C, 3) and rolling (C, 3) impulses each contact ended with.
    ``warm``: impulses (C,), (C, 3), (C, 3) to start from (warm starting,
    :mod:`animsim.bodies.warm`); applied first, contact by contact, except on impacts.
    ``rolling``: (C,) each contact's rolling resistance mu_r, a length (None: none), which
    limits its rolling impulse to mu_r times its normal impulse (:func:`rolling_total`).
    ``kh``: the method's energy shift times the step ``dt`` (:func:`_impact_target`).
    ``surface``: (C, 3) the velocity of the surface each contact touches (a keyframed collider;
    None: all still): every speed the contacts work with is relative to it.
    ``cold``: bodies rest on each other with no impulse to start from: the normal impulses are
    found first, without friction (:func:`sweeps`), then both.
    ``island``: (C,) the island of each contact (:func:`islands`; None: found here); each
    island is swept until its own contacts have converged.

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
        return e_out, np.zeros(0, dtype=bool), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))
    r = contact_rows(c, q, inv_mass, inv_inertia, rolling)
    vT, wT = v.T.copy(), w.T.copy()
    rest_b = np.where(r.has_b, resting_speed[r.bb], 0.0)
    limit = resting_speed[r.a] + rest_b + RESTING_FLOOR
    struck = _impact_pass(r, limit, dt, vT, wT)
    sv = None if surface is None else surface[r.order].T  # (3, C), in the solver's order
    bounce, target = _bounce_targets(r, vT, wT, limit, sv, dv, dx, kh, dt)
    e_used = np.where(bounce | struck, r.restitution, 0.0)
    jn = np.zeros(count)
    jt = np.zeros((3, count))
    jr = np.zeros((3, count))
    vT_rows, wT_rows = vT.T, wT.T  # (B, 3) views
    if warm is not None:
        jn = np.where(bounce | struck, 0.0, warm[0][r.order])
        jt = np.where(bounce | struck, 0.0, warm[1][r.order].T)
        jr = np.where(bounce | struck, 0.0, warm[2][r.order].T)
        _apply_warm(r, jn, jt, jr, vT_rows, wT_rows)
    groups = contact_groups(r)
    isl = (islands(c.a, c.b, v.shape[0]) if island is None else island)[r.order]
    if cold:
        unfree = replace(r, friction=np.zeros(count), rolls=False)
        sweeps(unfree, groups, sv, target, jn, jt, jr, vT, wT, iterations, max_sweeps, isl)
    sweeps(r, groups, sv, target, jn, jt, jr, vT, wT, iterations, max_sweeps, isl)
    v[:] = vT.T
    w[:] = wT.T
    e_out[r.order] = e_used
    hit_out = np.zeros(count, dtype=bool)
    hit_out[r.order] = bounce | struck
    jn_out = np.empty(count)
    jn_out[r.order] = jn
    jt_out = np.empty((count, 3))
    jt_out[r.order] = jt.T
    jr_out = np.empty((count, 3))
    jr_out[r.order] = jr.T
    return e_out, hit_out, jn_out, jt_out, jr_out


def _bounce_targets(
    r: ContactRows,
    vT: np.ndarray,
    wT: np.ndarray,
    limit: np.ndarray,
    sv: np.ndarray | None,
    dv: np.ndarray | None,
    dx: np.ndarray | None,
    kh: float,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Which contacts bounce (C,) and the normal speed each is solved toward (C,): minus e times
    the approach for a bounce (at the time of impact, :func:`_impact_target`, given ``dv`` and
    ``dx``), else the speed that closes a gap within the step (0 for a touching contact)."""
    a, bb, has_b, n = r.a, r.bb, r.has_b, r.n
    vel = vT[:, a] + cross3(wT[:, a], r.ra)
    if r.coupled:
        vel = np.where(has_b, vel - (vT[:, bb] + cross3(wT[:, bb], r.rb)), vel)
    if sv is not None:
        vel = vel - sv
    vn0 = dot3(vel, n)
    # a speculative contact (a gap, depth < 0) never bounces: it may close its gap in the step
    bounce = (vn0 < -limit) & (r.depth >= 0.0)
    target = np.where(bounce, -r.restitution * vn0, np.minimum(r.depth, 0.0) / dt)
    if dv is not None and dx is not None and bounce.any():
        # against a moving surface the approach over the step is relative to its move too
        target = np.where(
            bounce,
            _impact_target(
                a, bb, has_b, n, r.depth, r.restitution, vn0, dv, dx, kh, dt, None if sv is None else sv * dt
            ),
            target,
        )
    return bounce, target


def sweeps(
    r: ContactRows,
    groups: list[_Group],
    sv: np.ndarray | None,
    target: np.ndarray,
    jn: np.ndarray,
    jt: np.ndarray,
    jr: np.ndarray,
    vT: np.ndarray,
    wT: np.ndarray,
    least: int,
    most: int,
    island: np.ndarray,
) -> int:
    """Sweeps over the batches, at least ``least``, then until one changes no velocity by more than
    SWEEP_TOLERANCE, at most ``most`` (in place, as :func:`_solve_batch`); returns how many.
    The rule holds per island (``island`` (C,), in the solver's order; :func:`islands`): an
    island whose sweep changed none of its velocities by more than the tolerance is left as it
    is from then on, and the sweeps end when every island has converged or at ``most``. Islands
    share no body, so each ends as it would alone: a thousand bodies lying apart on a floor
    no longer all take the sweeps of the slowest one.

    ``jr`` (3, C): the rolling impulses, swept with the rest where ``r.rolls``.

    Without friction (``r.friction`` zero, ``r.rolls`` False) this is the first half of a cold step: from zero
    impulses, each corner of a box first pressed onto a floor slides out as the box turns, and
    friction stopping it there sets up a squeeze of the floor friction that the other corners'
    pushes never undo (measured: a ten-box stack ended its first step with two of its floor
    corners at the friction cone and kept them there). Finding the normal impulses first and
    the friction after (the staggered projections of Kaufman, Sueda, James and Pai, SIGGRAPH
    Asia 2008, one round of them) leaves the friction the little that is needed."""
    sweep = 0
    live = np.ones(int(island.max(initial=-1)) + 1, dtype=bool)
    for sweep in range(max(least, most)):
        change = np.zeros(live.size)
        for g in groups:
            act = live[island[g[0]]]
            if act.any():
                _solve_batch(r, g, sv, target, (jn, jt, jr), vT, wT, act, island[g[0]], change)
        if sweep + 1 >= least:
            live &= change > SWEEP_TOLERANCE
            if not live.any():
                break
    return sweep + 1


def contact_groups(r: ContactRows) -> list[_Group]:
    """The batches of the sweep (see :data:`_Group`), in order."""
    groups = []
    for k in range(r.cuts.size - 1):
        s = slice(int(r.cuts[k]), int(r.cuts[k + 1]))
        hb = np.flatnonzero(r.has_b[s])
        groups.append((s, r.a[s], hb, r.b[s][hb], r.cuts[k] + hb))
    return groups


def _solve_batch(
    r: ContactRows,
    g: _Group,
    sv: np.ndarray | None,
    target: np.ndarray,
    impulses: tuple[np.ndarray, np.ndarray, np.ndarray],
    vT: np.ndarray,
    wT: np.ndarray,
    act: np.ndarray,
    island: np.ndarray,
    change: np.ndarray,
) -> None:
    """One batch of a sweep (no body twice in it), normal, friction, then rolling; in place on the
    ``impulses`` jn (C,), jt (3, C), jr (3, C) and on vT, wT (3, B). Rows not ``act`` (their
    island has converged) keep their impulses (a change of zero, which leaves the velocities as
    they are); each island's largest change of velocity goes into ``change`` (per island;
    ``island`` the rows')."""
    jn, jt, jr = impulses
    s, ai, hb, bi, sb = g
    va, wa = vT[:, ai], wT[:, ai]
    vb, wb = vT[:, bi], wT[:, bi]  # empty when no contact of the batch has a body b
    dj = _normal_impulse(r, g, sv, target, jn, va, wa, vb, wb, act)
    imp = _friction_impulse(r, g, sv, jn, jt, va, wa, vb, wb, act)
    big = r.m_t[s] * np.maximum(np.abs(dj), np.abs(imp).max(axis=0))
    ga, gb = r.ga, r.gb
    va += r.ma[s] * imp
    wa += (ga[0][:, s] * imp[0] + ga[1][:, s] * imp[1]) + ga[2][:, s] * imp[2]
    if hb.size:
        ib = imp[:, hb]
        vb -= r.mb[sb] * ib
        wb -= (gb[0][:, sb] * ib[0] + gb[1][:, sb] * ib[1]) + gb[2][:, sb] * ib[2]
    if r.rolls:
        big = np.maximum(big, _rolling_impulse(r, g, jn, jr, wa, wb, act))
    np.maximum.at(change, island, big)
    vT[:, ai] = va
    wT[:, ai] = wa
    if hb.size:
        vT[:, bi] = vb
        wT[:, bi] = wb


def _normal_impulse(
    r: ContactRows,
    g: _Group,
    sv: np.ndarray | None,
    target: np.ndarray,
    jn: np.ndarray,
    va: np.ndarray,
    wa: np.ndarray,
    vb: np.ndarray,
    wb: np.ndarray,
    act: np.ndarray,
) -> np.ndarray:
    """The batch's normal impulses: updates jn and the batch's velocities va, wa, vb, wb (3, k) in
    place; returns the change of each normal impulse."""
    s, _, hb, _, sb = g
    n, ns = r.n, r.n[:, s]
    # normal: push (never pull) toward the target approach speed
    vn = dot3(va, ns) + dot3(wa, r.rna[:, s])
    if hb.size:
        vn[hb] = vn[hb] - (dot3(vb, n[:, sb]) + dot3(wb, r.rnb[:, sb]))
    if sv is not None:
        vn = vn - dot3(sv[:, s], ns)
    new = np.where(act, np.maximum(jn[s] + (target[s] - vn) * r.inv_kn[s], 0.0), jn[s])
    dj: np.ndarray = new - jn[s]
    jn[s] = new
    va += (r.ma[s] * dj) * ns
    wa += dj * r.gna[:, s]
    if hb.size:
        vb -= (r.mb[sb] * dj[hb]) * n[:, sb]
        wb -= dj[hb] * r.gnb[:, sb]
    return dj


def _friction_impulse(
    r: ContactRows,
    g: _Group,
    sv: np.ndarray | None,
    jn: np.ndarray,
    jt: np.ndarray,
    va: np.ndarray,
    wa: np.ndarray,
    vb: np.ndarray,
    wb: np.ndarray,
    act: np.ndarray,
) -> np.ndarray:
    """The batch's friction impulses (3, k) from the velocities after its normal impulses; updates
    jt in place and returns the change, which the caller applies."""
    s, _, hb, _, sb = g
    ns = r.n[:, s]
    # Coulomb friction: stop the sliding, within mu * (normal impulse so far)
    vel = va + cross3(wa, r.ra[:, s])
    if hb.size:
        vel[:, hb] = vel[:, hb] - (vb + cross3(wb, r.rb[:, sb]))
    if sv is not None:
        vel = vel - sv[:, s]
    vt = vel - dot3(vel, ns) * ns
    # the impulse that stops the sliding: -vt / (m_t + e.K e), e = vt/|vt|, written
    # without the square root as -vt |vt|^2 / (m_t |vt|^2 + vt.K vt)
    s2 = dot3(vt, vt)
    den = r.m_t[s] * s2 + dot3(vt, sym_matvec(r.k_t[:, s], vt))
    live = (s2 > 0.0) & (den > 0.0)
    f = np.where(live, s2 / np.where(live, den, 1.0), 0.0)
    jts = jt[:, s]
    want = jts - f * vt
    # ... within mu * (normal impulse so far)
    cap = r.friction[s] * jn[s]
    mag2 = dot3(want, want)
    over = mag2 > cap * cap
    want = np.where(over, want * (cap / np.sqrt(np.where(over, mag2, 1.0))), want)
    want = np.where(act, want, jts)
    imp: np.ndarray = want - jts
    jt[:, s] = want
    return imp


def _rolling_impulse(
    r: ContactRows,
    g: _Group,
    jn: np.ndarray,
    jr: np.ndarray,
    wa: np.ndarray,
    wb: np.ndarray,
    act: np.ndarray,
) -> np.ndarray:
    """The batch's rolling impulses (:func:`rolling_total`, the rule the numba twin calls) from
    the angular velocities after its friction: updates jr (3, C) and wa, wb (3, k) in place on
    the rows with a rolling resistance; returns each row's change as a velocity at the contact
    point (tr(K) |r_a| times the largest component of the impulse's change), 0 elsewhere."""
    s, _, hb, _, sb = g
    rel = wa.copy()
    if hb.size:
        rel[:, hb] = rel[:, hb] - wb
    n, k, old = r.n[:, s], r.k_r[:, s], jr[:, s]
    mu_r = r.rolling[s]
    new = np.stack(
        rolling_total(
            rel[0], rel[1], rel[2], n[0], n[1], n[2], k[0], k[1], k[2], k[3], k[4], k[5],
            old[0], old[1], old[2], mu_r * jn[s],
        )
    )  # fmt: skip
    live = act & (mu_r > 0.0)
    new = np.where(live, new, old)
    imp = new - old
    jr[:, s] = new
    wa[:] = np.where(live, wa + sym_matvec(r.ia[:, s], imp), wa)
    if hb.size:
        wb[:] = np.where(live[hb], wb - sym_matvec(r.ib[:, sb], imp[:, hb]), wb)
    out: np.ndarray = np.where(live, r.r_rate[s] * np.abs(imp).max(axis=0), 0.0)
    return out


def _impact_pass(
    r: ContactRows,
    limit: np.ndarray,
    dt: float,
    vT: np.ndarray,
    wT: np.ndarray,
    sweeps: int = IMPACT_SWEEPS,
) -> np.ndarray:
    """Impacts between bodies, one contact at a time, before the simultaneous solve; in place on
    vT, wT (3, B); returns which contacts were struck (C,), in the solver's order.

    A contact between two bodies with restitution, their only point of contact, that approaches
    faster than resting (``limit``), touching or closing its gap within the step, takes Newton's impulse
    ``J = -(1 + e) v_n / K`` (K the effective mass along n; Baraff 1997, section 8), and the
    contacts are swept forward and backward in turn until none is struck (at most ``sweeps``):
    the collision pass of Guendelman, Bridson and Fedkiw, SIGGRAPH 2003 (section 6). A blow is
    passed on through touching bodies one pair at a time, as in a Newton's cradle; solved all
    at once, it would be shared out and energy lost at e = 1. Contacts with restitution 0
    (stacks, resting boxes) are left to the simultaneous solve.

    The numba twin walks the list contact by contact; here a sweep takes the solver's batches
    (no body twice in one) in order, or in reverse order backward, which is the same sequence.
    """
    count = r.a.size
    struck = np.zeros(count, dtype=bool)
    if not r.coupled:
        return struck
    a, bb, n, depth, inv_kn = r.a, r.bb, r.n, r.depth, r.inv_kn
    # one point only: a face or an edge held at several points is left to the simultaneous
    # solve, where its points share the impact (struck one by one, a box landing flat on a box
    # would be set spinning)
    key = np.where(r.has_b, a * (bb.max(initial=0) + 1) + bb, -1 - np.arange(count))
    _, where, points = np.unique(key, return_inverse=True, return_counts=True)
    live = np.flatnonzero(r.has_b & (points[where] == 1) & (r.restitution > 0.0) & (inv_kn > 0.0))
    if live.size == 0:
        return struck
    levels = r.level[live]
    cuts = np.flatnonzero(np.r_[True, levels[1:] != levels[:-1]])  # live is in solver order
    groups = np.split(live, cuts[1:])
    e1 = 1.0 + r.restitution
    for sweep in range(sweeps):
        hit = False
        for s in groups if sweep % 2 == 0 else groups[::-1]:
            ai, bi = a[s], bb[s]
            ns = n[:, s]
            vn = dot3(vT[:, ai], ns) + dot3(wT[:, ai], r.rna[:, s])
            vn = vn - (dot3(vT[:, bi], ns) + dot3(wT[:, bi], r.rnb[:, s]))
            go = (vn < -limit[s]) & ((depth[s] >= 0.0) | (depth[s] - vn * dt >= 0.0))
            if not go.any():
                continue
            hit = True
            struck[s[go]] = True
            j = np.where(go, -e1[s] * vn * inv_kn[s], 0.0)
            vT[:, ai] += (r.ma[s] * j) * ns
            wT[:, ai] += j * r.gna[:, s]
            vT[:, bi] -= (r.mb[s] * j) * ns
            wT[:, bi] -= j * r.gnb[:, s]
        if not hit:
            break
    return struck


def _apply_warm(
    r: ContactRows, jn: np.ndarray, jt: np.ndarray, jr: np.ndarray, v: np.ndarray, w: np.ndarray
) -> None:
    """Apply the starting impulses jn (C,), jt (3, C), jr (3, C) to v, w (B, 3) in place: per
    contact (in the solver's order, which keeps each body's contacts in list order) its normal
    impulse on a, on b, then its friction impulse on a, on b, then its rolling impulse on a, on
    b (where it has one); ``np.add.at`` adds in index order, so every body sums as the numba
    twin's loop does."""
    a, bb, has_b, ma, mb, n, ga, gb = r.a, r.bb, r.has_b, r.ma, r.mb, r.n, r.ga, r.gb
    sn = ma * jn
    sbn = mb * jn
    rot_a = (ga[0] * jt[0] + ga[1] * jt[1]) + ga[2] * jt[2]
    rot_b = (gb[0] * jt[0] + gb[1] * jt[1]) + gb[2] * jt[2]
    # four updates per contact, interleaved: (a, normal), (b, normal), (a, friction), (b, friction)
    body = np.stack([a, bb, a, bb], axis=1).reshape(-1)
    live = np.stack([np.ones_like(has_b), has_b, np.ones_like(has_b), has_b], axis=1).reshape(-1)
    dvel = np.stack([(sn * n).T, -(sbn * n).T, (ma * jt).T, -(mb * jt).T], axis=1).reshape(-1, 3)
    np.add.at(v, body[live], dvel[live])
    turns = [(jn * r.gna).T, -(jn * r.gnb).T, rot_a.T, -rot_b.T]
    if r.rolls:  # and (a, rolling), (b, rolling) for the angular velocities
        rolled = (jr != 0.0).any(axis=0)
        body = np.stack([a, bb, a, bb, a, bb], axis=1).reshape(-1)
        live = np.stack([np.ones_like(has_b), has_b] * 2 + [rolled, has_b & rolled], axis=1).reshape(-1)
        turns += [sym_matvec(r.ia, jr).T, -sym_matvec(r.ib, jr).T]
    dw = np.stack(turns, axis=1).reshape(-1, 3)
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
    dvn = dot3(rel_dv, n)
    dxn = dot3(rel_dx, n)
    d0 = -dxn - depth
    span = d0 + depth
    s = np.clip(np.divide(d0, span, out=np.zeros_like(d0), where=span > 0), 0.0, 1.0)
    vn_imp = vn0 - (1.0 - s) * dvn
    target = np.maximum(-restitution * vn_imp + (1.0 - s) * dvn, 0.0)
    if kh == 0.0:
        return target
    kept = kept_end_speed(vn0 - dvn, np.maximum(d0, 0.0), dvn / dt, restitution * depth, restitution, kh)
    return np.where((restitution > 0.0) & (kept > 0.0), kept, target)
