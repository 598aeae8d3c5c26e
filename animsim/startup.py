"""Python's cyclic garbage collector, paused while a command starts.

A command's start-up (importing NumPy, numba, pydantic and animsim, building
the scene and loading the compiled kernels) creates some hundred thousand
objects that live as long as the process, and hardly any garbage in cycles.
Python's collector runs every 700 new objects and scans each new container,
and every so often all of them again: about 200 collections in a
one-particle ``animsim run``, 50 ms of its 0.6 s of CPU (measured with
``gc.callbacks``), all for nothing.

The command line pauses it (:func:`pause_collector`: ``python -m animsim``
before its imports, the ``animsim`` script as its ``main`` starts) and ``animsim
run`` keeps it paused until its loop (:func:`animsim.engine.run`) has its
stepper ready, just before the first step; every other command resumes it as
soon as it starts (:func:`resume_collector`). Resuming moves every object
alive then into Python's permanent generation (``gc.freeze``) instead of
collecting (one collection over all of them cost more than the pause saved):
they are the process's modules, kernels and scene, and the run's own
collections never scan them again. The start-up's garbage in cycles stays
until the process ends: a few thousand objects on a warm start, and no more
peak memory when numba compiles on a first run (335 MB either way, one
particle; 347 MB for a cloth over a sphere; 494 MB for the fountain).
Python code that calls animsim (the API, ``cli.main`` with arguments, the
tests) never pauses, so resuming is a no-op there.
"""

from __future__ import annotations

import gc

_paused = False


def pause_collector() -> None:
    """Turn the cyclic collector off until :func:`resume_collector` (if it is on now)."""
    global _paused
    if gc.isenabled():
        gc.disable()
        _paused = True


def resume_collector() -> None:
    """Turn the collector back on if :func:`pause_collector` turned it off (else nothing)."""
    global _paused
    if _paused:
        _paused = False
        gc.freeze()
        gc.enable()
