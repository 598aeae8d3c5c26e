"""Small vector helpers shared by the NumPy kernels.

:func:`dot3` sums a 3-component dot product in a fixed order, x then y then
z, as the numba kernels do: ``np.einsum`` and BLAS choose their own order
(SIMD pairs, fused multiply-adds), which rounds differently, and the two
backends must agree to the bit where they can.
"""

from __future__ import annotations

import numpy as np


def dot3(a: np.ndarray, b: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Row-wise a . b over a last axis of length 3: (a0 b0 + a1 b1) + a2 b2.

    ``b`` is either another array of a's shape or one vector (3,).
    """
    if b.ndim == 1:
        r = np.multiply(a[..., 0], b[0], out=out)
        r += a[..., 1] * b[1]
        r += a[..., 2] * b[2]
        return r
    p = a * b
    r = np.add(p[..., 0], p[..., 1], out=out)
    r += p[..., 2]
    return r
