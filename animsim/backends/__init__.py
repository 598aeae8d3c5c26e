"""Backends: which code steps a compiled scene (issue 8).

* ``numpy`` (default): the force terms and integrators of ``animsim.forces``
  and ``animsim.integrators``, with grid structures stepped by array slices
  (:mod:`animsim.forces.grid_springs`).
* ``numba``: the same physics compiled by numba
  (:mod:`animsim.backends.numba_backend`), many fused steps per call between
  recorded frames, parallel loops where they pay. Needs the ``fast`` extra.
* ``auto``: numba when it is importable and supports the scene, else numpy;
  ``explain`` says which and why.
* ``reference`` (not offered on the command line): the generic bincount
  spring path everywhere, kept as the baseline tests and benchmarks compare with.

This module imports nothing heavy: deciding whether numba can run a scene
must not cost numba's import when the answer is NumPy.
"""

from __future__ import annotations

import importlib.util
from typing import Any

from animsim.errors import UsageError

BACKEND_NUMPY = "numpy"
BACKEND_NUMBA = "numba"
BACKEND_AUTO = "auto"
BACKEND_REFERENCE = "reference"
#: the choices of ``--backend``
BACKENDS = (BACKEND_NUMPY, BACKEND_NUMBA, BACKEND_AUTO)
ALL_BACKENDS = (*BACKENDS, BACKEND_REFERENCE)

#: integrators the numba backend implements
NUMBA_INTEGRATORS = ("euler", "symplectic_euler", "euler_average", "midpoint", "heun", "rk4", "verlet")
#: force term classes the numba backend implements (by class name, so this needs no imports)
NUMBA_TERMS = (
    "Gravity",
    "Drag",
    "QuadraticDrag",
    "Wind",
    "Attractor",
    "Springs",
    "GridSprings",
    "PenaltyPlane",
)

INSTALL_HINT = 'pip install -e ".[fast]"'


def numba_available() -> bool:
    """True when numba can be imported (without importing it)."""
    return importlib.util.find_spec("numba") is not None


def numba_unsupported(compiled: Any) -> list[str]:
    """What in ``compiled`` the numba backend cannot run, as phrases for a message ([] if nothing)."""
    missing: list[str] = []
    if compiled.emitters is not None:
        missing.append("emitters")
    for term in compiled.dynamics.terms:
        kind = type(term).__name__
        if kind not in NUMBA_TERMS:
            missing.append(f"force term {kind} ({term.label})")
    if compiled.integrator.name not in NUMBA_INTEGRATORS:
        missing.append(f"integrator {compiled.integrator.name!r}")
    if getattr(compiled.scene, "adaptive", None) is not None:
        missing.append("adaptive step size")
    return missing


def attach_backend(compiled: Any, requested: str, *, threads: int | None = None) -> None:
    """Give ``compiled`` the stepper of backend ``requested``, or raise UsageError (exit 2).

    Sets ``compiled.backend`` (the one that runs) and ``compiled.stepper``
    (None for NumPy), and adds a ``backend:`` line to the stages ``explain`` shows.
    """
    if requested not in ALL_BACKENDS:
        raise UsageError(f"--backend: unknown backend {requested!r} (valid: {', '.join(BACKENDS)})")
    note = ""
    chosen = requested
    if requested in (BACKEND_NUMBA, BACKEND_AUTO):
        missing = numba_unsupported(compiled)
        if requested == BACKEND_NUMBA:
            if not numba_available():
                raise UsageError(f"--backend numba: numba is not installed ({INSTALL_HINT})")
            if missing:
                raise UsageError(
                    f"--backend numba: this scene uses {', '.join(missing)}, which the numba backend "
                    "does not support; use --backend numpy or --backend auto"
                )
        elif not numba_available():
            chosen, note = BACKEND_NUMPY, f"auto: numba is not installed ({INSTALL_HINT})"
        elif missing:
            chosen, note = BACKEND_NUMPY, f"auto: numba does not support {', '.join(missing)}"
        else:
            chosen, note = BACKEND_NUMBA, "auto: numba is installed"
    compiled.backend = chosen
    compiled.stepper = None
    if chosen == BACKEND_NUMBA:
        from animsim.backends.numba_backend import NumbaStepper

        compiled.stepper = NumbaStepper(compiled, threads=threads)
        line = f"backend: numba ({compiled.stepper.description})"
    elif chosen == BACKEND_REFERENCE:
        line = "backend: reference (generic bincount springs, the baseline)"
    else:
        line = "backend: numpy"
    compiled.stages.append(line + (f"; {note}" if note else ""))
