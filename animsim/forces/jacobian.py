"""Sparse Jacobians of force terms, for implicit integration.

A force term may offer ``jacobians(x, v) -> (Kx, Kv)``: the (3N, 3N) sparse
matrices dF/dx and dF/dv at (x, v), either of them None when it is zero;
they are new on every call and the caller may scale them in place.
Degree of freedom 3*i + axis is particle i's coordinate ``axis``. Terms
without the method (gravity, attractors, turbulence) are treated explicitly
by the implicit integrator (Baraff and Witkin, "Large Steps in Cloth
Simulation", SIGGRAPH 1998, section 5).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # SciPy loads only when implicit Euler asks for a Jacobian
    import scipy.sparse as sp

AXES = np.arange(3)


def block_pattern(p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row and column indices (k, 3, 3) of the 3x3 blocks (p[k], q[k])."""
    rows = 3 * p[:, None, None] + AXES[None, :, None]
    cols = 3 * q[:, None, None] + AXES[None, None, :]
    return np.broadcast_to(rows, (len(p), 3, 3)), np.broadcast_to(cols, (len(p), 3, 3))


def diagonal_blocks(index: np.ndarray, blocks: np.ndarray, n: int) -> sp.csr_matrix:
    """A (3n, 3n) matrix with the 3x3 ``blocks`` (k, 3, 3) on the diagonal at particles ``index``."""
    import scipy.sparse as sp

    rows, cols = block_pattern(index, index)
    return sp.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * n, 3 * n))


def scaled_identity(coef: float, n: int) -> sp.csr_matrix:
    import scipy.sparse as sp

    return sp.identity(3 * n, format="csr") * coef
