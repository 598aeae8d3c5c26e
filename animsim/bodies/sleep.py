"""Sleeping: bodies at rest stop being stepped until something awake touches them.

A pile at rest costs as much as a pile falling: its contacts are solved every step, and a
resting stack never gets below the tolerance at which the sweeps stop. Production engines
let such islands *sleep* (Catto, Box2D ``b2Island::Solve``, "sleep" and ``b2World::Solve``,
which wakes what an awake island touches; Bullet's deactivation, ``btRigidBody`` and
``btSimulationIslandManager``). The rules here, step by step (scene key ``sleep``):

* **At rest.** A body is at rest in a step when, after the contacts, its speed and its
  angular speed times its bounding radius (how fast its farthest point turns) are both below
  ``speed``. Its clock counts the time it has stayed at rest; any faster step resets it.
* **Falling asleep.** The bodies joined by this step's contacts between them form islands
  (planes, colliders and pinned bodies join nothing, as static bodies in Box2D). An island
  falls asleep when every body in it may sleep and has been at rest for ``after`` seconds:
  its velocities become exactly 0 and its poses are kept.
* **Asleep.** A sleeping body is not moved: each step its pose is put back and its
  velocities set to 0 before the contacts are found (the integrator's move, gravity's
  included, is undone), and its contacts with planes, colliders, resting pinned bodies and
  bodies of its own sleeping island are left out of the solve. Their last impulses are kept,
  so an island that wakes starts from them (warm starting).
* **Waking.** A sleeping island wakes whole when a contact joins one of its bodies to an
  awake body, to a pinned body that moves, or to a keyframed collider moving in this step;
  the contacts are then found again, the woken bodies' included, before the solve. A
  particle that touches a sleeping body wakes its island too (after the bodies' own
  contacts: that body answers the particle in the same step, the rest of its island is
  stepped from the next one).
* **Never asleep.** Pinned bodies (they keep their given motion), bodies with a spring
  attached, and every body when the scene has a force that a body standing still could feel
  change (a force element whose ``lets_bodies_sleep`` is False, :mod:`animsim.elements`).

What it costs: a sleeping body ignores nothing that can touch it, but it does not answer
velocities below ``speed``: a body creeping slower than that for ``after`` seconds stops.
"""

from __future__ import annotations

import numpy as np

from animsim.bodies.contact_batches import components


def body_islands(a: np.ndarray, b: np.ndarray, still: np.ndarray) -> np.ndarray:
    """(B,) island number of each body: bodies joined by contacts (a, b) between two bodies
    neither of which is ``still`` (B,) (pinned, or asleep) share a number; the others are
    islands of their own. Connected components (the solver's islands,
    :func:`animsim.bodies.contact_batches.islands`, are the same graph)."""
    bb = np.maximum(b, 0)
    return components(a, b, still.shape[0], (b >= 0) & ~still[a] & ~still[bb])


class Sleep:
    """Which bodies sleep, since when, where; the rules of the module docstring.

    bound: (B,) bounding radii (m); may_sleep: (B,) bool, False for the bodies that never
    sleep; pinned: (B,) bool.
    """

    def __init__(
        self, speed: float, after: float, bound: np.ndarray, may_sleep: np.ndarray, pinned: np.ndarray
    ) -> None:
        self.speed = float(speed)
        self.after = float(after)
        self.bound = np.asarray(bound, dtype=np.float64)
        self.may_sleep = np.asarray(may_sleep, dtype=bool) & ~np.asarray(pinned, dtype=bool)
        self.pinned = np.asarray(pinned, dtype=bool)
        count = self.bound.shape[0]
        self.asleep = np.zeros(count, dtype=bool)
        #: (B,) seconds each body has been at rest
        self.rested = np.zeros(count)
        #: (B,) the island each sleeping body fell asleep with (it wakes with it)
        self.group = np.full(count, -1, dtype=np.int64)
        self._next_group = 0
        self.pose_x = np.zeros((count, 3))
        self.pose_q = np.zeros((count, 4))
        #: pinned bodies that move (kinematic, with a velocity): they wake what they touch
        self.moving_pinned = np.zeros(count, dtype=bool)
        #: counts the changes of who sleeps (what is derived from ``asleep`` is kept until it moves)
        self.version = 0
        self._sleepers = np.zeros(0, dtype=np.int64)
        self._sleepers_at = -1
        self._moved: tuple[np.ndarray, ...] = (self._sleepers,)

    def label(self) -> str:
        """The line ``explain`` shows."""
        never = int((~self.may_sleep).sum())
        held = (
            f"; {never} of {self.may_sleep.size} never sleep (pinned, held by a spring, or under a force that changes)"
            if never
            else ""
        )
        return (
            f"sleeping: an island of touching bodies slower than {self.speed:g} m/s (and turning slower "
            f"than that at its bounding radius) for {self.after:g} s sleeps, unstepped, until an awake body, "
            f"a particle, a moving pinned body or a moving collider touches it{held}"
        )

    def reset(self, v: np.ndarray, w: np.ndarray) -> None:
        """At the start of a run: every body awake, its clock at 0."""
        self.asleep[:] = False
        self.rested[:] = 0.0
        self.group[:] = -1
        self._next_group = 0
        self.version += 1
        self.moving_pinned = self.pinned & ((v != 0.0).any(axis=1) | (w != 0.0).any(axis=1))

    def snapshot(self) -> tuple[object, ...]:
        """Who sleeps, since when and where, for :meth:`restore` (a replay from a kept state)."""
        arrays = (self.asleep, self.rested, self.group, self.pose_x, self.pose_q, self.moving_pinned)
        return (*(a.copy() for a in arrays), self._next_group)

    def restore(self, snap: tuple[object, ...]) -> None:
        *arrays, self._next_group = snap  # type: ignore[assignment]
        self.asleep, self.rested, self.group, self.pose_x, self.pose_q, self.moving_pinned = (
            np.array(a, copy=True) for a in arrays
        )
        self.version += 1  # what was derived from who sleeps is stale
        self._sleepers_at = -1

    @property
    def any_asleep(self) -> bool:
        return bool(self.asleep.any())

    def still(self) -> np.ndarray:
        """(B,) bodies that do not move in this step: asleep, or pinned without a velocity."""
        return self.asleep | (self.pinned & ~self.moving_pinned)

    def freeze(self, x: np.ndarray, v: np.ndarray, q: np.ndarray, w: np.ndarray) -> None:
        """Put the sleeping bodies back where they fell asleep, velocities 0 (in place)."""
        if not self.any_asleep:
            return
        if self._sleepers_at != self.version:
            self._sleepers, self._sleepers_at = np.flatnonzero(self.asleep), self.version
        s = self._sleepers
        # where the integrator took them, for those a contact wakes in this step (unfreeze)
        self._moved = (s, x[s].copy(), v[s].copy(), q[s].copy(), w[s].copy())
        x[s] = self.pose_x[s]
        q[s] = self.pose_q[s]
        v[s] = 0.0
        w[s] = 0.0

    def unfreeze(self, woken: np.ndarray, x: np.ndarray, v: np.ndarray, q: np.ndarray, w: np.ndarray) -> None:
        """Give the bodies ``woken`` (B,) bool in this step's contacts the step the integrator
        gave them (in place): woken by a contact, a body takes its step as if it had been awake
        (gravity's push included), so a woken stack meets the contact under its own weight."""
        s, mx, mv, mq, mw = self._moved
        pick = woken[s]
        rows = s[pick]
        x[rows], v[rows], q[rows], w[rows] = mx[pick], mv[pick], mq[pick], mw[pick]

    def pairs_to_find(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """(P,) bool: which candidate pairs to look for contacts in: not those of two bodies
        that do not move, one of them asleep (their contacts are left out of the solve)."""
        if not self.any_asleep:
            return np.ones(i.shape[0], dtype=bool)
        still = self.still()
        return ~(still[i] & still[j] & (self.asleep[i] | self.asleep[j]))

    def wake(self, bodies: np.ndarray) -> np.ndarray | None:
        """Wake the islands of ``bodies`` (indices) that sleep: (B,) bool of the woken bodies, or
        None if none woke."""
        if not self.any_asleep or bodies.size == 0:
            return None
        groups = self.group[bodies[self.asleep[bodies]]]
        if groups.size == 0:
            return None
        woken = self.asleep & np.isin(self.group, groups)
        self.asleep[woken] = False
        self.rested[woken] = 0.0
        self.group[woken] = -1
        self.version += 1
        return woken

    def wake_touched(self, a: np.ndarray, b: np.ndarray, surface: np.ndarray | None) -> np.ndarray | None:
        """Wake the sleeping islands that this step's contacts (a, b; b = -1: a plane or a
        collider, whose velocity at the contact is ``surface`` (C, 3), None: all still) join to
        something that moves: (B,) bool of the woken bodies, or None if none woke."""
        if not self.any_asleep or a.size == 0:
            return None
        still = self.still()
        pair = b >= 0
        bb = np.maximum(b, 0)
        # a pair of which one end moves: the other end, if asleep, wakes
        moving_a = ~still[a]
        moving_b = pair & ~still[bb]
        hit = np.concatenate([a[moving_b], bb[pair & moving_a]])
        if surface is not None:
            hit = np.concatenate([hit, a[~pair & (surface != 0.0).any(axis=1)]])
        return self.wake(hit)

    def to_solve(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(C,) bool: the contacts the solve takes: all but those of a sleeping body against
        something that does not move (after waking, a sleeping body touches nothing else)."""
        if not self.any_asleep:
            return np.ones(a.shape[0], dtype=bool)
        still = self.still()
        bb = np.maximum(b, 0)
        other_still = (b < 0) | still[bb]
        sleeper = self.asleep[a] | ((b >= 0) & self.asleep[bb])
        return ~(sleeper & still[a] & other_still)

    def settle(
        self,
        x: np.ndarray,
        v: np.ndarray,
        q: np.ndarray,
        w: np.ndarray,
        a: np.ndarray,
        b: np.ndarray,
        dt: float,
    ) -> None:
        """After the step's contacts (a, b, those solved): advance the clocks of the awake
        bodies, and put to sleep every island whose bodies have all rested ``after`` seconds."""
        awake = ~self.asleep
        speed2 = np.einsum("ij,ij->i", v, v)
        spin2 = np.einsum("ij,ij->i", w, w) * self.bound * self.bound
        limit2 = self.speed * self.speed
        resting = awake & self.may_sleep & (speed2 < limit2) & (spin2 < limit2)
        self.rested = np.where(resting, self.rested + dt, np.where(awake, 0.0, self.rested))
        ready = resting & (self.rested >= self.after)
        if not ready.any():
            return
        label = body_islands(a, b, self.still())
        # an island sleeps when none of its awake bodies is unready (pinned ones are islands alone)
        unready = np.bincount(label, weights=(awake & ~ready).astype(np.float64), minlength=label.size)
        falls = ready & (unready[label] == 0.0)
        if not falls.any():
            return
        self.asleep[falls] = True
        self.version += 1
        self.group[falls] = self._next_group + label[falls]
        self._next_group += label.size
        self.pose_x[falls] = x[falls]
        self.pose_q[falls] = q[falls]
        v[falls] = 0.0
        w[falls] = 0.0
