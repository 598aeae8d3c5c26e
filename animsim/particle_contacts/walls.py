"""The solid colliders and impulse planes a grain rests on, as one-sided contacts of the resting solve.

The colliders and planes stages run before the particle contacts and stop a grain's own fall
into them, but not the weight of the grains above it, which reaches it through the contacts'
impulses: a pile's bottom layer must push on the floor inside the same solve, or the floor
never carries the pile (the solve pushes the bottom layer in, the colliders' projection
afterwards only stops it, and the grains above keep falling by what was lost). So every grain
within the slop of a collider's surface (its centre ``radius`` from it) or of a plane (planes
hold centres) is a contact with an immovable body moving at the collider's velocity, solved
with the grain pairs (:mod:`animsim.particle_contacts.step_kernels`).

As for the pairs, the candidates (grains within the Verlet list's skin of a wall) are kept
between steps and found again when the list is rebuilt; each step keeps those that touch.
One definition for both backends: the contacts are found here, in NumPy, and handed to either
kernel as arrays (rows, unit normals out of the wall, the wall's velocity, its friction and a
key ``row * walls + wall`` under which the contact's impulses are kept for the next step).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from animsim.colliders.shapes import shape_of
from animsim.particle_contacts.constants import SLOP


class WallContacts(NamedTuple):
    rows: np.ndarray  # (Q,) int64
    normal: np.ndarray  # (Q, 3) unit, out of the wall
    velocity: np.ndarray  # (Q, 3) the wall's
    friction: np.ndarray  # (Q,)
    key: np.ndarray  # (Q,) int64, row * walls + wall, ascending


EMPTY = np.zeros(0, dtype=np.int64)
NO_WALLS = WallContacts(EMPTY, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), EMPTY)


class Walls:
    """Where grains touch the scene's colliders and impulse planes at the end of a step."""

    def __init__(self, colliders: Any, planes: Any) -> None:
        self.colliders = colliders
        self.planes = [] if planes is None else list(planes.planes)
        self.shapes = [] if colliders is None else [shape_of(p, 0.0) for p in colliders.params]
        self.count = len(self.shapes) + len(self.planes)
        #: keyframed colliders: their motion is not in the list's test, so every step looks at all rows
        self.moving = [bool(m >= 0) for m in (colliders.moving if self.shapes else [])] + [False] * len(
            self.planes
        )
        self._rows = [EMPTY] * self.count  # each wall's candidate rows, ascending
        self._all = EMPTY

    def _distance(
        self, wall: int, x: np.ndarray, radius: np.ndarray, rows: np.ndarray, t: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """How far rows' spheres are from ``wall`` (negative: inside) and its normal there."""
        if wall < len(self.shapes):
            d, n = self.shapes[wall].signed_distance(x[rows], self.colliders.offsets(t)[wall])
            return d - radius[rows], n
        plane = self.planes[wall - len(self.shapes)]
        return x[rows] @ plane.normal - plane.offset, np.broadcast_to(plane.normal, (rows.size, 3))

    def rebuild(self, x: np.ndarray, radius: np.ndarray, rows: np.ndarray, skin: float, t: float) -> None:
        """The candidates: ``rows`` within ``skin`` of each wall (colliders: first the boxes
        of :func:`animsim.colliders.shapes.shape_bounds`, grown by the largest radius and the skin)."""
        self._all = rows
        for wall in range(self.count):
            self.rebuild_one(wall, x, radius, skin, t)

    def rebuild_one(self, wall: int, x: np.ndarray, radius: np.ndarray, skin: float, t: float) -> None:
        rows = near = self._all
        if wall < len(self.shapes) and rows.size:
            off = self.colliders.offsets(t)[wall]
            grow = float(radius[rows].max()) * (1.0 + SLOP) + skin
            b = self.colliders.bounds[wall]
            lo, hi = b[:3] + off - grow, b[3:] + off + grow
            for a in range(3):  # one axis at a time: a wall's slab leaves few rows for the next
                c = x[near, a]
                near = near[(c >= lo[a]) & (c <= hi[a])]
        if near.size:
            d, _ = self._distance(wall, x, radius, near, t)
            near = near[d <= skin + SLOP * radius[near]]
        self._rows[wall] = near

    def contacts(
        self, x: np.ndarray, radius: np.ndarray, movable: np.ndarray, t0: float, t1: float
    ) -> WallContacts:
        """The candidates that touch (within the slop) and can move, in (row, wall) order."""
        parts = []
        for wall, rows in enumerate(self._rows):
            if self.moving[wall]:
                self.rebuild_one(wall, x, radius, 0.0, t1)
                rows = self._rows[wall]
            rows = rows[movable[rows]]
            if rows.size == 0:
                continue
            d, n = self._distance(wall, x, radius, rows, t1)
            touch = d <= SLOP * radius[rows]
            if not touch.any():
                continue
            if wall < len(self.shapes):
                off = self.colliders.offsets
                u, mu = (off(t1)[wall] - off(t0)[wall]) / (t1 - t0), float(self.colliders.friction[wall])
            else:
                u, mu = np.zeros(3), float(self.planes[wall - len(self.shapes)].friction)
            k = int(touch.sum())
            parts.append(
                (rows[touch] * self.count + wall, n[touch], np.broadcast_to(u, (k, 3)), np.full(k, mu))
            )
        if not parts:
            return NO_WALLS
        key = np.concatenate([p[0] for p in parts])
        order = np.argsort(key, kind="stable")
        key = key[order]
        return WallContacts(
            key // self.count,
            np.ascontiguousarray(np.concatenate([p[1] for p in parts])[order]),
            np.ascontiguousarray(np.concatenate([p[2] for p in parts])[order]),
            np.concatenate([p[3] for p in parts])[order],
            key,
        )
