"""The "Euler 2" of the CSE 3541 course notes: endv = v + dt a; x += dt (v + endv)/2; v = endv.

Exact for a constant force, first order otherwise; on an undamped oscillator the one-step
matrix has determinant 1 + (omega dt)^2 / 2, so it amplifies at every step size.
"""

import numpy as np

from animsim.methods import Method, register


def one_step(h: np.ndarray, k: np.ndarray, c: np.ndarray) -> np.ndarray:
    """a0 = -k x - c v; v1 = v + h a0; x1 = x + h (v + v1)/2 = x + h v + h^2/2 a0."""
    out = np.zeros((*h.shape, 2, 2))
    out[..., 0, 0] = 1.0 - 0.5 * h * h * k
    out[..., 0, 1] = h - 0.5 * h * h * c
    out[..., 1, 0] = -h * k
    out[..., 1, 1] = 1.0 - h * c
    return out


register(
    Method(
        name="euler_average",
        rank=30,
        order=1,
        description="Euler 2 of the notes: v1 = v + dt*a; x += dt*(v+v1)/2; v = v1",
        evaluations_per_step=1,
        one_step=one_step,
        follow_weight=0.5,
        stepper="animsim.integrators.symplectic:EulerAverage",
        work_vectors=2,
    )
)
