"""The numba backend's force sum for the step-by-step loop.

Every force element carries its own numba kernel with one uniform signature
(:mod:`animsim.elements`); here they are *called*, never re-implemented.
:class:`NumbaForces` replaces :meth:`Dynamics.acceleration` with one numba call that
sums every element's kernel (first-class functions), divides by the mass and zeroes
pinned rows (:func:`animsim.backends.fused_kernels.accelerations`), so any integrator
(including implicit Euler, adaptive steps and scenes with emitters) runs on numba
kernels through the one loop. The fixed-step explicit methods run many steps per call
instead (:mod:`animsim.backends.fused`).

Imported only when numba is in use.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from animsim.backends.fused_kernels import accelerations
from animsim.backends.kernel_calls import FastCall, addresses, array_tuple, element_tables, no_newborn
from animsim.elements import jit_kernel, live_array


class NumbaForces:
    """Dynamics.acceleration through the elements' numba kernels (see the module docstring).

    Elements without a numba kernel keep their NumPy kernel, added after.
    """

    def __init__(self, dynamics: Any):
        self.dynamics = dynamics
        self.kernels, self.fps, self.ips = element_tables(dynamics.terms)
        self.others = tuple(t for t in dynamics.terms if t.numba_source is None)
        self.pinned = np.ascontiguousarray(np.flatnonzero(dynamics.system.particle_pinned), dtype=np.int64)
        self._copies: dict[int, np.ndarray] = {}
        self._acc: Any = None
        self._pointwise = all(t.pointwise for t in dynamics.terms)

    def acceleration(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> np.ndarray:
        d = self.dynamics
        d.evaluations += 1
        for drive in d.drivers:  # keyframed rows on their path (animsim.keyframes)
            drive.drive(t, x, v)
        mass = live_array(d.mass, self._copies)
        if not self.others:
            inv_mass = live_array(d.inv_mass, self._copies)
            args = (x, v, float(t), out, self.kernels, self.fps, self.ips, mass, inv_mass, self.pinned)
            if self._acc is None:  # loads (or compiles) the kernel; then calls its overload directly
                self._acc = FastCall(accelerations, args)
            self._acc(*args)
            return out
        # Mixed: sum every force first (numba kernels, then NumPy ones), then divide.
        out.fill(0.0)
        for kern, fp, ip in zip(self.kernels, self.fps, self.ips, strict=True):
            kern.dispatcher(x, v, float(t), out, mass, fp, ip)
        for term in self.others:
            term.accumulate(x, v, t, out)
        for j in range(3):
            out[:, j] *= d.inv_mass
        if len(self.pinned):
            out[self.pinned] = 0.0
        return out

    def newborn_tables(self, colliders: list[Any]) -> tuple[Any, ...] | None:
        """What the compiled birth step (:func:`animsim.emitters.kernels._pool_step`) flies and
        collides an emitter's newborns with: (the force kernels, their float and integer
        parameters, the ``colliders``' newborn kernels, theirs). None unless the newborns'
        rows can be evaluated alone (every force pointwise, none left to NumPy, no row
        driven) and every collider has a newborn kernel; births then take the Python path,
        which evaluates every row."""
        d = self.dynamics
        if self.others or d.drivers or not self._pointwise:
            return None
        if any(st.numba_newborn_source is None for st in colliders):
            return None
        kernels = [st.numba_newborn for st in colliders] or [jit_kernel(no_newborn, newborn=True)]
        params = [st.numba_stage_params() for st in colliders] or [(np.zeros(0), np.zeros(0, dtype=np.int64))]
        return (
            self.kernels,
            self.fps,
            self.ips,
            addresses(kernels, newborn=True),
            array_tuple([p[0] for p in params], np.float64),
            array_tuple([p[1] for p in params], np.int64),
        )

    def masses(self) -> tuple[np.ndarray, np.ndarray]:
        """The live masses and inverse masses as the kernels take them."""
        d = self.dynamics
        return live_array(d.mass, self._copies), live_array(d.inv_mass, self._copies)
