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
slots are not unknowns: their rows and columns are removed, and their
prescribed velocities still reach the right-hand side through K v. The system
is symmetric positive definite (the spring Jacobians are clamped to stay
negative semidefinite), so it is solved with conjugate gradients and a Jacobi
(diagonal) preconditioner, warm-started from the last step's dv.
"""

from __future__ import annotations

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
        mass = system.particle_mass
        free = np.repeat(system.particle_inv_mass > 0, 3)  # unknown degrees of freedom
        kx, kv = self.jacobians(x, v)
        if (kx is None and kv is None) or not free.any():
            v += dt * a  # nothing implicit: A = M, dv = dt M^-1 f
            x += dt * v
            return
        m_dof = np.repeat(mass, 3)
        f = self._f
        np.multiply(a.ravel(), m_dof, out=f)  # f = M a on the free DOFs (a is 0 elsewhere)
        rhs = f.copy()
        a_mat = sp.diags(m_dof, format="csr")
        if kx is not None:
            rhs += dt * (kx @ v.ravel())
            a_mat = a_mat - (dt * dt) * kx
        if kv is not None:
            a_mat = a_mat - dt * kv
        rhs *= dt
        idx = np.flatnonzero(free)
        a_ff = a_mat[idx][:, idx].tocsr()
        b = rhs[idx]
        diag = a_ff.diagonal()
        precond = sp.diags(1.0 / diag)
        iterations = 0

        def count(_xk: np.ndarray) -> None:
            nonlocal iterations
            iterations += 1

        dv, info = spla.cg(
            a_ff,
            b,
            x0=self._dv[idx],
            rtol=CG_RTOL,
            atol=0.0,
            maxiter=CG_MAXITER_FACTOR * idx.size,
            M=precond,
            callback=count,
        )
        self.cg_iterations += iterations
        if info != 0:
            # Not converged (or broke down): the same system, solved directly, rather
            # than a half-solved step passed off as backward Euler.
            dv = spla.spsolve(a_ff.tocsc(), b)
            self.direct_solves += 1
        self._dv.fill(0.0)
        self._dv[idx] = dv
        v += self._dv.reshape(-1, 3)
        x += dt * v
