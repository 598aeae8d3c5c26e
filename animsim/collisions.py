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

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from animsim.elements import BuildContext, StepStage, numba_helper, numba_inline_helper, register
from animsim.forces.penalty import PenaltyPlane
from animsim.scene import models as m
from animsim.vec import add_scaled, dot3, put_rows, sub_scaled, take_rows

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

    @functools.cached_property
    def offset(self) -> float:
        """p.n: the plane is {x : x.n = offset} (kept: the NumPy rule reads it per block)."""
        return float(self.point @ self.normal)

    @functools.cached_property
    def axis(self) -> tuple[int, float] | None:
        """(j, n_j) when the unit normal is +-e_j exactly, else None."""
        return _axis(self.normal)


def apply_friction(vt: np.ndarray, dvn: np.ndarray, mu: float) -> np.ndarray:
    """Reduce tangential velocities (k, 3) by at most mu * dvn (k,), never reversing them."""
    if mu == 0.0:
        return vt
    out = vt.copy()
    k = len(vt)
    _friction_rows(out, dvn, mu, np.empty(k), np.empty(k), np.empty(k, dtype=bool))
    return out


#: contact rows handled together: the block's buffers (five of BLOCK x 3 floats, eight of
#: BLOCK) stay in a core's cache while the rule's ~150 NumPy calls pass over them, where
#: whole-array operations on a few hundred thousand contacts each went out to memory (and
#: allocated); 16,384 was the fastest of 1,024 to 65,536 (benchmarks/optimisation_log.md)
BLOCK = 16384


def _axis(n: np.ndarray) -> tuple[int, float] | None:
    """(j, n_j) when the unit normal is +-e_j exactly, else None."""
    nz = np.flatnonzero(n)
    if nz.size == 1 and abs(n[nz[0]]) == 1.0:
        return int(nz[0]), float(n[nz[0]])
    return None


def _candidates(x: np.ndarray, pl: ImpulsePlane) -> np.ndarray:
    """Rows of x that may be on or behind the plane (x.n - p.n <= 0), in increasing order.

    For an axis normal +-e_j this is one comparison of column j: for finite rows
    x.n - off is (+-x_j) - off up to the sign of a zero (the other products are
    zeros), and a difference of two floats is <= 0 exactly when a <= b. Rows
    with a non-finite component may be included; the exact test on the
    candidates (:meth:`_Blocks.collide`) drops them, as the full dot product does.
    """
    off = pl.offset
    axis = pl.axis
    if axis is not None:
        j, sign = axis
        col = x[:, j]
        return np.flatnonzero(col <= off) if sign > 0 else np.flatnonzero(col >= -off)
    d = dot3(x, pl.normal)
    d -= off
    return np.flatnonzero(d <= 0)


def _scale_rows(a: np.ndarray, s: np.ndarray) -> None:
    """a *= s[:, None] column by column: broadcasting with an inner axis of 3 runs NumPy's
    loop 3 elements at a time, several times slower; the products are the same."""
    for j in range(3):
        np.multiply(a[:, j], s, out=a[:, j])


class _Blocks:
    """Reused buffers for one block of contacts, and the rule on them.

    Operation for operation the rule of the numba kernel below (and of
    Lander's Eq. 3 with the time of impact, module docstring), each value
    computed by the same IEEE operations in the same order, so the two
    backends agree to the bit; only where the values live changed.
    """

    def __init__(self, rows: int | None = None):
        rows = BLOCK if rows is None else rows
        self.xo, self.vo, self.xh, self.vh, self.acc = (np.empty((rows, 3)) for _ in range(5))
        self.d0, self.d1, self.s, self.vn, self.vnn, self.w1, self.w2, self.w3 = (
            np.empty(rows) for _ in range(8)
        )
        self.b1, self.b2, self.b3 = (np.empty(rows, dtype=bool) for _ in range(3))

    def collide(
        self,
        pl: ImpulsePlane,
        x_old: np.ndarray,
        v_old: np.ndarray,
        x: np.ndarray,
        v: np.ndarray,
        dt: float | np.ndarray,
        inv_mass: np.ndarray,
        idx: np.ndarray,
        project: PlaneColliders | None,
        kappa: float,
    ) -> np.ndarray:
        """Collide candidate rows ``idx`` (at most the block) with one plane, writing them back.

        Returns the rows that touched the plane. With ``project`` (a single plane)
        the rows are settled (:meth:`PlaneColliders._project_rows`) before the write-back.
        ``kappa``: the method's energy shift (:func:`kept_bounce_speed`).
        """
        m = idx.size
        xh = np.take(x, idx, axis=0, out=self.xh[:m])
        vh = np.take(v, idx, axis=0, out=self.vh[:m])
        return self._respond(pl, idx, xh, vh, (x_old, v_old), x, v, dt, inv_mass, project, kappa)

    def collide_gathered(
        self,
        pl: ImpulsePlane,
        idx: np.ndarray,
        rows: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        x: np.ndarray,
        v: np.ndarray,
        dt: float,
        inv_mass: np.ndarray,
        project: PlaneColliders | None,
        kappa: float,
    ) -> np.ndarray:
        """:meth:`collide` on candidate rows already gathered, ``rows`` = (x, v, x_old, v_old)
        of ``idx`` (k, 3) each, which it may overwrite, and ``inv_mass`` of idx (k,)
        (:class:`_Capture` took them while their block was in cache); the result is written
        back into x and v."""
        xh, vh, xo, vo = rows
        return self._respond(pl, idx, xh, vh, (xo, vo), x, v, dt, inv_mass, project, kappa, gathered=True)

    def _respond(
        self,
        pl: ImpulsePlane,
        idx: np.ndarray,
        xh: np.ndarray,
        vh: np.ndarray,
        old: tuple[np.ndarray, np.ndarray],
        x: np.ndarray,
        v: np.ndarray,
        dt: float | np.ndarray,
        inv_mass: np.ndarray,
        project: PlaneColliders | None,
        kappa: float,
        gathered: bool = False,
    ) -> np.ndarray:
        """The rule on candidates ``idx`` whose end-of-step rows are xh, vh; ``old`` is the
        step's start: whole arrays (x_old, v_old), or with ``gathered`` the rows of idx."""
        n, off, m = pl.normal, pl.offset, idx.size
        d1 = dot3(xh, n, out=self.d1[:m])
        d1 -= off
        # Behind the plane, or exactly on it and still moving in (a contact that
        # would cross next step: Lander's "colliding contact"); never pinned
        # particles or dead pool slots.
        keep = np.less(dot3(vh, n, out=self.w1[:m]), 0, out=self.b1[:m])
        keep |= np.less(d1, 0, out=self.b2[:m])
        keep &= np.less_equal(d1, 0, out=self.b2[:m])
        # the rows' inverse masses (with ``gathered``, inv_mass holds the rows of idx already)
        im = inv_mass[:m] if gathered else np.take(inv_mass, idx, out=self.w1[:m])
        keep &= np.greater(im, 0, out=self.b2[:m])
        if keep.all():
            hit = idx
        else:
            hit = idx[keep]
            if hit.size == 0:
                return hit
            d1 = d1[keep]
            if gathered:
                xh = np.compress(keep, xh, axis=0, out=self.xh[: hit.size])
                vh = np.compress(keep, vh, axis=0, out=self.vh[: hit.size])
            else:
                xh = np.take(x, hit, axis=0, out=self.xh[: hit.size])
                vh = np.take(v, hit, axis=0, out=self.vh[: hit.size])
        k = hit.size
        if not gathered:
            xo = np.take(old[0], hit, axis=0, out=self.xo[:k])
            vo = np.take(old[1], hit, axis=0, out=self.vo[:k])
        elif k == m:
            xo, vo = old
        else:
            xo = np.compress(keep, old[0], axis=0, out=self.xo[:k])
            vo = np.compress(keep, old[1], axis=0, out=self.vo[:k])
        dt_row = dt if np.ndim(dt) == 0 else np.asarray(dt)[hit]
        d0 = dot3(xo, n, out=self.d0[:k])
        d0 -= off
        np.maximum(d0, 0.0, out=d0)
        gap = np.subtract(d0, d1, out=self.w1[:k])
        # fraction of the step at impact; a particle ending exactly on the plane touched it at the end
        s = self.s[:k]
        s.fill(1.0)
        np.divide(d0, gap, out=s, where=np.greater(gap, 0, out=self.b1[:k]))
        # the step's mean acceleration (vh - vo) / dt, then vh becomes vo + s (vh - vo)
        vh -= vo
        acc = self.acc[:k]
        if np.ndim(dt_row) == 0:
            np.divide(vh, dt_row, out=acc)
        else:
            for j in range(3):
                np.divide(vh[:, j], dt_row, out=acc[:, j])
        xh -= xo
        _scale_rows(xh, s)
        xh += xo  # xc = xo + s (xh - xo)
        _scale_rows(vh, s)
        vh += vo  # vc = vo + s (vh - vo)
        vc = vh
        # Reflect the approaching ones (Lander Eq. 3) with Coulomb friction.
        # An approach slower than what the pressing acceleration adds in
        # RESTING_STEPS steps is a resting contact: it stops instead of
        # bouncing, so a particle at rest does not jitter.
        vn = dot3(vc, n, out=self.vn[:k])
        vn_new = self.vnn[:k]
        np.copyto(vn_new, vn)
        # Only the approaching rows change their normal speed: worked on as a few gathered rows
        # (most contacts of a pile at rest are not approaching), each with the same operations.
        app = np.flatnonzero(np.less(vn, 0, out=self.b1[:k]))
        if app.size:
            vn_a = vn[app]
            pressing = dot3(np.take(acc, app, axis=0), n)
            np.negative(pressing, out=pressing)
            np.maximum(pressing, 0.0, out=pressing)
            pressing *= RESTING_STEPS
            pressing *= dt_row if np.ndim(dt_row) == 0 else dt_row[app]
            resting = -vn_a <= pressing
            # vn_new = -e vn with e = 0 when resting, the restitution otherwise (-0.0 is -e for e = 0)
            neg_e = np.where(resting, -0.0, -pl.restitution)
            vn_new[app] = neg_e * vn_a
            if kappa != 0.0 and pl.restitution > 0.0:
                self._keep_energy(pl, app[~resting], vo, acc, d0, s, dt_row, kappa, vn_new)
        tmp = self.w2[:k]
        for j in range(3):  # vt = vc - vn n
            sub_scaled(vc[:, j], vn, n[j], vc[:, j], tmp)
        vt = vc
        if pl.friction != 0.0:
            dvn = np.subtract(vn_new, vn, out=self.w1[:k])
            np.abs(dvn, out=dvn)
            _friction_rows(vt, dvn, pl.friction, self.w2[:k], self.w3[:k], self.b2[:k])
        for j in range(3):  # vr = vt + vn_new n
            add_scaled(vt[:, j], vn_new, n[j], vt[:, j], tmp)
        vr = vt
        if pl.friction != 0.0:
            hold_by_static_friction(vr, vn_new, acc, n, pl.friction)
        # Fly on for the rest of the step: r = (1 - s) dt.
        r = np.subtract(1.0, s, out=self.w1[:k])
        r *= dt_row
        half_r2 = np.multiply(r, 0.5, out=self.w3[:k])
        half_r2 *= r
        for j in range(3):
            np.multiply(r, vr[:, j], out=tmp)
            xh[:, j] += tmp  # xc + r vr
            np.multiply(half_r2, acc[:, j], out=tmp)
            xh[:, j] += tmp  # ... + (r^2 / 2) a
            np.multiply(r, acc[:, j], out=tmp)
            vr[:, j] += tmp  # v = vr + r a
        if project is not None:  # one plane: settle the rows before writing them back, once
            project._project_rows(xh, vr, self)
        put_rows(x, hit, xh)
        put_rows(v, hit, vr)
        return hit

    @staticmethod
    def _keep_energy(
        pl: ImpulsePlane,
        rows: np.ndarray,
        vo: np.ndarray,
        acc: np.ndarray,
        d0: np.ndarray,
        s: np.ndarray,
        dt: float | np.ndarray,
        kappa: float,
        vn_new: np.ndarray,
    ) -> None:
        """The bouncing ``rows`` get the normal speed that keeps e^2 of the method's energy
        (:func:`kept_bounce_speed`, as :func:`_hit_row` computes it), in ``vn_new``."""
        if rows.size == 0:
            return
        dt_rows = dt if np.ndim(dt) == 0 else np.asarray(dt)[rows]
        u0 = dot3(np.take(vo, rows, axis=0), pl.normal)
        an = dot3(np.take(acc, rows, axis=0), pl.normal)
        r = np.subtract(1.0, s[rows])
        r *= dt_rows
        w = kept_bounce_speed(u0, d0[rows], an, r, pl.restitution, np.multiply(kappa, dt_rows))
        vn_new[rows] = np.where(w > 0.0, w, vn_new[rows])


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


#: rows per block when the plane meets the rows inside the integrator's step: a block's x, v,
#: their start-of-step copies and the force terms' scratch stay in a core's L2 cache between
#: the update and the capture (4,096 beat 2,048, 8,192 and 16,384 at 1e5 and 1e6 particles;
#: benchmarks/optimisation_log.md)
CAPTURE_ROWS = 4096


class _Capture:
    """One impulse plane met a block of rows at a time, while the integrator steps them.

    Stepping a block of rows (:meth:`Dynamics.acceleration_blocks`) reads and
    writes rows that then sit in cache: ``before`` copies the block's start of
    step there, ``after`` finds the block's candidates and copies their rows
    (end and start of the step) into one buffer, and every BLOCK candidates the
    rule runs on that buffer (:meth:`_Blocks.collide_gathered`). The whole-array
    copies of the step's start and the gathers of the candidates' rows from
    memory (most of a million-particle step with a ground plane) are gone. Each
    row meets the plane by itself, reading only its own rows, so the values are
    those of :meth:`PlaneColliders.resolve` on the whole step: the same
    candidates, in the same order, with the same operations.
    """

    def __init__(self, block_rows: int):
        self.block_rows = block_rows
        rows = BLOCK + block_rows  # fewer than BLOCK wait between blocks, and a block adds at most its rows
        self.idx = np.empty(rows, dtype=np.intp)
        self.inv_mass = np.empty(rows)
        self.xh, self.vh, self.xo, self.vo = (np.empty((rows, 3)) for _ in range(4))
        self.start_x, self.start_v = np.empty((block_rows, 3)), np.empty((block_rows, 3))
        self.count = 0
        self.changed = False

    def begin(self, owner: PlaneColliders, x: np.ndarray, v: np.ndarray, dt: float) -> None:
        self.owner, self.plane, self.x, self.v, self.dt = owner, owner.planes[0], x, v, dt
        self.count = 0
        self.changed = False

    def before(self, rows: slice) -> None:
        """Keep the block's start of step (its rows are about to be updated)."""
        m = rows.stop - rows.start
        np.copyto(self.start_x[:m], self.x[rows])
        np.copyto(self.start_v[:m], self.v[rows])

    def after(self, rows: slice) -> None:
        """The block's rows have their end of step: take the candidates' rows."""
        xb = self.x[rows]
        cand = _candidates(xb, self.plane)
        k = cand.size
        if k == 0:
            return
        c, e = self.count, self.count + k
        np.add(cand, rows.start, out=self.idx[c:e])
        np.take(xb, cand, axis=0, out=self.xh[c:e])
        np.take(self.v[rows], cand, axis=0, out=self.vh[c:e])
        np.take(self.start_x, cand, axis=0, out=self.xo[c:e])
        np.take(self.start_v, cand, axis=0, out=self.vo[c:e])
        np.take(self.owner.inv_mass[rows], cand, out=self.inv_mass[c:e])
        self.count = e
        if e >= BLOCK:  # a full block of contacts: meet the plane, keep the rest for the next
            self._meet(BLOCK)
            rest = slice(BLOCK, e)
            for buf in (self.idx, self.inv_mass, self.xh, self.vh, self.xo, self.vo):
                buf[: e - BLOCK] = buf[rest]
            self.count = e - BLOCK

    def _meet(self, k: int) -> None:
        """Meet the plane with the first ``k`` candidates taken (at most BLOCK: ``after`` meets
        it whenever BLOCK are waiting)."""
        rows = slice(0, k)
        hit = self.owner._buffers(BLOCK).collide_gathered(
            self.plane,
            self.idx[rows],
            (self.xh[rows], self.vh[rows], self.xo[rows], self.vo[rows]),
            self.x,
            self.v,
            self.dt,
            self.inv_mass[rows],
            self.owner,
            self.owner.kappa,
        )
        self.changed |= hit.size > 0

    def finish(self) -> bool:
        """Meet the plane with the candidates left; whether any row changed in this step."""
        if self.count:
            self._meet(self.count)
            self.count = 0
        self.owner = self.x = self.v = None  # type: ignore[assignment]
        return self.changed


def _friction_rows(
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
    _scale_rows(vt, keep)


class PlaneColliders(StepStage):
    """All impulse planes of a scene, applied after each integrator step."""

    #: particle contacts push out of these planes after their own pass
    holds_planes = True

    def __init__(self, planes: list[ImpulsePlane], particle_inv_mass: np.ndarray, *, numba: bool = False):
        self.planes = planes
        self.inv_mass = particle_inv_mass  # rebound to the live state's by reset()
        self.numba = numba
        self.label = f"plane collisions: {len(planes)} impulse plane(s), time of impact inside the step"
        self.dissipative = any(p.restitution < 1 or p.friction > 0 for p in planes)

    collides_newborns = True
    #: what ``explain`` calls it when it meets the step's blocks of rows
    block_name = "plane"
    #: each particle meets the planes by itself (its own rows of the step's start and end)
    pointwise = True
    no_closed_form = "it has planes (collisions have no closed form here)"

    #: (N,) bool rows this stage may touch, or None for all (bodies have their own contacts)
    point_rows: np.ndarray | None = None
    #: the method's c (animsim.contact_stages.follow_weight), set at compile time: a bounce keeps
    #: e^2 of the energy the method conserves (kept_bounce_speed)
    follow_weight: float | None = 1.0

    @property
    def kappa(self) -> float:
        return energy_shift(self.follow_weight)

    def reset(self, state: Any) -> None:
        self.inv_mass = state.particle_inv_mass

    def collide_subset(
        self, x_old: np.ndarray, v_old: np.ndarray, x: np.ndarray, v: np.ndarray, dt: np.ndarray
    ) -> None:
        """Collide a few newborn particles (all movable) over their own step lengths ``dt`` (k,).

        One collider for the newborns is kept between steps, with its buffers: a fountain's
        births ask every step, and most steps none of them reaches a plane."""
        k = len(x)
        if self._newborns is None:
            self._newborns = PlaneColliders(self.planes, np.ones(0))
            self._newborns.follow_weight = self.follow_weight
        if len(self._newborn_ones) < k:
            self._newborn_ones = np.ones(max(k, 256))
        self._newborns.inv_mass = self._newborn_ones[:k]
        self._newborns.resolve(x_old, v_old, x, v, dt)

    _newborns: PlaneColliders | None = None
    _newborn_ones: np.ndarray = np.ones(0)  # inverse masses of the newborns: all movable

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
            [[len(self.planes)]]
            + [[*p.normal, p.offset, p.restitution, p.friction] for p in self.planes]
            + [[self.kappa]]
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

        Cost: one pass over all particles per plane (a comparison); everything
        else works on the particles that reached a plane, a block of rows at a
        time (:class:`_Blocks`), so the contacts' arithmetic stays in cache.
        """
        touched: list[np.ndarray] = []
        single = len(self.planes) == 1
        for pl in self.planes:
            cand = _candidates(x, pl)
            if cand.size == 0:
                continue
            blocks = self._buffers(min(BLOCK, len(x)))
            project = self if single else None
            hits = [
                blocks.collide(
                    pl, x_old, v_old, x, v, dt, self.inv_mass, cand[i : i + BLOCK], project, self.kappa
                )
                for i in range(0, cand.size, BLOCK)
            ]
            hit = np.concatenate(hits) if len(hits) > 1 else hits[0]
            if hit.size:
                touched.append(hit)
        if not touched:
            return False
        if not single:
            # Only particles moved above can be behind a plane now: every other
            # one ended its step in front of all of them.
            self.project_rows(x, v, np.unique(np.concatenate(touched)))
        return True

    def meets_blocks(self) -> bool:
        """Whether :meth:`block_session` serves: one plane (several each see the one before
        it), no bodies, the NumPy rule."""
        return len(self.planes) == 1 and self.point_rows is None and not self.numba

    def block_session(self, state: Any, dt: float) -> _Capture:
        """The plane applied a block of rows at a time inside the integrator's step (its
        ``before``/``after`` around each block's update, then ``finish``); only where
        :meth:`meets_blocks` (``steppers.block_stage``)."""
        if self._capture is None:
            self._capture = _Capture(CAPTURE_ROWS)
        self.inv_mass = state.particle_inv_mass
        self._capture.begin(self, state.particle_position, state.particle_velocity, dt)
        return self._capture

    _capture: _Capture | None = None
    _block_buffers: _Blocks | None = None

    def _buffers(self, rows: int) -> _Blocks:
        """Buffers for blocks of ``rows`` contacts, made on first use and kept."""
        if self._block_buffers is None or len(self._block_buffers.s) < rows:
            self._block_buffers = _Blocks(rows)
        return self._block_buffers

    def project_rows(self, x: np.ndarray, v: np.ndarray, idx: np.ndarray) -> None:
        """Put any of rows ``idx`` behind a plane onto it and stop its inward motion (after the
        hits of :meth:`resolve`, and for the stages that push particles: particle contacts,
        particle-body contacts)."""
        xs, vs = take_rows(x, idx), take_rows(v, idx)
        self._project_rows(xs, vs)
        put_rows(x, idx, xs)
        put_rows(v, idx, vs)

    def _project_rows(self, x: np.ndarray, v: np.ndarray, scratch: _Blocks | None = None) -> None:
        """:meth:`project_rows` on gathered rows (k, 3), in place (``scratch``: buffers of at least k rows
        other than those holding x and v)."""
        buf = scratch if scratch is not None else _Blocks(len(x))
        for pl in self.planes:
            _settle(pl, x, v, buf)


def _settle(pl: ImpulsePlane, x: np.ndarray, v: np.ndarray, buf: _Blocks) -> None:
    """Put rows (k, 3) of x behind the plane onto it and stop their inward motion, in place.

    Every operation runs over all k rows and only the rows behind the plane are
    written (``where=``), so the values are those of the rows alone: no gather,
    no scatter. Uses the buffers d0, d1, s, w1-w3, b1-b3 and vo of ``buf``.
    """
    n, off, k = pl.normal, pl.offset, len(x)
    d = dot3(x, n, out=buf.d0[:k])
    d -= off
    behind = np.less(d, 0, out=buf.b1[:k])
    if not behind.any():
        return
    tmp = buf.w2[:k]
    for j in range(3):  # x - d n
        sub_scaled(x[:, j], d, n[j], x[:, j], tmp, where=behind)
    # Rounding can leave the projected point 1 ulp behind; nudge until it is not.
    # (Rows in front keep x, so their distance is d again, and they are never nudged.)
    for _ in range(4):
        db = dot3(x, n, out=buf.d1[:k])
        db -= off
        still = np.less(db, 0, out=buf.b2[:k])
        if not still.any():
            break
        db *= 2.0
        for j in range(3):  # x -= 2 db n + spacing(|x|) sign(n)
            spacing = np.abs(x[:, j], out=buf.w3[:k])
            np.spacing(spacing, out=spacing)
            spacing *= np.sign(n[j])
            np.multiply(db, n[j], out=tmp)
            tmp += spacing
            np.subtract(x[:, j], tmp, out=x[:, j], where=still)
    vn = dot3(v, n, out=buf.d1[:k])
    inward = np.minimum(vn, 0.0, out=buf.d0[:k])
    vt = buf.vo[:k]
    for j in range(3):  # vt = v - vn n
        sub_scaled(v[:, j], vn, n[j], vt[:, j], tmp)
    if pl.friction != 0.0:
        dvn = np.negative(inward, out=buf.w1[:k])
        _friction_rows(vt, dvn, pl.friction, buf.w3[:k], buf.s[:k], buf.b3[:k])
    np.subtract(vn, inward, out=buf.d1[:k])  # vn - inward
    for j in range(3):  # v = vt + (vn - inward) n on the rows behind
        add_scaled(vt[:, j], buf.d1[:k], n[j], v[:, j], tmp, where=behind)


# --- the numba kernel: the same rule, particle by particle ---------------------------------
# Operation for operation as PlaneColliders.resolve and project_rows above (the dot
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
#
# The rule of one row is written once (_hit_row, _settle_row) and the loops call it:
# numba copies it into each loop (numba_inline_helper; a call would keep the loop off the
# vector units). ``friction`` is False exactly when the plane's friction is 0 (the factor
# is then 1, and t * 1.0 is t); where it is a constant at the call (the ground's loops,
# _run_one_plane) the frictionless loop has no square root or division at all. A single
# plane, the common case, hits and settles each row in one pass while its numbers are in
# registers (with several planes every hit comes before every settling, as above).
# Together with the padding below: 12 -> 9.5 ns a row and step with 55 % of the rows
# resting (benchmarks/optimisation_log.md, "fourth round").

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


def _stage_kernel(x_old, v_old, x, v, dt, inv_mass, fp, ip):
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


PlaneColliders.numba_stage_source = staticmethod(_stage_kernel)


def _newborn_kernel(x_old, v_old, x, v, rest, fp, ip):
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


PlaneColliders.numba_newborn_source = staticmethod(_newborn_kernel)


@register(m.Plane)
def build(entries: list[tuple[int, m.Plane]], ctx: BuildContext) -> list[Any]:
    """Penalty planes become force elements; impulse planes one collision stage."""
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
