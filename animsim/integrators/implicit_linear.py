"""The linear systems of implicit Euler's step (:mod:`animsim.integrators.implicit`): the
matrix A = M - dt^2 Kx - dt Kv written into one sparsity pattern fixed for the run
(:class:`Assembly`), and the factors that precondition conjugate gradients on a stiff system.

* CHOLMOD's supernodal sparse Cholesky through cvxopt (Chen, Davis, Hager and Rajamanickam,
  ACM TOMS 35(3), 2008), after a fill-reducing approximate minimum degree ordering, its
  symbolic analysis made once for the pattern (:class:`SparseCholesky`);
* without it, LAPACK's banded Cholesky (``?pbtrf``) after a reverse Cuthill-McKee ordering
  when the band is narrow, in single or double precision (:class:`BandedCholesky`);
* else SuperLU in its symmetric mode.

The Jacobi (diagonal) preconditioner has the factors' ``solve`` interface (:class:`Jacobi`).
"""

from __future__ import annotations

import functools
import warnings
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:  # SciPy's sparse modules load when a run steps with implicit Euler
    import scipy.sparse as sp

#: banded Cholesky (LAPACK) instead of SuperLU when unknowns x bandwidth^2 (after a reverse
#: Cuthill-McKee ordering) is below this (without CHOLMOD): 1.2e8 for a 32 x 32 cloth with
#: bend springs, 1.8e9 for a 64 x 64 one, whose single-precision factors take 46 ms against
#: SuperLU's 151 (48 x 48: 18 against 67; CPU time, one BLAS thread); the bound keeps the
#: band buffers (unknowns x bandwidth x 12 bytes) to tens of MB
BANDED_MAX_WORK = 2e9
#: CHOLMOD (through cvxopt) factors stiff systems when it is installed; False keeps to the
#: banded Cholesky and SuperLU (which the tests use to run both paths)
SPARSE_CHOLESKY = True


class Factors(Protocol):
    """What the step needs of factors of A (CHOLMOD's, banded Cholesky, SuperLU) and of the
    Jacobi preconditioner: x with A x = b (or its approximation)."""

    def solve(self, b: np.ndarray) -> np.ndarray: ...


def factor(plan: Assembly, a_mat: sp.csr_matrix, dtype: type = np.float64) -> tuple[Factors, str] | None:
    """Factors of A with a ``solve(b)``, and their kind: CHOLMOD's (always double precision)
    when cvxopt is installed, else banded Cholesky (in ``dtype``) when the band is narrow, else
    SuperLU (float64 only: None for float32, the caller then factors in float64). The factors
    overwrite the last ones of their kind (the buffers are reused)."""
    chol = plan.sparse_cholesky()
    if chol is not None:
        try:
            lu: Any = chol.factor(a_mat.data)
        except np.linalg.LinAlgError:  # not positive definite: the paths below
            lu = None
        if lu is not None:
            return lu, "cholmod"
    band = plan.band()
    if band is not None:
        try:
            lu = BandedCholesky(a_mat.data, band, dtype)
        except np.linalg.LinAlgError:  # not positive definite (in this precision): SuperLU pivots
            lu = None
        if lu is not None:
            return lu, f"banded {np.dtype(dtype).name}"
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
    return lu, "superlu"


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


class SparseCholesky:
    """A = P^T L L^T P by CHOLMOD (through cvxopt), in double precision.

    The symbolic analysis (the fill-reducing ordering, the elimination tree and the
    supernodes) is made once for the pattern; each ``factor`` writes this step's values into
    one cvxopt matrix and redoes only the numeric factorisation, in place, so only the
    latest factors are valid (as with the band buffers)."""

    def __init__(self, cholmod: Any, plan: Assembly):
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

    def factor(self, data: np.ndarray) -> SparseCholesky:
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


class BandLayout:
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


class BandedCholesky:
    """A = U^T U in LAPACK band storage (``?pbtrf``), in RCM order, in single or double precision.

    The factors overwrite the layout's band buffer of their precision, so only the
    latest factors of a precision are valid (the integrator keeps one at a time)."""

    def __init__(self, data: np.ndarray, layout: BandLayout, dtype: type = np.float64):
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


class Assembly:
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
        self._band: BandLayout | bool | None = False  # False: not computed yet
        self._cholesky: SparseCholesky | None = None

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

    def band(self) -> BandLayout | None:
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
                self._band = BandLayout(perm, upper, slot, width, n)
        return self._band  # type: ignore[return-value]

    def sparse_cholesky(self) -> SparseCholesky | None:
        """CHOLMOD's analysis of this pattern (made once), or None without cvxopt."""
        cholmod = sparse_cholesky_module()
        if cholmod is None:
            return None
        if self._cholesky is None:
            self._cholesky = SparseCholesky(cholmod, self)
        return self._cholesky


def diagonal_ratio(a_mat: sp.csr_matrix, plan: Assembly | None) -> float:
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


class Jacobi:
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
