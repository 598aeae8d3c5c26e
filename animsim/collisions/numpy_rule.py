"""The NumPy rule of impulse planes: an impulse plane, its candidate rows, the rule on a
block of contact rows (:class:`Blocks`) and the settling of rows left behind a plane.

The rule is Lander's Eq. 3 with the time of impact inside the step
(:mod:`animsim.collisions.stage` tells it). It works on a block of contact rows at a time in
reused buffers, each value computed by the numba kernel's operations in its order
(:mod:`animsim.collisions.kernels`), so the two backends agree to the bit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from animsim.collisions.response import (
    RESTING_STEPS,
    friction_rows,
    hold_by_static_friction,
    kept_bounce_speed,
    scale_rows,
)
from animsim.vec import add_scaled, dot3, put_rows, sub_scaled


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


def _axis(n: np.ndarray) -> tuple[int, float] | None:
    """(j, n_j) when the unit normal is +-e_j exactly, else None."""
    nz = np.flatnonzero(n)
    if nz.size == 1 and abs(n[nz[0]]) == 1.0:
        return int(nz[0]), float(n[nz[0]])
    return None


def candidates(x: np.ndarray, pl: ImpulsePlane) -> np.ndarray:
    """Rows of x that may be on or behind the plane (x.n - p.n <= 0), in increasing order.

    For an axis normal +-e_j this is one comparison of column j: for finite rows
    x.n - off is (+-x_j) - off up to the sign of a zero (the other products are
    zeros), and a difference of two floats is <= 0 exactly when a <= b. Rows
    with a non-finite component may be included; the exact test on the
    candidates (:meth:`Blocks.collide`) drops them, as the full dot product does.
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


class Settler(Protocol):
    """What settles gathered rows on every plane after a collision (the planes' stage does:
    :class:`animsim.collisions.stage.PlaneColliders`); named by what it does, so this module
    does not import the stage that imports it."""

    def project_gathered(self, x: np.ndarray, v: np.ndarray, scratch: Blocks | None = None) -> None: ...


class Blocks:
    """Reused buffers for one block of contacts, and the rule on them.

    Operation for operation the rule of the numba kernel (:mod:`animsim.collisions.kernels`;
    Lander's Eq. 3 with the time of impact, module docstring), each value
    computed by the same IEEE operations in the same order, so the two
    backends agree to the bit; only where the values live changed.
    """

    def __init__(self, rows: int):
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
        project: Settler | None,
        kappa: float,
    ) -> np.ndarray:
        """Collide candidate rows ``idx`` (at most the block) with one plane, writing them back.

        Returns the rows that touched the plane. With ``project`` (a single plane)
        the rows are settled (:meth:`animsim.collisions.stage.PlaneColliders.project_gathered`) before the write-back.
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
        project: Settler | None,
        kappa: float,
    ) -> np.ndarray:
        """:meth:`collide` on candidate rows already gathered, ``rows`` = (x, v, x_old, v_old)
        of ``idx`` (k, 3) each, which it may overwrite, and ``inv_mass`` of idx (k,)
        (:class:`animsim.collisions.stage._Capture` took them while their block was in cache); the result is written
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
        project: Settler | None,
        kappa: float,
        gathered: bool = False,
    ) -> np.ndarray:
        """The rule on candidates ``idx`` whose end-of-step rows are xh, vh; ``old`` is the
        step's start: whole arrays (x_old, v_old), or with ``gathered`` the rows of idx."""
        m = idx.size
        d1, keep = self._touching(pl, idx, xh, vh, inv_mass, gathered)
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
        d0, s, acc = self._to_impact(pl, xh, vh, xo, vo, d1, dt_row)
        vc = vh
        vn, vn_new = self._reflect(pl, vc, vo, acc, d0, s, dt_row, kappa)
        vr = self._tangential(pl, vc, vn, vn_new, acc)
        self._fly_on(xh, vr, acc, s, dt_row)
        if project is not None:  # one plane: settle the rows before writing them back, once
            project.project_gathered(xh, vr, self)
        put_rows(x, hit, xh)
        put_rows(v, hit, vr)
        return hit

    def _touching(
        self,
        pl: ImpulsePlane,
        idx: np.ndarray,
        xh: np.ndarray,
        vh: np.ndarray,
        inv_mass: np.ndarray,
        gathered: bool,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(distance from the plane at the step's end, which candidates touch it) of the
        m candidates ``idx`` (in the buffers d1 and b1)."""
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
        return d1, keep

    def _to_impact(
        self,
        pl: ImpulsePlane,
        xh: np.ndarray,
        vh: np.ndarray,
        xo: np.ndarray,
        vo: np.ndarray,
        d1: np.ndarray,
        dt_row: float | np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(distance at the step's start, fraction of the step at impact s, the step's mean
        acceleration) of the k rows that touch; xh and vh become the position and velocity
        at the impact, in place."""
        n, off, k = pl.normal, pl.offset, len(xh)
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
        scale_rows(xh, s)
        xh += xo  # xc = xo + s (xh - xo)
        scale_rows(vh, s)
        vh += vo  # vc = vo + s (vh - vo)
        return d0, s, acc

    def _reflect(
        self,
        pl: ImpulsePlane,
        vc: np.ndarray,
        vo: np.ndarray,
        acc: np.ndarray,
        d0: np.ndarray,
        s: np.ndarray,
        dt_row: float | np.ndarray,
        kappa: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(normal speed at the impact, normal speed after it) of the k rows at impact with
        velocity ``vc`` (in the buffers vn and vnn)."""
        n, k = pl.normal, len(vc)
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
        return vn, vn_new

    def _tangential(
        self, pl: ImpulsePlane, vc: np.ndarray, vn: np.ndarray, vn_new: np.ndarray, acc: np.ndarray
    ) -> np.ndarray:
        """The velocity after the impact, vt + vn_new n with Coulomb friction on vt = vc - vn n,
        in place of ``vc``; the rows static friction holds lose ``acc`` too."""
        n, k = pl.normal, len(vc)
        tmp = self.w2[:k]
        for j in range(3):  # vt = vc - vn n
            sub_scaled(vc[:, j], vn, n[j], vc[:, j], tmp)
        vt = vc
        if pl.friction != 0.0:
            dvn = np.subtract(vn_new, vn, out=self.w1[:k])
            np.abs(dvn, out=dvn)
            friction_rows(vt, dvn, pl.friction, self.w2[:k], self.w3[:k], self.b2[:k])
        for j in range(3):  # vr = vt + vn_new n
            add_scaled(vt[:, j], vn_new, n[j], vt[:, j], tmp)
        vr = vt
        if pl.friction != 0.0:
            hold_by_static_friction(vr, vn_new, acc, n, pl.friction)
        return vr

    def _fly_on(
        self, xh: np.ndarray, vr: np.ndarray, acc: np.ndarray, s: np.ndarray, dt_row: float | np.ndarray
    ) -> None:
        """Fly on for the rest of the step, r = (1 - s) dt, at the step's mean acceleration:
        xh (at the impact) and vr (after it) become the step's end, in place."""
        k = len(xh)
        tmp = self.w2[:k]
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
        (:func:`kept_bounce_speed`, as ``_hit_row`` of :mod:`animsim.collisions.kernels` computes
        it), in ``vn_new``."""
        if rows.size == 0:
            return
        dt_rows = dt if np.ndim(dt) == 0 else np.asarray(dt)[rows]
        u0 = dot3(np.take(vo, rows, axis=0), pl.normal)
        an = dot3(np.take(acc, rows, axis=0), pl.normal)
        r = np.subtract(1.0, s[rows])
        r *= dt_rows
        w = kept_bounce_speed(u0, d0[rows], an, r, pl.restitution, np.multiply(kappa, dt_rows))
        vn_new[rows] = np.where(w > 0.0, w, vn_new[rows])


def settle(pl: ImpulsePlane, x: np.ndarray, v: np.ndarray, buf: Blocks) -> None:
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
        friction_rows(vt, dvn, pl.friction, buf.w3[:k], buf.s[:k], buf.b3[:k])
    np.subtract(vn, inward, out=buf.d1[:k])  # vn - inward
    for j in range(3):  # v = vt + (vn - inward) n on the rows behind
        add_scaled(vt[:, j], buf.d1[:k], n[j], v[:, j], tmp, where=behind)
