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
        # A component of exactly 1 (an axis-aligned normal) is added without its product:
        # x * 1 is x in IEEE arithmetic, zeros, infinities and NaNs included, so the sums are
        # the same bits. (Not for -1: r - x picks between two NaNs as r + x * -1 may not.)
        if b[0] == 1.0:
            r = np.positive(a[..., 0], out=out)
        else:
            r = np.multiply(a[..., 0], b[0], out=out)
        for j in (1, 2):
            if b[j] == 1.0:
                r += a[..., j]
            else:
                r += a[..., j] * b[j]
        return r
    p = a * b
    r = np.add(p[..., 0], p[..., 1], out=out)
    r += p[..., 2]
    return r


def sub_scaled(
    a: np.ndarray, s: np.ndarray, c: float, out: np.ndarray, tmp: np.ndarray, where: np.ndarray | bool = True
) -> None:
    """out = a - s * c (where ``where``), ``tmp`` a scratch of s's shape; the product is
    skipped for c = 1, with the same bits (see :func:`dot3`)."""
    if c == 1.0:
        np.subtract(a, s, out=out, where=where)
    else:
        np.multiply(s, c, out=tmp)
        np.subtract(a, tmp, out=out, where=where)


def add_scaled(
    a: np.ndarray, s: np.ndarray, c: float, out: np.ndarray, tmp: np.ndarray, where: np.ndarray | bool = True
) -> None:
    """out = a + s * c (where ``where``), as :func:`sub_scaled`."""
    if c == 1.0:
        np.add(a, s, out=out, where=where)
    else:
        np.multiply(s, c, out=tmp)
        np.add(a, tmp, out=out, where=where)


def take_rows(a: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``a[idx]`` for an (N, 3) array, as a new array: ``np.take`` along the rows is about
    three times faster than fancy indexing for many rows (the same values: a copy)."""
    return np.take(a, idx, axis=0)


_ROW = np.dtype((np.void, 24))


def put_rows(a: np.ndarray, idx: np.ndarray, values: np.ndarray) -> None:
    """``a[idx] = values`` for (N, 3) float64 rows: each row moved as one 24-byte item
    (``np.put`` on a row view), about three times faster than fancy assignment for
    many rows; the bytes written are the same."""
    if a.dtype == np.float64 and a.flags.c_contiguous and a.ndim == 2 and a.shape[1] == 3:
        vals = np.ascontiguousarray(values, dtype=np.float64)
        np.put(a.view(_ROW).reshape(-1), idx, vals.view(_ROW).reshape(-1))
    else:
        a[idx] = values
