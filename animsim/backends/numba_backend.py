"""The numba backend: a compiled scene's whole step as numba kernels.

:class:`NumbaStepper` reads the force terms, impulse planes and integrator
the compiler built for NumPy (the same objects, so a scene compiles to
either backend and ``explain`` lists the same stages), packs their
constants into flat arrays once, and advances a :class:`State` many steps
per call (:mod:`animsim.backends.numba_kernels`). Kernels are compiled with
``cache=True``: the first run on a machine compiles them (seconds) and
stores the machine code under ``__pycache__``; later runs load it.
"""

from __future__ import annotations

import time
from typing import Any

import numba
import numpy as np

from animsim.backends import numba_kernels as K
from animsim.collisions import PlaneColliders
from animsim.forces.attractor import Attractor
from animsim.forces.drag import Drag, QuadraticDrag
from animsim.forces.gravity import Gravity
from animsim.forces.penalty import PenaltyPlane
from animsim.forces.springs import Springs
from animsim.forces.wind import Wind
from animsim.integrators.runge_kutta import RungeKutta
from animsim.integrators.symplectic import CACHE_TIME_RTOL
from animsim.system import State

#: particles + springs from which more than one thread is even tried; below
#: it a parallel region's start-up costs more than it saves
PARALLEL_MIN_WORK = 20_000
#: timed calls per thread count before the stepper settles on the faster one.
#: Measured, not assumed: on a machine whose cores other processes keep busy,
#: every parallel region waits for a descheduled thread, and 2 threads ran
#: cloth 128 at 25 steps/s against 425 on one (benchmarks/RESULTS.md).
THREAD_TRIALS = 2
#: largest (particles + springs) x steps one call may do, so Ctrl-C and the
#: progress bar are served about every few tenths of a second
MAX_WORK_PER_CALL = 20_000_000

_METHODS = {"symplectic_euler": K.SYMPLECTIC_EULER, "euler_average": K.EULER_AVERAGE, "verlet": K.VERLET}


def _rows(values: list[Any], width: int) -> np.ndarray:
    return np.array(values, dtype=np.float64).reshape(-1, width)


def incidence(a: np.ndarray, b: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR table of the springs at each particle: (row pointers, spring ids, signs +1 at a / -1 at b)."""
    ends = np.concatenate([a, b])
    springs = np.concatenate([np.arange(len(a)), np.arange(len(b))]).astype(np.int64)
    signs = np.concatenate([np.ones(len(a)), -np.ones(len(b))])
    order = np.argsort(ends, kind="stable")
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(ends, minlength=n), out=ptr[1:])
    return ptr, springs[order], signs[order]


class NumbaStepper:
    """Advances a compiled scene with the numba kernels (see the module docstring)."""

    def __init__(self, compiled: Any, threads: int | None = None):
        system = compiled.system
        n = system.particle_count
        gravity = np.zeros(3)
        drag_k = qdrag_c = 0.0
        winds: list[Any] = []
        wind_k: list[float] = []
        atts: list[Any] = []
        att_gm: list[float] = []
        att_eps2: list[float] = []
        pens: list[Any] = []
        pen_k: list[float] = []
        pen_c: list[float] = []
        springs: Springs | None = None
        for term in compiled.dynamics.terms:
            if isinstance(term, Gravity):
                gravity += term.g
            elif isinstance(term, Drag):
                drag_k += term.k
            elif isinstance(term, QuadraticDrag):
                qdrag_c += term.c
            elif isinstance(term, Wind):
                winds.append(term.w)
                wind_k.append(term.k)
            elif isinstance(term, Attractor):
                atts.append(term.center)
                att_gm.append(term.gm)
                att_eps2.append(term.eps2)
            elif isinstance(term, PenaltyPlane):
                pens.append(np.concatenate([term.p, term.n]))
                pen_k.append(term.k)
                pen_c.append(term.c)
            elif isinstance(term, Springs):
                springs = term
            else:  # attach_backend checked numba_unsupported first
                raise TypeError(f"numba backend: unsupported force term {type(term).__name__}")
        colliders: PlaneColliders | None = compiled.colliders
        planes = colliders.planes if colliders is not None else []
        if springs is not None:
            a, b = system.spring_index[:, 0].copy(), system.spring_index[:, 1].copy()
            ptr, inc, sign = incidence(a, b, n)
            rest, ks, kd = system.spring_rest_length, system.spring_ks, system.spring_kd
        else:
            a = b = inc = np.zeros(0, dtype=np.int64)
            ptr = np.zeros(n + 1, dtype=np.int64)
            sign = rest = ks = kd = np.zeros(0)
        pen = _rows(pens, 6)
        self.params = K.Params(
            mass=system.particle_mass,
            inv_mass=system.particle_inv_mass,
            gravity=gravity,
            drag_k=float(drag_k),
            qdrag_c=float(qdrag_c),
            wind_w=_rows(winds, 3),
            wind_k=np.array(wind_k, dtype=np.float64),
            att_c=_rows(atts, 3),
            att_gm=np.array(att_gm, dtype=np.float64),
            att_eps2=np.array(att_eps2, dtype=np.float64),
            pen_p=np.ascontiguousarray(pen[:, :3]),
            pen_n=np.ascontiguousarray(pen[:, 3:]),
            pen_k=np.array(pen_k, dtype=np.float64),
            pen_c=np.array(pen_c, dtype=np.float64),
            pl_p=_rows([pl.point for pl in planes], 3),
            pl_n=_rows([pl.normal for pl in planes], 3),
            pl_e=np.array([pl.restitution for pl in planes], dtype=np.float64),
            pl_mu=np.array([pl.friction for pl in planes], dtype=np.float64),
            spr_a=a,
            spr_b=b,
            spr_rest=np.ascontiguousarray(rest, dtype=np.float64),
            spr_ks=np.ascontiguousarray(ks, dtype=np.float64),
            spr_kd=np.ascontiguousarray(kd, dtype=np.float64),
            spr_damped=bool(np.any(kd > 0)),
            inc_ptr=ptr,
            inc_spring=inc,
            inc_sign=sign,
            spr_force=np.zeros((len(a), 3)),
        )
        integ = compiled.integrator
        self.integrator_name = integ.name
        if isinstance(integ, RungeKutta):
            tab = integ.tableau
            stages = len(tab.b)
            self.method = K.RUNGE_KUTTA
            self.tab_a = np.zeros((stages, stages))
            for i, row in enumerate(tab.a):
                self.tab_a[i, : len(row)] = row
            self.tab_b = np.array(tab.b, dtype=np.float64)
        else:
            stages = 1
            self.method = _METHODS[integ.name]
            self.tab_a = np.zeros((1, 1))
            self.tab_b = np.ones(1)
        # Particle-major needs independent particles and, for Verlet, no collisions
        # (one anywhere invalidates every particle's cached acceleration); RK
        # stages beyond one would need per-particle scratch, so they go step-major.
        self.particle_major = springs is None and (
            self.method in (K.SYMPLECTIC_EULER, K.EULER_AVERAGE)
            or (self.method == K.RUNGE_KUTTA and stages == 1)
            or (self.method == K.VERLET and not planes)
        )
        work = n + (len(a) if springs is not None else 0)
        cores = numba.config.NUMBA_NUM_THREADS
        if threads is not None:
            self._candidates = [max(1, min(threads, cores))]
        elif work >= PARALLEL_MIN_WORK and cores > 1:
            self._candidates = [cores, 1]
        else:
            self._candidates = [1]
        self._trials: dict[int, list[float]] = {c: [] for c in self._candidates}
        self.threads = self._candidates[0]
        self.max_steps_per_call = max(1, MAX_WORK_PER_CALL // max(work, 1))
        self._n = n
        self._stages = stages
        self._buffers: dict[str, np.ndarray] | None = None
        self._a0_valid = False
        mode = (
            "particle-major fused steps" if self.particle_major else "step-major, parallel springs and gather"
        )
        if len(self._candidates) > 1:
            how = f"threads: {' or '.join(map(str, self._candidates))}, whichever runs faster on the first calls"
        else:
            how = f"{self.threads} thread{'s' if self.threads != 1 else ''}"
        self.description = f"{mode}, {how}"

    def _buffer(self) -> dict[str, np.ndarray]:
        if self._buffers is None:
            n, s = self._n, self._stages
            big = not self.particle_major
            shape = (n, 3) if big else (0, 3)
            self._buffers = {
                "a0": np.zeros((n, 3)) if (big or self.method == K.VERLET) else np.zeros((0, 3)),
                "a1": np.zeros(shape),
                "xs": np.zeros(shape),
                "vs": np.zeros(shape),
                "kx": np.zeros((s, *shape)) if self.method == K.RUNGE_KUTTA and big else np.zeros((1, 0, 3)),
                "kv": np.zeros((s, *shape)) if self.method == K.RUNGE_KUTTA and big else np.zeros((1, 0, 3)),
                "xo": np.zeros(shape),
                "vo": np.zeros(shape),
            }
        return self._buffers

    def reset(self) -> None:
        """Forget Verlet's cached acceleration (a new run starts)."""
        self._a0_valid = False

    def verlet_refresh(self, clock: Any, first: int, steps: int) -> np.ndarray:
        """(steps,) bool: before which steps of this call Verlet recomputes its acceleration.

        The NumPy Verlet keys its cache on (revision, time) and stores
        ``time + dt``; the loop sets the time from the clock (``duration * i /
        steps``), which can differ from ``time + dt`` in the last bit, so the
        NumPy side compares with a relative tolerance (CACHE_TIME_RTOL) and
        only a real jump in time refreshes the cache. This mirrors that rule.
        """
        refresh = np.zeros(steps, dtype=bool)
        if self.method != K.VERLET:
            return refresh
        if clock is not None:
            idx = np.arange(first - 1, first + steps, dtype=np.int64)
            if clock.divides:
                t = clock.duration * idx / clock.steps
                dts = np.full(idx.shape, clock.dt)
            else:
                t = idx * clock.dt
                last = clock.duration - (clock.steps - 1) * clock.dt
                dts = np.where(idx < clock.steps - 1, clock.dt, last)
            t = np.where(idx >= clock.steps, clock.duration, t)
            refresh = np.abs(t[:-1] + dts[:-1] - t[1:]) > CACHE_TIME_RTOL * np.maximum(
                np.abs(t[1:]), dts[:-1]
            )
        if first == 0 or not self._a0_valid:
            refresh[0] = True
        return refresh

    def advance(self, state: State, steps: int, dt: float, clock: Any = None) -> tuple[int, int, bool]:
        """Advance ``state`` up to ``steps`` steps of ``dt`` in place (``clock``: the run's).

        Returns (steps taken, force evaluations, failed): on a non-finite
        state it stops after the first step that made one, exactly as the
        NumPy loop's Guard would, so the Guard can report it.
        ``state.revision`` is bumped when a collision changed the state.
        """
        trying = [c for c in self._candidates if len(self._trials[c]) < THREAD_TRIALS]
        if trying:
            self.threads = trying[0]
        numba.set_num_threads(self.threads)
        started = time.perf_counter()
        result = self._advance(state, steps, dt, clock)
        if trying and result[0]:
            self._trials[self.threads].append((time.perf_counter() - started) / result[0])
            if len(trying) == 1 and len(self._trials[self.threads]) == THREAD_TRIALS:
                self.threads = min(self._candidates, key=lambda c: min(self._trials[c]))
        return result

    def _advance(self, state: State, steps: int, dt: float, clock: Any) -> tuple[int, int, bool]:
        x, v = state.particle_position, state.particle_velocity
        buf = self._buffer()
        refresh = self.verlet_refresh(clock, state.step, steps)
        if self.particle_major:
            saved = (x.copy(), v.copy(), buf["a0"].copy())
            bad, changed = K.particle_chunk(x, v, steps, dt, self.method, buf["a0"], refresh, self.params)
            evals = steps + int(refresh.sum())
            taken = steps
            if bad:
                # Replay from the chunk's start one step at a time (the same
                # arithmetic, so the same states) to stop at the first bad step.
                np.copyto(x, saved[0])
                np.copyto(v, saved[1])
                np.copyto(buf["a0"], saved[2])
                evals = changed = 0
                for taken in range(1, steps + 1):
                    one = refresh[taken - 1 : taken]
                    evals += 1 + int(one.sum())
                    bad, c = K.particle_chunk(x, v, 1, dt, self.method, buf["a0"], one, self.params)
                    changed += c
                    if bad:
                        break
            self._a0_valid = self.method == K.VERLET
            if changed:
                state.revision += 1
            return taken, evals, bool(bad)
        if self.method == K.SYMPLECTIC_EULER:
            taken, changed_steps, failed = K.symplectic_chunk(x, v, steps, dt, self.params)
            state.revision += int(changed_steps)
            return int(taken), int(taken), bool(failed)
        taken, evals, changed_steps, valid, failed = K.coupled_chunk(
            x,
            v,
            steps,
            dt,
            self.method,
            self.tab_a,
            self.tab_b,
            buf["kx"],
            buf["kv"],
            buf["xs"],
            buf["vs"],
            buf["a0"],
            buf["a1"],
            buf["xo"],
            buf["vo"],
            self._a0_valid,
            refresh,
            self.params,
        )
        self._a0_valid = bool(valid)
        state.revision += int(changed_steps)
        return int(taken), int(evals), bool(failed)
