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
thousands; from then on the run uses a sparse LU factorisation (SuperLU,
minimum degree ordering on A + A^T) instead: its direct solve, and its factors
as the preconditioner of the following steps while they keep conjugate
gradients within ``REUSE_ITERATIONS`` iterations (a cloth coming to rest
changes its matrix little). Measured on a stiff cloth in
``benchmarks/stiff_cloth.py``.
"""

from __future__ import annotations

import warnings
from typing import Any

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
#: Jacobi-preconditioned iterations after which a system counts as stiff (LU from then on)
JACOBI_ITERATIONS = 100
#: iterations with an old factorisation as preconditioner before it is replaced by a new one
REUSE_ITERATIONS = 12
#: steps a failed reuse of old factors makes the solver factor directly, at most
REUSE_BACKOFF_MAX = 16
#: banded Cholesky (LAPACK) instead of SuperLU when unknowns x bandwidth^2 (after a reverse
#: Cuthill-McKee ordering) is below this: 1.1e8 for a 32 x 32 cloth, factored in 8 ms
#: against SuperLU's 14 (CPU time on the benchmark machine)
BANDED_MAX_WORK = 2e8
#: free degrees of freedom above which no LU is made (fill-in grows faster than the
#: matrix; Jacobi CG with the full iteration cap serves those)
LU_MAX_DOF = 60_000


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
        #: LU factorisations made (each serves as the preconditioner of the steps after it)
        self.factorizations = 0
        self._lu: tuple[np.ndarray, object] | None = None  # (free DOF mask it was made for, factors)
        self._stiff = False  # Jacobi CG was too slow once: LU from then on
        self._skip = 0  # steps left that factor directly instead of trying old factors
        self._backoff = 0

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
        dv = self._solve(a_mat, rhs, free)
        dv[pinned] = 0.0
        self._dv[:] = dv
        v += self._dv.reshape(-1, 3)
        x += dt * v

    def _factor(self, a_mat: sp.csr_matrix, free: np.ndarray) -> Any:
        """Factors of A with a ``solve(b)``: banded Cholesky when the band is narrow, else SuperLU."""
        band = self._band_layout(a_mat)
        if band is not None:
            try:
                lu: Any = _BandedCholesky(a_mat, *band)
            except np.linalg.LinAlgError:  # not positive definite after all: SuperLU pivots
                lu = None
            if lu is not None:
                self._lu = (free.copy(), lu)
                self.factorizations += 1
                return lu
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", spla.MatrixRankWarning)
            # A is symmetric: order A + A^T and pivot on the diagonal (SuperLU's symmetric mode).
            lu = spla.splu(
                a_mat.tocsc(),
                permc_spec="MMD_AT_PLUS_A",
                diag_pivot_thresh=0.0,
                options={"SymmetricMode": True},
            )
        self._lu = (free.copy(), lu)
        self.factorizations += 1
        return lu

    def _cg(
        self, a_mat: sp.csr_matrix, rhs: np.ndarray, precond: Any, maxiter: int
    ) -> tuple[np.ndarray, int]:
        iterations = 0

        def count(_xk: np.ndarray) -> None:
            nonlocal iterations
            iterations += 1

        dv, info = spla.cg(
            a_mat, rhs, x0=self._dv, rtol=CG_RTOL, atol=0.0, maxiter=maxiter, M=precond, callback=count
        )
        self.cg_iterations += iterations
        return dv, info

    def _band_layout(self, a_mat: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray, int] | None:
        """(RCM permutation, each stored entry's place in the upper band or -1, bandwidth), or
        None when the band is too wide; computed once per sparsity pattern."""
        cached = getattr(self, "_band", None)
        if (
            cached is not None
            and np.array_equal(cached[0], a_mat.indptr)
            and np.array_equal(cached[1], a_mat.indices)
        ):
            return cached[2]
        from scipy.sparse.csgraph import reverse_cuthill_mckee

        n = a_mat.shape[0]
        perm = reverse_cuthill_mckee(a_mat, symmetric_mode=True)
        where = np.empty(n, dtype=np.int64)
        where[perm] = np.arange(n)
        rows = where[np.repeat(np.arange(n), np.diff(a_mat.indptr))]
        cols = where[a_mat.indices]
        width = int(np.max(np.abs(rows - cols))) if len(rows) else 0
        layout = None
        if n * width * width <= BANDED_MAX_WORK:
            # LAPACK's upper band storage: ab[width + i - j, j] = A[i, j] for i <= j
            upper = rows <= cols
            slot = np.where(upper, (width + rows - cols) * n + cols, -1)
            layout = (perm, slot, width)
        self._band = (a_mat.indptr.copy(), a_mat.indices.copy(), layout)
        return layout

    def _solve(self, a_mat: sp.csr_matrix, rhs: np.ndarray, free: np.ndarray) -> np.ndarray:
        """dv with A dv = rhs (see the module docstring for the choice of solver)."""
        unknowns = int(free.sum())
        lu_ok = unknowns <= LU_MAX_DOF
        if not (self._stiff and lu_ok):
            cap = CG_MAXITER_FACTOR * unknowns
            dv, info = self._cg(
                a_mat, rhs, _diagonal(1.0 / a_mat.diagonal()), min(cap, JACOBI_ITERATIONS) if lu_ok else cap
            )
            if info == 0:
                return dv
            if not lu_ok:
                return self._fallback(a_mat, rhs)
            self._stiff = True
        old = self._lu
        if self._skip == 0 and old is not None and np.array_equal(old[0], free):
            precond = spla.LinearOperator(a_mat.shape, matvec=old[1].solve, dtype=np.float64)  # type: ignore[attr-defined]
            dv, info = self._cg(a_mat, rhs, precond, REUSE_ITERATIONS)
            if info == 0:
                self._backoff = 0
                return dv
            # The old factors are too far from this matrix: factor directly for a while.
            self._backoff = min(2 * self._backoff + 1, REUSE_BACKOFF_MAX)
            self._skip = self._backoff
        elif self._skip:
            self._skip -= 1
        try:
            lu = self._factor(a_mat, free)
        except RuntimeError:  # exactly singular: the step is meaningless (see _fallback)
            self._lu = None
            return self._fallback(a_mat, rhs)
        dv = lu.solve(rhs)  # type: ignore[attr-defined]
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
            warnings.simplefilter("ignore", spla.MatrixRankWarning)
            dv = spla.spsolve(a_mat.tocsc(), rhs)
        self.direct_solves += 1
        return np.asarray(dv, dtype=np.float64)


class _BandedCholesky:
    """A = L L^T in LAPACK band storage (``scipy.linalg.cholesky_banded``), in RCM order."""

    def __init__(self, a_mat: sp.csr_matrix, perm: np.ndarray, slot: np.ndarray, width: int):
        import scipy.linalg as sl

        n = a_mat.shape[0]
        ab = np.zeros((width + 1) * n)
        keep = slot >= 0
        np.add.at(ab, slot[keep], a_mat.data[keep])  # duplicates (none after tocsr) would add
        self._solve = sl.cho_solve_banded
        self.factor = sl.cholesky_banded(ab.reshape(width + 1, n), lower=False, check_finite=False)
        self.perm = perm

    def solve(self, b: np.ndarray) -> np.ndarray:
        x = np.empty_like(b)
        x[self.perm] = self._solve((self.factor, False), b[self.perm], check_finite=False)
        return x


def _diagonal(values: np.ndarray) -> sp.csr_matrix:
    """A diagonal CSR matrix, built directly (scipy.sparse.diags is slow for a per-step call)."""
    n = len(values)
    index = np.arange(n + 1)
    return sp.csr_matrix((values, index[:-1], index), shape=(n, n))
