"""Springs with an end fixed in a rigid body (a force element).

An end is a particle row, or a point ``at`` fixed in body b (body frame). At
orientation q that point is at p = x_b + r with r = R(q) at, and moves with
v_b + omega_b x r. The spring is the damped spring of the particle springs
(Lander 1999, eq. 2): with d = p_b - p_a, L = |d|, u = d / L,

    f_a = (ks (L - rest) + kd (v_pb - v_pa) . u) u,   f_b = -f_a,

applied at the attachment points: on the body's centre-of-mass row f, and the
torque r x f about its centre of mass (Baraff 1997, "Rigid Body Dynamics", force
and torque). Potential energy 1/2 ks (L - rest)^2.
"""

from __future__ import annotations

import numpy as np

from animsim.bodies import quaternion as quat
from animsim.elements import ELASTIC, ForceElement


class BodySprings(ForceElement):
    """Damped springs of which at least one end is a point of a body.

    rows_a, rows_b: (S,) particle rows of the ends (for a body end: the body's centre-of-mass row).
    body_a, body_b: (S,) body numbers, -1 for a particle end.
    at_a, at_b: (S,3) points in the body frames (0 for particle ends).
    """

    watch_role = ELASTIC
    acts_on_bodies = True
    no_closed_form = "springs to bodies have no closed form here"

    def bodies_kept_awake(self, count: int) -> np.ndarray:
        """The bodies a spring is fixed in never sleep (animsim.bodies.sleep): the other end
        moves them, and a spring at rest pulls as hard as one that stretches."""
        kept = np.zeros(count, dtype=bool)
        kept[self.body_a[self.body_a >= 0]] = True
        kept[self.body_b[self.body_b >= 0]] = True
        return kept

    def __init__(
        self,
        rows_a: np.ndarray,
        rows_b: np.ndarray,
        body_a: np.ndarray,
        body_b: np.ndarray,
        at_a: np.ndarray,
        at_b: np.ndarray,
        rest: np.ndarray,
        ks: np.ndarray,
        kd: np.ndarray,
        body_count: int,
        names: list[str] | None = None,
    ) -> None:
        self.rows_a = np.asarray(rows_a, dtype=np.int64)
        self.rows_b = np.asarray(rows_b, dtype=np.int64)
        self.body_a = np.asarray(body_a, dtype=np.int64)
        self.body_b = np.asarray(body_b, dtype=np.int64)
        self.at_a = np.asarray(at_a, dtype=np.float64).reshape(-1, 3)
        self.at_b = np.asarray(at_b, dtype=np.float64).reshape(-1, 3)
        self.rest = np.asarray(rest, dtype=np.float64)
        self.ks = np.asarray(ks, dtype=np.float64)
        self.kd = np.asarray(kd, dtype=np.float64)
        self.body_count = body_count
        #: (B, 3) inverse principal moments, for the stability bounds (set by the builder)
        self.inv_inertia: np.ndarray | None = None
        self.has_damping = bool(np.any(self.kd > 0))
        self.names = names or []
        n = len(self.ks)
        self.label = (
            f"springs to bodies: {n} damped spring(s) with an end fixed in a body; force at the "
            "attachment point, torque r x f on the body"
        )

    @property
    def count(self) -> int:
        return int(self.ks.shape[0])

    def _arm(self, body: np.ndarray, at: np.ndarray, q: np.ndarray) -> np.ndarray:
        """r = R(q_b) at for body ends, 0 for particle ends."""
        has = body >= 0
        r = np.zeros_like(at)
        if has.any():
            r[has] = quat.rotate(q[body[has]], at[has])
        return r

    def ends(self, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """World attachment points p_a, p_b and lever arms r_a, r_b."""
        ra = self._arm(self.body_a, self.at_a, q)
        rb = self._arm(self.body_b, self.at_b, q)
        return x[self.rows_a] + ra, x[self.rows_b] + rb, ra, rb

    def rest_lengths_auto(self, x: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Initial distances between the ends (for rest: auto)."""
        pa, pb, _, _ = self.ends(x, q)
        return np.linalg.norm(pb - pa, axis=1)

    def forces(
        self, x: np.ndarray, v: np.ndarray, q: np.ndarray, w: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(f_a (S,3) on end a, r_a, r_b)."""
        pa, pb, ra, rb = self.ends(x, q)
        va = v[self.rows_a].copy()
        vb = v[self.rows_b].copy()
        has_a, has_b = self.body_a >= 0, self.body_b >= 0
        if has_a.any():
            va[has_a] += np.cross(w[self.body_a[has_a]], ra[has_a])
        if has_b.any():
            vb[has_b] += np.cross(w[self.body_b[has_b]], rb[has_b])
        d = pb - pa
        length = np.linalg.norm(d, axis=1)
        u = d / np.where(length > 0, length, 1.0)[:, None]
        mag = self.ks * (length - self.rest) + self.kd * np.einsum("si,si->s", vb - va, u)
        return mag[:, None] * u, ra, rb

    def accumulate_bodies(
        self,
        x: np.ndarray,
        v: np.ndarray,
        q: np.ndarray,
        w: np.ndarray,
        t: float,
        out: np.ndarray,
        torque_out: np.ndarray,
    ) -> None:
        fa, ra, rb = self.forces(x, v, q, w)
        np.add.at(out, self.rows_a, fa)
        np.add.at(out, self.rows_b, -fa)
        has_a, has_b = self.body_a >= 0, self.body_b >= 0
        if has_a.any():
            np.add.at(torque_out, self.body_a[has_a], np.cross(ra[has_a], fa[has_a]))
        if has_b.any():
            np.add.at(torque_out, self.body_b[has_b], np.cross(rb[has_b], -fa[has_b]))

    def potential_bodies(self, x: np.ndarray, q: np.ndarray) -> float:
        """1/2 sum ks (L - rest)^2 at positions x and orientations q."""
        pa, pb, _, _ = self.ends(x, q)
        stretch = np.linalg.norm(pb - pa, axis=1) - self.rest
        return float(0.5 * np.sum(self.ks * stretch * stretch))

    def stiffness_rows(self, inv_mass: np.ndarray, k_rows: np.ndarray, c_rows: np.ndarray) -> None:
        """Gershgorin rows of M^-1/2 K M^-1/2 as for particle springs, a body end standing as its
        centre-of-mass row with the mobility of the attachment point in place of 1/m.

        A point at lever arm r of a body moves under a force f by f/m (translation) plus up to
        |r|^2 |f| / I_min (rotation about the softest axis), so 1/m + |r|^2 / I_min bounds its
        inverse effective mass: exact for the translation, an upper bound for the rotation
        (the stable step it suggests is on the safe side).
        """
        inv_eff = [
            self._mobility(inv_mass, rows, body, at)
            for rows, body, at in (
                (self.rows_a, self.body_a, self.at_a),
                (self.rows_b, self.body_b, self.at_b),
            )
        ]
        ia, ib = inv_eff
        cross = np.sqrt(ia * ib)
        n = len(k_rows)
        for coef, rows in ((self.ks, k_rows), (self.kd, c_rows)):
            rows += np.bincount(self.rows_a, weights=coef * (ia + cross), minlength=n)
            rows += np.bincount(self.rows_b, weights=coef * (ib + cross), minlength=n)

    def _mobility(
        self, inv_mass: np.ndarray, rows: np.ndarray, body: np.ndarray, at: np.ndarray
    ) -> np.ndarray:
        out = inv_mass[rows].astype(np.float64)
        has = body >= 0
        if has.any() and self.inv_inertia is not None:
            lever2 = np.einsum("si,si->s", at[has], at[has])
            out[has] += lever2 * self.inv_inertia[body[has]].max(axis=1)
        return out
