"""Quaternion math and the rotational equations of motion of rigid bodies.

Conventions (as in the scene language): Hamilton quaternions ``[w, x, y, z]``;
``R(q)`` maps the body frame to the world, so a point ``p`` fixed in the body is
at ``x + R(q) p``; angular velocity ``omega`` is in the world frame.

Equations (Baraff, "Rigid Body Dynamics", SIGGRAPH 1997 course notes, sections
on orientation and angular momentum):

* ``q' = 1/2 (0, omega) (x) q``                        (notes, eq. 4-2 in quaternion form)
* ``I_w = R diag(I) R^T``                               (inertia in the world)
* ``omega' = I_w^-1 (tau - omega x (I_w omega))``      (Euler's equations in the world)

Every function is vectorised over bodies (leading axis B). The numba twin of
:func:`angular_acceleration` lives here too, built on first use so importing
this module never imports numba.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

from animsim.elements import compile_helpers, numba_helper

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p (x) q of (..., 4) arrays."""
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def conjugate(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def normalise(q: np.ndarray) -> np.ndarray:
    """q / |q| (unit quaternions stay rotations; integrators drift off the unit sphere).

    |q|^2 is summed w, x, y, z in order, as the numba kernels do (``np.linalg.norm``
    chooses its own order), so both backends round alike.
    """
    s = ((q[..., 0] * q[..., 0] + q[..., 1] * q[..., 1]) + q[..., 2] * q[..., 2]) + q[..., 3] * q[..., 3]
    return q / np.sqrt(s)[..., None]


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q) v for unit q, without building matrices: v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z)."""
    # written out (np.cross costs more than the arithmetic on many short rows); the same
    # operations as the cross products, and q broadcasts against v ((B, 1, 4) with (B, K, 3))
    qw, ux, uy, uz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    tx = 2.0 * (uy * vz - uz * vy)
    ty = 2.0 * (uz * vx - ux * vz)
    tz = 2.0 * (ux * vy - uy * vx)
    return np.stack(
        [
            vx + qw * tx + (uy * tz - uz * ty),
            vy + qw * ty + (uz * tx - ux * tz),
            vz + qw * tz + (ux * ty - uy * tx),
        ],
        axis=-1,
    )


@numba_helper
def rotate_scalar(
    qw: float, ux: float, uy: float, uz: float, vx: float, vy: float, vz: float
) -> tuple[float, float, float]:
    """:func:`rotate` on scalars, for the numba loops (the same operations in the same
    order, so both backends agree to the bit). For R(q)^T v pass u = -(x, y, z)."""
    tx = 2.0 * (uy * vz - uz * vy)
    ty = 2.0 * (uz * vx - ux * vz)
    tz = 2.0 * (ux * vy - uy * vx)
    return (
        vx + qw * tx + (uy * tz - uz * ty),
        vy + qw * ty + (uz * tx - ux * tz),
        vz + qw * tz + (ux * ty - uy * tx),
    )


def rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q)^T v: a world vector in the body frame."""
    return rotate(conjugate(q), v)


def to_matrix(q: np.ndarray) -> np.ndarray:
    """R(q), shape (..., 3, 3), of a unit quaternion."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )


def from_axis_angle(axis: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    """The unit quaternion of a right-handed rotation by ``angle`` (radians) about ``axis``."""
    axis = np.asarray(axis, dtype=np.float64)
    a = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = 0.5 * np.asarray(angle, dtype=np.float64)[..., None]
    return np.concatenate([np.cos(half), np.sin(half) * a], axis=-1)


def derivative(q: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """q' = 1/2 (0, omega) (x) q with omega in the world frame (Baraff 1997).

    The Hamilton product of :func:`multiply` with its zero term left out, written
    in the order :func:`_advance_orientation_loop` uses.
    """
    wx, wy, wz = omega[..., 0], omega[..., 1], omega[..., 2]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return 0.5 * np.stack(
        [
            (-wx * qx - wy * qy) - wz * qz,
            (wx * qw + wy * qz) - wz * qy,
            (-wx * qz + wy * qw) + wz * qx,
            (wx * qy - wy * qx) + wz * qw,
        ],
        axis=-1,
    )


def advance_orientation(q: np.ndarray, omega: np.ndarray, alpha: np.ndarray, dt: float) -> None:
    """In place: omega += dt alpha; q += dt q'(q, omega); q /= |q| (symplectic Euler's rotation
    half). The numba backend runs :func:`numba_advance_orientation`, the same operations."""
    omega += dt * alpha
    q += dt * derivative(q, omega)
    q[:] = normalise(q)


def _advance_orientation_loop(q: np.ndarray, omega: np.ndarray, alpha: np.ndarray, dt: float) -> None:
    """Loop form of :func:`advance_orientation`, compiled by numba."""
    for b in range(q.shape[0]):
        omega[b, 0] += dt * alpha[b, 0]
        omega[b, 1] += dt * alpha[b, 1]
        omega[b, 2] += dt * alpha[b, 2]
        wx, wy, wz = omega[b, 0], omega[b, 1], omega[b, 2]
        qw, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        d0 = 0.5 * ((-wx * qx - wy * qy) - wz * qz)
        d1 = 0.5 * ((wx * qw + wy * qz) - wz * qy)
        d2 = 0.5 * ((-wx * qz + wy * qw) + wz * qx)
        d3 = 0.5 * ((wx * qy - wy * qx) + wz * qw)
        q0, q1, q2, q3 = qw + dt * d0, qx + dt * d1, qy + dt * d2, qz + dt * d3
        norm = np.sqrt(((q0 * q0 + q1 * q1) + q2 * q2) + q3 * q3)
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = q0 / norm, q1 / norm, q2 / norm, q3 / norm


@cache
def numba_advance_orientation() -> Any:
    """The numba twin of :func:`advance_orientation`, compiled on first use."""
    from numba import njit

    return njit(cache=True)(_advance_orientation_loop)


def world_inertia(q: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """I_w = R diag(I) R^T, shape (B, 3, 3)."""
    r = to_matrix(q)
    return np.einsum("bij,bj,bkj->bik", r, inertia, r)


def angular_momentum(q: np.ndarray, omega: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """L = I_w omega about each centre of mass, (B, 3)."""
    return rotate(q, inertia * rotate_inverse(q, omega))


def rotational_energy(q: np.ndarray, omega: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """1/2 omega . I_w omega per body, (B,)."""
    wb = rotate_inverse(q, omega)
    return 0.5 * np.einsum("bi,bi->b", inertia * wb, wb)


def angular_acceleration(
    q: np.ndarray, omega: np.ndarray, inertia: np.ndarray, inv_inertia: np.ndarray, torque: np.ndarray
) -> np.ndarray:
    """omega' = I_w^-1 (tau - omega x (I_w omega)), (B, 3), world frame.

    Evaluated in the body frame, where I_w is diagonal: with w_b = R^T omega and
    tau_b = R^T tau, R^T (omega x I_w omega) = w_b x (I w_b), so
    omega' = R (I^-1 (tau_b - w_b x (I w_b))). ``inv_inertia`` is 0 for pinned
    bodies, whose angular velocity then never changes.
    """
    wb = rotate_inverse(q, omega)
    tb = rotate_inverse(q, torque)
    ab = inv_inertia * (tb - np.cross(wb, inertia * wb))
    return rotate(q, ab)


def _angular_acceleration_loop(
    q: np.ndarray,
    omega: np.ndarray,
    inertia: np.ndarray,
    inv_inertia: np.ndarray,
    torque: np.ndarray,
    out: np.ndarray,
) -> None:
    """Loop form of :func:`angular_acceleration`, compiled by numba (same operations, same order)."""
    for b in range(q.shape[0]):
        qw, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        # body frame: R^T v, the rotation with u = -(x, y, z)
        bx, by, bz = rotate_scalar(qw, -qx, -qy, -qz, omega[b, 0], omega[b, 1], omega[b, 2])
        cx, cy, cz = rotate_scalar(qw, -qx, -qy, -qz, torque[b, 0], torque[b, 1], torque[b, 2])
        lx, ly, lz = inertia[b, 0] * bx, inertia[b, 1] * by, inertia[b, 2] * bz
        ax = inv_inertia[b, 0] * (cx - (by * lz - bz * ly))
        ay = inv_inertia[b, 1] * (cy - (bz * lx - bx * lz))
        az = inv_inertia[b, 2] * (cz - (bx * ly - by * lx))
        out[b, 0], out[b, 1], out[b, 2] = rotate_scalar(qw, qx, qy, qz, ax, ay, az)


@cache
def numba_angular_acceleration() -> Any:
    """The numba twin of :func:`angular_acceleration`, compiled on first use.

    Signature: (q (B,4), omega (B,3), inertia (B,3), inv_inertia (B,3), torque (B,3), out (B,3)).
    """
    from numba import njit

    compile_helpers(globals())
    return njit(cache=True)(_angular_acceleration_loop)
