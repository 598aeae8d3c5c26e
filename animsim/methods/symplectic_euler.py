"""Symplectic (semi-implicit) Euler, the course notes' default: v += dt a(t); x += dt v(t + dt).

Symplectic, so an undamped oscillator's energy stays bounded for omega dt < 2
(Hairer, Lubich and Wanner, "Geometric Numerical Integration", I.1).
"""

import numpy as np

from animsim.methods import Method, register


def one_step(h: np.ndarray, k: np.ndarray, c: np.ndarray) -> np.ndarray:
    """v1 = v + h (-k x - c v); x1 = x + h v1."""
    out = np.zeros((*h.shape, 2, 2))
    out[..., 1, 0] = -h * k
    out[..., 1, 1] = 1.0 - h * c
    out[..., 0, 0] = 1.0 + h * out[..., 1, 0]
    out[..., 0, 1] = h * out[..., 1, 1]
    return out


def closed_form_limit(omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """h <= 2 (sqrt(zeta^2 + 1) - zeta) / omega, i.e. (sqrt(c^2 + 4 k m) - c) / k for one spring:
    where the trace of the one-step matrix, 2 - h c - h^2 k, reaches -(1 + det) = -(2 - h c)."""
    # written without the cancellation (and the inf - inf of a zeta beyond 1e154) of the difference
    return np.asarray(2.0 / ((np.hypot(zeta, 1.0) + zeta) * omega))


register(
    Method(
        name="symplectic_euler",
        rank=20,
        order=1,
        description="semi-implicit Euler: v += dt*a(t); x += dt*v(t+dt)",
        evaluations_per_step=1,
        one_step=one_step,
        follow_weight=1.0,
        stepper="animsim.integrators.symplectic:SymplecticEuler",
        closed_form_limit=closed_form_limit,
        work_vectors=1,
        suggest_rank=1,
        aliases=("semi_implicit_euler", "symplectic"),
    )
)
