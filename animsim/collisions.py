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
from typing import Any

import numpy as np

from animsim.elements import BuildContext, StepStage, numba_helper, register
from animsim.scene import models as m
from animsim.vec import dot3, outer3, put_rows, rep3, take_rows

#: penalty stiffness when a penalty plane names none, N/m
DEFAULT_PENALTY_STIFFNESS = 1e4

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
    speed = np.sqrt(dot3(vt, vt))
    with np.errstate(divide="ignore", invalid="ignore"):
        keep = np.where(speed > 0, np.maximum(speed - mu * dvn, 0.0) / speed, 0.0)
    return vt * rep3(keep)


class PlaneColliders(StepStage):
    """All impulse planes of a scene, applied after each integrator step."""

    def __init__(self, planes: list[ImpulsePlane], particle_inv_mass: np.ndarray, *, numba: bool = False):
        self.planes = planes
        self.inv_mass = particle_inv_mass  # rebound to the live state's by reset()
        self.numba = numba
        self.label = f"plane collisions: {len(planes)} impulse plane(s), time of impact inside the step"
        self.dissipative = any(p.restitution < 1 or p.friction > 0 for p in planes)

    collides_newborns = True
    #: each particle meets the planes by itself (its own rows of the step's start and end)
    pointwise = True
    no_closed_form = "it has planes (collisions have no closed form here)"

    #: (N,) bool rows this stage may touch, or None for all (bodies have their own contacts)
    point_rows: np.ndarray | None = None

    def reset(self, state: Any) -> None:
        self.inv_mass = state.particle_inv_mass

    def collide_subset(
        self, x_old: np.ndarray, v_old: np.ndarray, x: np.ndarray, v: np.ndarray, dt: np.ndarray
    ) -> None:
        """Collide a few newborn particles (all movable) over their own step lengths ``dt`` (k,)."""
        PlaneColliders(self.planes, np.ones(len(x))).resolve(x_old, v_old, x, v, dt)

    def apply(
        self, state: Any, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float, dt: float
    ) -> bool:
        x, v = state.particle_position, state.particle_velocity
        if self.point_rows is not None:
            # body centres are not particles: no mass here, so no plane moves them (bodies have
            # their own contacts); recomputed per step because births change the live masses
            self.inv_mass = np.where(self.point_rows, state.particle_inv_mass, 0.0)
        if self.numba:
            fp, ip = self.numba_stage_params()
            inv_mass = self.inv_mass if self.inv_mass.flags.writeable else self.inv_mass.copy()
            return bool(self.numba_stage(x_old, v_old, x, v, dt, inv_mass, fp, ip))
        return self.resolve(x_old, v_old, x, v, dt)

    def numba_stage_params(self) -> tuple[np.ndarray, np.ndarray]:
        fp = np.concatenate(
            [[len(self.planes)]] + [[*p.normal, p.offset, p.restitution, p.friction] for p in self.planes]
        )
        return fp.astype(np.float64), np.zeros(0, dtype=np.int64)

    def resolve(
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
        single = len(self.planes) == 1
        for pl in self.planes:
            n = pl.normal
            # Signed distance as x.n - p.n: no (N, 3) temporary.
            d_new = dot3(x, n) - pl.offset
            cand = np.flatnonzero(d_new <= 0)
            if cand.size == 0:
                continue
            # Behind the plane, or exactly on it and still moving in (a contact
            # that would cross next step: Lander's "colliding contact"); never
            # pinned particles or dead pool slots.
            d1 = d_new[cand]
            keep = ((d1 < 0) | (dot3(take_rows(v, cand), n) < 0)) & (self.inv_mass[cand] > 0)
            hit = cand[keep]
            if hit.size == 0:
                continue
            touched.append(hit)
            d1 = d1[keep]
            # rows gathered with np.take and written back with put_rows: the same values as
            # fancy indexing, a third of its cost (these gathers were most of the stage)
            xo, vo, xh, vh = (
                take_rows(x_old, hit),
                take_rows(v_old, hit),
                take_rows(x, hit),
                take_rows(v, hit),
            )
            d0 = np.maximum(dot3(xo, n) - pl.offset, 0.0)
            gap = d0 - d1
            # fraction of the step at impact; a particle ending exactly on the plane touched it at the end
            s = np.divide(d0, gap, out=np.ones_like(d0), where=gap > 0)
            # (k, 3) copies of per-row factors (rep3, outer3): the products of the
            # broadcast forms, without NumPy's slow inner loop of three
            s3 = rep3(s)
            dt_row = dt if np.ndim(dt) == 0 else np.asarray(dt)[hit]
            dv = vh - vo
            mean_acc = dv / (dt_row if np.ndim(dt_row) == 0 else dt_row[:, None])
            xh -= xo
            xh *= s3
            xc = np.add(xo, xh, out=xh)  # xo + s (xh - xo)
            dv *= s3
            vc = np.add(vo, dv, out=dv)  # vo + s (vh - vo)
            # Reflect the approaching ones (Lander Eq. 3) with Coulomb friction.
            # An approach slower than what the pressing acceleration adds in
            # RESTING_STEPS steps is a resting contact: it stops instead of
            # bouncing, so a particle at rest does not jitter.
            vn = dot3(vc, n)
            approaching = vn < 0
            pressing = np.maximum(-dot3(mean_acc, n), 0.0)
            resting = approaching & (-vn <= RESTING_STEPS * pressing * dt_row)
            e = np.where(resting, 0.0, pl.restitution)
            vn_new = np.where(approaching, -e * vn, vn)
            vt = vc - outer3(vn, n)
            vt = _apply_friction(vt, np.abs(vn_new - vn), pl.friction)
            vr = vt + outer3(vn_new, n)
            # Fly on for the rest of the step.
            r = (1.0 - s) * dt_row
            r3 = rep3(r)
            x_hit = xc + r3 * vr + rep3(0.5 * r * r) * mean_acc
            v_hit = vr + r3 * mean_acc
            if single:  # one plane: settle the rows before writing them back, once
                self._project_rows(x_hit, v_hit)
            put_rows(x, hit, x_hit)
            put_rows(v, hit, v_hit)
        if not touched:
            return False
        if not single:
            # Only particles moved above can be behind a plane now: every other
            # one ended its step in front of all of them.
            self._project(x, v, np.unique(np.concatenate(touched)))
        return True

    def _project(self, x: np.ndarray, v: np.ndarray, idx: np.ndarray) -> None:
        """Put any of ``idx`` still behind a plane onto it and stop its inward motion."""
        xs, vs = take_rows(x, idx), take_rows(v, idx)
        self._project_rows(xs, vs)
        put_rows(x, idx, xs)
        put_rows(v, idx, vs)

    def _project_rows(self, x: np.ndarray, v: np.ndarray) -> None:
        """:meth:`_project` on gathered rows (k, 3), in place."""
        for pl in self.planes:
            n = pl.normal
            d = dot3(x, n) - pl.offset
            sel = d < 0
            if not sel.any():
                continue
            behind = np.flatnonzero(sel)
            xb = take_rows(x, behind) - outer3(d[behind], n)
            # Rounding can leave the projected point 1 ulp behind; nudge until it is not.
            for _ in range(4):
                db = dot3(xb, n) - pl.offset
                still = db < 0
                if not still.any():
                    break
                xb[still] -= (2.0 * db[still])[:, None] * n + np.spacing(np.abs(xb[still])) * np.sign(n)
            put_rows(x, behind, xb)
            vb = take_rows(v, behind)
            vn = dot3(vb, n)
            inward = np.minimum(vn, 0.0)
            vt = vb - outer3(vn, n)
            vt = _apply_friction(vt, -inward, pl.friction)
            put_rows(v, behind, vt + outer3(vn - inward, n))


# --- the numba kernel: the same rule, particle by particle ---------------------------------
# Operation for operation as PlaneColliders.resolve and _project above (the dot
# products summed x, y, z), so the backends agree to rounding.


@numba_helper
def _friction_scale(t0, t1, t2, dvn, mu):
    if mu == 0.0:
        return 1.0
    speed = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if speed > 0:
        return max(speed - mu * dvn, 0.0) / speed
    return 0.0


def _stage_kernel(x_old, v_old, x, v, dt, inv_mass, fp, ip):
    count = int(fp[0])
    changed = False
    for i in range(x.shape[0]):
        if inv_mass[i] <= 0:
            continue
        touched = False
        for k in range(count):
            base = 1 + 6 * k
            n0, n1, n2, off, e0, mu = (
                fp[base],
                fp[base + 1],
                fp[base + 2],
                fp[base + 3],
                fp[base + 4],
                fp[base + 5],
            )
            d1 = x[i, 0] * n0 + x[i, 1] * n1 + x[i, 2] * n2 - off
            if not d1 <= 0:  # NaN too, as the NumPy kernel's comparison
                continue
            if not (d1 < 0 or v[i, 0] * n0 + v[i, 1] * n1 + v[i, 2] * n2 < 0):
                continue
            touched = True
            d0 = max(x_old[i, 0] * n0 + x_old[i, 1] * n1 + x_old[i, 2] * n2 - off, 0.0)
            gap = d0 - d1
            s = d0 / gap if gap > 0 else 1.0
            a0 = (v[i, 0] - v_old[i, 0]) / dt
            a1 = (v[i, 1] - v_old[i, 1]) / dt
            a2 = (v[i, 2] - v_old[i, 2]) / dt
            xc0 = x_old[i, 0] + s * (x[i, 0] - x_old[i, 0])
            xc1 = x_old[i, 1] + s * (x[i, 1] - x_old[i, 1])
            xc2 = x_old[i, 2] + s * (x[i, 2] - x_old[i, 2])
            vc0 = v_old[i, 0] + s * (v[i, 0] - v_old[i, 0])
            vc1 = v_old[i, 1] + s * (v[i, 1] - v_old[i, 1])
            vc2 = v_old[i, 2] + s * (v[i, 2] - v_old[i, 2])
            vn = vc0 * n0 + vc1 * n1 + vc2 * n2
            approaching = vn < 0
            pressing = max(-(a0 * n0 + a1 * n1 + a2 * n2), 0.0)
            resting = approaching and (-vn <= RESTING_STEPS * pressing * dt)
            e = 0.0 if resting else e0
            vn_new = -e * vn if approaching else vn
            t0 = vc0 - vn * n0
            t1 = vc1 - vn * n1
            t2 = vc2 - vn * n2
            f = _friction_scale(t0, t1, t2, abs(vn_new - vn), mu)
            vr0 = t0 * f + vn_new * n0
            vr1 = t1 * f + vn_new * n1
            vr2 = t2 * f + vn_new * n2
            r = (1.0 - s) * dt
            x[i, 0] = xc0 + r * vr0 + 0.5 * r * r * a0
            x[i, 1] = xc1 + r * vr1 + 0.5 * r * r * a1
            x[i, 2] = xc2 + r * vr2 + 0.5 * r * r * a2
            v[i, 0] = vr0 + r * a0
            v[i, 1] = vr1 + r * a1
            v[i, 2] = vr2 + r * a2
        if not touched:
            continue
        changed = True
        for k in range(count):
            base = 1 + 6 * k
            n0, n1, n2, off, mu = fp[base], fp[base + 1], fp[base + 2], fp[base + 3], fp[base + 5]
            d = x[i, 0] * n0 + x[i, 1] * n1 + x[i, 2] * n2 - off
            if not d < 0:
                continue
            b0 = x[i, 0] - d * n0
            b1 = x[i, 1] - d * n1
            b2 = x[i, 2] - d * n2
            for _ in range(4):
                db = b0 * n0 + b1 * n1 + b2 * n2 - off
                if not db < 0:
                    break
                b0 -= 2.0 * db * n0 + np.spacing(abs(b0)) * np.sign(n0)
                b1 -= 2.0 * db * n1 + np.spacing(abs(b1)) * np.sign(n1)
                b2 -= 2.0 * db * n2 + np.spacing(abs(b2)) * np.sign(n2)
            x[i, 0] = b0
            x[i, 1] = b1
            x[i, 2] = b2
            vn = v[i, 0] * n0 + v[i, 1] * n1 + v[i, 2] * n2
            inward = min(vn, 0.0)
            t0 = v[i, 0] - vn * n0
            t1 = v[i, 1] - vn * n1
            t2 = v[i, 2] - vn * n2
            f = _friction_scale(t0, t1, t2, -inward, mu)
            v[i, 0] = t0 * f + (vn - inward) * n0
            v[i, 1] = t1 * f + (vn - inward) * n1
            v[i, 2] = t2 * f + (vn - inward) * n2
    return changed


PlaneColliders.numba_stage_source = staticmethod(_stage_kernel)


@register(m.Plane)
def build(entries: list[tuple[int, m.Plane]], ctx: BuildContext) -> list[Any]:
    """Penalty planes become force elements; impulse planes one collision stage."""
    from animsim.forces.penalty import PenaltyPlane

    out: list[Any] = []
    impulse: list[ImpulsePlane] = []
    for _, p in entries:
        normal = np.array(p.normal) / np.linalg.norm(p.normal)
        if p.response == "penalty":
            stiffness = p.stiffness if p.stiffness is not None else DEFAULT_PENALTY_STIFFNESS
            out.append(PenaltyPlane(np.array(p.point), normal, stiffness, p.damping or 0.0))
        else:
            impulse.append(ImpulsePlane(np.array(p.point), normal, p.restitution, p.friction))
    if impulse:
        stage = PlaneColliders(impulse, ctx.system.particle_inv_mass, numba=ctx.backend == "numba")
        if ctx.system.body_count:
            stage.point_rows = ctx.system.point_rows
        out.append(stage)
    return out
