"""Tearing: springs that break for good when stretched too far.

A spring with ``max_strain`` breaks at the end of the first step where its
strain ``|L| / rest - 1`` exceeds the limit (a spring of rest length 0 has no
strain: it breaks as soon as its ends part). A broken spring stays broken:
``State.spring_intact`` is False for it and the spring forces skip it. Only
the springs that can tear are looked at, in index order, from positions
alone, so a run tears the same springs at the same steps every time.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from animsim.elements import StepStage
from animsim.system import State

if TYPE_CHECKING:  # types only
    from animsim.forces.springs import Springs


def strain(x: np.ndarray, a: np.ndarray, b: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """|L| / rest - 1 of springs (a, b); +inf for a stretched zero-rest spring, 0 for a slack one."""
    d = x[a] - x[b]
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(
            rest > 0, length / np.where(rest > 0, rest, 1.0) - 1.0, np.where(length > 0, np.inf, 0.0)
        )
    return s


def tear_numpy(
    x: np.ndarray,
    which: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    rest: np.ndarray,
    limit: np.ndarray,
    intact: np.ndarray,
) -> int:
    """Break every intact spring of ``which`` past its limit; the number broken now."""
    live = which[intact[which]]
    if live.size == 0:
        return 0
    broke = live[strain(x, a[live], b[live], rest[live]) > limit[live]]
    intact[broke] = False
    return int(broke.size)


_KERNEL = None


def numba_kernel():
    global _KERNEL
    if _KERNEL is not None:
        return _KERNEL
    import numba

    @numba.njit(cache=True)
    def tear(x, which, a, b, rest, limit, intact):  # pragma: no cover - compiled
        broken = 0
        for k in range(which.shape[0]):
            s = which[k]
            if not intact[s]:
                continue
            d2 = 0.0
            for ax in range(3):
                t = x[a[s], ax] - x[b[s], ax]
                d2 += t * t
            length = np.sqrt(d2)
            if rest[s] > 0:
                st = length / rest[s] - 1.0
            else:
                st = np.inf if length > 0 else 0.0
            if st > limit[s]:
                intact[s] = False
                broken += 1
        return broken

    _KERNEL = tear
    return tear


class Tearing(StepStage):
    """The tearing stage: runs after contacts, before emitters."""

    injects = False
    dissipative = True  # a breaking spring takes its stored energy with it
    no_closed_form = "tearing springs"

    def __init__(
        self,
        index: np.ndarray,
        rest: np.ndarray,
        max_strain: np.ndarray,
        backend: str = "numpy",
        families: list[tuple[str, int, int]] | None = None,
    ):
        self.a = np.ascontiguousarray(index[:, 0], dtype=np.int64)
        self.b = np.ascontiguousarray(index[:, 1], dtype=np.int64)
        self.rest = np.ascontiguousarray(rest, dtype=np.float64)
        self.limit = np.ascontiguousarray(max_strain, dtype=np.float64)
        self.which = np.flatnonzero(np.isfinite(self.limit)).astype(np.int64)
        self.backend = backend
        self._kernel = numba_kernel() if backend == "numba" else None
        self.broken = 0
        self.first_break: float | None = None
        #: the spring element (animsim.forces.springs.Springs) whose broken springs are switched off
        self.springs: Springs | None = None
        self.label = f"tearing: {self.which.size} spring(s) break for good past their max_strain " + (
            _families_text(self.limit, families)
            if families
            else f"({', '.join(f'{v:g}' for v in np.unique(self.limit[self.which])[:6])})"
        )

    def stability_note(self, dt: float) -> str:
        return "tearing: the bound above counts every spring; torn springs only lower it"

    def reset(self, state: State) -> None:
        """At a run's start (or a replay's): the springs broken in ``state`` are the broken ones."""
        self.broken = 0 if state.spring_intact is None else int((~state.spring_intact).sum())
        self.first_break = None
        if self.springs is not None and state.spring_intact is not None:
            self.springs.set_intact(state.spring_intact)

    def apply(
        self,
        state: State,
        x_old: np.ndarray,
        v_old: np.ndarray,
        t0: float,
        t1: float,
        dt: float | None = None,
    ) -> bool:
        intact = state.spring_intact
        if intact is None:
            return False
        x = state.particle_position
        if self.springs is not None and self.broken != intact.size - int(np.count_nonzero(intact)):
            # the state was replaced (a replay, an adaptive trial): follow its springs
            self.broken = intact.size - int(np.count_nonzero(intact))
            self.springs.set_intact(intact)
        if self._kernel is not None:
            now = int(self._kernel(x, self.which, self.a, self.b, self.rest, self.limit, intact))
        else:
            now = tear_numpy(x, self.which, self.a, self.b, self.rest, self.limit, intact)
        if now:
            self.broken += now
            if self.first_break is None:
                self.first_break = t1
            if self.springs is not None:
                self.springs.set_intact(intact)
        return now > 0

    def run_summary(self) -> dict[str, float | int | None]:
        return {"springs_broken": self.broken, "first_break_time": self.first_break}


def _families_text(limit: np.ndarray, families: list[tuple[str, int, int]]) -> str:
    """Which spring families tear (with their limits) and which never do, so a structure
    whose stretch springs tear while its bend springs hold it together is seen before the run."""
    tear, hold = [], []
    for name, a, b in families:
        if b <= a:
            continue
        part = limit[a:b]
        finite = np.unique(part[np.isfinite(part)])
        if finite.size == 0:
            hold.append(name)
            continue
        values = ", ".join(f"{v:g}" for v in finite[:3]) + (", ..." if finite.size > 3 else "")
        count = int(np.isfinite(part).sum())
        tear.append(f"{name} {values}" + (f" ({count} of {b - a})" if count < b - a else ""))
    return f"({'; '.join(tear)})" + (f"; never: {', '.join(hold)}" if hold else "")
