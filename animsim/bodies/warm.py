"""Warm starting: each contact starts the step from the impulses it ended the last one with.

Sequential impulses converge like Gauss-Seidel: a resting stack of ten boxes needs hundreds
of sweeps from zero impulses each step, and what the sweeps leave unconverged turns into a
drift that topples it. A resting contact needs nearly the same impulse step after step, so
starting from the last one (Catto, "Iterative Dynamics with Temporal Coherence", GDC 2005;
Box2D and Bullet do the same) leaves the sweeps only the change to find.

A contact of this step is the same as one of the last step when it joins the same two things
(the same bodies, plane or collider side) at nearly the same point of body a: within
``REACH`` of its bounding radius, in a's own frame (so a box turning on the floor keeps its
corners' impulses). An impact never starts warm: its impulse is a bounce, found afresh.
"""

from __future__ import annotations

import numpy as np

from animsim.bodies import quaternion as quat

#: a contact matches one of the last step within this fraction of body a's bounding radius
REACH = 0.05


class WarmStart:
    """The last step's contacts and impulses, and the guesses they give for this step's."""

    def __init__(self, bound: np.ndarray, planes: int) -> None:
        self.bound = bound
        # what a contact joins body a to: another body (0 .. B-1), a collider (B), a plane
        # (B + 1 ..): the keys below stay distinct for any number of planes
        self._others = bound.shape[0] + 1 + planes
        self.forget()

    def forget(self) -> None:
        self._key = np.zeros(0, dtype=np.int64)
        self._local = np.zeros((0, 3))
        self._jn = np.zeros(0)
        self._jt = np.zeros((0, 3))
        self._jr = np.zeros((0, 3))

    def snapshot(self) -> tuple[np.ndarray, ...]:
        """What :meth:`restore` puts back (the arrays are replaced, never changed in place)."""
        return (self._key, self._local, self._jn, self._jt, self._jr)

    def restore(self, snap: tuple[np.ndarray, ...]) -> None:
        self._key, self._local, self._jn, self._jt, self._jr = snap

    def _keys(self, a: np.ndarray, b: np.ndarray, plane: np.ndarray, n: np.ndarray) -> np.ndarray:
        """One integer per (body a, body b or plane, side of a collider by normal)."""
        nb = self.bound.shape[0]
        axis = np.argmax(np.abs(n), axis=1)
        side = axis * 2 + (n[np.arange(n.shape[0]), axis] > 0)
        other = np.where(b >= 0, b, nb + 1 + np.maximum(plane, -1))
        return (a * self._others + other) * 6 + side

    def guess(
        self, a: np.ndarray, b: np.ndarray, plane: np.ndarray, n: np.ndarray, ra: np.ndarray, q: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Starting impulses, normal (C,), friction (C, 3) and rolling (C, 3), for this step's
        contacts (zero where none matches), and the contact points in body a's frame (C, 3), for
        :meth:`keep`."""
        count = a.shape[0]
        jn, jt, jr = np.zeros(count), np.zeros((count, 3)), np.zeros((count, 3))
        local = quat.rotate_inverse(q[a], ra) if count else np.zeros((0, 3))
        if count == 0 or self._key.size == 0:
            return jn, jt, jr, local
        key = self._keys(a, b, plane, n)
        lo = np.searchsorted(self._key, key, side="left")
        hi = np.searchsorted(self._key, key, side="right")
        best = np.full(count, np.inf)
        pick = np.full(count, -1)
        reach = REACH * self.bound[a]
        for k in range(int((hi - lo).max(initial=0))):
            m = lo + k
            ok = m < hi
            mm = np.where(ok, m, 0)
            gap = local - self._local[mm]
            dist = np.sqrt(np.einsum("ij,ij->i", gap, gap))
            better = ok & (dist < best) & (dist <= reach)
            best = np.where(better, dist, best)
            pick = np.where(better, mm, pick)
        hit = pick >= 0
        jn[hit] = self._jn[pick[hit]]
        jt[hit] = self._jt[pick[hit]]
        jr[hit] = self._jr[pick[hit]]
        return jn, jt, jr, local

    def keep(
        self,
        a: np.ndarray,
        b: np.ndarray,
        plane: np.ndarray,
        n: np.ndarray,
        local: np.ndarray,
        jn: np.ndarray,
        jt: np.ndarray,
        jr: np.ndarray,
        held: np.ndarray | None = None,
    ) -> None:
        """Remember this step's contacts (points in body a's frame, from :meth:`guess`) and the
        impulses they ended with; and, for the bodies ``held`` (B,) bool (asleep, their contacts
        not solved: :mod:`animsim.bodies.sleep`), the impulses they were remembered with."""
        key = self._keys(a, b, plane, n)
        if held is not None and self._key.size:
            carry = held[self._key // 6 // self._others]
            key = np.concatenate([key, self._key[carry]])
            local = np.concatenate([local, self._local[carry]])
            jn = np.concatenate([jn, self._jn[carry]])
            jt = np.concatenate([jt, self._jt[carry]])
            jr = np.concatenate([jr, self._jr[carry]])
        order = np.argsort(key, kind="stable")
        self._key = key[order]
        self._local = local[order]
        self._jn = jn[order].copy()
        self._jt = jt[order].copy()
        self._jr = jr[order].copy()
