"""The response rules every contact shares: what a bounce keeps, resting, Coulomb friction.

Impulse planes (:mod:`animsim.collisions.stage`), solid colliders (:mod:`animsim.colliders`)
and rigid bodies (:mod:`animsim.bodies`) reflect a contact's normal speed and take friction off
its tangential speed by these rules, in NumPy (whole rows) and as numba helpers (one row,
compiled into the kernels that call them).

Restitution keeps e^2 of the energy the method itself conserves. A method that is
not exact under a constant acceleration a keeps a shifted energy instead of E:
symplectic Euler keeps H = E + (dt / 2) a.v exactly in free flight (the modified
energy of backward error analysis; Hairer, Lubich and Wanner, "Geometric Numerical
Integration", 2006, ch. IX), explicit Euler E - (dt / 2) a.v. A bounce that kept E
would drop H by dt |a.n| |v.n| each time (the ball of the course notes, dropped at
dt = 0.01, came 4.4 % low after one bounce and 13 % after three with e = 1). So on
a bounce (:func:`kept_bounce_speed`) the normal speed after the impact is the one
whose H, at the end of the step, is e^2 times the H the row had at its start: every
apex then reaches e^(2n) of the first, as the exact motion does.
"""

from __future__ import annotations

import numpy as np

from animsim.elements import numba_inline_helper
from animsim.vec import dot3

# A contact approaching slower than the normal acceleration adds in this many
# steps is resting, not bouncing (a restitution velocity threshold, as rigid
# body engines use, scaled by the step so it vanishes as dt -> 0).
RESTING_STEPS = 2.0


def apply_friction(vt: np.ndarray, dvn: np.ndarray, mu: float) -> np.ndarray:
    """Reduce tangential velocities (k, 3) by at most mu * dvn (k,), never reversing them."""
    if mu == 0.0:
        return vt
    out = vt.copy()
    k = len(vt)
    friction_rows(out, dvn, mu, np.empty(k), np.empty(k), np.empty(k, dtype=bool))
    return out


def scale_rows(a: np.ndarray, s: np.ndarray) -> None:
    """a *= s[:, None] column by column: broadcasting with an inner axis of 3 runs NumPy's
    loop 3 elements at a time, several times slower; the products are the same."""
    for j in range(3):
        np.multiply(a[:, j], s, out=a[:, j])


def friction_rows(
    vt: np.ndarray, dvn: np.ndarray, mu: float, speed: np.ndarray, keep: np.ndarray, moving: np.ndarray
) -> None:
    """Coulomb friction on vt (k, 3) in place: each row's speed drops by at most mu * dvn (k,)
    and never reverses, vt * max(|vt| - mu dvn, 0) / |vt| (0 at rest). ``speed``, ``keep`` (k,)
    and ``moving`` (k,) bool are scratch arrays."""
    dot3(vt, vt, out=speed)
    np.sqrt(speed, out=speed)
    np.multiply(dvn, mu, out=keep)
    np.subtract(speed, keep, out=keep)
    np.maximum(keep, 0.0, out=keep)
    np.greater(speed, 0, out=moving)
    np.divide(keep, speed, out=keep, where=moving)
    np.copyto(keep, 0.0, where=~moving)
    scale_rows(vt, keep)


def hold_by_static_friction(
    vr: np.ndarray, vn_new: np.ndarray, acc: np.ndarray, n: np.ndarray, mu: float
) -> None:
    """Zero ``acc`` (k, 3) on the rows that static friction holds for the rest of the step
    (the NumPy form of :func:`static_friction_holds`, with the same operations); ``n`` is
    one normal (3,) or a normal per row (k, 3)."""
    still = (vn_new == 0.0) & ((vr[:, 0] * vr[:, 0] + vr[:, 1] * vr[:, 1]) + vr[:, 2] * vr[:, 2] == 0.0)
    if not still.any():
        return
    nr = n.reshape(-1, 3)
    an = (acc[:, 0] * nr[:, 0] + acc[:, 1] * nr[:, 1]) + acc[:, 2] * nr[:, 2]
    at = acc - an[:, None] * nr
    held = (
        still
        & (an < 0.0)
        & ((at[:, 0] * at[:, 0] + at[:, 1] * at[:, 1]) + at[:, 2] * at[:, 2] <= (mu * an) * (mu * an))
    )
    acc[held] = 0.0


@numba_inline_helper
def static_friction_holds(vr0, vr1, vr2, vn_new, a0, a1, a2, n0, n1, n2, mu, friction):
    """Static friction holds the row for the rest of the step: it stopped on the plane (no
    normal nor tangential speed left), the step's acceleration a presses it on (a.n < 0),
    and Coulomb's cone holds a's tangential part, |a_t| <= mu |a.n|. The plane's normal
    force and friction then cancel a, so the flight after the impact is no flight: without
    this the row slid (1/2) a_t r^2 a step and crept down any slope."""
    if not friction or vn_new != 0.0 or vr0 * vr0 + vr1 * vr1 + vr2 * vr2 != 0.0:
        return False
    an = a0 * n0 + a1 * n1 + a2 * n2
    at0 = a0 - an * n0
    at1 = a1 - an * n1
    at2 = a2 - an * n2
    return an < 0.0 and at0 * at0 + at1 * at1 + at2 * at2 <= (mu * an) * (mu * an)


def energy_shift(follow_weight: float | None) -> float:
    """kappa = c - 1/2 of :func:`kept_bounce_speed` for a method's c (a contact stage's
    ``follow_weight``, 1 until compile sets it): how far the energy the method conserves under
    a constant acceleration is shifted from E; 0 for the methods exact there."""
    return (1.0 if follow_weight is None else follow_weight) - 0.5


@numba_inline_helper
def kept_bounce_speed(u0, d0, an, r, e, kh):
    """The normal speed w after a bounce that keeps e^2 of the method's energy in the normal
    direction, H = u^2 / 2 - an d + kappa dt an u (module docstring), NaN-free only where the
    caller uses it. Scalars or arrays alike (one rule for both backends).

    ``u0``, ``d0``: the row's normal speed and its distance from the surface at the step's
    start; ``an``: the step's normal acceleration; ``r``: the rest of the step after the
    impact, flown at that acceleration; ``kh``: kappa dt, kappa = c - 1/2 for the method's
    c of :func:`animsim.contact_stages.follow_weight`. After the impact at the surface, the
    flight gives u = w + an r and E = w^2 / 2 at the step's end, so H there is
    w^2 / 2 + kh an (w + an r); setting it to e^2 H(start) gives
    w = -kh an + sqrt((kh an)^2 - 2 kh an^2 r + 2 e^2 H(start)).
    """
    beta = kh * an
    before = 0.5 * u0 * u0 - an * d0 + beta * u0
    disc = beta * beta - 2.0 * beta * an * r + 2.0 * (e * e) * before
    return np.sqrt(np.maximum(disc, 0.0)) - beta


@numba_inline_helper
def kept_end_speed(u0, d0, an, d1, e, kh):
    """The normal speed at the end of a step that bounced, for a caller that placed the row at
    distance ``d1`` from the surface by its own rule (bodies: the penetration mirrored, e
    depth): the speed whose H (:func:`kept_bounce_speed`) there is e^2 times the H of the
    step's start (``u0``, ``d0``): u^2 / 2 - an d1 + kh an u = e^2 H(start)."""
    beta = kh * an
    before = 0.5 * u0 * u0 - an * d0 + beta * u0
    disc = beta * beta + 2.0 * ((e * e) * before + an * d1)
    return np.sqrt(np.maximum(disc, 0.0)) - beta
