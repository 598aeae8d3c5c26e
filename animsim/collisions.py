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
#
# Laid out for the processor's vector units: the rows of a run that are on or behind a
# plane are copied into one small buffer, a coordinate per line (structure of arrays),
# and each plane's response is computed for every copied row without a branch, then
# kept only where the row hit (a select, not a jump); the guarded divisions are done
# unguarded (np.true_divide: an infinity or NaN where the guard fails, never kept). Each
# row still sees its planes in order, every hit before every projection, and gets the
# same numbers: only which rows are computed side by side has changed. The rare nudge of
# a projected point that rounding left behind its plane runs row by row afterwards, from
# the same point. Measured on 512 rows and a ground plane, one thread, per row and step:
# 23 -> 17 ns when every row rests on the plane, 12.8 -> 11.4 when a third does, 5.4 ->
# 6.4 when none does (2 ns of each is copying the rows for the measurement).

#: rows copied into the vector buffer at a time (12 coordinates x 128 rows, 12 KB)
STAGE_RUN = 128


@numba_helper
def _friction_scale(t0, t1, t2, dvn, mu):
    if mu == 0.0:
        return 1.0
    speed = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if speed > 0:
        return max(speed - mu * dvn, 0.0) / speed
    return 0.0


@numba_helper
def _run_hits(buf, w, c, n0, n1, n2, off, e0, mu, dt, touched):
    """One plane's impulse on the first ``c`` rows of ``buf`` (lines 0-2 x, 3-5 v, 6-8 the
    step's start x, 9-11 its v), in place where a row hit it; True if any did."""
    any_hit = False
    for j in range(c):
        x0, x1, x2 = buf[0, j], buf[1, j], buf[2, j]
        v0, v1, v2 = buf[3, j], buf[4, j], buf[5, j]
        xo0, xo1, xo2 = buf[6, j], buf[7, j], buf[8, j]
        vo0, vo1, vo2 = buf[9, j], buf[10, j], buf[11, j]
        d1 = x0 * n0 + x1 * n1 + x2 * n2 - off
        # behind the plane, or on it and moving in (NaN: no); never pinned or dead rows
        hit = (not w[j] <= 0) & (d1 <= 0) & ((d1 < 0) | (v0 * n0 + v1 * n1 + v2 * n2 < 0))
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
        t0 = vc0 - vn * n0
        t1 = vc1 - vn * n1
        t2 = vc2 - vn * n2
        # _friction_scale(t0, t1, t2, abs(vn_new - vn), mu), its branches as selects
        speed = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        scaled = np.true_divide(max(speed - mu * abs(vn_new - vn), 0.0), speed)
        f = 1.0 if mu == 0.0 else (scaled if speed > 0 else 0.0)
        vr0 = t0 * f + vn_new * n0
        vr1 = t1 * f + vn_new * n1
        vr2 = t2 * f + vn_new * n2
        r = (1.0 - s) * dt
        buf[0, j] = xc0 + r * vr0 + 0.5 * r * r * a0 if hit else x0
        buf[1, j] = xc1 + r * vr1 + 0.5 * r * r * a1 if hit else x1
        buf[2, j] = xc2 + r * vr2 + 0.5 * r * r * a2 if hit else x2
        buf[3, j] = vr0 + r * a0 if hit else v0
        buf[4, j] = vr1 + r * a1 if hit else v1
        buf[5, j] = vr2 + r * a2 if hit else v2
        touched[j] |= hit
        any_hit |= hit
    return any_hit


@numba_helper
def _run_projections(buf, c, n0, n1, n2, off, mu, touched, nudge):
    """Put touched rows behind one plane onto it and stop their inward motion; ``nudge``
    marks those rounding left behind it (True if any)."""
    any_nudge = False
    for j in range(c):
        x0, x1, x2 = buf[0, j], buf[1, j], buf[2, j]
        v0, v1, v2 = buf[3, j], buf[4, j], buf[5, j]
        d = x0 * n0 + x1 * n1 + x2 * n2 - off
        behind = touched[j] & (d < 0)
        b0 = x0 - d * n0
        b1 = x1 - d * n1
        b2 = x2 - d * n2
        again = behind & (b0 * n0 + b1 * n1 + b2 * n2 - off < 0)
        nudge[j] = again
        any_nudge |= again
        vn = v0 * n0 + v1 * n1 + v2 * n2
        inward = min(vn, 0.0)
        t0 = v0 - vn * n0
        t1 = v1 - vn * n1
        t2 = v2 - vn * n2
        # _friction_scale(t0, t1, t2, -inward, mu), its branches as selects
        speed = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        scaled = np.true_divide(max(speed - mu * -inward, 0.0), speed)
        f = 1.0 if mu == 0.0 else (scaled if speed > 0 else 0.0)
        buf[0, j] = b0 if behind else x0
        buf[1, j] = b1 if behind else x1
        buf[2, j] = b2 if behind else x2
        buf[3, j] = t0 * f + (vn - inward) * n0 if behind else v0
        buf[4, j] = t1 * f + (vn - inward) * n1 if behind else v1
        buf[5, j] = t2 * f + (vn - inward) * n2 if behind else v2
    return any_nudge


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


def _stage_kernel(x_old, v_old, x, v, dt, inv_mass, fp, ip):
    count = int(fp[0])
    m = x.shape[0]
    buf = np.empty((13, STAGE_RUN))  # the rows' coordinates, and their inverse masses
    w = buf[12]
    rows = np.empty(STAGE_RUN, dtype=np.int64)
    flags = np.empty((2, STAGE_RUN), dtype=np.bool_)
    touched = flags[0]
    nudge = flags[1]
    changed = False
    for lo in range(0, m, STAGE_RUN):
        # The rows on or behind some plane (and movable) may hit one; no other row can:
        # only a hit moves a row, and a row that hits one plane is in this list already.
        c = 0
        for i in range(lo, min(lo + STAGE_RUN, m)):
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
            w[j] = inv_mass[i]
            touched[j] = False
        hit = False
        for k in range(count):
            p = fp[1 + 6 * k : 7 + 6 * k]  # normal, offset, restitution, friction
            if _run_hits(buf, w, c, p[0], p[1], p[2], p[3], p[4], p[5], dt, touched):
                hit = True
        if not hit:
            continue
        changed = True
        for k in range(count):
            p = fp[1 + 6 * k : 7 + 6 * k]
            if _run_projections(buf, c, p[0], p[1], p[2], p[3], p[5], touched, nudge):
                _run_nudges(buf, c, p[0], p[1], p[2], p[3], nudge)
        for j in range(c):
            i = rows[j]
            for k in range(3):
                x[i, k] = buf[k, j]
                v[i, k] = buf[3 + k, j]
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
