"""Keyframed paths: positions given at times, and the path between them.

One module serves pinned particles that follow ``keyframes`` and colliders
that move along ``motion``. A path is a list of keys ``(t_k, p_k)`` with
strictly increasing times and one of two interpolations:

* ``linear``: straight segments; the velocity is constant on each segment
  (at a key the velocity of the segment that starts there).
* ``smooth``: a C1 cubic Hermite spline through the keys (Catmull-Rom with
  the non-uniform finite-difference tangent ``m_k = (p_{k+1} - p_{k-1}) /
  (t_{k+1} - t_{k-1})`` at interior keys, Catmull & Rom 1974 / Hermite basis
  as in Foley & van Dam, "Computer Graphics", section 11.2) and a ZERO tangent
  at the first and last key. The zero end tangents make the path ease in and
  out, so the velocity stays continuous where the path starts and ends holding.

Before the first key the path holds the first key's position, after the last
key the last one's, with zero velocity. The velocity reported is always the
exact derivative of the position function, so damping of a spring attached to
a keyframed particle sees the motion it really has.

Many paths are evaluated at once from padded arrays (paths x keys), so a step
costs a handful of NumPy operations whatever the number of driven particles.
"""

from __future__ import annotations

import numpy as np

from animsim.elements import StepStage
from animsim.paths import Paths, evaluate_numpy
from animsim.system import State

LINEAR = 0
SMOOTH = 1
INTERPOLATIONS = {"linear": LINEAR, "smooth": SMOOTH}


_NUMBA_EVAL = None


def numba_evaluate():
    """The numba twin of :func:`evaluate_numpy` (compiled on first use)."""
    global _NUMBA_EVAL
    if _NUMBA_EVAL is not None:
        return _NUMBA_EVAL
    import numba

    @numba.njit(cache=True)
    def evaluate(times, points, tangents, count, smooth, t, pos, vel):  # pragma: no cover - compiled
        for i in range(count.shape[0]):
            last = count[i] - 1
            k = -1
            for j in range(times.shape[1]):
                if times[i, j] <= t:
                    k = j
            if k < 0 or k >= last:
                key = 0 if k < 0 else last
                for a in range(3):
                    pos[i, a] = points[i, key, a]
                    vel[i, a] = 0.0
                continue
            t0 = times[i, k]
            h = times[i, k + 1] - t0
            u = (t - t0) / h
            if u < 0.0:
                u = 0.0
            elif u > 1.0:
                u = 1.0
            u2 = u * u
            u3 = u2 * u
            for a in range(3):
                p0 = points[i, k, a]
                p1 = points[i, k + 1, a]
                if smooth[i]:
                    m0 = tangents[i, k, a] * h
                    m1 = tangents[i, k + 1, a] * h
                    pos[i, a] = (
                        (2 * u3 - 3 * u2 + 1) * p0
                        + (u3 - 2 * u2 + u) * m0
                        + (-2 * u3 + 3 * u2) * p1
                        + (u3 - u2) * m1
                    )
                    vel[i, a] = (
                        (6 * u2 - 6 * u) * p0
                        + (3 * u2 - 4 * u + 1) * m0
                        + (-6 * u2 + 6 * u) * p1
                        + (3 * u2 - 2 * u) * m1
                    ) / h
                else:
                    pos[i, a] = p0 + u * (p1 - p0)
                    vel[i, a] = (p1 - p0) / h

    _NUMBA_EVAL = evaluate
    return evaluate


class PathEvaluator:
    """Evaluates a :class:`Paths` on one backend, into reused buffers."""

    def __init__(self, paths: Paths, backend: str = "numpy"):
        self.paths = paths
        self.backend = backend
        self._pos = np.zeros((paths.size, 3))
        self._vel = np.zeros((paths.size, 3))
        self._kernel = numba_evaluate() if backend == "numba" else None

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if self._kernel is None:
            return evaluate_numpy(self.paths, t)
        p = self.paths
        self._kernel(p.times, p.points, p.tangents, p.count, p.smooth, float(t), self._pos, self._vel)
        return self._pos, self._vel


class KeyframeDrive(StepStage):
    """Pinned particles that follow keyframed paths.

    Row ``rows[i]`` sits at ``base[i] + path[which[i]](t)`` with velocity
    ``path'(t)``. Listed particles have their own path and base 0; a
    structure's pins share the structure's ``pin_motion`` path, each offset by
    its initial position.

    As a step stage it runs first after each step, putting the driven rows on
    their path at the step's end; ``drive(t, x, v)`` does the same at any
    stage time inside a step, so springs to a driven particle see the path.
    """

    injects = True  # the path pushes whatever is attached to it: energy comes in
    dissipative = False
    no_closed_form = "keyframed particles"

    def __init__(self, rows: np.ndarray, which: np.ndarray, base: np.ndarray, paths: Paths, backend: str):
        self.rows = np.asarray(rows, dtype=np.int64)
        self.which = np.asarray(which, dtype=np.int64)
        self.base = np.asarray(base, dtype=np.float64).reshape(-1, 3)
        self.paths = paths
        self.evaluator = PathEvaluator(paths, backend)
        kinds = sorted({"smooth" if s else "linear" for s in paths.smooth})
        self.label = (
            f"keyframes: {len(self.rows)} pinned particle(s) on {paths.size} path(s) "
            f"({', '.join(kinds)}), position and velocity set from the path"
        )

    def stability_note(self, dt: float) -> str:
        return "keyframes: driven particles follow their paths and put energy in (the watchdog's energy test is off)"

    def drive(self, t: float, x: np.ndarray, v: np.ndarray) -> None:
        pos, vel = self.evaluator(t)
        x[self.rows] = self.base + pos[self.which]
        v[self.rows] = vel[self.which]

    def reset(self, state: State) -> None:
        self.drive(state.time, state.particle_position, state.particle_velocity)

    def apply(
        self,
        state: State,
        x_old: np.ndarray,
        v_old: np.ndarray,
        t0: float,
        t1: float,
        dt: float | None = None,
    ) -> bool:
        self.drive(t1, state.particle_position, state.particle_velocity)
        return True
