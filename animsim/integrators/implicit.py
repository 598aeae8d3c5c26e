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
into one sparsity pattern fixed for the run (:class:`_Assembly`), so the
orderings, the band layout and CHOLMOD's symbolic analysis are computed once.
Measured on a stiff cloth in ``benchmarks/stiff_cloth.py``
(``benchmarks/optimisation_log.md``).
"""

from __future__ import annotations

import functools
import math
import warnings
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from animsim.dynamics import Dynamics
from animsim.integrators.base import Integrator
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
#: banded Cholesky (LAPACK) instead of SuperLU when unknowns x bandwidth^2 (after a reverse
#: Cuthill-McKee ordering) is below this (without CHOLMOD): 1.2e8 for a 32 x 32 cloth with
#: bend springs, 1.8e9 for a 64 x 64 one, whose single-precision factors take 46 ms against
#: SuperLU's 151 (48 x 48: 18 against 67; CPU time, one BLAS thread); the bound keeps the
#: band buffers (unknowns x bandwidth x 12 bytes) to tens of MB
BANDED_MAX_WORK = 2e9
#: CHOLMOD (through cvxopt) factors stiff systems when it is installed; False keeps to the
#: banded Cholesky and SuperLU (which the tests use to run both paths)
SPARSE_CHOLESKY = True
#: free degrees of freedom above which no LU is made (fill-in grows faster than the
#: matrix; Jacobi CG with the full iteration cap serves those)
LU_MAX_DOF = 60_000


class _Factors(Protocol):
    """What the step needs of factors of A (CHOLMOD's, banded Cholesky, SuperLU) and of the
    Jacobi preconditioner: x with A x = b (or its approximation)."""

    def solve(self, b: np.ndarray) -> np.ndarray: ...


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
        self._lu: tuple[np.ndarray, _Factors] | None = None  # (free DOF mask it was made for, factors)
        self._stiff = False  # Jacobi CG was too slow once: LU from then on
        self._skip = 0  # steps left that factor directly instead of trying old factors
        self._backoff = 0
        self._plan: _Assembly | None = None  # A's sparsity pattern and where the terms' entries go

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
            plan = self._plan = _Assembly(kx, kv, free, m_dof)
        a_mat = plan.fill(kx, kv, dt)
        dv = self._solve(a_mat, rhs, free)
        dv[pinned] = 0.0
        self._dv[:] = dv
        v += self._dv.reshape(-1, 3)
        x += dt * v

    def _factor(self, a_mat: sp.csr_matrix, free: np.ndarray, dtype: type = np.float64) -> _Factors | None:
        """Factors of A with a ``solve(b)``: CHOLMOD's (always double precision) when cvxopt is
        installed, else banded Cholesky (in ``dtype``) when the band is narrow, else SuperLU
        (float64 only: None for float32, the caller then factors in float64)."""
        plan = self._plan
        assert plan is not None
        self._lu = None  # the factor buffers are reused: old factors are gone from here on
        chol = plan.sparse_cholesky()
        if chol is not None:
            try:
                lu: Any = chol.factor(a_mat.data)
            except np.linalg.LinAlgError:  # not positive definite: the paths below
                lu = None
            if lu is not None:
                return self._made(free, lu, "cholmod")
        band = plan.band()
        if band is not None:
            try:
                lu = _BandedCholesky(a_mat.data, band, dtype)
            except np.linalg.LinAlgError:  # not positive definite (in this precision): SuperLU pivots
                lu = None
            if lu is not None:
                return self._made(free, lu, f"banded {np.dtype(dtype).name}")
        if dtype is not np.float64:
            return None
        with warnings.catch_warnings():
            import scipy.sparse.linalg as spla

            warnings.simplefilter("ignore", spla.MatrixRankWarning)
            # A is symmetric: order A + A^T and pivot on the diagonal (SuperLU's symmetric mode).
            lu = spla.splu(
                a_mat.tocsc(),
                permc_spec="MMD_AT_PLUS_A",
                diag_pivot_thresh=0.0,
                options={"SymmetricMode": True},
            )
        return self._made(free, lu, "superlu")

    def _made(self, free: np.ndarray, lu: _Factors, kind: str) -> _Factors:
        """Keep new factors (for the next steps' reuse) and count them."""
        self._lu = (free.copy(), lu)
        self.factorizations += 1
        self.factor_kind = kind
        return lu

    def _cg(
        self,
        a_mat: sp.csr_matrix,
        rhs: np.ndarray,
        precond: _Factors,
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
        if not self._stiff and lu_ok and _diagonal_ratio(a_mat, self._plan) > JACOBI_MAX_DIAGONAL_RATIO:
            self._stiff = True  # Jacobi CG would need hundreds of iterations: factor at once
        if not (self._stiff and lu_ok):
            cap = CG_MAXITER_FACTOR * unknowns
            dv, info = self._cg(
                a_mat, rhs, _Jacobi(a_mat.diagonal()), min(cap, JACOBI_ITERATIONS) if lu_ok else cap
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


@functools.cache
def _find_cholmod() -> Any | None:
    """cvxopt's CHOLMOD module, or None when cvxopt is not installed (looked for once)."""
    try:
        from cvxopt import cholmod
    except ImportError:
        return None
    return cholmod


def sparse_cholesky_module() -> Any | None:
    """The sparse Cholesky that stiff systems get (cvxopt's CHOLMOD), or None: banded/SuperLU."""
    return _find_cholmod() if SPARSE_CHOLESKY else None


def factor_description() -> str:
    """Which factors precondition conjugate gradients on a stiff system, on this installation."""
    if sparse_cholesky_module() is not None:
        return "sparse Cholesky factors (CHOLMOD through cvxopt, minimum degree ordering)"
    return (
        "banded Cholesky factors (single precision, reverse Cuthill-McKee ordering; SuperLU "
        "when the band is wide; install the cholmod extra for a sparse Cholesky)"
    )


class _SparseCholesky:
    """A = P^T L L^T P by CHOLMOD (through cvxopt), in double precision.

    The symbolic analysis (the fill-reducing ordering, the elimination tree and the
    supernodes) is made once for the pattern; each ``factor`` writes this step's values into
    one cvxopt matrix and redoes only the numeric factorisation, in place, so only the
    latest factors are valid (as with the band buffers)."""

    def __init__(self, cholmod: Any, plan: _Assembly):
        from cvxopt import matrix, spmatrix

        # A is symmetric: its CSR entries on or above the diagonal, row after row, are its
        # lower triangle column after column (the compressed-column order cvxopt stores).
        # Entries between an unknown and a pinned row are zero on every step: left out.
        diagonal = plan.rows == plan.indices
        self.entries = np.flatnonzero((plan.rows <= plan.indices) & ((plan.keep > 0) | diagonal))
        self._cholmod = cholmod
        self._matrix = matrix
        n = plan.n
        # built with ones so that no entry is dropped as zero; the values come with each step
        self.a = spmatrix(
            matrix(np.ones(len(self.entries))),
            matrix(plan.indices[self.entries]),
            matrix(plan.rows[self.entries]),
            (n, n),
        )
        self.symbolic = cholmod.symbolic(self.a, uplo="L")

    def factor(self, data: np.ndarray) -> _SparseCholesky:
        """This step's numeric factorisation (LinAlgError when A is not positive definite)."""
        self.a.V = self._matrix(data[self.entries])  # the values only: the pattern stays
        try:
            self._cholmod.numeric(self.a, self.symbolic)
        except ArithmeticError as exc:
            raise np.linalg.LinAlgError(f"not positive definite (CHOLMOD: {exc})") from exc
        return self

    def solve(self, b: np.ndarray) -> np.ndarray:
        x = self._matrix(b)  # a copy: solved in place
        self._cholmod.solve(self.symbolic, x)
        return np.asarray(x).reshape(-1)


class _BandLayout:
    """Where A's entries go in LAPACK's upper band storage after a reverse Cuthill-McKee
    ordering, and the band buffers (one per precision), reused by every factorisation."""

    def __init__(self, perm: np.ndarray, upper: np.ndarray, slot: np.ndarray, width: int, n: int):
        self.perm = perm
        self.upper = upper  # A's stored entries on or above the diagonal (in RCM order)
        self.slot = slot  # their flat places in a Fortran-ordered (width + 1, n) band
        self.width = width
        self.n = n
        self.buffers: dict[type, np.ndarray] = {}

    def buffer(self, dtype: type) -> np.ndarray:
        ab = self.buffers.get(dtype)
        if ab is None:
            ab = self.buffers[dtype] = np.zeros((self.width + 1, self.n), dtype=dtype, order="F")
        return ab


class _BandedCholesky:
    """A = U^T U in LAPACK band storage (``?pbtrf``), in RCM order, in single or double precision.

    The factors overwrite the layout's band buffer of their precision, so only the
    latest factors of a precision are valid (the integrator keeps one at a time)."""

    def __init__(self, data: np.ndarray, layout: _BandLayout, dtype: type = np.float64):
        from scipy.linalg import get_lapack_funcs

        ab = layout.buffer(dtype)
        ab.fill(0.0)  # the last factors' fill-in
        ab.T.reshape(-1)[layout.slot] = data[layout.upper]  # ab.T is C-ordered: a view
        trf, self._trs = get_lapack_funcs(("pbtrf", "pbtrs"), dtype=dtype)
        factor, info = trf(ab, lower=0, overwrite_ab=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"band matrix not positive definite (pbtrf info {info})")
        self.factor = factor
        self.perm = layout.perm
        self.dtype = dtype

    def solve(self, b: np.ndarray) -> np.ndarray:
        x = np.empty(len(b))
        y, _info = self._trs(self.factor, b[self.perm].astype(self.dtype), lower=0)
        x[self.perm] = y
        return x


class _Assembly:
    """A = M - dt^2 Kx - dt Kv on one sparsity pattern fixed for the run.

    The pattern is the union of the terms' Jacobian patterns and the diagonal,
    kept whatever values the entries take (SciPy's sparse sum drops zeros, so a
    flat cloth's axis-aligned springs made the pattern, and with it the band
    ordering, change from step to step). Built when the terms' patterns or the
    unknowns change; every step then only writes the values into it: the
    same sums and products, in the same order, as adding the scaled matrices.
    """

    def __init__(
        self,
        kx: sp.csr_matrix | None,
        kv: sp.csr_matrix | None,
        free: np.ndarray,
        m_dof: np.ndarray,
    ):
        n = len(free)
        self.n = n
        self.patterns = tuple(None if m is None else (m.indptr.copy(), m.indices.copy()) for m in (kx, kv))
        diagonal = np.arange(n, dtype=np.int64) * (n + 1)
        given = [m for m in (kx, kv) if m is not None]
        keys = _keys(given[0], n)
        where = np.minimum(np.searchsorted(keys, diagonal), max(len(keys) - 1, 0))
        if (
            len(keys)
            and all(_same_pattern(m, given[0]) for m in given[1:])
            and np.array_equal(keys[where], diagonal)
        ):
            # the common case (springs): Kx and Kv share one pattern holding the diagonal
            self.indptr = given[0].indptr.astype(np.int64)
            self.indices = given[0].indices.astype(np.int64)
            self.slots: tuple[np.ndarray | None, ...] = (None, None)
        else:
            union = _diagonal(np.ones(n))
            for m in given:
                # all entries positive: nothing cancels, nothing dropped
                union = union + _csr((np.ones(m.nnz), m.indices, m.indptr), shape=(n, n))
            union.sum_duplicates()
            union.sort_indices()
            self.indptr = union.indptr.astype(np.int64)
            self.indices = union.indices.astype(np.int64)
            keys = _keys(union, n)
            slots = []
            for m in (kx, kv):
                slot = None if m is None else np.searchsorted(keys, _keys(m, n))
                if slot is not None and len(slot) == len(keys):
                    slot = None  # the same pattern (the union holds all of m's places)
                slots.append(slot)
            self.slots = tuple(slots)
            where = np.searchsorted(keys, diagonal)
        rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(self.indptr))
        self.rows = rows
        self.free = free.copy()
        self.m_dof = m_dof.copy()
        # stiffness entries kept: both ends unknowns (pinned rows and columns drop out)
        self.keep = (free[rows] & free[self.indices]).astype(np.float64)
        self.base = np.zeros(len(keys))
        self.base[where] = np.where(free, m_dof, 1.0)
        self.work = np.zeros(len(keys))
        self.matrix = _csr((np.zeros(len(keys)), self.indices, self.indptr), shape=(n, n))
        self._band: _BandLayout | bool | None = False  # False: not computed yet
        self._cholesky: _SparseCholesky | None = None

    def matches(
        self, kx: sp.csr_matrix | None, kv: sp.csr_matrix | None, free: np.ndarray, m_dof: np.ndarray
    ) -> bool:
        for m, pattern in zip((kx, kv), self.patterns, strict=True):
            if (m is None) != (pattern is None):
                return False
            if m is not None and not (
                pattern is not None  # both present: the check above
                and np.array_equal(m.indptr, pattern[0])
                and np.array_equal(m.indices, pattern[1])
            ):
                return False
        return np.array_equal(free, self.free) and np.array_equal(m_dof, self.m_dof)

    def fill(self, kx: sp.csr_matrix | None, kv: sp.csr_matrix | None, dt: float) -> sp.csr_matrix:
        """The matrix A of this step (the pattern's one CSR matrix, its values rewritten)."""
        data = self.matrix.data
        data.fill(0.0)
        work = self.work
        for m, slot, scale in ((kx, self.slots[0], -dt * dt), (kv, self.slots[1], -dt)):
            if m is None:
                continue
            if slot is None:  # the term's pattern is the union's: no scatter
                np.multiply(m.data, scale, out=work)
            else:
                work.fill(0.0)
                work[slot] = m.data
                work *= scale
            data += work
        data *= self.keep
        data += self.base
        return self.matrix

    def band(self) -> _BandLayout | None:
        """The band layout of this pattern, or None when the band is too wide (computed once)."""
        if self._band is False:
            from scipy.sparse.csgraph import reverse_cuthill_mckee

            n = self.n
            perm = reverse_cuthill_mckee(self.matrix, symmetric_mode=True)
            where = np.empty(n, dtype=np.int64)
            where[perm] = np.arange(n)
            rows = where[self.rows]
            cols = where[self.indices]
            width = int(np.max(np.abs(rows - cols))) if len(rows) else 0
            self._band = None
            if n * width * width <= BANDED_MAX_WORK:
                # LAPACK's upper band storage: ab[width + i - j, j] = A[i, j] for i <= j,
                # at flat place j (width + 1) + width + i - j of the Fortran-ordered band
                upper = np.flatnonzero(rows <= cols)
                slot = cols[upper] * (width + 1) + width + rows[upper] - cols[upper]
                self._band = _BandLayout(perm, upper, slot, width, n)
        return self._band  # type: ignore[return-value]

    def sparse_cholesky(self) -> _SparseCholesky | None:
        """CHOLMOD's analysis of this pattern (made once), or None without cvxopt."""
        cholmod = sparse_cholesky_module()
        if cholmod is None:
            return None
        if self._cholesky is None:
            self._cholesky = _SparseCholesky(cholmod, self)
        return self._cholesky


def _diagonal_ratio(a_mat: sp.csr_matrix, plan: _Assembly | None) -> float:
    """max over the unknowns of A_ii / m_i (1 for the pinned identity rows)."""
    if plan is None:
        return 1.0
    return float(np.max(a_mat.diagonal() / np.where(plan.free, plan.m_dof, 1.0)))


def _same_pattern(m: sp.csr_matrix, other: sp.csr_matrix) -> bool:
    return np.array_equal(m.indptr, other.indptr) and np.array_equal(m.indices, other.indices)


def _keys(m: sp.csr_matrix, n: int) -> np.ndarray:
    rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(m.indptr))
    keys: np.ndarray = rows * n + m.indices
    return keys


class _Jacobi:
    """The diagonal preconditioner, with the factors' ``solve`` interface."""

    def __init__(self, diagonal: np.ndarray):
        self.inverse: np.ndarray = 1.0 / diagonal

    def solve(self, b: np.ndarray) -> np.ndarray:
        x: np.ndarray = self.inverse * b
        return x


def _diagonal(values: np.ndarray) -> sp.csr_matrix:
    """A diagonal CSR matrix, built directly (scipy.sparse.diags is slow for a per-step call)."""
    n = len(values)
    index = np.arange(n + 1)
    return _csr((values, index[:-1], index), shape=(n, n))


def _csr(*args: Any, **kwargs: Any) -> sp.csr_matrix:
    """scipy.sparse.csr_matrix, imported on first use (the module loads with every run)."""
    import scipy.sparse as sp

    return sp.csr_matrix(*args, **kwargs)
