"""Impulse collisions with infinite one-sided planes.

Detection and response follow Lander (Game Developer 1999, Eq. 3): with unit
normal N, a particle whose signed distance (X - P).N drops below zero has hit
the plane; its velocity is split into V_n = (N.V) N and V_t = V - V_n and
becomes V_t - K_r V_n. Friction is Coulomb's: the tangential speed drops by at
most ``friction`` times the change of normal speed.

Unlike the article's "back up the simulator a little and try again", the time
of impact is found inside the step by interpolating the step's start and end
(so a 1e4 m/s bullet cannot tunnel), the particle is put on the plane,
reflected, and moved on for the rest of the step with the step's mean
acceleration. If it still ends behind the plane (a sticky plane, or a
resting contact pressed by gravity) it is projected onto the plane and its
inward normal velocity removed, so resting particles stay at rest without
jitter. A particle never ends a step behind a plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# A contact approaching slower than the normal acceleration adds in this many
# steps is resting, not bouncing (a restitution velocity threshold, as rigid
# body engines use, scaled by the step so it vanishes as dt -> 0).
RESTING_STEPS = 2.0


@dataclass(frozen=True)
class ImpulsePlane:
    point: np.ndarray  # (3,) m
    normal: np.ndarray  # (3,) unit
    restitution: float
    friction: float

    @property
    def offset(self) -> float:
        """p.n: the plane is {x : x.n = offset}."""
        return float(self.point @ self.normal)


def _apply_friction(vt: np.ndarray, dvn: np.ndarray, mu: float) -> np.ndarray:
    """Reduce tangential velocities (k, 3) by at most mu * dvn (k,), never reversing them."""
    if mu == 0.0:
        return vt
    speed = np.sqrt(np.einsum("ij,ij->i", vt, vt))
    with np.errstate(divide="ignore", invalid="ignore"):
        keep = np.where(speed > 0, np.maximum(speed - mu * dvn, 0.0) / speed, 0.0)
    return vt * keep[:, None]


class PlaneColliders:
    """All impulse planes of a scene, applied after each integrator step."""

    def __init__(self, planes: list[ImpulsePlane], particle_inv_mass: np.ndarray):
        self.planes = planes
        self.inv_mass = particle_inv_mass  # shared: pool births/deaths change it
        self.label = f"plane collisions: {len(planes)} impulse plane(s), time of impact inside the step"

    def apply(
        self,
        x_old: np.ndarray,
        v_old: np.ndarray,
        x: np.ndarray,
        v: np.ndarray,
        dt: float | np.ndarray,
    ) -> bool:
        """Resolve crossings of the step x_old -> x in place; True if anything changed.

        ``dt`` may be an (N,) array of per-particle step lengths: an emitted
        particle moves only for the rest of its birth step.

        Cost: one pass over all particles per plane (a signed distance and a
        comparison); everything else works on the few that reached a plane.
        """
        touched: list[np.ndarray] = []
        for pl in self.planes:
            n = pl.normal
            # Signed distance as x.n - p.n: no (N, 3) temporary.
            d_new = x @ n - pl.offset
            cand = np.flatnonzero(d_new <= 0)
            if cand.size == 0:
                continue
            # Behind the plane, or exactly on it and still moving in (a contact
            # that would cross next step: Lander's "colliding contact"); never
            # pinned particles or dead pool slots.
            d1 = d_new[cand]
            keep = ((d1 < 0) | (v[cand] @ n < 0)) & (self.inv_mass[cand] > 0)
            hit = cand[keep]
            if hit.size == 0:
                continue
            touched.append(hit)
            d1 = d1[keep]
            xo, vo, xh, vh = x_old[hit], v_old[hit], x[hit], v[hit]
            d0 = np.maximum(xo @ n - pl.offset, 0.0)
            gap = d0 - d1
            # fraction of the step at impact; a particle ending exactly on the plane touched it at the end
            s = np.divide(d0, gap, out=np.ones_like(d0), where=gap > 0)[:, None]
            dt_hit = dt if np.ndim(dt) == 0 else np.asarray(dt)[hit][:, None]
            mean_acc = (vh - vo) / dt_hit
            xc = xo + s * (xh - xo)
            vc = vo + s * (vh - vo)
            # Reflect the approaching ones (Lander Eq. 3) with Coulomb friction.
            # An approach slower than what the pressing acceleration adds in
            # RESTING_STEPS steps is a resting contact: it stops instead of
            # bouncing, so a particle at rest does not jitter.
            vn = vc @ n
            approaching = vn < 0
            pressing = np.maximum(-(mean_acc @ n), 0.0)
            resting = approaching & (-vn <= RESTING_STEPS * pressing * np.ravel(dt_hit))
            e = np.where(resting, 0.0, pl.restitution)
            vn_new = np.where(approaching, -e * vn, vn)
            vt = vc - vn[:, None] * n
            vt = _apply_friction(vt, np.abs(vn_new - vn), pl.friction)
            vr = vt + vn_new[:, None] * n
            # Fly on for the rest of the step.
            r = (1.0 - s) * dt_hit
            x[hit] = xc + r * vr + 0.5 * r * r * mean_acc
            v[hit] = vr + r * mean_acc
        if not touched:
            return False
        # Only particles moved above can be behind a plane now: every other
        # one ended its step in front of all of them.
        self._project(x, v, touched[0] if len(touched) == 1 else np.unique(np.concatenate(touched)))
        return True

    def _project(self, x: np.ndarray, v: np.ndarray, idx: np.ndarray) -> None:
        """Put any of ``idx`` still behind a plane onto it and stop its inward motion."""
        for pl in self.planes:
            n = pl.normal
            d = x[idx] @ n - pl.offset
            sel = d < 0
            if not sel.any():
                continue
            behind = idx[sel]
            xb = x[behind] - d[sel, None] * n
            # Rounding can leave the projected point 1 ulp behind; nudge until it is not.
            for _ in range(4):
                db = xb @ n - pl.offset
                still = db < 0
                if not still.any():
                    break
                xb[still] -= (2.0 * db[still])[:, None] * n + np.spacing(np.abs(xb[still])) * np.sign(n)
            x[behind] = xb
            vb = v[behind]
            vn = vb @ n
            inward = np.minimum(vn, 0.0)
            vt = vb - vn[:, None] * n
            vt = _apply_friction(vt, -inward, pl.friction)
            v[behind] = vt + (vn - inward)[:, None] * n
