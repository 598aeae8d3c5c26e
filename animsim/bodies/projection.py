"""Moving bodies out of what they touch: planes, colliders and each other (positions only).

After the impulses, a contact can still be ``depth`` inside. The projection moves the bodies
so that none is: per *group* of contacts that one push settles (a body and a plane, a body and
one face of a collider, two bodies) the deepest contact decides the push, along its normal
(several corners of a box behind one plane need one push, not the sum). A bouncing contact
is moved out by (1 + e) times its depth, where the reflected motion would have carried it
after the impact inside the step; a resting contact whose depth the step's impulses have
already taken out (negative) is brought back onto the surface, so a body never hovers.

**Stacks: shock propagation** (Guendelman, Bridson and Fedkiw, "Nonconvex rigid bodies with
stacking", SIGGRAPH 2003, section 7). Each body gets a level: 0 if it touches something that
does not move (a plane, a collider, a pinned body), else one more than the lowest level it
touches. Groups are settled from the lowest level up, and between two bodies of different
levels only the upper one moves: a box is pushed out of the box below it, never the box
below into the floor. A stack is then settled in one sweep, from the floor up; without it,
pushes shared by mass drive the lower boxes into the floor and the stack walks. Bodies of
equal level (side by side, or a pile that touches nothing still) share a push by inverse
mass. A few sweeps settle what one push unsettles elsewhere (a box on two others).

The sweeps are written on scalars for both backends (numba compiles :func:`settle`).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

#: sweeps over the groups at most ...
SWEEPS = 8
#: ... until no contact is deeper than this (m)
TOLERANCE = 1e-12


def levels(a: np.ndarray, b: np.ndarray, inv_mass: np.ndarray) -> np.ndarray:
    """Each body's distance, in contacts, from something that does not move (B,); bodies with
    no such path get B (all alike)."""
    nb = inv_mass.shape[0]
    level = np.full(nb, nb, dtype=np.int64)
    level[inv_mass <= 0.0] = 0
    level[a[b < 0]] = 0
    pair = b >= 0
    pa, pb = a[pair], b[pair]
    for step in range(1, nb):
        low_a, low_b = level[pa] < level[pb], level[pb] < level[pa]
        reach = np.concatenate([pb[low_a & (level[pa] == step - 1)], pa[low_b & (level[pb] == step - 1)]])
        reach = reach[level[reach] > step]
        if reach.size == 0:
            break
        level[reach] = step
    return level


def groups(
    a: np.ndarray, b: np.ndarray, n: np.ndarray, plane: np.ndarray, level: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The contacts ordered by group, groups from the lowest level up (then in the order they
    first appear in the list): (order (C,), starts (G + 1,)), group g being the contacts
    ``order[starts[g]:starts[g + 1]]``."""
    count = a.shape[0]
    # a group's key: (kind, body a, body b or plane, normal for colliders)
    kind = np.where(b >= 0, 2, np.where(plane >= 0, 0, 1))
    other = np.where(b >= 0, b, np.where(plane >= 0, plane, -1))
    rounded = np.where((kind == 1)[:, None], np.round(n, 12), 0.0)
    key = np.concatenate([kind[:, None], a[:, None], other[:, None], rounded], axis=1).astype(np.float64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    # a group's rank: the lower level of its bodies, then where it first appears
    low = np.where(b >= 0, np.minimum(level[a], level[np.where(b >= 0, b, 0)]), -1)
    rank_of = np.lexsort((first, low[first]))
    rank = np.empty_like(rank_of)
    rank[rank_of] = np.arange(rank_of.size)
    order = np.lexsort((np.arange(count), rank[inverse]))
    starts = np.searchsorted(rank[inverse][order], np.arange(rank_of.size + 1))
    return order.astype(np.int64), starts.astype(np.int64)


def settle(
    order: np.ndarray,
    starts: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    n: np.ndarray,
    push: np.ndarray,
    level: np.ndarray,
    inv_mass: np.ndarray,
    x: np.ndarray,
    sweeps: int,
    tolerance: float,
) -> None:
    """Sweeps over the groups (contacts ``order[starts[g]:starts[g + 1]]``): each moves its
    bodies by its deepest contact's remaining push (``push`` less how far the bodies have moved
    apart along its normal), the first sweep also by a negative one (back onto the surface),
    later sweeps only out. In place on x (B, 3)."""
    moved = np.zeros(x.shape)
    for sweep in range(sweeps):
        worst = 0.0
        for g in range(starts.shape[0] - 1):
            best, pick = -np.inf, -1
            for m in range(starts[g], starts[g + 1]):
                c = order[m]
                ai, bi = a[c], b[c]
                apart = (moved[ai, 0] * n[c, 0] + moved[ai, 1] * n[c, 1]) + moved[ai, 2] * n[c, 2]
                if bi >= 0:
                    apart -= (moved[bi, 0] * n[c, 0] + moved[bi, 1] * n[c, 1]) + moved[bi, 2] * n[c, 2]
                need = push[c] - apart
                if need > best:
                    best, pick = need, c
            if pick < 0 or (sweep > 0 and not best > tolerance):
                continue
            if best > worst:
                worst = best
            ai, bi = a[pick], b[pick]
            wa = inv_mass[ai]
            wb = inv_mass[bi] if bi >= 0 else 0.0
            if bi >= 0 and wa > 0.0 and wb > 0.0:
                # shock propagation: between levels only the upper body moves
                if level[ai] < level[bi]:
                    wa = 0.0
                elif level[bi] < level[ai]:
                    wb = 0.0
            total = wa + wb
            if not total > 0.0:
                continue
            sa, sb = best * wa / total, best * wb / total
            for k in range(3):
                moved[ai, k] += sa * n[pick, k]
                if bi >= 0:
                    moved[bi, k] -= sb * n[pick, k]
        if sweep > 0 and not worst > tolerance:
            break
    for i in range(x.shape[0]):
        for k in range(3):
            x[i, k] += moved[i, k]


@cache
def numba_settle() -> Any:
    """:func:`settle` compiled by numba."""
    from numba import njit

    return njit(cache=True)(settle)


def pushes(found: np.ndarray, left: np.ndarray, e_used: np.ndarray) -> np.ndarray:
    """How far each contact wants its bodies moved apart along its normal: ``found`` the depth
    the contact was found with, ``left`` what the step's impulses left of it. A bouncing contact
    (1 + e) times its depth, a resting one its depth, even negative (back onto the surface); a
    speculative one (found with a gap) never pulls, only pushes once the impulses took it in."""
    push = left * (1.0 + e_used)
    return np.where(found >= 0.0, push, np.where(left > 0.0, left, -np.inf))


def project(
    a: np.ndarray,
    b: np.ndarray,
    n: np.ndarray,
    push: np.ndarray,
    plane: np.ndarray,
    x: np.ndarray,
    inv_mass: np.ndarray,
    level: np.ndarray,
    compiled: bool = False,
) -> None:
    """Move the bodies x (B, 3) by the contacts' ``pushes`` (module docstring), in place;
    ``level``: the bodies' :func:`levels` for these contacts (the step's shock pass uses them too)."""
    if a.shape[0] == 0:
        return
    order, starts = groups(a, b, n, plane, level)
    run = numba_settle() if compiled else settle
    run(order, starts, a, b, np.ascontiguousarray(n), push, level, inv_mass, x, SWEEPS, TOLERANCE)
