"""Velocity Verlet (Swope, Andersen, Berens and Wilson 1982), as animsim steps it.

Velocity-dependent forces (drag, spring damping) are evaluated at the predicted
velocity v + dt a, then corrected by the trapezoid rule, so the method stays second
order. The acceleration taken at the end of one step (at the predicted velocity) is
reused as the next step's first one, so the state one step hands to the next is
(x, v, a): with damping its stability limit is below the textbook velocity Verlet's
(2 (sqrt 2 - 1) / omega instead of 2 / omega at zeta = 0.5).
"""

import numpy as np

from animsim.methods import Method, register


def one_step(h: np.ndarray, k: np.ndarray, c: np.ndarray) -> np.ndarray:
    """State (x, v, a0), a0 the cached acceleration (animsim.integrators.symplectic.Verlet.step):
    x1 = x + h v + h^2/2 a0,  vp = v + h a0,  a1 = -k x1 - c vp,  v1 = v + h/2 (a0 + a1),
    next a0 = a1."""
    zero, one = np.zeros_like(h), np.ones_like(h)
    x1 = np.stack([one, h, 0.5 * h * h], axis=-1)
    vp = np.stack([zero, one, h], axis=-1)
    a1 = -k[..., None] * x1 - c[..., None] * vp
    out = np.zeros((*h.shape, 3, 3))
    out[..., 0, :] = x1
    out[..., 1, :] = np.stack([zero, one, 0.5 * h], axis=-1) + 0.5 * h[..., None] * a1
    out[..., 2, :] = a1
    return out


def initial_state(omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """Verlet computes its first acceleration, a = -omega^2 x - 2 zeta omega v, from (x, v)."""
    out = np.zeros((*omega.shape, 3, 2))
    out[..., 0, 0] = out[..., 1, 1] = 1.0
    out[..., 2, 0] = -(omega**2)
    out[..., 2, 1] = -2.0 * zeta * omega
    return out


register(
    Method(
        name="verlet",
        rank=80,
        order=2,
        description="velocity Verlet; velocity-dependent forces at a predicted velocity",
        evaluations_per_step=1,
        one_step=one_step,
        follow_weight=0.5,
        stepper="animsim.integrators.symplectic:Verlet",
        state_size=3,
        initial_state=initial_state,
        work_vectors=3,
        suggest_rank=2,
        aliases=("velocity_verlet", "leapfrog"),
    )
)
