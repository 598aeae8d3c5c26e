"""The numba backend's fused stepper: many steps per numba call.

Every force element and collision stage carries its own numba kernel with one
uniform signature (:mod:`animsim.elements`). Here they are *called*, never
re-implemented: :class:`FusedStepper` runs many steps per call for the fixed-step
explicit methods through the compiled step loops of :mod:`animsim.backends.fused_kernels`:
the integrator's arithmetic (the same operations, in the same order, as
:mod:`animsim.integrators`), the element kernels and the collision stage, stopping
after the first step that is not finite. When no particle acts on another, it steps
them a cache-sized block at a time (``blocked_chunk``), and from PARALLEL_MIN_BLOCKS
blocks on may share the blocks among numba's threads (``blocked_chunk_parallel``), with
the same bits on any thread count; :class:`BuildChooser` times both and keeps the faster.

The numba backend's other way to step, element kernels called from the loop one step
at a time, is :class:`animsim.backends.numba_forces.NumbaForces`.

Imported only when numba is in use.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numba
import numpy as np

from animsim import backends
from animsim.backends.fused_kernels import (
    CHECK_PIECE,
    blocked_chunk,
    blocked_chunk_parallel,
    checked_chunk,
    fused_chunk,
    quick_check_pieces,
    quick_check_state,
)
from animsim.backends.kernel_calls import (
    FastCall,
    addresses,
    array_tuple,
    element_tables,
    energy_table,
    no_stage,
)
from animsim.elements import jit_kernel, live_array
from animsim.thread_choice import BuildChooser

#: largest (particles + springs) x steps one call may do, so Ctrl-C and the
#: progress bar are served about every few tenths of a second
MAX_WORK_PER_CALL = 20_000_000

#: a compiled check passes only below (1 - CHECK_MARGIN) times the watchdog's allowance; a
#: growth in the band up to the allowance stops the chunk and Python's check decides. The
#: compiled sums add in particle order where NumPy adds pairwise or through BLAS, so the two
#: growths differ by rounding (about 1e-15 relative, more only where released energies of
#: opposite signs cancel); the band makes both checks decide alike wherever they differ by
#: less than it, instead of only away from the threshold's knife edge.
CHECK_MARGIN = 1e-6


def check_room(pieces: int, tables: tuple[Any, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Room for :func:`quick_check_pieces`: each piece's flag, movable count and sums (the
    kinetic energy, then a column per energy kernel the check calls). ``tables``: the
    elastic then the releasing :func:`energy_table`. The columns are counted from the
    tables, not from the element lists: a table holds a kernel that adds nothing where its
    list is empty, and the check writes that kernel's column too."""
    return (
        np.ones(pieces, dtype=np.bool_),
        np.zeros(pieces, dtype=np.int64),
        np.zeros((pieces, 1 + len(tables[0]) + len(tables[3]))),
    )


class FusedStepper:
    """Many fixed steps per numba call (see the module docstring)."""

    def __init__(self, compiled: Any):
        self.compiled = compiled
        integ = compiled.integrator
        n = compiled.system.particle_count
        self.method, tableau = integ.numba_chunk_kind()
        if tableau is None:
            c, a, b = np.zeros(1), np.zeros((1, 1)), np.zeros(1)
        else:
            s = len(tableau.b)
            c = np.array(tableau.c, dtype=np.float64)
            a = np.zeros((s, s))
            for i, row in enumerate(tableau.a):
                a[i, : len(row)] = row
            b = np.array(tableau.b, dtype=np.float64)
        self.tab = (c, a, b)
        stages = b.shape[0]
        self.kernels, self.fps, self.ips = element_tables(compiled.dynamics.terms)
        fusable = [st for st in compiled.post_step if st.numba_stage_source is not None]
        if fusable:
            self.stages = addresses([st.numba_stage for st in fusable], stage=True)
            self.stage_owner = fusable[0]
            params = [st.numba_stage_params() for st in fusable]
        else:
            self.stages = addresses([jit_kernel(no_stage, stage=True)], stage=True)
            self.stage_owner = None
            params = [(np.zeros(0), np.zeros(0, dtype=np.int64))]
        self.stage_fps = array_tuple([p[0] for p in params], np.float64)
        self.stage_ips = array_tuple([p[1] for p in params], np.int64)
        #: rows are independent (animsim.backends.fused_in_blocks): blocked_chunk steps them
        self.blocked = backends.fused_in_blocks(compiled)
        pinned = compiled.system.particle_pinned
        #: the pinned rows' indices, as the plain chunk (and the checked one) takes them
        self.plain_pinned = np.ascontiguousarray(np.flatnonzero(pinned), dtype=np.int64)
        self._checks: Any = None
        if self.blocked:
            # per-row pinned flags for the blocks; Verlet's cached acceleration, and room to
            # save each block's rows (position, velocity, that acceleration) at a call's start
            self.pinned = np.ascontiguousarray(pinned, dtype=np.bool_)
            self.kx = self.kv = np.zeros((stages, 0, 3))
            self.work = tuple(np.zeros((n, 3)) for _ in range(4))  # a0, x, v and a0 saved
        else:
            self.pinned = self.plain_pinned
            self.kx = np.zeros((stages, n, 3))
            self.kv = np.zeros((stages, n, 3))
            self.work = tuple(np.zeros((n, 3)) for _ in range(6))  # xs, vs, a0, a1, xo, vo
        #: enough blocks to share among numba's threads (when it has several): the blocked
        #: chunk's calls then run them in parallel (blocked_chunk_parallel)
        self.parallel_blocks = self.blocked and -(-n // backends.BLOCK) >= backends.PARALLEL_MIN_BLOCKS
        #: which of the two builds runs a call, by timing them (BuildChooser)
        self.chooser = BuildChooser()
        self.a0_valid = False
        work = n + compiled.system.spring_count
        self.max_steps_per_call = max(1, MAX_WORK_PER_CALL // max(work, 1))
        self.compile_seconds = 0.0
        self._copies: dict[int, np.ndarray] = {}
        #: the chunk kernels this stepper has called, each called directly from then on
        self._chunks: dict[Any, FastCall] = {}
        #: steps a collision changed, over every call so far
        self.changed_steps = 0

    def reset(self) -> None:
        self.a0_valid = False

    def warm_up(self, state: Any) -> float:
        """Compile (or load from the disk cache) every kernel with a zero-step call; its seconds."""
        t0 = time.perf_counter()
        no_steps = (state, np.array([state.time]), np.zeros(0))
        self._advance(*no_steps, False)
        if self.threaded():  # both blocked builds: the run times them and may switch
            self._advance(*no_steps, True)
        self.compile_seconds = time.perf_counter() - t0
        return self.compile_seconds

    def threaded(self) -> bool:
        """Whether the blocked chunk may share its blocks among threads for this call."""
        # numba's thread count is asked only for scenes big enough to use it: asking
        # starts numba's thread pool, which a small scene's run should not wait for
        return self.parallel_blocks and numba.get_num_threads() > 1

    def _common(self, state: Any, times: np.ndarray, dts: np.ndarray, pinned: np.ndarray) -> tuple[Any, ...]:
        """The arguments every chunk kernel starts with (state, clock, method, elements, stages)."""
        d = self.compiled.dynamics
        c, a, b = self.tab
        return (
            state.particle_position,
            state.particle_velocity,
            times,
            dts,
            self.method,
            c,
            a,
            b,
            self.kernels,
            self.fps,
            self.ips,
            live_array(d.mass, self._copies),
            live_array(d.inv_mass, self._copies),
            pinned,
            # a tuple of addresses, so numba types them as first-class functions (by
            # signature), not as these dispatchers: the cached kernel then serves every stage
            self.stages,
            self.stage_fps,
            self.stage_ips,
        )

    def advance(
        self, state: Any, times: np.ndarray, dts: np.ndarray, threaded: bool | None = None
    ) -> tuple[int, int, bool]:
        """len(dts) steps from times[0]; (steps taken, force evaluations, failed).
        ``threaded``: what :meth:`threaded` answers, when the caller asked it already (a
        caller making many one-step calls asks once: each ask takes about 8 us right after
        a large call)."""
        if threaded is None:
            threaded = self.threaded()
        return self._advance(state, times, dts, threaded and self.chooser.pick(), threaded)

    def _advance(
        self, state: Any, times: np.ndarray, dts: np.ndarray, threaded: bool, timed: bool | None = None
    ) -> tuple[int, int, bool]:
        """advance, on numba's threads when ``threaded`` (blocked scenes only); ``timed``: the
        chooser books the call (None: ask, as :meth:`threaded` does; asking numba for its thread
        count takes about 8 us after a large call, so advance asks once)."""
        common = self._common(state, times, dts, self.pinned)
        has_stage = self.stage_owner is not None
        if self.blocked:  # work: a0 and the rows saved at the call's start (x, v, a0)
            kernel = blocked_chunk_parallel if threaded else blocked_chunk
            args = (*common, *self.work, self.a0_valid, has_stage, backends.BLOCK)
        else:  # work: xs, vs, a0, a1, xo, vo
            kernel = fused_chunk
            args = (*common, self.kx, self.kv, *self.work, self.a0_valid, has_stage)
        call = self._chunks.get(kernel)
        if call is None:  # loads (or compiles) the chunk; then calls its overload directly
            call = self._chunks[kernel] = FastCall(kernel, args)
        t0 = time.perf_counter()
        result = call(*args)
        taken, evals, changed, self.a0_valid, failed = result
        if timed is None:
            timed = self.threaded()
        if timed:
            self.chooser.record(kernel is blocked_chunk_parallel, time.perf_counter() - t0, int(taken))
        self.changed_steps += int(changed)
        if changed:
            state.revision += 1
        return int(taken), int(evals), bool(failed)

    def check_inside(self, watch: Any) -> bool:
        """Take the watchdog's checks into the chunks (:meth:`advance_checked`) for the books of
        ``watch`` (an opened :class:`animsim.measures.watchdog.EnergyWatch`), when every
        element its energy test sums has a compiled energy kernel; False leaves them to Python.

        Only for a run without births (the books never change after they opened) and
        without rigid bodies (the fused stepper has none).
        """
        self._checks = None
        if watch.alive_prev is not None:
            return False
        energy = watch.disabled is None
        elastic: list[Any] = watch.elastic if energy else []
        releasing: list[Any] = watch.releasing if energy else []
        if any(t.numba_energy_source is None for t in (*elastic, *releasing)):
            return False
        no_u = np.zeros(0)
        u_refs = array_tuple(list(watch.u_ref) if releasing else [no_u], np.float64)
        books = np.array([*watch.budget_constants(), watch.allowance * (1.0 - CHECK_MARGIN)])
        n = self.compiled.system.particle_count
        stages = self.kx.shape[0]
        if self.blocked:  # the blocked chunk's Verlet acceleration is shared, so either may go on
            a0 = self.work[0]
            work = (np.zeros((n, 3)), np.zeros((n, 3)), a0, *(np.zeros((n, 3)) for _ in range(3)))
            kx, kv = np.zeros((stages, n, 3)), np.zeros((stages, n, 3))
        else:
            work, kx, kv = self.work, self.kx, self.kv
        self._checks = (
            (kx, kv, *work),
            (
                energy,
                *energy_table(elastic),
                *energy_table(releasing),
                u_refs,
                np.ascontiguousarray(watch.x_ref),
                no_u,
                books,
            ),
            (np.zeros((n, 3)), np.zeros((n, 3))),
        )
        self._checked_call: Any = None
        return True

    def quick_check(self, watch: Any) -> Callable[[Any], bool] | None:
        """The watchdog's check of a state compiled, for runs whose checks stay in Python
        (births, or more particles than the chunks check themselves): a function of the
        state that is True only where ``Guard.check`` passes it, finite and below
        (1 - CHECK_MARGIN) times the allowance, so the loop may skip Python's check; where
        it is False, Python's check decides. None when the energy test is off or an element
        the watchdog sums has no compiled energy sum.

        Python's check sums the kinetic energy with NumPy (an ``einsum`` and a dot product
        over every particle) and tests finiteness with two more sums: 0.96 ms of a
        100,000-slot fountain's check, against one compiled pass.
        """
        if watch.disabled is not None:
            return None
        elastic, releasing = watch.elastic, watch.releasing
        if any(t.numba_energy_source is None for t in (*elastic, *releasing)):
            return None
        tables = (*energy_table(elastic), *energy_table(releasing))
        no_u = np.zeros(0)
        births = watch.alive_prev is not None
        books = np.zeros(6)
        call: dict[Any, FastCall] = {}
        copies: dict[int, np.ndarray] = {}
        # several pieces of rows, every watched element pointwise: the check may share them
        # among numba's threads, when the stepper's own calls do (its chooser keeps them)
        n = self.compiled.system.particle_count
        pieces = self.blocked and n >= 2 * CHECK_PIECE and all(t.pointwise for t in (*elastic, *releasing))
        npieces = -(-n // CHECK_PIECE)
        room = check_room(npieces, tables)

        def quick(state: Any) -> bool:
            watch.book_births(state)  # as EnergyWatch.budget does first (a no-op when booked)
            books[:5] = watch.budget_constants()
            books[5] = watch.allowance * (1.0 - CHECK_MARGIN)
            args = (
                state.particle_position,
                state.particle_velocity,
                float(state.time),
                live_array(watch.mass, copies),
                *tables,
                array_tuple(list(watch.u_ref) if releasing else [no_u], np.float64),
                watch.x_ref,
                no_u,
                books,
                births,
            )
            kernel = quick_check_state
            if pieces and self.threaded() and self.chooser.parallel:
                kernel = quick_check_pieces
                args = (*args, *room)
            fast = call.get(kernel)
            if fast is None:  # loads (or compiles) the check; then calls its overload directly
                fast = call[kernel] = FastCall(kernel, args)
            return bool(fast(*args))

        return quick

    def advance_checked(
        self,
        state: Any,
        k0: int,
        times: np.ndarray,
        dts: np.ndarray,
        checked: int,
        stride: int,
        last: int,
        rec: np.ndarray,
        shots: tuple[np.ndarray, np.ndarray],
    ) -> tuple[int, int, int, bool, int]:
        """len(dts) steps from clock position k0 with the watchdog's checks inside
        (:func:`checked_chunk`; ``times`` has one more entry than ``dts``), copying the
        states at the positions ``rec`` into ``shots``; (steps taken, force evaluations,
        the position of the last passed check, stopped, states copied)."""
        work, books, good = self._checks
        args = (
            *self._common(state, times, dts, self.plain_pinned),
            *work,
            self.a0_valid,
            self.stage_owner is not None,
            k0,
            checked,
            stride,
            last,
            *books,
            *good,
            rec,
            *shots,
        )
        if self._checked_call is None:  # loads (or compiles) the chunk; then calls its overload
            self._checked_call = FastCall(checked_chunk, args)
        result = self._checked_call(*args)
        taken, evals, changed, self.a0_valid, passed, stopped, copied = result
        self.changed_steps += int(changed)
        if changed:
            state.revision += 1
        return int(taken), int(evals), int(passed), bool(stopped), int(copied)

    def good_state(self, dest: Any) -> None:
        """Copy the positions and velocities of the last passed check into ``dest``."""
        x_good, v_good = self._checks[2]
        dest.particle_position[...] = x_good
        dest.particle_velocity[...] = v_good


__all__ = ["FusedStepper", "numba"]
