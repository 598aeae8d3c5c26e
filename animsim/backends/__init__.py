"""Backends: which kernels step a compiled scene.

* ``numpy``: every element's NumPy kernel, grid structures by
  array slices (:mod:`animsim.forces.grid_springs`).
* ``numba``: every element's numba kernel (each element module holds both).
  A scene whose elements all have numba kernels and whose method has a fused
  kernel runs many steps per call (:mod:`animsim.backends.fused`), or one step
  per call with births (emitters) called from Python between calls (each
  emitter's step a compiled call of its own where its forces and colliders allow);
  any other scene
  (adaptive steps, implicit Euler, an element without a numba kernel) runs step
  by step through the same loop with the numba kernels of the elements that have
  one. Needs the ``fast`` extra.
* ``auto`` (the default of the command line and ``animsim.simulate``): numba when
  it is importable, else numpy; ``explain`` says which and why.
* ``reference`` (not offered on the command line): the generic bincount
  spring path everywhere, kept as the baseline tests and benchmarks compare with.

This module imports nothing heavy: deciding whether numba can run a scene
must not cost numba's import when the answer is NumPy.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Iterator
from contextlib import contextmanager

# ``compiled`` below is animsim.compile.Compiled: Any, since backends may not import compile (layers)
from typing import Any

from animsim.errors import UsageError

BACKEND_NUMPY = "numpy"
BACKEND_NUMBA = "numba"
BACKEND_AUTO = "auto"
BACKEND_REFERENCE = "reference"
#: the choices of ``--backend``
BACKENDS = (BACKEND_NUMPY, BACKEND_NUMBA, BACKEND_AUTO)
ALL_BACKENDS = (*BACKENDS, BACKEND_REFERENCE)

INSTALL_HINT = 'pip install -e ".[fast]"'

#: rows per block of the numba backend's blocked chunk (animsim.backends.fused_kernels), here so
#: that ``explain`` can tell without importing numba: a block's position, velocity, acceleration and
#: step-start copies (5 x 512 x 24 bytes, 60 KB) stay in the near caches over all of a
#: call's steps; measured on 1e6 particles with a plane, 1 thread: 128 rows 43 M
#: particle-steps/s, 256 47, 512 49, 1,024 50, 2,048 46, 4,096 42 (smaller blocks pay
#: the calls into the element kernels more often, larger ones leave the cache)
BLOCK = 512

#: blocks from which a call runs them on several threads (when numba has more than one).
#: Measured on a quiet 2-core machine, particles with a plane, 16 steps a call (the
#: watchdog's stride), M particle-steps/s wall, 1 thread / 2: one block 35.7 / 35.4 (and
#: twice the CPU time: the idle thread waits), two 39.6 / 72.4, three 39.3 / 56.8, four
#: 38.9 / 72.7, sixteen 39.3 / 76.9. On cores busy with other work a parallel call waits
#: for the slowest thread, which costs more at any size (compile_scene's ``threads``),
#: and the most where a call's work is short: a 1,024-particle scene at load 2-5 went
#: 21.8 -> 5.6. So threads start at eight blocks (4,096 particles), where the watchdog's
#: checks leave the compiled steps too (smaller scenes keep them inside, on one thread).
PARALLEL_MIN_BLOCKS = 8


def numba_available() -> bool:
    """True when numba can be imported (without importing it)."""
    return importlib.util.find_spec("numba") is not None


def choose_backend(requested: str) -> tuple[str, str]:
    """(the backend that will run, a note for ``explain``); UsageError (exit 2) when impossible."""
    if requested not in ALL_BACKENDS:
        raise UsageError(f"--backend: unknown backend {requested!r} (valid: {', '.join(BACKENDS)})")
    if requested == BACKEND_NUMBA and not numba_available():
        raise UsageError(f"--backend numba: numba is not installed ({INSTALL_HINT})")
    if requested == BACKEND_AUTO:
        if numba_available():
            return BACKEND_NUMBA, "auto: numba is installed"
        return BACKEND_NUMPY, f"auto: numba is not installed ({INSTALL_HINT})"
    return requested, ""


@contextmanager
def numba_threads(compiled: Any) -> Iterator[None]:
    """numba's thread count is ``compiled.threads`` inside the block, then what it was.

    It bounds the threads that step large particle systems in blocks and sum the springs
    of very large scenes. Nothing happens when the scene runs on NumPy or leaves numba its
    default (every core, or ``NUMBA_NUM_THREADS``): numba is then not even imported.
    """
    threads = compiled.threads
    if threads is None or compiled.backend != BACKEND_NUMBA:
        yield
        return
    import numba

    most: int = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]  # set at numba's import
    if threads > most:
        raise UsageError(f"threads: {threads} is more than numba may start here ({most}, NUMBA_NUM_THREADS)")
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        yield
    finally:
        numba.set_num_threads(before)


def fused_unsupported(compiled: Any) -> list[str]:
    """Why the numba backend cannot fuse many steps per call for ``compiled`` ([] if it can)."""
    why: list[str] = []
    if compiled.adaptive is not None:
        why.append("adaptive step size")
    if compiled.system.body_count:
        why.append("rigid bodies")
    if compiled.integrator.numba_chunk_kind() is None:
        why.append(f"integrator {compiled.integrator.name!r}")
    for term in compiled.dynamics.terms:
        if term.numba_source is None:
            why.append(f"force {term.label!r}")
    for stage in compiled.post_step:
        # births are called from Python between one-step chunks (animsim.steppers.Fused)
        if stage.numba_stage_source is None and not stage.fused_between_steps:
            why.append(stage.label.split(":")[0])
    return why


def fused_in_blocks(compiled: Any) -> bool:
    """True when the fused chunks may step ``compiled`` a block of particles at a time.

    Every force and every fused stage must be pointwise (row i reads only row i, see
    :mod:`animsim.elements`) and no row may be put on a keyframed path inside a step:
    the particles are then independent, and each block runs a call's steps in the cache.
    """
    d = compiled.dynamics
    if d.drivers:
        return False
    if not all(t.pointwise for t in d.terms):
        return False
    return all(st.pointwise for st in compiled.post_step if st.numba_stage_source is not None)


def _block_cores(compiled: Any) -> str:
    """How many of numba's threads share the blocks (animsim.backends.fused.FusedStepper)."""
    n = compiled.system.particle_count
    if -(-n // BLOCK) < PARALLEL_MIN_BLOCKS:
        return f" on one thread (below {PARALLEL_MIN_BLOCKS * BLOCK:,} particles)"
    import numba

    threads = compiled.threads if compiled.threads is not None else numba.get_num_threads()
    return f" shared among {threads} thread{'s' if threads != 1 else ''}"


def block_stage(compiled: Any) -> Any:
    """The scene's one post-step stage when the NumPy step may run it a block of rows at a
    time inside the integrator's step (a pointwise stage that offers it, ``meets_blocks``,
    and an integrator that steps in blocks), else None. Whether a step then runs in blocks
    is decided per step (:attr:`Dynamics.blocks`)."""
    stages = compiled.post_step
    only = stages[0] if len(stages) == 1 else None
    if only is None or not only.pointwise or not compiled.integrator.block_stages:
        return None
    return only if only.meets_blocks() else None


def backend_line(compiled: Any, chosen: str, note: str) -> str:
    """The ``backend:`` line ``explain`` shows."""
    if chosen == BACKEND_NUMBA:
        why = fused_unsupported(compiled)
        between = any(st.fused_between_steps for st in compiled.post_step)
        if why:
            how = f"element kernels step by step ({', '.join(why)} need the step-by-step loop)"
        else:
            how = "element kernels fused with the integrator, " + (
                "one step per call, births between calls" if between else "many steps per call"
            )
            if fused_in_blocks(compiled):
                how += ", in blocks of particles (no particle acts on another)" + _block_cores(compiled)
        line = f"backend: numba ({how})"
    elif chosen == BACKEND_REFERENCE:
        line = "backend: reference (generic bincount springs, the baseline)"
    else:
        line = "backend: numpy"
        if compiled.integrator.block_stages and compiled.dynamics.blocks:
            stage = block_stage(compiled)
            line += " (a block of particles at a time while it is in cache: no particle acts on another" + (
                f"; the {stage.block_name} meets each block inside the step)" if stage is not None else ")"
            )
    return line + (f"; {note}" if note else "")
