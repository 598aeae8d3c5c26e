"""Backward (implicit) Euler, linearised once per step (Baraff and Witkin, "Large steps in
cloth simulation", SIGGRAPH 1998, Eq. 6). A-stable: no step-size limit on linear damped
springs. With no force that offers a Jacobian its linear system is M dv = dt f, which is
symplectic Euler step for step."""

import numpy as np

from animsim.methods import Method, register


def one_step(h: np.ndarray, k: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(I - h J) y1 = y0 for J = [[0, 1], [-k, -c]]."""
    j = np.zeros((*h.shape, 2, 2))
    j[..., 0, 1] = h
    j[..., 1, 0] = -h * k
    j[..., 1, 1] = -h * c
    return np.linalg.inv(np.eye(2) - j)


register(
    Method(
        name="implicit_euler",
        rank=90,
        order=1,
        description="backward Euler linearised per step (Baraff & Witkin 1998)",
        evaluations_per_step=1,
        one_step=one_step,
        follow_weight=1.0,
        stepper="animsim.integrators.implicit:ImplicitEuler",
        # conjugate-gradient vectors and the linearised system's work arrays
        work_vectors=12,
        # the linearised step adds a 3x3 block of float64 per spring, both directions, twice
        spring_work_bytes=2 * 9 * 8 * 2,
        # linearised over particle positions only
        integrates_bodies=False,
        # runs on its own in compare and the parity tables: its cost is of another kind
        listed=False,
        aliases=("backward_euler",),
        explicit_fallback="symplectic_euler",
    )
)
