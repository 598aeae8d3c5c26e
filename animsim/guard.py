"""The watchdog a run checks its state with, and what it reports when a run fails.

Both the loop (:mod:`animsim.engine`) and the steppers (:mod:`animsim.steppers`,
which may replay checks themselves) use them, so they stand below both.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from animsim.compile import Compiled
from animsim.measures import stability
from animsim.measures.watchdog import EnergyWatch, WatchBooks
from animsim.system import State


@dataclass
class Failure:
    """Where and why a run became unstable."""

    step: int
    time: float
    particle: str | None
    reason: str
    spring: str | None = None
    growth: float | None = None
    suggestion: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if v is not None}

    def describe(self) -> str:
        parts = [f"unstable at step {self.step} (t = {self.time:.6g} s): {self.reason}"]
        if self.particle is not None:
            parts.append(f"particle {self.particle!r}")
        if self.spring is not None:
            parts.append(f"spring {self.spring}")
        text = "; ".join(parts)
        if self.suggestion:
            text += f"\n  fix: {self.suggestion}"
        return text


class Guard:
    """The watchdog: stops a run at the first step whose state is not finite or
    whose mechanical energy has grown far beyond what the forces put in
    (:mod:`animsim.measures.watchdog`).

    ``check`` returns a Failure (with the particle and spring most to blame and
    a fix from :mod:`animsim.measures.stability`) or None. How often it runs
    is the stepper's ``check_stride`` (:mod:`animsim.steppers`).
    """

    def __init__(self, compiled: Compiled, dt: float | None = None):
        self.compiled = compiled
        self.watch = EnergyWatch(compiled, dt if dt is not None else compiled.clock.dt)
        #: a compiled test that is True only where check passes (the stepper's quick_check)
        self.quick: Callable[[State], bool] | None = None

    def start(self, state: State) -> None:
        """Open the energy books at the run's initial state."""
        self.watch.bind(state)
        self.watch.reset(state)

    def book(self, state: State) -> None:
        """After a step of a run with births: book the newborns as a check would (cheap)."""
        self.watch.book_births(state)

    def snapshot(self) -> WatchBooks | None:
        """The watchdog's books at a checked state, for a replay from it."""
        return self.watch.snapshot()

    def restore(self, snap: WatchBooks | None) -> None:
        self.watch.restore(snap)

    def check(self, state: State) -> Failure | None:
        if self.quick is not None and self.quick(state):
            return None  # passes: finite, and the energy test below its margin
        x, v = state.particle_position, state.particle_velocity
        # One reduction each instead of an (N, 3) boolean array: a NaN or inf
        # anywhere makes the sum non-finite.
        if not (math.isfinite(x.sum()) and math.isfinite(v.sum())):
            bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
            if bad.any():  # else the sum overflowed on huge but finite values
                i = int(np.flatnonzero(bad)[0])
                return self._failure(
                    state, i, self._stiffest_spring_at(i), None, "a position or velocity is not finite"
                )
        if state.body_orientation is not None:
            found = self._body_not_finite(state)
            if found is not None:
                return found
        if self.watch.disabled is not None:
            return None
        with np.errstate(over="ignore", invalid="ignore"):
            h, b, growth = self.watch.growth(state)
        if growth <= self.watch.allowance:  # False for NaN too: an overflowed energy is a blow-up
            return None
        particle, spring = self.watch.blame(state)
        reason = f"the mechanical energy {h:.3g} J is {growth:.3g} times what the forces put in ({b:.3g} J)"
        return self._failure(state, particle, spring, growth, reason)

    def _body_not_finite(self, state: State) -> Failure | None:
        """A rigid body whose orientation or angular velocity is not finite, named by its id."""
        q, w = state.body_orientation, state.body_angular_velocity
        assert q is not None and w is not None  # called for states with bodies only
        if np.isfinite(q.sum()) and np.isfinite(w.sum()):
            return None
        bad = ~(np.isfinite(q).all(axis=1) & np.isfinite(w).all(axis=1))
        if not bad.any():
            return None
        i = self.compiled.system.body_first + int(np.flatnonzero(bad)[0])
        return self._failure(
            state, i, None, None, "a rigid body's orientation or angular velocity is not finite"
        )

    def _stiffest_spring_at(self, i: int) -> int | None:
        sysm = self.compiled.system
        if not sysm.spring_count:
            return None
        idx = sysm.spring_index
        touching = np.flatnonzero((idx[:, 0] == i) | (idx[:, 1] == i))
        if touching.size == 0:
            return None
        inv = sysm.particle_inv_mass
        w2 = sysm.spring_ks[touching] * (inv[idx[touching, 0]] + inv[idx[touching, 1]])
        return int(touching[np.argmax(w2)])

    def _failure(
        self, state: State, i: int, spring: int | None, growth: float | None, reason: str
    ) -> Failure:
        report = stability.analyse(self.compiled)
        return Failure(
            step=state.step,
            time=state.time,
            particle=stability.particle_name(self.compiled, i),
            reason=reason,
            spring=None if spring is None else stability.spring_label(self.compiled.system, spring),
            growth=None if growth is None else float(growth),
            suggestion=report.suggestion(),
        )
