"""Fixed-order arithmetic of the NumPy contact solver (:mod:`animsim.bodies.contact_solve`), shared
with its numba twins (:mod:`animsim.bodies.contact_kernels`) in the order of every sum.

Vectors are (3, k) arrays, one row per component, and every sum is written out in the order the
numba kernels use (x, then y, then z; a matrix row as (m0 u0 + m1 u1) + m2 u2): the two
backends then round alike, contact by contact.
"""

from __future__ import annotations

import numpy as np


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of (3, k) arrays."""
    return np.stack((a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]))


def dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a . b of (3, k) arrays, (k,): (a0 b0 + a1 b1) + a2 b2."""
    return (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]


def sym_matvec(m: np.ndarray, u: np.ndarray) -> np.ndarray:
    """M u for symmetric M given as (6, k) rows (m00, m01, m02, m11, m12, m22) and u (3, k)."""
    return np.stack(
        (
            (m[0] * u[0] + m[1] * u[1]) + m[2] * u[2],
            (m[1] * u[0] + m[3] * u[1]) + m[4] * u[2],
            (m[2] * u[0] + m[4] * u[1]) + m[5] * u[2],
        )
    )


def arm_inertia(m: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """(K, G) for symmetric M (6, k) and lever arms r (3, k): K = [r]x^T M [r]x as (6, k) rows
    (k00, k01, k02, k11, k12, k22), K_ij = c_i . M c_j with c_j the columns of [r]x; and
    G = M [r]x as its three columns M c_j, (3, k) each, so that M (r x f) = sum_j G_j f_j."""
    zero = np.zeros_like(r[0])
    cols = (np.stack((zero, r[2], -r[1])), np.stack((-r[2], zero, r[0])), np.stack((r[1], -r[0], zero)))
    mc = [sym_matvec(m, c) for c in cols]
    return np.stack(
        (
            dot3(cols[0], mc[0]),
            dot3(cols[0], mc[1]),
            dot3(cols[0], mc[2]),
            dot3(cols[1], mc[1]),
            dot3(cols[1], mc[2]),
            dot3(cols[2], mc[2]),
        )
    ), mc


def inv_world_inertia(q: np.ndarray, inv_inertia: np.ndarray) -> np.ndarray:
    """R diag(I^-1) R^T of every body as (6, B) rows (m00, m01, m02, m11, m12, m22)."""
    qw, qx, qy, qz = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r00 = 1 - 2 * (qy * qy + qz * qz)
    r01 = 2 * (qx * qy - qw * qz)
    r02 = 2 * (qx * qz + qw * qy)
    r10 = 2 * (qx * qy + qw * qz)
    r11 = 1 - 2 * (qx * qx + qz * qz)
    r12 = 2 * (qy * qz - qw * qx)
    r20 = 2 * (qx * qz - qw * qy)
    r21 = 2 * (qy * qz + qw * qx)
    r22 = 1 - 2 * (qx * qx + qy * qy)
    i0, i1, i2 = inv_inertia[:, 0], inv_inertia[:, 1], inv_inertia[:, 2]
    return np.stack(
        (
            r00 * i0 * r00 + r01 * i1 * r01 + r02 * i2 * r02,
            r00 * i0 * r10 + r01 * i1 * r11 + r02 * i2 * r12,
            r00 * i0 * r20 + r01 * i1 * r21 + r02 * i2 * r22,
            r10 * i0 * r10 + r11 * i1 * r11 + r12 * i2 * r12,
            r10 * i0 * r20 + r11 * i1 * r21 + r12 * i2 * r22,
            r20 * i0 * r20 + r21 * i1 * r21 + r22 * i2 * r22,
        )
    )
