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
    in a fixed order.
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


#: the free rotation's implicit midpoint equation is solved by fixed-point iteration until an
#: iterate moves L by no more than this fraction of |L| (or MIDPOINT_ITERATIONS iterations)
MIDPOINT_TOLERANCE = 1e-15
MIDPOINT_ITERATIONS = 100


def advance_rotation(
    q: np.ndarray,
    omega: np.ndarray,
    alpha_torque: np.ndarray,
    inertia: np.ndarray,
    inv_inertia: np.ndarray,
    dt: float,
) -> None:
    """In place: the rotation half of symplectic Euler, a kick by the torques then a free rotation
    that keeps the body's energy and angular momentum.

    1. Kick: omega += dt I_w^-1 tau (``alpha_torque``, the torques' part of omega' alone).
    2. Free rotation for dt, in the body frame, where L = I w and Euler's equations read
       L' = L x I^-1 L: the implicit midpoint rule L1 = L0 + dt (Lm x I^-1 Lm), Lm = (L0 + L1) / 2.
       Like every symplectic Runge-Kutta method it keeps the quadratic invariants |L|^2 and
       L . I^-1 L (the kinetic energy) exactly (Hairer, Lubich, Wanner, "Geometric Numerical
       Integration", 2006, sec. IV.2 and VII.5). Given wm = I^-1 Lm, the step is the Cayley
       rotation L1 = cay(-dt [wm]x) L0; turning the body by the same Cayley rotation,
       q1 = q0 (x) (1, dt wm / 2) / |.|, keeps L in the world, R1 L1 = R0 L0, exactly.
       The equation is solved by fixed-point iteration (contracting while dt |omega| < 1).

    The explicit gyroscopic term of ``omega += dt omega'`` instead pumps energy into a tumbling
    body (its kinetic energy triples in 100 s at dt 0.01); this update keeps it to rounding.
    Pinned bodies (``inv_inertia`` 0) keep omega and turn with it. The numba backend runs
    :func:`numba_advance_rotation`, the same operations in the same order.
    """
    free = inv_inertia[:, 0] > 0.0
    omega += dt * alpha_torque
    wb = rotate_inverse(q, omega)
    l0 = inertia * wb
    l1 = l0.copy()
    scale = MIDPOINT_TOLERANCE * np.sqrt((l0[:, 0] * l0[:, 0] + l0[:, 1] * l0[:, 1]) + l0[:, 2] * l0[:, 2])
    active = free.copy()
    wm = wb.copy()
    for _ in range(MIDPOINT_ITERATIONS):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        lm = 0.5 * (l0[idx] + l1[idx])
        wmi = inv_inertia[idx] * lm
        nx = l0[idx, 0] + dt * (lm[:, 1] * wmi[:, 2] - lm[:, 2] * wmi[:, 1])
        ny = l0[idx, 1] + dt * (lm[:, 2] * wmi[:, 0] - lm[:, 0] * wmi[:, 2])
        nz = l0[idx, 2] + dt * (lm[:, 0] * wmi[:, 1] - lm[:, 1] * wmi[:, 0])
        moved = np.maximum(
            np.abs(nx - l1[idx, 0]), np.maximum(np.abs(ny - l1[idx, 1]), np.abs(nz - l1[idx, 2]))
        )
        l1[idx, 0], l1[idx, 1], l1[idx, 2] = nx, ny, nz
        active[idx] = moved > scale[idx]
    lm = 0.5 * (l0 + l1)
    wm = np.where(free[:, None], inv_inertia * lm, wb)
    half = 0.5 * dt
    turn = np.stack([np.ones(q.shape[0]), half * wm[:, 0], half * wm[:, 1], half * wm[:, 2]], axis=-1)
    q[:] = normalise(multiply(q, turn))
    omega[:] = np.where(free[:, None], rotate(q, inv_inertia * l1), omega)


def _advance_rotation_loop(
    q: np.ndarray,
    omega: np.ndarray,
    alpha_torque: np.ndarray,
    inertia: np.ndarray,
    inv_inertia: np.ndarray,
    dt: float,
) -> None:
    """Loop form of :func:`advance_rotation`, compiled by numba (same operations, same order)."""
    for b in range(q.shape[0]):
        free = inv_inertia[b, 0] > 0.0
        omega[b, 0] += dt * alpha_torque[b, 0]
        omega[b, 1] += dt * alpha_torque[b, 1]
        omega[b, 2] += dt * alpha_torque[b, 2]
        qw, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        bx, by, bz = rotate_scalar(qw, -qx, -qy, -qz, omega[b, 0], omega[b, 1], omega[b, 2])
        l0x, l0y, l0z = inertia[b, 0] * bx, inertia[b, 1] * by, inertia[b, 2] * bz
        l1x, l1y, l1z = l0x, l0y, l0z
        scale = MIDPOINT_TOLERANCE * np.sqrt((l0x * l0x + l0y * l0y) + l0z * l0z)
        if free:
            for _ in range(MIDPOINT_ITERATIONS):
                lmx, lmy, lmz = 0.5 * (l0x + l1x), 0.5 * (l0y + l1y), 0.5 * (l0z + l1z)
                wx, wy, wz = inv_inertia[b, 0] * lmx, inv_inertia[b, 1] * lmy, inv_inertia[b, 2] * lmz
                nx = l0x + dt * (lmy * wz - lmz * wy)
                ny = l0y + dt * (lmz * wx - lmx * wz)
                nz = l0z + dt * (lmx * wy - lmy * wx)
                moved = max(abs(nx - l1x), max(abs(ny - l1y), abs(nz - l1z)))
                l1x, l1y, l1z = nx, ny, nz
                if not moved > scale:
                    break
            lmx, lmy, lmz = 0.5 * (l0x + l1x), 0.5 * (l0y + l1y), 0.5 * (l0z + l1z)
            mx, my, mz = inv_inertia[b, 0] * lmx, inv_inertia[b, 1] * lmy, inv_inertia[b, 2] * lmz
        else:
            mx, my, mz = bx, by, bz
        half = 0.5 * dt
        px, py, pz = half * mx, half * my, half * mz
        # q (x) (1, p), as multiply()
        q0 = ((qw * 1.0 - qx * px) - qy * py) - qz * pz
        q1 = ((qw * px + qx * 1.0) + qy * pz) - qz * py
        q2 = ((qw * py - qx * pz) + qy * 1.0) + qz * px
        q3 = ((qw * pz + qx * py) - qy * px) + qz * 1.0
        norm = np.sqrt(((q0 * q0 + q1 * q1) + q2 * q2) + q3 * q3)
        q0, q1, q2, q3 = q0 / norm, q1 / norm, q2 / norm, q3 / norm
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = q0, q1, q2, q3
        if free:
            ox, oy, oz = rotate_scalar(
                q0, q1, q2, q3, inv_inertia[b, 0] * l1x, inv_inertia[b, 1] * l1y, inv_inertia[b, 2] * l1z
            )
            omega[b, 0], omega[b, 1], omega[b, 2] = ox, oy, oz


@cache
def numba_advance_rotation() -> Any:
    """The numba twin of :func:`advance_rotation`, compiled on first use."""
    from numba import njit

    compile_helpers(globals())
    return njit(cache=True)(_advance_rotation_loop)


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
