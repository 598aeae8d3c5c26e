"""Backward (implicit) Euler, linearised once per step.

Baraff and Witkin, "Large Steps in Cloth Simulation" (SIGGRAPH 1998), Eq. 6 and
section 5: with K = dF/dx and D = dF/dv at the start of the step,

    (M - dt D - dt^2 K) dv = dt (f + dt K v),    v += dv,    x += dt v

which is one Newton iteration of backward Euler, x1 = x + dt v1,
v1 = v + dt M^-1 f(x1, v1). On a linear spring it is exactly backward Euler:
A-stable, order 1, and it damps the fast modes instead of blowing up on them,
so a stiff chain can take animation-sized steps (Hairer and Wanner, "Solving
Ordinary Differential Equations II", IV.3).

Forces that offer ``jacobians(x, v)`` (springs, penalty planes, drag, wind;
:mod:`animsim.forces.jacobian`) are implicit; the others (gravity, attractors,
turbulence) enter only through f, explicitly. Pinned particles and dead pool
slots are not unknowns: their rows and columns are removed (replaced by
identity rows with a zero right-hand side, so their dv is 0), and their
prescribed velocities still reach the right-hand side through K v. The system
is symmetric positive definite (the spring Jacobians are clamped to stay
negative semidefinite), so it is solved with conjugate gradients and a Jacobi
(diagonal) preconditioner, warm-started from the last step's dv.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from animsim.dynamics import Dynamics
from animsim.integrators.base import Integrator
from animsim.system import State

#: relative residual at which conjugate gradients stops; far below the method's own error
CG_RTOL = 1e-10
#: iteration cap as a multiple of the number of unknowns (exact arithmetic needs at most 1x)
CG_MAXITER_FACTOR = 10


class ImplicitEuler(Integrator):
    name = "implicit_euler"
    order = 1
    evaluations_per_step = 1
    description = "backward Euler linearised per step (Baraff & Witkin 1998), sparse CG with Jacobi"

    def __init__(self, dynamics: Dynamics):
        super().__init__(dynamics)
        n = dynamics.system.particle_count
        self._a = np.zeros((n, 3))
        self._f = np.zeros(3 * n)
        self._dv = np.zeros(3 * n)  # last step's solution, the next warm start
        self.implicit_terms = [t for t in dynamics.terms if hasattr(t, "jacobians")]
        #: conjugate-gradient iterations over the run, and solves that fell back to a direct solver
        self.cg_iterations = 0
        self.direct_solves = 0

    def reset(self) -> None:
        self._dv.fill(0.0)

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[sp.csr_matrix | None, sp.csr_matrix | None]:
        """Sum of the terms' dF/dx and dF/dv (3N x 3N), None where no term contributes."""
        kx = kv = None
        for term in self.implicit_terms:
            jx, jv = term.jacobians(x, v)
            if jx is not None:
                kx = jx if kx is None else kx + jx
            if jv is not None:
                kv = jv if kv is None else kv + jv
        return kx, kv

    def step(self, state: State, dt: float) -> None:
        x, v = state.particle_position, state.particle_velocity
        system = self.dynamics.system
        a = self.dynamics.acceleration(x, v, state.time, self._a)
        free = np.repeat(system.particle_inv_mass > 0, 3)  # unknown degrees of freedom
        kx, kv = self.jacobians(x, v)
        if (kx is None and kv is None) or not free.any():
            v += dt * a  # nothing implicit: A = M, dv = dt M^-1 f
            x += dt * v
            return
        m_dof = np.repeat(system.particle_mass, 3)
        f = self._f
        np.multiply(a.ravel(), m_dof, out=f)  # f = M a on the free DOFs (a is 0 elsewhere)
        rhs = f.copy()
        if kx is not None:
            rhs += dt * (kx @ v.ravel())  # the anchors' prescribed velocities enter here too
        rhs *= dt
        # -dt^2 Kx - dt Kv, scaled in place (the terms built these matrices for this step)
        parts = []
        for mat, scale in ((kx, -dt * dt), (kv, -dt)):
            if mat is not None:
                mat.data *= scale
                parts.append(mat)
        stiff = parts[0] if len(parts) == 1 else parts[0] + parts[1]
        pinned = ~free
        if pinned.any():
            # Pinned particles and dead slots are not unknowns: their rows and columns
            # drop out (identity rows with a zero right-hand side), so dv = 0 there.
            rows = np.repeat(np.arange(stiff.shape[0]), np.diff(stiff.indptr))
            stiff.data *= free[rows] & free[stiff.indices]
            rhs[pinned] = 0.0
        a_mat = (stiff + _diagonal(np.where(free, m_dof, 1.0))).tocsr()
        precond = _diagonal(1.0 / a_mat.diagonal())
        iterations = 0

        def count(_xk: np.ndarray) -> None:
            nonlocal iterations
            iterations += 1

        dv, info = spla.cg(
            a_mat,
            rhs,
            x0=self._dv,
            rtol=CG_RTOL,
            atol=0.0,
            maxiter=CG_MAXITER_FACTOR * int(free.sum()),
            M=precond,
            callback=count,
        )
        self.cg_iterations += iterations
        if info != 0:
            # Not converged (or broke down): the same system, solved directly, rather
            # than a half-solved step passed off as backward Euler.
            # A singular system (it happens only when the step is meaningless,
            # e.g. extreme stiffness against tiny masses) gives NaN, which the
            # watchdog reports as an unstable run with its fix; SciPy's own
            # warning would only repeat that, without the where and why.
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", spla.MatrixRankWarning)
                dv = spla.spsolve(a_mat.tocsc(), rhs)
            self.direct_solves += 1
        dv[pinned] = 0.0
        self._dv[:] = dv
        v += self._dv.reshape(-1, 3)
        x += dt * v


def _diagonal(values: np.ndarray) -> sp.csr_matrix:
    """A diagonal CSR matrix, built directly (scipy.sparse.diags is slow for a per-step call)."""
    n = len(values)
    index = np.arange(n + 1)
    return sp.csr_matrix((values, index[:-1], index), shape=(n, n))
