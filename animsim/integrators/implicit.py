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
negative semidefinite), so it is solved with conjugate gradients, warm-started
from the last step's dv.

Conjugate gradients use a Jacobi (diagonal) preconditioner while it
converges within ``JACOBI_ITERATIONS`` iterations (small steps: the matrix is
close to M). A stiff system at animation-sized steps needs hundreds or
thousands (a diagonal over ``JACOBI_MAX_DIAGONAL_RATIO`` times the mass says so
before trying); from then on each step is factored, and the factors serve as
the preconditioner of conjugate gradients, which still stop at ``CG_RTOL`` in
double precision. With cvxopt installed (the ``cholmod`` extra) the factors are
CHOLMOD's supernodal sparse Cholesky (Chen, Davis, Hager and Rajamanickam, ACM
TOMS 35(3), 2008) after a fill-reducing approximate minimum degree ordering:
its symbolic analysis is made once for the run's fixed pattern, each step
redoes only the numeric factorisation, and the exact double-precision factors
leave CG one iteration. Without it (or when CHOLMOD finds the matrix not
positive definite): a banded Cholesky factorisation (LAPACK ``?pbtrf``) after a
reverse Cuthill-McKee ordering when the band is narrow, else SuperLU. The
banded factors are made in single precision, half the work of double (two or
three CG iterations on a stiff cloth); double-precision factors and their
direct solve are the fallback. Before factoring, the last factors are tried as
the preconditioner while they keep conjugate gradients within
``REUSE_ITERATIONS`` (a cloth coming to rest changes its matrix little; a
falling one changes it too much at a frame-sized step, and the attempt is given
up after ``PROBE_ITERATIONS`` and tried again later and later). A is written
into one sparsity pattern fixed for the run
(:class:`animsim.integrators.implicit_linear.Assembly`), so the
orderings, the band layout and CHOLMOD's symbolic analysis are computed once.
Measured on a stiff cloth in ``benchmarks/stiff_cloth.py``
(``benchmarks/optimisation_log.md``).
"""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING

import numpy as np

from animsim.dynamics import Dynamics
from animsim.integrators.base import Integrator
from animsim.integrators.implicit_linear import (
    Assembly,
    Factors,
    Jacobi,
    diagonal_ratio,
    factor,
    factor_description,
)
from animsim.system import State

if TYPE_CHECKING:  # SciPy's sparse modules load when a run steps with implicit Euler
    import scipy.sparse as sp

#: relative residual at which conjugate gradients stops; far below the method's own error
CG_RTOL = 1e-10
#: iteration cap as a multiple of the number of unknowns (exact arithmetic needs at most 1x)
CG_MAXITER_FACTOR = 10
#: Jacobi-preconditioned iterations after which a system counts as stiff (LU from then on)
JACOBI_ITERATIONS = 100
#: largest diagonal of A over the mass (1 + dt^2 k / m for one spring) at which Jacobi CG is
#: tried first: beyond it the Jacobi-preconditioned matrix's condition number (about twice the
#: ratio) needs hundreds of iterations, more than JACOBI_ITERATIONS
JACOBI_MAX_DIAGONAL_RATIO = 1e3
#: iterations with an old factorisation as preconditioner before it is replaced by a new one
REUSE_ITERATIONS = 12
#: iterations with this step's single-precision factors as preconditioner before the step is
#: factored again in double precision and solved directly
FRESH_ITERATIONS = 30
#: iterations after which CG with old factors is given up if its rate so far is too slow
PROBE_ITERATIONS = 3
#: steps a failed reuse of old factors makes the solver factor afresh, at most
REUSE_BACKOFF_MAX = 16
#: free degrees of freedom above which no LU is made (fill-in grows faster than the
#: matrix; Jacobi CG with the full iteration cap serves those)
LU_MAX_DOF = 60_000


class ImplicitEuler(Integrator):
    method_name = "implicit_euler"

    def __init__(self, dynamics: Dynamics):
        super().__init__(dynamics)
        #: what ``animsim explain`` shows: the solver a stiff system gets on this installation
        self.description = (
            "backward Euler linearised per step (Baraff & Witkin 1998): conjugate gradients, "
            f"Jacobi-preconditioned, or on a stiff system with each step's {factor_description()}"
        )
        n = dynamics.system.particle_count
        self._a = np.zeros((n, 3))
        self._f = np.zeros(3 * n)
        self._dv = np.zeros(3 * n)  # last step's solution, the next warm start
        self.implicit_terms = [t for t in dynamics.terms if t.offers_jacobians]
        #: conjugate-gradient iterations over the run, and solves that fell back to a direct solver
        self.cg_iterations = 0
        self.direct_solves = 0
        #: LU factorisations made (each serves as the preconditioner of the steps after it)
        self.factorizations = 0
        #: the kind of the last factorisation: "cholmod", "banded float32", "banded float64",
        #: "superlu" (None before the first)
        self.factor_kind: str | None = None
        self._lu: tuple[np.ndarray, Factors] | None = None  # (free DOF mask it was made for, factors)
        self._stiff = False  # Jacobi CG was too slow once: LU from then on
        self._skip = 0  # steps left that factor directly instead of trying old factors
        self._backoff = 0
        self._plan: Assembly | None = None  # A's sparsity pattern and where the terms' entries go

    def reset(self) -> None:
        self._dv.fill(0.0)
        self._lu = None
        self._stiff = False
        self._skip = self._backoff = 0

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[sp.csr_matrix | None, sp.csr_matrix | None]:
        """Sum of the terms' dF/dx and dF/dv (3N x 3N), None where no term contributes."""
        kx = kv = None
        for term in self.implicit_terms:
            jx, jv = term.jacobians(x, v)
            if jx is not None:
                kx = jx if kx is None else kx + jx
            if jv is not None:
                kv = jv if kv is None else kv + jv
        for m in (kx, kv):
            if m is not None:
                m.sum_duplicates()  # one entry per place (a no-op on the terms' canonical matrices)
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
        pinned = ~free
        if pinned.any():
            # Pinned particles and dead slots are not unknowns: their rows and columns
            # drop out (identity rows with a zero right-hand side), so dv = 0 there.
            rhs[pinned] = 0.0
        plan = self._plan
        if plan is None or not plan.matches(kx, kv, free, m_dof):
            plan = self._plan = Assembly(kx, kv, free, m_dof)
        a_mat = plan.fill(kx, kv, dt)
        dv = self._solve(a_mat, rhs, free)
        dv[pinned] = 0.0
        self._dv[:] = dv
        v += self._dv.reshape(-1, 3)
        x += dt * v

    def _factor(self, a_mat: sp.csr_matrix, free: np.ndarray, dtype: type = np.float64) -> Factors | None:
        """This step's factors of A (:func:`animsim.integrators.implicit_linear.factor`), kept
        for the next steps' reuse and counted; None when none are made in ``dtype``."""
        plan = self._plan
        assert plan is not None
        self._lu = None  # the factor buffers are reused: old factors are gone from here on
        made = factor(plan, a_mat, dtype)
        if made is None:
            return None
        lu, kind = made
        self._lu = (free.copy(), lu)
        self.factorizations += 1
        self.factor_kind = kind
        return lu

    def _cg(
        self,
        a_mat: sp.csr_matrix,
        rhs: np.ndarray,
        precond: Factors,
        maxiter: int,
        probe: bool = False,
        warm: bool = True,
    ) -> tuple[np.ndarray, int]:
        """Preconditioned conjugate gradients from the last step's dv, as SciPy's ``cg`` (the same
        operations and stopping test, ||r|| < CG_RTOL ||rhs||), on the matrix and the
        preconditioner's ``solve`` directly. ``probe``: give up after PROBE_ITERATIONS when the
        residual's fall so far says ``maxiter`` will not be enough (old factors far off).

        Returns (dv, 0) when converged, else (the last iterate, iterations done).
        """
        x = self._dv.copy() if warm else np.zeros_like(rhs)
        tol = CG_RTOL * float(np.linalg.norm(rhs))
        if tol == 0.0:
            return rhs.copy(), 0
        psolve = precond.solve
        r = rhs - a_mat @ x if x.any() else rhs.copy()
        start = float(np.linalg.norm(r))
        rho_prev = np.float64(1.0)
        p = np.empty_like(r)
        # NumPy scalars, as in SciPy: a zero denominator (a singular system) gives inf or NaN
        # (reported by the watchdog), not an exception
        with np.errstate(divide="ignore", invalid="ignore"):
            for iteration in range(maxiter):
                rnorm = float(np.linalg.norm(r))
                if rnorm < tol:
                    self.cg_iterations += iteration
                    return x, 0
                if not math.isfinite(rnorm):  # a breakdown (p.Ap = 0 on a singular system): give up
                    self.cg_iterations += iteration
                    return x, max(iteration, 1)
                if probe and iteration == PROBE_ITERATIONS and start > 0.0 and rnorm > 0.0:
                    # at this rate, iterations to fall from start to tol (no fall: never)
                    fall = rnorm / start
                    needed = iteration * math.log(tol / start) / math.log(fall) if fall < 1.0 else math.inf
                    if needed > maxiter:
                        self.cg_iterations += iteration
                        return x, iteration
                z = psolve(r)
                rho = np.dot(r, z)
                if iteration > 0:
                    p *= rho / rho_prev
                    p += z
                else:
                    p[:] = z
                q = a_mat @ p
                alpha = rho / np.dot(p, q)
                x += alpha * p
                r -= alpha * q
                rho_prev = rho
        self.cg_iterations += maxiter
        return x, maxiter

    def _solve(self, a_mat: sp.csr_matrix, rhs: np.ndarray, free: np.ndarray) -> np.ndarray:
        """dv with A dv = rhs (see the module docstring for the choice of solver)."""
        unknowns = int(free.sum())
        lu_ok = unknowns <= LU_MAX_DOF
        if not self._stiff and lu_ok and diagonal_ratio(a_mat, self._plan) > JACOBI_MAX_DIAGONAL_RATIO:
            self._stiff = True  # Jacobi CG would need hundreds of iterations: factor at once
        if not (self._stiff and lu_ok):
            cap = CG_MAXITER_FACTOR * unknowns
            dv, info = self._cg(
                a_mat, rhs, Jacobi(a_mat.diagonal()), min(cap, JACOBI_ITERATIONS) if lu_ok else cap
            )
            if info == 0:
                return dv
            if not lu_ok:
                return self._fallback(a_mat, rhs)
            self._stiff = True
        old = self._lu
        if self._skip == 0 and old is not None and np.array_equal(old[0], free):
            dv, info = self._cg(a_mat, rhs, old[1], REUSE_ITERATIONS, probe=True)
            if info == 0:
                self._backoff = 0
                return dv
            # The old factors are too far from this matrix: factor afresh for a while.
            self._backoff = min(2 * self._backoff + 1, REUSE_BACKOFF_MAX)
            self._skip = self._backoff
        elif self._skip:
            self._skip -= 1
        # This step's own factors as conjugate gradients' preconditioner: CHOLMOD's (exact: one
        # iteration), else banded ones in single precision (half the work of double); CG still
        # stops at CG_RTOL in double.
        lu32 = self._factor(a_mat, free, np.float32)
        if lu32 is not None:
            dv, info = self._cg(a_mat, rhs, lu32, FRESH_ITERATIONS, warm=False)
            if info == 0:
                return dv
        try:
            lu = self._factor(a_mat, free)
        except RuntimeError:  # exactly singular: the step is meaningless (see _fallback)
            self._lu = None
            return self._fallback(a_mat, rhs)
        assert lu is not None  # in float64 SuperLU always factors (None is for float32 only)
        dv = lu.solve(rhs)
        if not np.all(np.isfinite(dv)):
            self._lu = None
            return self._fallback(a_mat, rhs)
        return dv

    def _fallback(self, a_mat: sp.csr_matrix, rhs: np.ndarray) -> np.ndarray:
        # A singular system (it happens only when the step is meaningless, e.g.
        # extreme stiffness against tiny masses) gives NaN, which the watchdog
        # reports as an unstable run with its fix; SciPy's own warning would
        # only repeat that, without the where and why.
        with warnings.catch_warnings():
            import scipy.sparse.linalg as spla

            warnings.simplefilter("ignore", spla.MatrixRankWarning)
            dv = spla.spsolve(a_mat.tocsc(), rhs)
        self.direct_solves += 1
        return np.asarray(dv, dtype=np.float64)
