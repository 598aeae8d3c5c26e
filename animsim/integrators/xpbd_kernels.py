"""xpbd's numba kernels: the NumPy passes of :mod:`animsim.integrators.xpbd_constraints`
constraint by constraint, and a whole step when nothing but constant forces acts.

The constraints of one colour share no particle, so the order within a colour changes
nothing: these give the NumPy passes' numbers (the same formulas, to rounding).

They run on one thread. A colour's loop could be split over numba's threads (``prange``),
but a step then opens a parallel region per colour and substep (120 a step on a cloth of
12 colours at 10 substeps), and on a machine whose cores are shared each region waits for the slowest
thread: measured on the 128 x 128 stiff cloth on 2 shared cores (load about 4.5), a step
took 830 ms (median; best 65 ms) on two threads against 30 ms (best 17 ms) on one.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np


def constraints_kernel(
    x: np.ndarray,
    p_old: np.ndarray,
    bounds: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    rest: np.ndarray,
    ca: np.ndarray,
    cb: np.ndarray,
    da: np.ndarray,
    db: np.ndarray,
) -> None:
    """:meth:`ConstraintGroups.project`: colour after colour (bounds[k]:bounds[k + 1]), a
    constraint after the other (numba: compiled)."""
    for k in range(bounds.shape[0] - 1):
        for s in range(bounds[k], bounds[k + 1]):
            i = a[s]
            j = b[s]
            d0 = x[i, 0] - x[j, 0]
            d1 = x[i, 1] - x[j, 1]
            d2 = x[i, 2] - x[j, 2]
            length = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
            inv = 1.0 / length if length > 0.0 else 0.0
            c = length - rest[s]
            fa = ca[s] * c
            fb = cb[s] * c
            if da[s] != 0.0 or db[s] != 0.0:
                m0 = d0 - (p_old[i, 0] - p_old[j, 0])
                m1 = d1 - (p_old[i, 1] - p_old[j, 1])
                m2 = d2 - (p_old[i, 2] - p_old[j, 2])
                gdot = ((d0 * m0 + d1 * m1) + d2 * m2) * inv
                fa += da[s] * gdot
                fb += db[s] * gdot
            fa *= inv
            fb *= inv
            x[i, 0] -= fa * d0
            x[i, 1] -= fa * d1
            x[i, 2] -= fa * d2
            x[j, 0] += fb * d0
            x[j, 1] += fb * d1
            x[j, 2] += fb * d2


def tethers_kernel(
    x: np.ndarray, pins: np.ndarray, ptr: np.ndarray, rows: np.ndarray, limit: np.ndarray
) -> None:
    """:meth:`Tethers.project`: a pin after the other, each row after the other (numba:
    compiled)."""
    for k in range(pins.shape[0]):
        p = pins[k]
        for r in range(ptr[k], ptr[k + 1]):
            i = rows[r]
            d0 = x[i, 0] - x[p, 0]
            d1 = x[i, 1] - x[p, 1]
            d2 = x[i, 2] - x[p, 2]
            length = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
            if length > limit[r]:
                f = (length - limit[r]) / length
                x[i, 0] -= f * d0
                x[i, 1] -= f * d1
                x[i, 2] -= f * d2


def steps_kernel(
    x: np.ndarray,
    v: np.ndarray,
    p_old: np.ndarray,
    dv: np.ndarray,
    movable: np.ndarray,
    substeps: int,
    h: float,
    bounds: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    rest: np.ndarray,
    ca: np.ndarray,
    cb: np.ndarray,
    da: np.ndarray,
    db: np.ndarray,
    tethers: bool,
    tp: np.ndarray,
    tptr: np.ndarray,
    tr: np.ndarray,
    tl: np.ndarray,
) -> None:
    """A whole step of :meth:`XPBD.step` when every external force is constant (``dv`` = h a,
    0 on immovable rows) and nothing is driven or touches a plane: for each substep the
    prediction, the constraints' and the tethers' passes (the kernels above) and the new
    velocities, the NumPy step's operations in its order (numba: compiled)."""
    n = x.shape[0]
    for _ in range(substeps):
        for i in range(n):
            for k in range(3):
                v[i, k] += dv[i, k]
                p_old[i, k] = x[i, k]
                x[i, k] += v[i, k] * h
        _constraints_pass(x, p_old, bounds, a, b, rest, ca, cb, da, db)
        if tethers:
            _tethers_pass(x, tp, tptr, tr, tl)
        for i in range(n):
            if movable[i]:
                for k in range(3):
                    v[i, k] = (x[i, k] - p_old[i, k]) / h


#: what steps_kernel calls: the pure functions here, their compiled twins once jit compiles it
_constraints_pass = constraints_kernel
_tethers_pass = tethers_kernel

#: numba's dispatchers (untyped: numba ships no annotations for them)
_JITTED: dict[str, Any] = {}


def jit(fn: Callable[..., None]) -> Any:
    """``fn`` compiled by numba (imported when an xpbd run asks for it; cached on disk)."""
    got = _JITTED.get(fn.__name__)
    if got is None:
        import numba

        if fn is steps_kernel:  # it calls the two passes: their compiled twins
            fn.__globals__["_constraints_pass"] = jit(constraints_kernel)
            fn.__globals__["_tethers_pass"] = jit(tethers_kernel)
        got = _JITTED[fn.__name__] = numba.njit(cache=True)(fn)
    return got
