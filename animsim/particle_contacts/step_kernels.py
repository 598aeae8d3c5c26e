"""The numba kernel of one step's particle contacts, :func:`contact_step`, and the helpers it calls
(the impact pass's :func:`bounce_pair` is run by NumPy too): impacts, then the resting solve with
the walls, then the overlap removal.

The kernel and every helper it calls live in this one module: numba's disk cache checks only
the file of the function it cached, so a helper in another file could go stale in the cache
after an edit. ``contact_step`` runs the step's passes, one helper each; they share the
per-pair buffers ``pair_setup`` fills once.

**Threads.** The passes over every contact are shared among numba's threads without
changing a bit: a contact's change is written to one *slot* of each of its two particles
(``incidence``: a particle's slots hold first the pairs where it is the second sphere,
then those where it is the first, each in pair order, then its walls), and each particle
sums its own slots from 0.0 (``gather``). Pairs are sorted by (i, j) with i < j, so that
is the order in which a scatter pair by pair adds them: the sums are the same to the last
bit on any number of threads, and the same as the NumPy backend's ``np.add.at``. Not
shared (``shared`` false: a short list, or a busy machine, see
:mod:`animsim.thread_choice`), the same passes scatter pair by pair into ``dv`` on the
calling thread, through one-thread builds of the helpers (:func:`animsim.elements.one_thread`)
or a loop of their own: a test of ``shared`` inside one loop cost the one-thread passes a
quarter of their time. The helpers take the tuple ``sums`` apart before their ``prange``
loops: numba (0.68) loses the writes through an array unpacked from a tuple inside one.
"""

from __future__ import annotations

import numpy as np

from animsim.elements import (
    compile_helpers,
    numba_helper,
    numba_inline_helper,
    numba_parallel_helper,
    one_thread,
)

prange = range  # numba's prange once compiled (compile_helpers sets it for parallel helpers)


@numba_inline_helper
def normal_speed(v, i, j, n0, n1, n2):  # pragma: no cover - compiled too
    """How fast sphere j moves away from sphere i along the unit normal n (negative: closing)."""
    return (v[j, 0] - v[i, 0]) * n0 + (v[j, 1] - v[i, 1]) * n1 + (v[j, 2] - v[i, 2]) * n2


@numba_helper
def bounce_pair(i, j, n0, n1, n2, w, limit, e, v, inv_mass):  # pragma: no cover - compiled too
    """One impact between two spheres, in place on ``v``; returns the normal impulse (0.0: none).

    Newton's law of restitution for a two-body impact along the line of centres
    ``n`` (Goldstein, "Classical Mechanics", section 3.11): ``J = -(1 + e) v_n / w``
    with ``w = 1/m_i + 1/m_j``, ``+J n`` on j and ``-J n`` on i. Only an approach
    faster than ``limit`` is an impact (its bounce, e times it, would be faster than twice
    what the step's forces added to a sphere touching either); a slower one is resting contact, left
    to the Jacobi passes (a grain settling into a pile does not bounce by a hair).
    """
    vn = normal_speed(v, i, j, n0, n1, n2)
    if not -vn > limit:
        return 0.0
    jn = -(1.0 + e) * vn / w
    ci = inv_mass[i] * jn
    cj = inv_mass[j] * jn
    v[i, 0] -= ci * n0
    v[i, 1] -= ci * n1
    v[i, 2] -= ci * n2
    v[j, 0] += cj * n0
    v[j, 1] += cj * n1
    v[j, 2] += cj * n2
    return jn


@numba_helper
def approaching(pi, pj, nrm, limit, v, due, p):  # pragma: no cover - compiled
    """due[k]: pair k approaches faster than its limit now; returns how many do."""
    count = 0
    for k in range(p):
        i = pi[k]
        j = pj[k]
        due[k] = -normal_speed(v, i, j, nrm[k, 0], nrm[k, 1], nrm[k, 2]) > limit[k]
        if due[k]:
            count += 1
    return count


@numba_helper
def bounce_sweeps(pi, pj, nrm, w, limit, e, v, inv_mass, jb, due, p, sweeps):  # pragma: no cover - compiled
    """The impact pass; ``jb[k]``: pair k's impulses. Each sweep marks the pairs that approach
    faster than resting, then strikes them one after the other in pair order
    (:func:`bounce_pair`, which looks again: an earlier impact may have parted the pair),
    until no pair approaches (at most ``sweeps``).

    Sequential, not simultaneous: an impact is passed on through touching spheres one pair
    per sweep, as in the collision pass of Guendelman, Bridson and Fedkiw, "Nonconvex rigid
    bodies with stacking", SIGGRAPH 2003 (section 6). So a ball hitting a row of touching
    equal balls stops and the last one leaves with its speed (Newton's cradle); a
    simultaneous (Jacobi) solution shares the impulse and loses energy even at e = 1.
    Marking first and striking only the marked is what lets NumPy run the same pass as
    cheaply (:func:`bounce_sweeps_numpy`): its Python loop sees the impacts, not every pair.
    """
    for k in range(p):
        jb[k] = 0.0
    for _ in range(sweeps):
        if approaching(pi, pj, nrm, limit, v, due, p) == 0:
            return
        for k in range(p):
            if due[k]:
                jb[k] += bounce_pair(
                    pi[k], pj[k], nrm[k, 0], nrm[k, 1], nrm[k, 2], w[k], limit[k], e, v, inv_mass
                )


# The step kernel's pieces, in the order contact_step runs them; the per-pair buffers they
# share are filled once by ``pair_setup``.
@numba_helper
def overlapping(ci, cj, reach2, touch2, x, inv_mass, pi, pj, pk):  # pragma: no cover - compiled
    """The candidates that touch (closer than their contact distance times ``touch2``, the slop's
    margin squared): returns (how many overlap, how many touch between particles not both
    fixed); those pairs into ``pi``, ``pj`` and their candidate's index into ``pk``."""
    found = 0
    p = 0
    for k in range(ci.shape[0]):
        i = ci[k]
        j = cj[k]
        t0 = x[j, 0] - x[i, 0]
        t1 = x[j, 1] - x[i, 1]
        t2 = x[j, 2] - x[i, 2]
        d2 = t0 * t0 + t1 * t1 + t2 * t2
        if not (d2 < reach2[k] * touch2):
            continue
        if d2 < reach2[k]:
            found += 1
        if inv_mass[i] + inv_mass[j] > 0:
            pi[p] = i
            pj[p] = j
            pk[p] = k
            p += 1
    return found, p


@numba_helper
def incidence(shared, pi, pj, p, wr, sums):  # pragma: no cover - compiled
    """Each particle's contacts counted: ``start[r + 1] - start[r]`` pairs and ``wstart[r + 1]
    - wstart[r]`` walls (``sums``: see :func:`contact_step`). When the passes are ``shared`` among
    threads, also each particle's slots (see the module's "Threads"): pair k's change goes to
    slot ``sj[k]`` of its second sphere and, negated, to slot ``si[k]`` of its first;
    particle r's are ``start[r]`` to ``start[r + 1]`` (those where it is the second sphere
    first), its walls ``wlist[wstart[r]:wstart[r + 1]]``. A counting sort, in pair (and wall)
    order."""
    si, sj, slots, wc, start, wstart, wlist, dv = sums
    n = start.shape[0] - 1
    start[:] = 0
    wstart[:] = 0
    for k in range(p):
        start[pi[k] + 1] += 1
        start[pj[k] + 1] += 1
    for k in range(wr.shape[0]):
        wstart[wr[k] + 1] += 1
    for r in range(n):
        start[r + 1] += start[r]
        wstart[r + 1] += wstart[r]
    if not shared:
        return
    # the second-sphere slots come first: fill them from the start of each particle's
    # slots, the first-sphere ones from the end of its second-sphere ones (counted first)
    fill_i = start[:-1].copy()
    for k in range(p):
        fill_i[pj[k]] += 1
    fill_j = start[:-1].copy()
    for k in range(p):
        j = pj[k]
        sj[k] = fill_j[j]
        fill_j[j] += 1
        i = pi[k]
        si[k] = fill_i[i]
        fill_i[i] += 1
    fill_w = wstart[:-1].copy()
    for k in range(wr.shape[0]):
        r = wr[k]
        wlist[fill_w[r]] = k
        fill_w[r] += 1


@numba_inline_helper
def put(slots, si, sj, k, c0, c1, c2):  # pragma: no cover - compiled too
    """Pair k's change c into its slots (shared among threads): +c for its second sphere, -c
    for its first."""
    a = sj[k]
    slots[a, 0] = c0
    slots[a, 1] = c1
    slots[a, 2] = c2
    b = si[k]
    slots[b, 0] = -c0
    slots[b, 1] = -c1
    slots[b, 2] = -c2


@numba_inline_helper
def scatter(dv, i, j, c0, c1, c2):  # pragma: no cover - compiled too
    """Pair (i, j)'s change c added to its spheres' sums at once (one thread): -c to i, +c to j."""
    dv[i, 0] -= c0
    dv[i, 1] -= c1
    dv[i, 2] -= c2
    dv[j, 0] += c0
    dv[j, 1] += c1
    dv[j, 2] += c2


@numba_helper
def clear(a, value):  # pragma: no cover - compiled
    """a[:] = value, as a plain loop: a one-thread pass's sums start from it (in a parallel
    helper ``a[:] = value`` would start threads)."""
    for r in range(a.shape[0]):
        for c in range(a.shape[1]):
            a[r, c] = value


@numba_parallel_helper
def gather(out, slots, wc, start, wstart, wlist, inv_mass):  # pragma: no cover - compiled
    """out[r] += (the sum of r's slots, then of its walls' changes ``wc``, from 0.0) / m_r for
    every row, each on its own thread's share: the bits a scatter pair by pair and then wall
    by wall gives (a - c is a + (-c) in IEEE arithmetic)."""
    for r in prange(out.shape[0]):
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        for q in range(start[r], start[r + 1]):
            a0 += slots[q, 0]
            a1 += slots[q, 1]
            a2 += slots[q, 2]
        for q in range(wstart[r], wstart[r + 1]):
            k = wlist[q]
            a0 += wc[k, 0]
            a1 += wc[k, 1]
            a2 += wc[k, 2]
        w_r = inv_mass[r]
        out[r, 0] += a0 * w_r
        out[r, 1] += a1 * w_r
        out[r, 2] += a2 * w_r


@numba_helper
def apply(shared, sums, out, wr, inv_mass):  # pragma: no cover - compiled
    """out += the pass's sums (pairs, then the walls' ``wc``) / m, for every row."""
    si, sj, slots, wc, start, wstart, wlist, dv = sums
    if shared:
        gather(out, slots, wc, start, wstart, wlist, inv_mass)
        return
    for k in range(wr.shape[0]):
        r = wr[k]
        dv[r, 0] += wc[k, 0]
        dv[r, 1] += wc[k, 1]
        dv[r, 2] += wc[k, 2]
    for r in range(out.shape[0]):
        w_r = inv_mass[r]
        for a in range(3):
            out[r, a] += dv[r, a] * w_r


@numba_inline_helper
def contacts_of(r, start, wstart):  # pragma: no cover - compiled too
    """How many contacts particle r has this step, pairs and walls (:func:`incidence`)."""
    return (start[r + 1] - start[r]) + (wstart[r + 1] - wstart[r])


@numba_parallel_helper
def pair_setup(
    pi, pj, p, wr, x, inv_mass, relax_factor, w, rel, wrel, nrm, sums
):  # pragma: no cover - compiled
    """Per pair: ``w`` the summed inverse masses, ``rel`` the relaxation (averaged over the
    contacts per particle, its slots and walls, :func:`incidence`; ``wrel`` a wall contact's)
    over ``w`` (what turns a change of relative velocity or position into the pair's share of
    it) and ``nrm`` the unit line of centres."""
    start, wstart = sums[4], sums[5]
    for k in range(wr.shape[0]):
        r = wr[k]
        wrel[k] = min(relax_factor / contacts_of(r, start, wstart), 1.0) / inv_mass[r]
    for k in prange(p):
        i = pi[k]
        j = pj[k]
        w[k] = inv_mass[i] + inv_mass[j]
        rel[k] = (
            min(relax_factor / max(contacts_of(i, start, wstart), contacts_of(j, start, wstart)), 1.0) / w[k]
        )
        d2 = 0.0
        for a in range(3):
            t = x[j, a] - x[i, a]
            nrm[k, a] = t
            d2 += t * t
        dist = np.sqrt(d2)
        if dist > 0:
            for a in range(3):
                nrm[k, a] /= dist
        else:
            nrm[k, 0], nrm[k, 1], nrm[k, 2] = 0.0, 1.0, 0.0


@numba_helper
def step_change(pi, pj, p, v, v_old, added, near):  # pragma: no cover - compiled
    """``near[r]``: the largest change of velocity the step made (before the contacts,
    ``added[r] = |v - v_old|``) to row r or to a sphere touching it: what resting contact
    may take off again (an impact is faster, :func:`bounce_limits`; :func:`follow`)."""
    for r in range(v.shape[0]):
        t0 = v[r, 0] - v_old[r, 0]
        t1 = v[r, 1] - v_old[r, 1]
        t2 = v[r, 2] - v_old[r, 2]
        added[r] = np.sqrt((t0 * t0 + t1 * t1) + t2 * t2)
        near[r] = 0.0
    for k in range(p):
        both = max(added[pi[k]], added[pj[k]])
        near[pi[k]] = max(near[pi[k]], both)
        near[pj[k]] = max(near[pj[k]], both)


@numba_helper
def bounce_limits(pi, pj, p, limit, near, e, resting_steps, bounce_floor):  # pragma: no cover - compiled
    """``limit``: each pair's impact limit, an approach whose bounce, ``e`` times it, would be
    faster than ``resting_steps`` times the larger ``near`` of its spheres."""
    for k in range(p):
        limit[k] = (resting_steps * max(near[pi[k]], near[pj[k]]) + bounce_floor) / e


@numba_inline_helper
def cone(f0, f1, f2, cap):  # pragma: no cover - compiled too
    """The friction impulse f cut to Coulomb's bound |f| <= cap (cap = mu times the normal one)."""
    m = np.sqrt((f0 * f0 + f1 * f1) + f2 * f2)
    if m > cap:
        s = cap / m
        return f0 * s, f1 * s, f2 * s
    return f0, f1, f2


@numba_inline_helper
def warm_pair(k, pk, nrm, lam_c, ft_c, stamp_c, stamp, lam, ft, jb, mu):  # pragma: no cover - compiled too
    """Pair k's impulses of the last step, if it overlapped then (``stamp_c == stamp - 1``),
    into ``lam``, ``ft`` (the friction impulse without its part along the new normal, cut to
    the cone); returns the change of velocity times mass they make, n lam + f."""
    c = pk[k]
    n0, n1, n2 = nrm[k, 0], nrm[k, 1], nrm[k, 2]
    if stamp_c[c] == stamp - 1:
        lam[k] = lam_c[c]
        fn = (ft_c[c, 0] * n0 + ft_c[c, 1] * n1) + ft_c[c, 2] * n2
        f0, f1, f2 = cone(
            ft_c[c, 0] - fn * n0, ft_c[c, 1] - fn * n1, ft_c[c, 2] - fn * n2, mu * (lam[k] + jb[k])
        )
    else:
        lam[k], f0, f1, f2 = 0.0, 0.0, 0.0, 0.0
    ft[k, 0], ft[k, 1], ft[k, 2] = f0, f1, f2
    return lam[k] * n0 + f0, lam[k] * n1 + f1, lam[k] * n2 + f2


@numba_parallel_helper
def warm_start(
    pi, pj, pk, p, nrm, lam_c, ft_c, stamp_c, stamp, lam, ft, jb, mu, wr, wn, wmu, wlam, wft, v, inv_mass,
    shared, sums,
):  # pragma: no cover - compiled  # fmt: skip
    """Every contact's impulses of the last step applied again (:func:`warm_pair`; the walls'
    ``wlam``, ``wft`` as the caller found them, their friction likewise cut to the cone)."""
    si, sj, slots, wc, start, wstart, wlist, dv = sums
    if shared:
        for k in prange(p):
            c0, c1, c2 = warm_pair(k, pk, nrm, lam_c, ft_c, stamp_c, stamp, lam, ft, jb, mu)
            put(slots, si, sj, k, c0, c1, c2)
    else:
        clear(dv, 0.0)
        for k in range(p):
            c0, c1, c2 = warm_pair(k, pk, nrm, lam_c, ft_c, stamp_c, stamp, lam, ft, jb, mu)
            scatter(dv, pi[k], pj[k], c0, c1, c2)
    for k in range(wr.shape[0]):
        n0, n1, n2 = wn[k, 0], wn[k, 1], wn[k, 2]
        fn = (wft[k, 0] * n0 + wft[k, 1] * n1) + wft[k, 2] * n2
        f0, f1, f2 = cone(wft[k, 0] - fn * n0, wft[k, 1] - fn * n1, wft[k, 2] - fn * n2, wmu[k] * wlam[k])
        wft[k, 0], wft[k, 1], wft[k, 2] = f0, f1, f2
        wc[k, 0] = wlam[k] * n0 + f0
        wc[k, 1] = wlam[k] * n1 + f1
        wc[k, 2] = wlam[k] * n2 + f2
    apply(shared, sums, v, wr, inv_mass)


@numba_inline_helper
def contact_update(r0, r1, r2, n0, n1, n2, rw, lam, f0, f1, f2, cap_mu, extra):  # pragma: no cover
    """One contact's Jacobi update from its relative velocity r (of the second body against the
    first) and normal n (``rw``: its relaxation over its summed inverse masses): the accumulated
    normal impulse ``lam`` kept >= 0 and the friction impulse f within ``cap_mu * (lam +
    extra)``; returns the new lam, f and their changes."""
    vn = (r0 * n0 + r1 * n1) + r2 * n2
    new = max(lam - vn * rw, 0.0)
    cap = cap_mu * (new + extra)
    if cap == 0.0 and f0 == 0.0 and f1 == 0.0 and f2 == 0.0:  # no friction to give: none
        return new, 0.0, 0.0, 0.0, new - lam, 0.0, 0.0, 0.0
    g0, g1, g2 = cone(f0 - (r0 - vn * n0) * rw, f1 - (r1 - vn * n1) * rw, f2 - (r2 - vn * n2) * rw, cap)
    return new, g0, g1, g2, new - lam, g0 - f0, g1 - f1, g2 - f2


@numba_inline_helper
def small(a, b, c, d, w, tol):  # pragma: no cover - compiled too
    """Each of a contact's four impulse changes (normal, friction vector) times ``w`` is at most
    ``tol`` (a NaN is not)."""
    return abs(a) * w <= tol and abs(b) * w <= tol and abs(c) * w <= tol and abs(d) * w <= tol


@numba_inline_helper
def rest_pair(k, pi, pj, nrm, w, rel, lam, ft, jb, mu, v, tol):  # pragma: no cover - compiled too
    """Pair k's resting update from the velocities before the pass (:func:`contact_update`),
    in place on ``lam``, ``ft``; returns its change c and whether it changed at all and by
    more than ``tol`` (1 or 0 each)."""
    i = pi[k]
    j = pj[k]
    n0, n1, n2 = nrm[k, 0], nrm[k, 1], nrm[k, 2]
    lam[k], ft[k, 0], ft[k, 1], ft[k, 2], dl, d0, d1, d2 = contact_update(
        v[j, 0] - v[i, 0], v[j, 1] - v[i, 1], v[j, 2] - v[i, 2],
        n0, n1, n2, rel[k], lam[k], ft[k, 0], ft[k, 1], ft[k, 2], mu, jb[k],
    )  # fmt: skip
    moved = 0
    big = 0
    if dl != 0.0 or d0 != 0.0 or d1 != 0.0 or d2 != 0.0:
        moved = 1
        if not small(dl, d0, d1, d2, w[k], tol):
            big = 1
    return dl * n0 + d0, dl * n1 + d1, dl * n2 + d2, moved, big


@numba_parallel_helper
def pair_pass(pi, pj, p, nrm, w, rel, lam, ft, jb, mu, v, tol, shared, sums):  # pragma: no cover - compiled
    """One resting pass's pair updates (:func:`rest_pair`), each change into its slots when
    ``shared``, else into ``dv``; returns (how many contacts changed, how many by more than
    ``tol``)."""
    si, sj, slots, wc, start, wstart, wlist, dv = sums
    moved = 0
    big = 0
    if shared:
        for k in prange(p):
            c0, c1, c2, m, g = rest_pair(k, pi, pj, nrm, w, rel, lam, ft, jb, mu, v, tol)
            moved += m
            big += g
            put(slots, si, sj, k, c0, c1, c2)
    else:
        clear(dv, 0.0)
        for k in range(p):
            c0, c1, c2, m, g = rest_pair(k, pi, pj, nrm, w, rel, lam, ft, jb, mu, v, tol)
            moved += m
            big += g
            scatter(dv, pi[k], pj[k], c0, c1, c2)
    return moved, big


@numba_helper
def resting_passes(
    pi, pj, p, nrm, w, rel, lam, ft, jb, mu, wr, wn, wu, wmu, wrel, wlam, wft, v, inv_mass, iterations, tol,
    shared, sums,
):  # pragma: no cover - compiled  # fmt: skip
    """The Jacobi passes of the resting contacts (pairs, then walls): each stores every
    contact's change, then every particle adds its sum / m (:func:`apply`); a pass that
    changed nothing adds nothing. A pass in which no contact's change of impulse times its
    summed inverse masses (``w``; a wall's: its grain's) exceeds ``tol`` is the last; returns
    how many passes ran."""
    wc = sums[3]
    passes = 0
    for _ in range(iterations):
        passes += 1
        moved, big = pair_pass(pi, pj, p, nrm, w, rel, lam, ft, jb, mu, v, tol, shared, sums)
        for k in range(wr.shape[0]):
            r = wr[k]
            n0, n1, n2 = wn[k, 0], wn[k, 1], wn[k, 2]
            wlam[k], wft[k, 0], wft[k, 1], wft[k, 2], dl, d0, d1, d2 = contact_update(
                v[r, 0] - wu[k, 0], v[r, 1] - wu[k, 1], v[r, 2] - wu[k, 2],
                n0, n1, n2, wrel[k], wlam[k], wft[k, 0], wft[k, 1], wft[k, 2], wmu[k], 0.0,
            )  # fmt: skip
            if dl != 0.0 or d0 != 0.0 or d1 != 0.0 or d2 != 0.0:
                moved += 1
                if not small(dl, d0, d1, d2, inv_mass[r], tol):
                    big += 1
            wc[k, 0] = dl * n0 + d0
            wc[k, 1] = dl * n1 + d1
            wc[k, 2] = dl * n2 + d2
        if moved > 0:
            apply(shared, sums, v, wr, inv_mass)
        if big == 0:
            break
    return passes


@numba_parallel_helper
def follow(x, v, v0, near, resting_steps, dt):  # pragma: no cover - compiled
    """x += (v - v0) dt, the step's position as if the resting impulses had acted before it, for
    as much of the change as resting contact may make (``resting_steps * near``): what held a
    resting grain against gravity moves it back by g dt^2, but a grain stopped from a fast
    approach keeps its position (the overlap passes part it) instead of being put back where
    it was."""
    for r in prange(x.shape[0]):
        allow = resting_steps * near[r]
        d0 = v[r, 0] - v0[r, 0]
        d1 = v[r, 1] - v0[r, 1]
        d2 = v[r, 2] - v0[r, 2]
        m = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
        s = dt * (allow / m) if m > allow else dt
        x[r, 0] += d0 * s
        x[r, 1] += d1 * s
        x[r, 2] += d2 * s


@numba_inline_helper
def overlap_pair(k, pi, pj, x, radius, rel):  # pragma: no cover - compiled too
    """Pair k's overlap correction from the positions before the pass, along its line of
    centres: (c, whether it overlaps, whether c is not zero)."""
    i = pi[k]
    j = pj[k]
    d0 = x[j, 0] - x[i, 0]
    d1 = x[j, 1] - x[i, 1]
    d2 = x[j, 2] - x[i, 2]
    dist = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    over = radius[i] + radius[j] - dist
    if over <= 0:
        return 0.0, 0.0, 0.0, False, 0
    if dist > 0:
        d0, d1, d2 = d0 / dist, d1 / dist, d2 / dist
    else:
        d0, d1, d2 = 0.0, 1.0, 0.0
    c = over * rel[k]
    return c * d0, c * d1, c * d2, True, 1 if c != 0.0 else 0


@numba_parallel_helper
def overlap_pass(pi, pj, p, x, radius, rel, shared, sums):  # pragma: no cover - compiled
    """One overlap pass's pair corrections (:func:`overlap_pair`), into their slots when
    ``shared`` (a pair that does not overlap puts -0.0, which adds nothing to any sum), else
    into ``dv`` (it adds nothing); returns how many pairs moved."""
    si, sj, slots, wc, start, wstart, wlist, dv = sums
    moved = 0
    if shared:
        for k in prange(p):
            c0, c1, c2, over, m = overlap_pair(k, pi, pj, x, radius, rel)
            moved += m
            if over:
                put(slots, si, sj, k, c0, c1, c2)
            else:
                put(slots, si, sj, k, -0.0, -0.0, -0.0)
    else:
        clear(dv, 0.0)
        for k in range(p):
            c0, c1, c2, over, m = overlap_pair(k, pi, pj, x, radius, rel)
            moved += m
            if over:
                scatter(dv, pi[k], pj[k], c0, c1, c2)
    return moved


@numba_helper
def position_passes(
    pi, pj, p, x, radius, rel, inv_mass, iterations, wr, shared, sums
):  # pragma: no cover - compiled
    """The Jacobi passes on position: each pair's overlap pushed apart along its current line
    of centres, as :func:`resting_passes` does velocities (the walls take no part: their
    changes are -0.0)."""
    wc = sums[3]
    wc[:] = -0.0
    for _ in range(iterations):
        if overlap_pass(pi, pj, p, x, radius, rel, shared, sums) == 0:
            break
        apply(shared, sums, x, wr, inv_mass)


@numba_parallel_helper
def remember(pk, p, lam, ft, lam_c, ft_c, stamp_c, stamp):  # pragma: no cover - compiled
    """Each overlapping pair's impulses kept under its candidate for the next step's warm start."""
    for k in prange(p):
        c = pk[k]
        lam_c[c] = lam[k]
        ft_c[c, 0], ft_c[c, 1], ft_c[c, 2] = ft[k, 0], ft[k, 1], ft[k, 2]
        stamp_c[c] = stamp


# The one-thread builds of the shared helpers that only loop over their rows (the same code,
# no threads started): what contact_step calls when it is not shared. The passes that sum
# contacts into particles instead keep a loop of each kind (slots or a scatter): a test of
# ``shared`` inside one loop cost a quarter of the one-thread passes' time.
pair_setup_one = one_thread(pair_setup)
follow_one = one_thread(follow)
remember_one = one_thread(remember)


@numba_helper
def contact_step(
    ci, cj, reach2, touch2, x, v, v_old, inv_mass, radius, e, mu, iterations, overlap_passes, relax_factor, dt,
    pi, pj, pk, w, rel, nrm, limit, lam, ft, jb, due, lam_c, ft_c, stamp_c, stamp,
    wr, wn, wu, wmu, wrel, wlam, wft, v0, added, near, resting_steps, bounce_floor, bounce_limit, converged,
    shared, sums,
):  # pragma: no cover - compiled  # fmt: skip
    """Keep the candidates that overlap, then the passes of :func:`resolve_pairs_numpy`.

    ``pi`` .. ``jb``: buffers of at least the candidates' length; ``lam_c``, ``ft_c``,
    ``stamp_c``: the candidates' impulses and the step they were kept at; ``wr`` .. ``wft``:
    the wall contacts (:class:`animsim.particle_contacts.walls.WallContacts`, their
    remembered impulses in ``wlam``, ``wft``, which end as this step's); ``v0`` (N, 3),
    ``added``, ``near`` (N,): per particle. ``sums`` = (``si``, ``sj`` (P,) each pair's slots,
    ``slots`` (2 P, 3), ``wc`` (W, 3) the walls' changes, ``start``, ``wstart`` (N + 1,) each
    particle's first slot and wall, ``wlist`` (W,) the walls by particle, ``dv`` (N, 3)): the
    arrays the passes sum the contacts' changes in (:func:`incidence`); ``shared``: the passes
    share their contacts among numba's threads (slots), else run on this one (``dv``).
    Returns (overlapping pairs, whether any pair was resolved, how many resting passes ran).
    """
    found, p = overlapping(ci, cj, reach2, touch2, x, inv_mass, pi, pj, pk)
    if p == 0:
        return found, False, 0
    incidence(shared, pi, pj, p, wr, sums)
    if shared:
        pair_setup(pi, pj, p, wr, x, inv_mass, relax_factor, w, rel, wrel, nrm, sums)
    else:
        pair_setup_one(pi, pj, p, wr, x, inv_mass, relax_factor, w, rel, wrel, nrm, sums)
    step_change(pi, pj, p, v, v_old, added, near)
    # impacts first, sequentially (see bounce_sweeps), when anything bounces at all
    if e > 0:
        bounce_limits(pi, pj, p, limit, near, e, resting_steps, bounce_floor)
        bounce_sweeps(pi, pj, nrm, w, limit, e, v, inv_mass, jb, due, p, bounce_limit)
    else:
        for k in range(p):
            jb[k] = 0.0
    v0[:] = v
    warm_start(
        pi, pj, pk, p, nrm, lam_c, ft_c, stamp_c, stamp, lam, ft, jb, mu, wr, wn, wmu, wlam, wft, v, inv_mass,
        shared, sums,
    )  # fmt: skip
    passes = resting_passes(
        pi, pj, p, nrm, w, rel, lam, ft, jb, mu, wr, wn, wu, wmu, wrel, wlam, wft, v, inv_mass, iterations,
        converged, shared, sums,
    )  # fmt: skip
    if shared:
        follow(x, v, v0, near, resting_steps, dt)
    else:
        follow_one(x, v, v0, near, resting_steps, dt)
    position_passes(pi, pj, p, x, radius, rel, inv_mass, overlap_passes, wr, shared, sums)
    if shared:
        remember(pk, p, lam, ft, lam_c, ft_c, stamp_c, stamp)
    else:
        remember_one(pk, p, lam, ft, lam_c, ft_c, stamp_c, stamp)
    return found, True, passes


_STEP = None


def compiled_step():  # type: ignore[no-untyped-def]
    """:func:`contact_step` compiled (or loaded from numba's disk cache) on first use."""
    global _STEP
    if _STEP is None:
        compile_helpers(globals())
        _STEP = globals()["contact_step"]
    return _STEP
